//! Reading every frame once before anything is written: checks, the layout, sizes, runs of one
//! topology and their bounding boxes; and the frames' glTF key times.

use std::borrow::Cow;
use std::ops::Range;
use std::path::Path;

use glam::DVec3;

use super::options::SequenceLayout;
use super::pca::sketch_stride;
use super::source::FrameSource;
use crate::io::error::IoError;
use crate::mesh::TriMesh;

/// Consecutive runs of frames whose buffers stay within `max_bytes`: each frame's bound from
/// `sizes`, plus the morph layout's weights track (4 bytes per frame and target, quadratic in
/// the frames of a part).
pub(super) fn split(
    path: &Path,
    sizes: &[u64],
    max_bytes: u64,
) -> Result<Vec<std::ops::Range<usize>>, IoError> {
    let fits = |frames: u64, bytes: u64| bytes.saturating_add(4 * frames * frames) <= max_bytes;
    let mut runs = Vec::new();
    let (mut start, mut bytes) = (0, 0u64);
    for (k, &size) in sizes.iter().enumerate() {
        if !fits(1, size) {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                what: format!("frame {k} alone needs {size} bytes, over the {max_bytes}-byte part"),
            });
        }
        if !fits((k + 1 - start) as u64, bytes + size) {
            runs.push(start..k);
            (start, bytes) = (k, 0);
        }
        bytes += size;
    }
    runs.push(start..sizes.len());
    Ok(runs)
}

/// What one read of every frame tells before anything is written.
pub(super) struct Survey {
    /// Whether the morph-target layout is used.
    pub(super) morph: bool,
    /// Morph targets carry normal deltas (every frame has normals).
    pub(super) normals: bool,
    /// Per frame, an upper bound of the buffer bytes it adds in either layout (its vertex
    /// data, its own indices and its animation keys).
    pub(super) sizes: Vec<u64>,
    /// Runs of consecutive frames with one vertex count and the same triangles (a frame
    /// without triangles is a run of its own; one run per frame for
    /// [`SequenceLayout::NodePerFrame`]).
    pub(super) segments: Vec<Range<usize>>,
    /// Per segment, the bounding box (min, max) of its vertices over all its frames.
    pub(super) bounds: Vec<(DVec3, DVec3)>,
    /// Per segment, the smallest bounding-box diagonal of one of its frames.
    pub(super) diagonals: Vec<f64>,
    /// The diagonal of the bounding box of every vertex of every frame (0 without vertices).
    pub(super) diagonal: f64,
    /// The quantised position deltas of one morph target per frame after each segment's first
    /// (8 bytes per vertex), before compression: what a morph basis would replace.
    pub(super) target_payload: u64,
    /// Per frame, its positions at every [`sketch_stride`]-th vertex, when asked for: the
    /// morph basis's sketch taken in this reading (module `pca`), so that its fit reads every
    /// frame once less. Empty when not asked for or taken.
    pub(super) sketch: Vec<Vec<DVec3>>,
}

impl Survey {
    /// Checks every frame (finite positions; for morph targets the topology of frame 0) and
    /// decides the layout; with `sketch`, keeps every frame's positions at every
    /// [`sketch_stride`]-th vertex ([`Self::sketch`]).
    pub(super) fn of(
        path: &Path,
        frames: &dyn FrameSource,
        layout: SequenceLayout,
        sketch: bool,
    ) -> Result<Self, IoError> {
        let base = frames.frame(0)?;
        let mut same = base.triangle_count() > 0;
        let mut segments: Vec<Range<usize>> = Vec::new();
        segments.push(0..1);
        // The first frame of the current segment (frame 0 is `base`).
        let mut segment_base: Option<TriMesh> = None;
        if layout == SequenceLayout::MorphTargets && !same {
            return Err(IoError::malformed(
                path,
                "frame 0",
                "has no triangles (morph targets need a base mesh)",
            ));
        }
        let mut normals = base.normals().is_some();
        let empty = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let mut bounds = vec![empty];
        let mut diagonals = vec![f64::INFINITY];
        let mut all = empty;
        let mut sizes = Vec::with_capacity(frames.frame_count());
        let mut target_payload = 0u64;
        let mut sketches = Vec::new();
        for k in 0..frames.frame_count() {
            let frame = if k == 0 {
                Cow::Borrowed(base.as_ref())
            } else {
                frames.frame(k)?
            };
            if sketch {
                let positions = frame.positions();
                let stride = sketch_stride(positions.len());
                sketches.push(positions.iter().step_by(stride).copied().collect());
            }
            if let Some(v) = frame.positions().iter().position(|p| !p.is_finite()) {
                return Err(IoError::malformed(
                    path,
                    format!("frame {k} vertex {v}"),
                    "position is not finite",
                ));
            }
            normals &= frame.normals().is_some();
            let frame_box = frame
                .positions()
                .iter()
                .fold(empty, |(lo, hi), p| (lo.min(*p), hi.max(*p)));
            all = (all.0.min(frame_box.0), all.1.max(frame_box.1));
            let per_vertex = 12
                + if frame.normals().is_some() { 12 } else { 0 }
                + if frame.uvs().is_some() { 8 } else { 0 }
                + if frame.colors().is_some() { 16 } else { 0 };
            sizes.push(
                (per_vertex * frame.vertex_count() + 12 * frame.triangle_count() + 64) as u64,
            );
            let frame_diagonal = if frame_box.0.x <= frame_box.1.x {
                (frame_box.1 - frame_box.0).length()
            } else {
                0.0
            };
            if k == 0 {
                bounds[0] = frame_box;
                diagonals[0] = frame_diagonal;
                continue;
            }
            let current = segment_base.as_ref().unwrap_or(&base);
            let joins = layout != SequenceLayout::NodePerFrame
                && current.triangle_count() > 0
                && topology_difference(current, &frame).is_none();
            match (segments.last_mut(), bounds.last_mut(), diagonals.last_mut()) {
                (Some(segment), Some(b), Some(d)) if joins => {
                    target_payload += 8 * frame.vertex_count() as u64;
                    segment.end = k + 1;
                    *b = (b.0.min(frame_box.0), b.1.max(frame_box.1));
                    *d = d.min(frame_diagonal);
                }
                _ => {
                    segments.push(k..k + 1);
                    bounds.push(frame_box);
                    diagonals.push(frame_diagonal);
                    segment_base = Some(frame.clone().into_owned());
                }
            }
            if layout == SequenceLayout::NodePerFrame || !same {
                continue;
            }
            if let Some(message) = topology_difference(&base, &frame) {
                if layout == SequenceLayout::MorphTargets {
                    return Err(IoError::malformed(
                        path,
                        format!("frame {k}"),
                        format!("{message} (morph targets need the topology of frame 0)"),
                    ));
                }
                same = false;
            }
        }
        Ok(Self {
            morph: layout != SequenceLayout::NodePerFrame && same,
            normals,
            sizes,
            segments,
            bounds,
            diagonals,
            diagonal: if all.0.x <= all.1.x {
                (all.1 - all.0).length()
            } else {
                0.0
            },
            target_payload,
            sketch: sketches,
        })
    }

    /// The segments of frames `run`, cut to it and counted from its first frame, with their
    /// bounding boxes and smallest frame diagonals (over the whole segment).
    pub(super) fn segments_in(
        &self,
        run: &Range<usize>,
    ) -> Vec<(Range<usize>, (DVec3, DVec3), f64)> {
        self.segments
            .iter()
            .zip(&self.bounds)
            .zip(&self.diagonals)
            .filter(|((s, _), _)| s.start < run.end && s.end > run.start)
            .map(|((s, b), d)| {
                (
                    s.start.max(run.start) - run.start..s.end.min(run.end) - run.start,
                    *b,
                    *d,
                )
            })
            .collect()
    }
}

/// The glTF key time of every frame: the largest `f32` not above it, checked to be finite,
/// non-negative and strictly increasing (in `f64` and as `f32`).
pub(crate) fn key_times(path: &Path, frames: usize, times: &[f64]) -> Result<Vec<f32>, IoError> {
    if frames == 0 {
        return Err(IoError::malformed(path, "frames", "no frames to write"));
    }
    if times.len() != frames {
        return Err(IoError::malformed(
            path,
            "frame times",
            format!("{} times for {frames} frames", times.len()),
        ));
    }
    let mut keys = Vec::with_capacity(frames);
    for (k, &t) in times.iter().enumerate() {
        let element = || format!("frame time {k}");
        if !(t.is_finite() && t >= 0.0) {
            return Err(IoError::malformed(
                path,
                element(),
                format!("{t} is not a finite, non-negative number of seconds"),
            ));
        }
        if k > 0 && t <= times[k - 1] {
            return Err(IoError::malformed(
                path,
                element(),
                format!(
                    "{t} s does not come after frame time {} ({} s): times must increase strictly",
                    k - 1,
                    times[k - 1]
                ),
            ));
        }
        #[expect(clippy::cast_possible_truncation, reason = "rounded down just below")]
        let mut key = t as f32;
        if f64::from(key) > t {
            key = key.next_down();
        }
        if let Some(&previous) = keys.last()
            && key <= previous
        {
            return Err(IoError::malformed(
                path,
                element(),
                format!(
                    "{t} s is too close to frame time {} to be a distinct glTF (f32) key time",
                    k - 1
                ),
            ));
        }
        keys.push(key);
    }
    Ok(keys)
}

/// What differs between the topology of `frame` and `base`, if anything.
fn topology_difference(base: &TriMesh, frame: &TriMesh) -> Option<String> {
    if frame.vertex_count() != base.vertex_count() {
        return Some(format!(
            "has {} vertices, frame 0 has {}",
            frame.vertex_count(),
            base.vertex_count()
        ));
    }
    if frame.triangle_count() != base.triangle_count() {
        return Some(format!(
            "has {} triangles, frame 0 has {}",
            frame.triangle_count(),
            base.triangle_count()
        ));
    }
    frame
        .triangles()
        .iter()
        .zip(base.triangles())
        .position(|(a, b)| a != b)
        .map(|t| {
            format!(
                "triangle {t} is {:?}, in frame 0 {:?}",
                frame.triangles()[t],
                base.triangles()[t]
            )
        })
}
