//! Wavefront OBJ reading and writing.
//!
//! The reader is a small hand-written parser rather than `tobj`: tobj's multi-index mode renumbers
//! vertices by first use and drops unreferenced ones (it cannot keep the file's vertex order,
//! which per-vertex data such as blendshapes and registrations rely on), and its errors do not say
//! which line is wrong. Supported: `v x y z [w]` and `v x y z r g b` (vertex colours), `vt`, `vn`,
//! `f` with `v`, `v/vt`, `v//vn`, `v/vt/vn` corners and negative (relative) indices, polygons
//! fan-triangulated (`0 1 2`, `0 2 3`, ...; as tobj and trimesh), `usemtl`. Materials are not
//! loaded, so a missing `.mtl` is not an error. Lines, points, `o`, `g`, `s`, `mtllib` are ignored.
//! Corners that name texture coordinates or normals in a file that has no `vt` (or no `vn`) lines
//! at all, as VOCA's `f v/vt/vn` exports do, read with those references dropped (as trimesh);
//! any other reference to something that does not exist is an error naming the face and line.
//!
//! Two ways to turn the corners into vertices ([`ObjVertices`]):
//! - [`ObjVertices::Positions`] (default): one vertex per `v` line, in file order, unreferenced
//!   ones included. Texture coordinates and normals are attached only when every corner of a
//!   vertex uses the same value (and every corner has one); when they are indexed differently
//!   (uv seams, hard edges) they are dropped, because one value per vertex cannot hold them.
//! - [`ObjVertices::SplitSeams`]: trimesh's layout (`trimesh.load(path, process=False)`): faces are
//!   grouped by `usemtl` name, and within each group every distinct `(v, vt, vn)` corner becomes
//!   its own vertex (first-use order); unreferenced vertices disappear. Keeps uvs and normals and
//!   gives the vertex counts trimesh reports.
//! - [`ObjVertices::Auto`]: `Positions` when nothing would be dropped, else `SplitSeams`.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

use glam::{DVec3, Vec2, Vec3};

use super::error::IoError;
use crate::color::Rgba;
use crate::mesh::TriMesh;

/// How OBJ corners become mesh vertices (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ObjVertices {
    /// One vertex per `v` line, in file order; uvs/normals only when consistent per vertex.
    #[default]
    Positions,
    /// One vertex per distinct `(v, vt, vn)` corner within each material group (trimesh's
    /// layout): keeps uv seams and hard normals.
    SplitSeams,
    /// `Positions` when that loses nothing (every vertex has a single uv and normal, or the
    /// file has none), else `SplitSeams`. What `trisplat convert` uses.
    Auto,
}

/// "No index" marker for a corner without `vt` or `vn`.
const NONE: u32 = u32::MAX;

#[derive(Clone, Copy, PartialEq, Eq, Hash)]
struct Corner {
    v: u32,
    vt: u32,
    vn: u32,
}

/// The raw contents of an OBJ file.
#[derive(Default)]
struct ObjData {
    /// f64: the file's decimals are read as f64 (meshes store f64 positions).
    positions: Vec<DVec3>,
    colors: Vec<Rgba>,
    texcoords: Vec<Vec2>,
    normals: Vec<Vec3>,
    /// Triangles as corner triples, with their material group.
    triangles: Vec<[Corner; 3]>,
    groups: Vec<u32>,
}

fn parse_floats<const N: usize>(
    words: &mut std::str::SplitAsciiWhitespace<'_>,
) -> Option<[f32; N]> {
    let mut out = [0.0f32; N];
    for x in &mut out {
        *x = words.next()?.parse().ok()?;
    }
    Some(out)
}

/// Resolves a 1-based (or negative, relative) OBJ index into a 0-based one.
fn resolve(token: &str, len: usize) -> Option<u32> {
    let i: i64 = token.parse().ok()?;
    let len = i64::try_from(len).ok()?;
    let zero_based = if i > 0 { i - 1 } else { len + i };
    if (0..len).contains(&zero_based) {
        u32::try_from(zero_based).ok()
    } else {
        None
    }
}

/// The first face corner that named a `vt` (or `vn`) while the file had none yet:
/// `(face, line, corner text)`.
type Dangling = Option<(usize, usize, String)>;

fn parse(path: &Path, text: &str) -> Result<ObjData, IoError> {
    let mut d = ObjData::default();
    let mut material_ids: HashMap<String, u32> = HashMap::new();
    let mut group = 0u32;
    let mut face_count = 0usize;
    let mut corners: Vec<Corner> = Vec::new();
    let mut dangling_vt: Dangling = None;
    let mut dangling_vn: Dangling = None;
    for (line_index, line) in text.lines().enumerate() {
        let line_no = line_index + 1;
        let at = |what: String, msg: &str| {
            IoError::malformed(path, format!("{what} (line {line_no})"), msg.to_owned())
        };
        let mut words = line.split_ascii_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        match keyword {
            "v" => {
                let vertex = d.positions.len();
                let values: Vec<&str> = words.collect();
                let parsed: Option<Vec<f64>> = values.iter().map(|w| w.parse().ok()).collect();
                let Some(p) = parsed.filter(|p| p.len() >= 3) else {
                    return Err(at(format!("vertex {vertex}"), "needs three numbers x y z"));
                };
                let pos = DVec3::new(p[0], p[1], p[2]);
                if !pos.is_finite() {
                    return Err(at(format!("vertex {vertex}"), "non-finite coordinate"));
                }
                d.positions.push(pos);
                if p.len() >= 6 {
                    #[expect(clippy::cast_possible_truncation, reason = "colours are f32")]
                    d.colors.push([p[3] as f32, p[4] as f32, p[5] as f32, 1.0]);
                }
            }
            "vt" => {
                // `vt u [v [w]]`: a missing v is 0.
                let u = words.next().and_then(|w| w.parse::<f32>().ok());
                let v = words.next().map_or(Some(0.0), |w| w.parse::<f32>().ok());
                match (u, v) {
                    (Some(u), Some(v)) if u.is_finite() && v.is_finite() => {
                        d.texcoords.push(Vec2::new(u, v));
                    }
                    _ => {
                        return Err(at(
                            format!("texture coordinate {}", d.texcoords.len()),
                            "needs finite numbers u [v]",
                        ));
                    }
                }
            }
            "vn" => match parse_floats::<3>(&mut words) {
                Some(n) if n.iter().all(|x| x.is_finite()) => d.normals.push(Vec3::from(n)),
                _ => {
                    return Err(at(
                        format!("normal {}", d.normals.len()),
                        "needs three finite numbers",
                    ));
                }
            },
            "usemtl" => {
                let name = line.trim_start()[6..].trim().to_owned();
                let next = u32::try_from(material_ids.len()).unwrap_or(u32::MAX);
                group = *material_ids.entry(name).or_insert(next + 1);
            }
            "f" => {
                let face = face_count;
                face_count += 1;
                corners.clear();
                for word in words {
                    let mut parts = word.split('/');
                    let v = parts.next().and_then(|t| resolve(t, d.positions.len()));
                    // A file with no `vt` (or no `vn`) lines at all whose faces still name them
                    // (VOCA's `f v/vt/vn` exports): the references are dropped, as trimesh
                    // does, unless such lines come later (checked at the end of the file).
                    let attribute =
                        |token: Option<&str>, len: usize, first: &mut Dangling| match token {
                            None | Some("") => Some(NONE),
                            Some(_) if len == 0 => {
                                first.get_or_insert((face, line_no, word.to_owned()));
                                Some(NONE)
                            }
                            Some(t) => resolve(t, len),
                        };
                    let vt = attribute(parts.next(), d.texcoords.len(), &mut dangling_vt);
                    let vn = attribute(parts.next(), d.normals.len(), &mut dangling_vn);
                    match (v, vt, vn) {
                        (Some(v), Some(vt), Some(vn)) => corners.push(Corner { v, vt, vn }),
                        _ => return Err(missing_corner(&at, face, word, &d)),
                    }
                }
                for k in 2..corners.len() {
                    d.triangles.push([corners[0], corners[k - 1], corners[k]]);
                    d.groups.push(group);
                }
            }
            _ => {}
        }
    }
    if !d.colors.is_empty() && d.colors.len() != d.positions.len() {
        d.colors.clear();
    }
    // A reference made before any `vt`/`vn` line existed is only forgiven when none ever came.
    for (first, count) in [
        (dangling_vt, d.texcoords.len()),
        (dangling_vn, d.normals.len()),
    ] {
        if let Some((face, line_no, word)) = first
            && count > 0
        {
            let at = |what: String, msg: &str| {
                IoError::malformed(path, format!("{what} (line {line_no})"), msg.to_owned())
            };
            return Err(missing_corner(&at, face, &word, &d));
        }
    }
    Ok(d)
}

/// The error for a face corner naming a vertex, texture coordinate or normal that does not
/// exist.
fn missing_corner(
    at: &impl Fn(String, &str) -> IoError,
    face: usize,
    word: &str,
    d: &ObjData,
) -> IoError {
    at(
        format!("face {face}"),
        &format!(
            "corner `{word}` refers to a vertex, texture coordinate or normal that does not exist \
             (so far {} v, {} vt, {} vn)",
            d.positions.len(),
            d.texcoords.len(),
            d.normals.len()
        ),
    )
}

/// One value per vertex when every corner of each vertex agrees, else `None`.
fn per_vertex<T: Copy + PartialEq + Default>(
    n: usize,
    triangles: &[[Corner; 3]],
    values: &[T],
    index: impl Fn(&Corner) -> u32,
) -> Option<Vec<T>> {
    if values.is_empty() {
        return None;
    }
    let mut out: Vec<Option<T>> = vec![None; n];
    for c in triangles.iter().flatten() {
        let i = index(c);
        let value = *values.get(i as usize)?;
        let slot = &mut out[c.v as usize];
        match slot {
            Some(old) if *old != value => return None,
            _ => *slot = Some(value),
        }
    }
    Some(out.into_iter().map(Option::unwrap_or_default).collect())
}

fn build(path: &Path, d: ObjData, mode: ObjVertices) -> Result<TriMesh, IoError> {
    let bad = |e: crate::mesh::MeshError| IoError::malformed(path, "mesh", e.to_string());
    let mode = match mode {
        ObjVertices::Auto => {
            let n = d.positions.len();
            let lossless = (d.texcoords.is_empty()
                || per_vertex(n, &d.triangles, &d.texcoords, |c| c.vt).is_some())
                && (d.normals.is_empty()
                    || per_vertex(n, &d.triangles, &d.normals, |c| c.vn).is_some());
            if lossless {
                ObjVertices::Positions
            } else {
                ObjVertices::SplitSeams
            }
        }
        other => other,
    };
    match mode {
        ObjVertices::Positions => {
            let n = d.positions.len();
            let uvs = per_vertex(n, &d.triangles, &d.texcoords, |c| c.vt);
            let normals = per_vertex(n, &d.triangles, &d.normals, |c| c.vn);
            let triangles = d.triangles.iter().map(|t| t.map(|c| c.v)).collect();
            let mut mesh = TriMesh::try_new(d.positions, triangles).map_err(bad)?;
            if let Some(uv) = uvs {
                mesh = mesh.with_uvs(uv).map_err(bad)?;
            }
            if let Some(nrm) = normals {
                mesh = mesh.with_normals(nrm).map_err(bad)?;
            }
            if !d.colors.is_empty() {
                mesh = mesh.with_colors(d.colors).map_err(bad)?;
            }
            Ok(mesh)
        }
        ObjVertices::SplitSeams | ObjVertices::Auto => {
            // Group order: by first appearance of the group, as trimesh concatenates them.
            let mut order: Vec<u32> = Vec::new();
            for &g in &d.groups {
                if !order.contains(&g) {
                    order.push(g);
                }
            }
            let mut positions = Vec::new();
            let mut uvs = Vec::new();
            let mut normals = Vec::new();
            let mut colors = Vec::new();
            let mut triangles = Vec::with_capacity(d.triangles.len());
            for g in order {
                let mut map: HashMap<Corner, u32> = HashMap::new();
                for (tri, _) in d
                    .triangles
                    .iter()
                    .zip(&d.groups)
                    .filter(|(_, gg)| **gg == g)
                {
                    let mut out = [0u32; 3];
                    for (o, c) in out.iter_mut().zip(tri) {
                        *o = *map.entry(*c).or_insert_with(|| {
                            let id = u32::try_from(positions.len()).unwrap_or(u32::MAX);
                            positions.push(d.positions[c.v as usize]);
                            uvs.push(d.texcoords.get(c.vt as usize).copied().unwrap_or_default());
                            normals.push(d.normals.get(c.vn as usize).copied().unwrap_or_default());
                            if let Some(col) = d.colors.get(c.v as usize) {
                                colors.push(*col);
                            }
                            id
                        });
                    }
                    triangles.push(out);
                }
            }
            let mut mesh = TriMesh::try_new(positions, triangles).map_err(bad)?;
            if !d.texcoords.is_empty() {
                mesh = mesh.with_uvs(uvs).map_err(bad)?;
            }
            if !d.normals.is_empty() {
                mesh = mesh.with_normals(normals).map_err(bad)?;
            }
            if !d.colors.is_empty() {
                mesh = mesh.with_colors(colors).map_err(bad)?;
            }
            Ok(mesh)
        }
    }
}

/// Parses OBJ text already in memory.
///
/// # Errors
/// [`IoError::Malformed`] naming the line when the bytes are not UTF-8, a coordinate is not a
/// finite number, or a face refers to a missing vertex.
pub fn parse_obj(path: &Path, bytes: &[u8], mode: ObjVertices) -> Result<TriMesh, IoError> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let valid = &bytes[..e.valid_up_to()];
        let line = valid.iter().filter(|&&b| b == b'\n').count() + 1;
        IoError::malformed(
            path,
            format!("line {line}"),
            "not UTF-8 text (is this really an OBJ file?)",
        )
    })?;
    build(path, parse(path, text)?, mode)
}

/// Reads an OBJ file.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be read, otherwise see [`parse_obj`].
pub fn read_obj(path: &Path, mode: ObjVertices) -> Result<TriMesh, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::os(path, e))?;
    parse_obj(path, &bytes, mode)
}

/// Writes `mesh` as OBJ text: `v x y z [r g b]`, `vt`, `vn`, and `f` with 1-based corners
/// (`a/a/a` when both uvs and normals are present). Floats use the shortest text that reads
/// back to the same value (an f32 value as an f32, see [`Coordinate`]).
///
/// # Errors
/// [`IoError::Os`] when writing fails.
pub fn write_obj_to(path: &Path, out: &mut dyn Write, mesh: &TriMesh) -> Result<(), IoError> {
    let os = |e| IoError::os(path, e);
    let mut s = String::with_capacity(1 << 16);
    let flush = |s: &mut String, out: &mut dyn Write| -> Result<(), IoError> {
        out.write_all(s.as_bytes()).map_err(os)?;
        s.clear();
        Ok(())
    };
    s.push_str("# written by trisplat\n");
    let colors = mesh.colors();
    for (i, p) in mesh.positions().iter().enumerate() {
        let _ = write!(
            s,
            "v {} {} {}",
            Coordinate(p.x),
            Coordinate(p.y),
            Coordinate(p.z)
        );
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            let _ = write!(s, " {} {} {}", c[0], c[1], c[2]);
        }
        s.push('\n');
        if s.len() > 1 << 16 {
            flush(&mut s, out)?;
        }
    }
    if let Some(uvs) = mesh.uvs() {
        for uv in uvs {
            let _ = writeln!(s, "vt {} {}", uv.x, uv.y);
            if s.len() > 1 << 16 {
                flush(&mut s, out)?;
            }
        }
    }
    if let Some(normals) = mesh.normals() {
        for n in normals {
            let _ = writeln!(s, "vn {} {} {}", n.x, n.y, n.z);
            if s.len() > 1 << 16 {
                flush(&mut s, out)?;
            }
        }
    }
    let (has_uv, has_n) = (mesh.uvs().is_some(), mesh.normals().is_some());
    for t in mesh.triangles() {
        s.push('f');
        for &v in t {
            let i = u64::from(v) + 1;
            let _ = match (has_uv, has_n) {
                (false, false) => write!(s, " {i}"),
                (true, false) => write!(s, " {i}/{i}"),
                (false, true) => write!(s, " {i}//{i}"),
                (true, true) => write!(s, " {i}/{i}/{i}"),
            };
        }
        s.push('\n');
        if s.len() > 1 << 16 {
            flush(&mut s, out)?;
        }
    }
    flush(&mut s, out)
}

/// A vertex coordinate written with the fewest digits that read back as the same f64: an f32
/// value as an f32 (`0.1`, not `0.10000000149011612`), any other value as an f64.
struct Coordinate(f64);

impl std::fmt::Display for Coordinate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        #[expect(clippy::cast_possible_truncation, reason = "compared back exactly")]
        let narrow = self.0 as f32;
        if f64::from(narrow) == self.0 {
            write!(f, "{narrow}")
        } else {
            write!(f, "{}", self.0)
        }
    }
}
