//! The mapping between PLY documents and [`TriMesh`] / [`PointCloud`]: what vertex and face
//! properties become, what is kept in [`PlyExtras`], and the mesh and point file functions.

use std::path::Path;

use glam::{DVec3, Vec2, Vec3};

use super::model::{
    PlyDocument, PlyElement, PlyEncoding, PlyExtras, PlyProperty, PropertyData, ScalarColumn,
    ScalarType,
};
use super::read::read_ply_document;
use super::write::write_ply_document;
use crate::color::Rgba;
use crate::io::atomic::write_atomically;
use crate::io::error::IoError;
use crate::mesh::TriMesh;
use crate::points::PointCloud;

const UV_NAMES: [(&str, &str); 4] = [
    ("texture_u", "texture_v"),
    ("u", "v"),
    ("s", "t"),
    ("texture_s", "texture_t"),
];
const FACE_INDEX_NAMES: [&str; 2] = ["vertex_indices", "vertex_index"];

/// Vertex data decoded from a `vertex` element.
struct VertexData {
    /// f64: `double` coordinates are kept exactly (meshes store f64 positions).
    positions: Vec<DVec3>,
    normals: Option<Vec<Vec3>>,
    colors: Option<Vec<Rgba>>,
    uvs: Option<Vec<Vec2>>,
    used: Vec<&'static str>,
}

fn triple<'a>(e: &'a PlyElement, names: [&str; 3]) -> Option<[&'a ScalarColumn; 3]> {
    Some([
        e.scalar(names[0])?,
        e.scalar(names[1])?,
        e.scalar(names[2])?,
    ])
}

/// Three columns read as one type (`to_f32`, `to_f64`) and zipped into vectors.
fn zip3<T: Copy, V>(
    c: [&ScalarColumn; 3],
    read: impl Fn(&ScalarColumn) -> Vec<T>,
    vector: impl Fn(T, T, T) -> V,
) -> Vec<V> {
    let [x, y, z] = c.map(read);
    x.iter()
        .zip(&y)
        .zip(&z)
        .map(|((&x, &y), &z)| vector(x, y, z))
        .collect()
}

fn decode_vertices(path: &Path, doc: &PlyDocument) -> Result<VertexData, IoError> {
    let Some(v) = doc.element("vertex") else {
        return Err(IoError::malformed(path, "header", "no `vertex` element"));
    };
    let xyz = triple(v, ["x", "y", "z"]).ok_or_else(|| {
        IoError::malformed(
            path,
            "element vertex",
            "needs scalar properties `x`, `y` and `z`",
        )
    })?;
    let positions = zip3(xyz, ScalarColumn::to_f64, DVec3::new);
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        let p = positions[i];
        return Err(IoError::malformed(
            path,
            format!("vertex {i}"),
            format!("non-finite coordinate ({}, {}, {})", p.x, p.y, p.z),
        ));
    }
    let mut used = vec!["x", "y", "z"];
    let normals = triple(v, ["nx", "ny", "nz"]).map(|c| {
        used.extend(["nx", "ny", "nz"]);
        zip3(c, ScalarColumn::to_f32, Vec3::new)
    });
    if let Some(n) = &normals
        && let Some(i) = n.iter().position(|p| !p.is_finite())
    {
        let p = n[i];
        return Err(IoError::malformed(
            path,
            format!("vertex {i}"),
            format!("non-finite normal ({}, {}, {})", p.x, p.y, p.z),
        ));
    }
    let colors = triple(v, ["red", "green", "blue"]).map(|[r, g, b]| {
        used.extend(["red", "green", "blue"]);
        let (r, g, b) = (r.to_unit_color(), g.to_unit_color(), b.to_unit_color());
        let a = v.scalar("alpha").map(|a| {
            used.push("alpha");
            a.to_unit_color()
        });
        (0..r.len())
            .map(|i| [r[i], g[i], b[i], a.as_ref().map_or(1.0, |a| a[i])])
            .collect()
    });
    let mut uvs = None;
    for (un, vn) in UV_NAMES {
        if let (Some(u), Some(w)) = (v.scalar(un), v.scalar(vn)) {
            let (u, w) = (u.to_f32(), w.to_f32());
            uvs = Some(u.iter().zip(&w).map(|(&u, &w)| Vec2::new(u, w)).collect());
            used.extend([un, vn]);
            break;
        }
    }
    Ok(VertexData {
        positions,
        normals,
        colors,
        uvs,
        used,
    })
}

fn index_list(e: &PlyElement) -> Option<(&str, &[usize], &ScalarColumn)> {
    FACE_INDEX_NAMES
        .iter()
        .find_map(|&name| match e.property(name) {
            Some(PropertyData::List {
                offsets, values, ..
            }) => Some((name, offsets.as_slice(), values)),
            _ => None,
        })
}

/// `raw` (a list value, `-1` when it is not an integer) as a vertex index below `n`.
fn checked_index(path: &Path, what: &str, row: usize, raw: i64, n: usize) -> Result<u32, IoError> {
    match u32::try_from(raw) {
        Ok(v) if (v as usize) < n => Ok(v),
        _ => Err(IoError::malformed(
            path,
            format!("{what} {row}"),
            format!("vertex index {raw} is out of range (the file has {n} vertices)"),
        )),
    }
}

/// Triangles of the `face` and `tristrips` elements; also whether every face was a triangle.
fn decode_triangles(
    path: &Path,
    doc: &PlyDocument,
    n: usize,
) -> Result<(Vec<[u32; 3]>, bool), IoError> {
    let mut triangles = Vec::new();
    let mut all_triangles = true;
    if let Some(face) = doc.element("face") {
        let (_, offsets, values) = index_list(face).ok_or_else(|| {
            IoError::malformed(
                path,
                "element face",
                "needs a list property `vertex_indices` or `vertex_index`",
            )
        })?;
        triangles.reserve(face.count);
        let values = values.to_i64_or_minus_one();
        for row in 0..face.count {
            let (a, b) = (offsets[row], offsets[row + 1]);
            if b - a != 3 {
                all_triangles = false;
            }
            if b - a < 3 {
                continue;
            }
            let first = checked_index(path, "face", row, values[a], n)?;
            let mut prev = checked_index(path, "face", row, values[a + 1], n)?;
            for &raw in &values[a + 2..b] {
                let cur = checked_index(path, "face", row, raw, n)?;
                triangles.push([first, prev, cur]);
                prev = cur;
            }
        }
    }
    if let Some(strips) = doc.element("tristrips") {
        all_triangles = false;
        let (_, offsets, values) = index_list(strips).ok_or_else(|| {
            IoError::malformed(
                path,
                "element tristrips",
                "needs a list property `vertex_indices`",
            )
        })?;
        for row in 0..strips.count {
            let mut strip: Vec<u32> = Vec::new();
            let flush = |strip: &mut Vec<u32>, out: &mut Vec<[u32; 3]>| {
                for k in 0..strip.len().saturating_sub(2) {
                    let (a, b, c) = (strip[k], strip[k + 1], strip[k + 2]);
                    if a == b || b == c || a == c {
                        continue;
                    }
                    out.push(if k % 2 == 0 { [a, b, c] } else { [b, a, c] });
                }
                strip.clear();
            };
            for i in offsets[row]..offsets[row + 1] {
                if values.get_i64(i) == Some(-1) {
                    flush(&mut strip, &mut triangles);
                } else {
                    let raw = values.get_i64(i).unwrap_or(-1);
                    strip.push(checked_index(path, "tristrips", row, raw, n)?);
                }
            }
            flush(&mut strip, &mut triangles);
        }
    }
    Ok((triangles, all_triangles))
}

fn extras_of(doc: &PlyDocument, used_vertex: &[&str], keep_face: bool) -> PlyExtras {
    let mut extras = PlyExtras {
        comments: doc.comments.clone(),
        obj_info: doc.obj_info.clone(),
        ..PlyExtras::default()
    };
    for e in &doc.elements {
        match e.name.as_str() {
            "vertex" => {
                extras.vertex_properties = e
                    .properties
                    .iter()
                    .filter(|p| !used_vertex.contains(&p.name.as_str()))
                    .cloned()
                    .collect();
            }
            "face" => {
                if keep_face {
                    let index_name = index_list(e).map(|(n, _, _)| n);
                    extras.face_properties = e
                        .properties
                        .iter()
                        .filter(|p| Some(p.name.as_str()) != index_name)
                        .cloned()
                        .collect();
                }
            }
            "tristrips" => {}
            _ => extras.other_elements.push(e.clone()),
        }
    }
    extras
}

/// Builds a mesh (and the rest of the file) from a parsed PLY document.
///
/// # Errors
/// [`IoError::Malformed`] for a missing `vertex` element or coordinates, a non-finite position
/// (naming the vertex) or an index out of range (naming the face).
pub fn ply_to_mesh(path: &Path, doc: &PlyDocument) -> Result<(TriMesh, PlyExtras), IoError> {
    let v = decode_vertices(path, doc)?;
    let (triangles, all_triangles) = decode_triangles(path, doc, v.positions.len())?;
    let extras = extras_of(doc, &v.used, all_triangles);
    let bad_len =
        |e: crate::mesh::MeshError| IoError::malformed(path, "element vertex", e.to_string());
    let mut mesh = TriMesh::try_new(v.positions, triangles).map_err(bad_len)?;
    if let Some(n) = v.normals {
        mesh = mesh.with_normals(n).map_err(bad_len)?;
    }
    if let Some(c) = v.colors {
        mesh = mesh.with_colors(c).map_err(bad_len)?;
    }
    if let Some(uv) = v.uvs {
        mesh = mesh.with_uvs(uv).map_err(bad_len)?;
    }
    Ok((mesh, extras))
}

/// Builds a point cloud from the `vertex` element of a parsed PLY document (faces ignored).
///
/// # Errors
/// [`IoError::Malformed`] for a missing `vertex` element or a non-finite position.
pub fn ply_to_points(path: &Path, doc: &PlyDocument) -> Result<(PointCloud, PlyExtras), IoError> {
    ply_to_points_around(path, doc, DVec3::ZERO).map(|(cloud, extras, _)| (cloud, extras))
}

/// [`ply_to_points`] with the positions relative to a local origin, returned beside them:
/// the points' [`crate::Aabb::local_origin`] (zero unless they are far from the world origin),
/// subtracted from the file's values in `f64` before they are stored in `f32`.
///
/// # Errors
/// As [`ply_to_points`].
pub fn ply_to_points_local(
    path: &Path,
    doc: &PlyDocument,
) -> Result<(PointCloud, PlyExtras, DVec3), IoError> {
    ply_to_points_around(path, doc, DVec3::NAN)
}

/// The points of `doc` relative to `origin`, or to their local origin when `origin` is NaN.
fn ply_to_points_around(
    path: &Path,
    doc: &PlyDocument,
    origin: DVec3,
) -> Result<(PointCloud, PlyExtras, DVec3), IoError> {
    let v = decode_vertices(path, doc)?;
    let extras = extras_of(doc, &v.used, false);
    let bad = |e: crate::mesh::MeshError| IoError::malformed(path, "element vertex", e.to_string());
    let origin = if origin.is_nan() {
        crate::mesh::Aabb::from_dpoints(&v.positions).map_or(DVec3::ZERO, |b| b.local_origin())
    } else {
        origin
    };
    let positions = v
        .positions
        .iter()
        .map(|&p| (p - origin).as_vec3())
        .collect();
    let mut cloud = PointCloud::try_new(positions).map_err(bad)?;
    if let Some(n) = v.normals {
        cloud = cloud.with_normals(n).map_err(bad)?;
    }
    if let Some(c) = v.colors {
        cloud = cloud.with_colors(c).map_err(bad)?;
    }
    Ok((cloud, extras, origin))
}

/// Reads a PLY mesh and everything else it holds.
///
/// # Errors
/// See [`read_ply_document`] and [`ply_to_mesh`].
pub fn read_ply_mesh(path: &Path) -> Result<(TriMesh, PlyExtras), IoError> {
    ply_to_mesh(path, &read_ply_document(path)?)
}

fn f32_column(values: impl Iterator<Item = f32>) -> PropertyData {
    PropertyData::Scalar(ScalarColumn::F32(values.collect()))
}

#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "clamped to [0, 255] first"
)]
fn u8_color(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn prop(name: &str, data: PropertyData) -> PlyProperty {
    PlyProperty {
        name: name.to_owned(),
        data,
    }
}

/// `x y z` columns of f32 points.
fn position_columns_f32(positions: &[Vec3]) -> [PlyProperty; 3] {
    [
        prop("x", f32_column(positions.iter().map(|p| p.x))),
        prop("y", f32_column(positions.iter().map(|p| p.y))),
        prop("z", f32_column(positions.iter().map(|p| p.z))),
    ]
}

/// `x y z` columns of f64 mesh vertices: `float` when every coordinate is an f32 value (the
/// file is then what an f32 writer would write), else `double`, so nothing is rounded.
fn position_columns_f64(positions: &[DVec3]) -> [PlyProperty; 3] {
    let exact_in_f32 = positions.iter().all(|p| p.as_vec3().as_dvec3() == *p);
    if exact_in_f32 {
        return position_columns_f32(&positions.iter().map(|p| p.as_vec3()).collect::<Vec<_>>());
    }
    let column = |axis: usize| {
        PropertyData::Scalar(ScalarColumn::F64(
            positions.iter().map(|p| p[axis]).collect(),
        ))
    };
    [
        prop("x", column(0)),
        prop("y", column(1)),
        prop("z", column(2)),
    ]
}

fn vertex_element(
    positions: [PlyProperty; 3],
    normals: Option<&[Vec3]>,
    uvs: Option<&[Vec2]>,
    colors: Option<&[Rgba]>,
    extra: &[PlyProperty],
) -> PlyElement {
    let count = positions[0].data.rows();
    let mut props = positions.to_vec();
    if let Some(n) = normals {
        props.push(prop("nx", f32_column(n.iter().map(|p| p.x))));
        props.push(prop("ny", f32_column(n.iter().map(|p| p.y))));
        props.push(prop("nz", f32_column(n.iter().map(|p| p.z))));
    }
    if let Some(uv) = uvs {
        props.push(prop("s", f32_column(uv.iter().map(|p| p.x))));
        props.push(prop("t", f32_column(uv.iter().map(|p| p.y))));
    }
    if let Some(c) = colors {
        for (k, name) in ["red", "green", "blue", "alpha"].into_iter().enumerate() {
            let column = ScalarColumn::U8(c.iter().map(|c| u8_color(c[k])).collect());
            props.push(prop(name, PropertyData::Scalar(column)));
        }
    }
    for p in extra {
        if p.data.rows() == count && !props.iter().any(|q| q.name == p.name) {
            props.push(p.clone());
        }
    }
    PlyElement {
        name: "vertex".into(),
        count,
        properties: props,
    }
}

/// The PLY document for `mesh` plus `extras`: `vertex` (`x y z` float, or double when a
/// coordinate is not an f32 value, `nx ny nz`, `s t`,
/// `red green blue alpha` uchar when present, then extra properties), `face` (`list uchar int
/// vertex_indices`, then extra face properties when their row count matches), other elements.
/// Extras whose row count does not match the mesh are left out.
#[must_use]
pub fn mesh_to_ply(mesh: &TriMesh, extras: &PlyExtras) -> PlyDocument {
    let vertex = vertex_element(
        position_columns_f64(mesh.positions()),
        mesh.normals(),
        mesh.uvs(),
        mesh.colors(),
        &extras.vertex_properties,
    );
    let tris = mesh.triangles();
    #[expect(clippy::cast_possible_wrap, reason = "vertex counts fit i32 in PLY")]
    let indices = ScalarColumn::I32(tris.iter().flatten().map(|&i| i as i32).collect());
    let mut face_props = vec![prop(
        "vertex_indices",
        PropertyData::List {
            count_type: ScalarType::U8,
            offsets: (0..=tris.len()).map(|i| 3 * i).collect(),
            values: indices,
        },
    )];
    for p in &extras.face_properties {
        if p.data.rows() == tris.len() && p.name != "vertex_indices" {
            face_props.push(p.clone());
        }
    }
    let face = PlyElement {
        name: "face".into(),
        count: tris.len(),
        properties: face_props,
    };
    document_with_extras(vec![vertex, face], extras)
}

/// The PLY document for a point cloud: one `vertex` element (see [`mesh_to_ply`]).
#[must_use]
pub fn points_to_ply(points: &PointCloud, extras: &PlyExtras) -> PlyDocument {
    points_to_ply_at(points, DVec3::ZERO, extras)
}

/// [`points_to_ply`] for points stored relative to `origin` (see
/// [`crate::io::read_points_local`]): written at `p + origin`, computed in f64, as `double` when
/// that is not an f32 value.
#[must_use]
pub fn points_to_ply_at(points: &PointCloud, origin: DVec3, extras: &PlyExtras) -> PlyDocument {
    let positions = if origin == DVec3::ZERO {
        position_columns_f32(points.positions())
    } else {
        position_columns_f64(
            &points
                .positions()
                .iter()
                .map(|p| p.as_dvec3() + origin)
                .collect::<Vec<_>>(),
        )
    };
    let vertex = vertex_element(
        positions,
        points.normals(),
        None,
        points.colors(),
        &extras.vertex_properties,
    );
    document_with_extras(vec![vertex], extras)
}

/// A document (default encoding) of `elements` followed by the other elements of `extras`,
/// with its comments and `obj_info` lines.
fn document_with_extras(mut elements: Vec<PlyElement>, extras: &PlyExtras) -> PlyDocument {
    elements.extend(extras.other_elements.iter().cloned());
    PlyDocument {
        encoding: PlyEncoding::default(),
        comments: extras.comments.clone(),
        obj_info: extras.obj_info.clone(),
        elements,
    }
}

/// Writes a mesh with the extras of the file it came from, atomically.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be written.
pub fn write_ply_mesh(
    path: &Path,
    mesh: &TriMesh,
    extras: &PlyExtras,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    let doc = mesh_to_ply(mesh, extras);
    write_atomically(path, |w| write_ply_document(path, w, &doc, encoding))
}

/// Writes a point cloud with the extras of the file it came from, atomically.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be written.
pub fn write_ply_points(
    path: &Path,
    points: &PointCloud,
    extras: &PlyExtras,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    write_ply_points_at(path, points, DVec3::ZERO, extras, encoding)
}

/// [`write_ply_points`] for points stored relative to `origin` ([`points_to_ply_at`]).
///
/// # Errors
/// [`IoError::Os`] when the file cannot be written.
pub fn write_ply_points_at(
    path: &Path,
    points: &PointCloud,
    origin: DVec3,
    extras: &PlyExtras,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    let doc = points_to_ply_at(points, origin, extras);
    write_atomically(path, |w| write_ply_document(path, w, &doc, encoding))
}
