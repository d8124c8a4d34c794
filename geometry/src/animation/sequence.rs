//! OBJ/PLY frame sequences of fixed topology: one file per frame, from a directory (natural
//! order: `f2` before `f10`), a printf pattern (`frames/f_%04d.ply`) or a glob on the file
//! name (`frames/f_*.obj`).

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::error::AnimationError;
use super::template::{AnimatedTemplate, DEFAULT_FPS, frame_rate_or};
use crate::io::files::read_mesh;
use crate::mesh::TriMesh;

/// A sequence of mesh files with the topology of the first one.
///
/// Frames are read on demand; each is checked against the first (same vertex count and the
/// same triangles), and a mismatch names the frame file.
#[derive(Clone, Debug)]
pub struct MeshSequence {
    files: Vec<PathBuf>,
    rest: TriMesh,
    fps: f64,
}

/// Compares file names in natural order: runs of digits compare by value (`2 < 10`),
/// everything else byte by byte; ties (`01` vs `1`) fall back to plain comparison.
#[must_use]
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (ab, bb) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < ab.len() && j < bb.len() {
        if ab[i].is_ascii_digit() && bb[j].is_ascii_digit() {
            let si = i;
            while i < ab.len() && ab[i].is_ascii_digit() {
                i += 1;
            }
            let sj = j;
            while j < bb.len() && bb[j].is_ascii_digit() {
                j += 1;
            }
            let da = a[si..i].trim_start_matches('0');
            let db = b[sj..j].trim_start_matches('0');
            let ord = da.len().cmp(&db.len()).then_with(|| da.cmp(db));
            if ord != Ordering::Equal {
                return ord;
            }
        } else {
            let ord = ab[i].cmp(&bb[j]);
            if ord != Ordering::Equal {
                return ord;
            }
            i += 1;
            j += 1;
        }
    }
    (ab.len() - i).cmp(&(bb.len() - j)).then_with(|| a.cmp(b))
}

/// Matches `name` against a glob with `*` (any run) and `?` (one character).
fn glob_match(pattern: &[char], name: &[char]) -> bool {
    match pattern.split_first() {
        None => name.is_empty(),
        Some(('*', rest)) => (0..=name.len()).any(|k| glob_match(rest, &name[k..])),
        Some(('?', rest)) => !name.is_empty() && glob_match(rest, &name[1..]),
        Some((c, rest)) => name.first() == Some(c) && glob_match(rest, &name[1..]),
    }
}

/// Parses a printf integer conversion (`%d`, `%4d`, `%04d`) in `pattern`: prefix, minimum
/// width, suffix.
fn printf_parts(pattern: &str) -> Option<(&str, usize, &str)> {
    let start = pattern.find('%')?;
    let rest = &pattern[start + 1..];
    let d = rest.find('d')?;
    let spec = &rest[..d];
    if !spec.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    // Only a zero-padded conversion fixes the digit count; `%d` and `%4d` take any digits.
    let width = if spec.starts_with('0') {
        spec.trim_start_matches('0').parse().unwrap_or(0)
    } else {
        0
    };
    Some((&pattern[..start], width, &rest[d + 1..]))
}

fn is_mesh_file(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("obj") || e.eq_ignore_ascii_case("ply"))
}

fn list_dir(dir: &Path) -> Result<Vec<PathBuf>, AnimationError> {
    let entries = std::fs::read_dir(dir).map_err(|error| AnimationError::Os {
        path: dir.to_path_buf(),
        error,
    })?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|error| AnimationError::Os {
            path: dir.to_path_buf(),
            error,
        })?;
        let path = entry.path();
        if path.is_file() {
            files.push(path);
        }
    }
    Ok(files)
}

fn sort_natural(files: &mut [PathBuf]) {
    files.sort_by(|a, b| {
        let an = a
            .file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default();
        let bn = b
            .file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default();
        natural_cmp(&an, &bn)
    });
}

impl MeshSequence {
    /// Every `.obj`/`.ply` file in `dir`, in natural order of their names.
    ///
    /// # Errors
    /// [`AnimationError::NoFrames`] when there are none; read errors of the first frame.
    pub fn from_dir(dir: &Path) -> Result<Self, AnimationError> {
        let mut files: Vec<PathBuf> = list_dir(dir)?
            .into_iter()
            .filter(|p| is_mesh_file(p))
            .collect();
        sort_natural(&mut files);
        Self::from_files(files, &dir.display().to_string())
    }

    /// Files matching `pattern`: a printf integer conversion in the file name
    /// (`out/frame_%04d.ply`, ordered by the number; `%04d` takes 4 digits, or more without a
    /// leading zero; `%d` any digits) or a glob with `*`/`?` in the file name (natural
    /// order). A pattern naming a directory lists that directory.
    ///
    /// # Errors
    /// [`AnimationError::NoFrames`] when nothing matches; read errors of the first frame.
    pub fn from_pattern(pattern: &str) -> Result<Self, AnimationError> {
        let as_path = Path::new(pattern);
        if as_path.is_dir() {
            return Self::from_dir(as_path);
        }
        let dir = match as_path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name_pattern = as_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut files = Vec::new();
        if let Some((prefix, width, suffix)) = printf_parts(&name_pattern) {
            let mut numbered = Vec::new();
            for path in list_dir(&dir)? {
                let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else {
                    continue;
                };
                let Some(mid) = name
                    .strip_prefix(prefix)
                    .and_then(|r| r.strip_suffix(suffix))
                else {
                    continue;
                };
                let digits_ok = !mid.is_empty() && mid.bytes().all(|b| b.is_ascii_digit());
                // `%0Nd` pads to N digits: shorter is not ours, longer only without a
                // leading zero.
                let width_ok = width == 0
                    || mid.len() == width
                    || (mid.len() > width && !mid.starts_with('0'));
                if digits_ok
                    && width_ok
                    && let Ok(n) = mid.parse::<u64>()
                {
                    numbered.push((n, path));
                }
            }
            numbered.sort();
            files = numbered.into_iter().map(|(_, p)| p).collect();
        } else if name_pattern.contains(['*', '?']) {
            let pat: Vec<char> = name_pattern.chars().collect();
            for path in list_dir(&dir)? {
                let name: Vec<char> = path
                    .file_name()
                    .map(|n| n.to_string_lossy().chars().collect())
                    .unwrap_or_default();
                if glob_match(&pat, &name) {
                    files.push(path);
                }
            }
            sort_natural(&mut files);
        } else if as_path.is_file() {
            files.push(as_path.to_path_buf());
        }
        Self::from_files(files, pattern)
    }

    /// An explicit list of frame files, in this order (`what` names the source in errors).
    ///
    /// # Errors
    /// [`AnimationError::NoFrames`] for an empty list; read errors of the first frame.
    pub fn from_files(files: Vec<PathBuf>, what: &str) -> Result<Self, AnimationError> {
        let Some(first) = files.first() else {
            return Err(AnimationError::NoFrames {
                pattern: what.to_string(),
            });
        };
        let rest = read_mesh(first)?;
        Ok(Self {
            files,
            rest,
            fps: DEFAULT_FPS,
        })
    }

    /// Sets the frame rate (finite and > 0; other values keep the current one).
    #[must_use]
    pub fn with_fps(mut self, fps: f64) -> Self {
        self.fps = frame_rate_or(fps, self.fps);
        self
    }

    /// The frame files in order.
    #[must_use]
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Reads every frame once and checks its topology, reporting the first bad file.
    ///
    /// # Errors
    /// As [`AnimatedTemplate::frame`].
    pub fn validate_all(&self) -> Result<(), AnimationError> {
        (0..self.files.len()).try_for_each(|i| self.frame(i).map(|_| ()))
    }
}

impl AnimatedTemplate for MeshSequence {
    fn frame_count(&self) -> usize {
        self.files.len()
    }

    fn frame_time(&self, frame: usize) -> Option<f64> {
        (frame < self.files.len()).then(|| frame as f64 / self.fps)
    }

    fn topology(&self) -> &[[u32; 3]] {
        self.rest.triangles()
    }

    fn rest(&self) -> &TriMesh {
        &self.rest
    }

    fn frame(&self, frame: usize) -> Result<Vec<DVec3>, AnimationError> {
        let path = self
            .files
            .get(frame)
            .ok_or(AnimationError::FrameOutOfRange {
                frame,
                count: self.files.len(),
            })?;
        if frame == 0 {
            return Ok(self.rest.positions().to_vec());
        }
        let mesh = read_mesh(path)?;
        check_topology(&mesh, &self.rest, path, &self.files[0])?;
        let (positions, ..) = mesh.into_parts();
        Ok(positions)
    }
}

/// Checks that `mesh` (read from `path`) has the vertex count and triangles of `reference`
/// (read from `reference_path`).
///
/// # Errors
/// [`AnimationError::TopologyMismatch`] naming both files and the first difference.
pub fn check_topology(
    mesh: &TriMesh,
    reference: &TriMesh,
    path: &Path,
    reference_path: &Path,
) -> Result<(), AnimationError> {
    let mismatch = |message: String| AnimationError::TopologyMismatch {
        path: path.to_path_buf(),
        reference: reference_path.to_path_buf(),
        message,
    };
    if mesh.vertex_count() != reference.vertex_count() {
        return Err(mismatch(format!(
            "{} vertices instead of {}",
            mesh.vertex_count(),
            reference.vertex_count()
        )));
    }
    if mesh.triangle_count() != reference.triangle_count() {
        return Err(mismatch(format!(
            "{} triangles instead of {}",
            mesh.triangle_count(),
            reference.triangle_count()
        )));
    }
    if let Some(t) = mesh
        .triangles()
        .iter()
        .zip(reference.triangles())
        .position(|(a, b)| a != b)
    {
        return Err(mismatch(format!(
            "triangle {t} is {:?} instead of {:?}",
            mesh.triangles()[t],
            reference.triangles()[t]
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut v = vec!["f10.obj", "f2.obj", "f1.obj", "f02.obj", "a.obj"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["a.obj", "f1.obj", "f02.obj", "f2.obj", "f10.obj"]);
    }

    #[test]
    fn glob_and_printf() {
        let p: Vec<char> = "f_*.p?y".chars().collect();
        assert!(glob_match(&p, &"f_12.ply".chars().collect::<Vec<_>>()));
        assert!(!glob_match(&p, &"g_12.ply".chars().collect::<Vec<_>>()));
        assert_eq!(printf_parts("f_%04d.ply"), Some(("f_", 4, ".ply")));
        assert_eq!(printf_parts("f_%d.ply"), Some(("f_", 0, ".ply")));
        assert_eq!(printf_parts("f_%4d.ply"), Some(("f_", 0, ".ply")));
        assert_eq!(printf_parts("f_%s.ply"), None);
    }
}
