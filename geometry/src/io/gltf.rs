//! glTF 2.0 (`.gltf` with data-URI or external buffers, `.glb`): static meshes.
//!
//! Reading (the rest state, as `trimesh.load(path, force="mesh", process=False)` gives it):
//! - the node tree of the document's `scene`, or of scene 0 when it names none (as trimesh), or
//!   of every root node when the file has no scenes; each node's local transform (matrix or
//!   TRS) is composed from the root down and applied to its mesh (positions; normals by the
//!   inverse transpose; winding reversed when the transform mirrors);
//! - every primitive of every mesh instance becomes its own block of vertices (a mesh used by two
//!   nodes appears twice, primitives never share vertices), in depth-first node order;
//! - modes TRIANGLES, TRIANGLE_STRIP (odd triangles re-ordered to keep the winding) and
//!   TRIANGLE_FAN; indexed and non-indexed; POINTS and LINES primitives are skipped;
//! - `NORMAL`, `TEXCOORD_0` and `COLOR_0` are kept when every primitive has them;
//! - skins and morph targets are ignored: a skinned mesh comes out in its bind pose with its
//!   node's transform applied, morph targets at weight zero (trimesh does the same).
//!
//! Accessors are decoded by `io::gltf_data` (shared with the animation reader) rather than
//! with the `gltf` crate's readers, so that every offset, stride and count is checked against
//! the bytes present (sparse accessors included) and a bad file gives an error naming the
//! accessor instead of a panic.
//!
//! Writing: one scene, one node, one mesh with one TRIANGLES primitive: `POSITION` (with `min`
//! and `max`), `NORMAL`, `TEXCOORD_0` and `COLOR_0` (float RGBA) when present, `u32` indices.
//! `.glb` holds the buffer in its binary chunk; `.gltf` embeds it as a base64 data URI, so the
//! output is one self-contained file that can be written atomically.

use std::path::Path;

use base64::Engine as _;
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3};
use gltf::accessor::Dimensions;
use gltf::mesh::{Mode, Semantic};
use serde_json::json;

use super::error::IoError;
use super::gltf_codes::{ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, UNSIGNED_INT};
use super::gltf_data::GltfData;
use crate::color::Rgba;
use crate::mesh::TriMesh;

/// `COLOR_0` as RGBA (VEC3 gets alpha 1; normalised integers already scaled by the reader).
fn read_colors(data: &GltfData, accessor: &gltf::Accessor<'_>) -> Result<Vec<Rgba>, IoError> {
    let comps = accessor.dimensions().multiplicity();
    if !matches!(accessor.dimensions(), Dimensions::Vec3 | Dimensions::Vec4) {
        return Err(IoError::malformed(
            data.path(),
            format!("accessor {}", accessor.index()),
            "COLOR_0 must be VEC3 or VEC4",
        ));
    }
    Ok(data
        .read(accessor)?
        .chunks_exact(comps)
        .map(|c| {
            let alpha = if comps == 4 { c[3] as f32 } else { 1.0 };
            [c[0] as f32, c[1] as f32, c[2] as f32, alpha]
        })
        .collect())
}

fn read_vec<const N: usize>(
    data: &GltfData,
    accessor: &gltf::Accessor<'_>,
    what: &str,
) -> Result<Vec<[f64; N]>, IoError> {
    let n = accessor.dimensions().multiplicity();
    if n < N
        || matches!(
            accessor.dimensions(),
            Dimensions::Mat2 | Dimensions::Mat3 | Dimensions::Mat4
        )
    {
        return Err(IoError::malformed(
            data.path(),
            format!("accessor {}", accessor.index()),
            format!("{what} needs {N} components, it has {n}"),
        ));
    }
    let values = data.read(accessor)?;
    Ok(values
        .chunks_exact(n)
        .map(|c| {
            let mut a = [0.0; N];
            a.copy_from_slice(&c[..N]);
            a
        })
        .collect())
}

/// Per-triangle inputs of the base colour ([`super::gltf_material`]), gathered when asked.
#[derive(Default)]
pub(super) struct SurfaceParts {
    /// Per triangle, its corners' `TEXCOORD_0` (zero where the primitive has none).
    pub(super) corner_uvs: Vec<[Vec2; 3]>,
    /// Per triangle, its corners' `COLOR_0` (white where the primitive has none).
    pub(super) corner_colors: Vec<[Rgba; 3]>,
    /// Whether any primitive has `COLOR_0`.
    pub(super) any_colors: bool,
    /// Per triangle, its primitive's material (`None`: glTF's default material).
    pub(super) material: Vec<Option<usize>>,
    /// Primitives without a usable `TEXCOORD_0`: their element name, material and why.
    pub(super) without_uvs: Vec<(String, Option<usize>, String)>,
}

/// The vertex and triangle blocks gathered so far.
#[derive(Default)]
pub(super) struct Gathered {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    colors: Vec<Rgba>,
    triangles: Vec<[u32; 3]>,
    all_normals: bool,
    all_uvs: bool,
    all_colors: bool,
    primitives: usize,
    /// Base-colour inputs, when asked for.
    pub(super) surface: Option<SurfaceParts>,
}

#[expect(
    clippy::cast_possible_truncation,
    reason = "f32 storage is the documented precision of meshes"
)]
fn add_primitive(
    path: &Path,
    out: &mut Gathered,
    mesh: &gltf::Mesh<'_>,
    prim: &gltf::Primitive<'_>,
    world: &DMat4,
    data: &GltfData,
) -> Result<(), IoError> {
    let element = format!("mesh {} primitive {}", mesh.index(), prim.index());
    let mode = prim.mode();
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        return Ok(());
    }
    let Some(pos) = prim.get(&Semantic::Positions) else {
        return Ok(());
    };
    let positions = read_vec::<3>(data, &pos, "POSITION")?;
    let n = positions.len();
    let base = out.positions.len();
    let too_many = || IoError::malformed(path, &element, "more vertices than u32 indices hold");
    let base_u32 = u32::try_from(base).map_err(|_| too_many())?;
    u32::try_from(base + n).map_err(|_| too_many())?;
    for (i, p) in positions.iter().enumerate() {
        let w = world.transform_point3(DVec3::from(*p)).as_vec3();
        if !w.is_finite() {
            return Err(IoError::malformed(
                path,
                format!("{element} vertex {i}"),
                format!("non-finite position ({}, {}, {})", p[0], p[1], p[2]),
            ));
        }
        out.positions.push(w);
    }
    let normal_matrix = DMat3::from_mat4(*world).inverse().transpose();
    match prim.get(&Semantic::Normals) {
        Some(acc) if acc.count() == n && out.all_normals => {
            for v in read_vec::<3>(data, &acc, "NORMAL")? {
                let m = (normal_matrix * DVec3::from(v)).normalize_or_zero();
                out.normals.push(m.as_vec3());
            }
        }
        _ => out.all_normals = false,
    }
    match prim.get(&Semantic::TexCoords(0)) {
        Some(acc) if acc.count() == n && out.all_uvs => {
            for v in read_vec::<2>(data, &acc, "TEXCOORD_0")? {
                out.uvs.push(Vec2::new(v[0] as f32, v[1] as f32));
            }
        }
        _ => out.all_uvs = false,
    }
    match prim.get(&Semantic::Colors(0)) {
        Some(acc) if acc.count() == n && out.all_colors => {
            out.colors.extend(read_colors(data, &acc)?);
        }
        _ => out.all_colors = false,
    }
    let indices: Vec<u32> = match prim.indices() {
        Some(acc) => {
            let values = data.read(&acc)?;
            let mut idx = Vec::with_capacity(values.len());
            for (k, &v) in values.iter().enumerate() {
                #[expect(clippy::cast_sign_loss, reason = "checked in range first")]
                if v.fract() != 0.0 || v < 0.0 || v >= n as f64 {
                    return Err(IoError::malformed(
                        path,
                        format!("{element} index {k}"),
                        format!("vertex index {v} is out of range ({n} vertices)"),
                    ));
                } else {
                    idx.push(v as u32);
                }
            }
            idx
        }
        None => (0..u32::try_from(n).map_err(|_| too_many())?).collect(),
    };
    let tri = |a: u32, b: u32, c: u32| [base_u32 + a, base_u32 + b, base_u32 + c];
    let mut triangles: Vec<[u32; 3]> = match mode {
        Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
            .map(|i| {
                let (a, b, c) = (indices[i], indices[i + 1], indices[i + 2]);
                if i % 2 == 0 {
                    tri(a, b, c)
                } else {
                    tri(b, a, c)
                }
            })
            .collect(),
        Mode::TriangleFan => (1..indices.len().saturating_sub(1))
            .map(|i| tri(indices[i], indices[i + 1], indices[0]))
            .collect(),
        _ => indices
            .chunks_exact(3)
            .map(|c| tri(c[0], c[1], c[2]))
            .collect(),
    };
    if world.determinant() < 0.0 {
        for t in &mut triangles {
            t.swap(1, 2);
        }
    }
    if let Some(surface) = &mut out.surface {
        add_surface(path, surface, data, prim, &element, n, base_u32, &triangles)?;
    }
    out.triangles.extend(triangles);
    out.primitives += 1;
    Ok(())
}

/// Adds the corner uvs and colours of a primitive's `triangles` (global indices, `base` its
/// first vertex; `n` vertices) and their material.
#[expect(clippy::too_many_arguments, reason = "the primitive's context")]
#[expect(
    clippy::cast_possible_truncation,
    reason = "f32 storage is the documented precision of meshes"
)]
fn add_surface(
    path: &Path,
    out: &mut SurfaceParts,
    data: &GltfData,
    prim: &gltf::Primitive<'_>,
    element: &str,
    n: usize,
    base: u32,
    triangles: &[[u32; 3]],
) -> Result<(), IoError> {
    let material = prim.material().index();
    let uvs = match prim.get(&Semantic::TexCoords(0)) {
        Some(acc) if acc.count() == n => read_vec::<2>(data, &acc, "TEXCOORD_0")?
            .into_iter()
            .map(|v| Vec2::new(v[0] as f32, v[1] as f32))
            .collect(),
        other => {
            let why = match other {
                Some(acc) => format!(
                    "TEXCOORD_0 (accessor {}) has {} entries for {n} vertices",
                    acc.index(),
                    acc.count()
                ),
                None => "it has no TEXCOORD_0".to_string(),
            };
            out.without_uvs.push((element.to_string(), material, why));
            vec![Vec2::ZERO; n]
        }
    };
    if let Some(k) = uvs.iter().position(|v| !v.is_finite()) {
        return Err(IoError::malformed(
            path,
            format!("{element} vertex {k}"),
            "TEXCOORD_0 is not finite in f32",
        ));
    }
    let colors: Vec<Rgba> = match prim.get(&Semantic::Colors(0)) {
        Some(acc) if acc.count() == n => {
            out.any_colors = true;
            read_colors(data, &acc)?
        }
        Some(acc) => {
            return Err(IoError::malformed(
                path,
                format!("accessor {}", acc.index()),
                format!("COLOR_0 has {} entries for {n} vertices", acc.count()),
            ));
        }
        None => vec![[1.0; 4]; n],
    };
    for t in triangles {
        let local = t.map(|v| (v - base) as usize);
        out.corner_uvs.push(local.map(|v| uvs[v]));
        out.corner_colors.push(local.map(|v| colors[v]));
        out.material.push(material);
    }
    Ok(())
}

/// Calls `each` for the mesh of `root` and of each of its descendants, depth first in file
/// order, with its world transform. Iterative (an explicit stack): a chain of 20,000 nested
/// nodes must not overflow the thread's stack.
fn visit(
    path: &Path,
    root: gltf::Node<'_>,
    max_depth: usize,
    each: &mut dyn FnMut(&gltf::Mesh<'_>, &DMat4) -> Result<(), IoError>,
) -> Result<(), IoError> {
    let mut stack = vec![(root, DMat4::IDENTITY, 0usize)];
    while let Some((node, parent, depth)) = stack.pop() {
        if depth > max_depth {
            return Err(IoError::malformed(
                path,
                format!("node {}", node.index()),
                "the node hierarchy has a cycle",
            ));
        }
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            each(&mesh, &world)?;
        }
        let children: Vec<gltf::Node<'_>> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world, depth + 1)));
    }
    Ok(())
}

/// The root nodes read: those of the document's `scene`, else of scene 0, else every node
/// that is no other node's child.
fn scene_roots(doc: &gltf::Document) -> Vec<gltf::Node<'_>> {
    match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    if let Some(flag) = is_child.get_mut(c.index()) {
                        *flag = true;
                    }
                }
            }
            doc.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    }
}

/// Calls `each` for every mesh instance of the scene read (see the module docs), in order.
fn for_each_instance(
    data: &GltfData,
    each: &mut dyn FnMut(&gltf::Mesh<'_>, &DMat4) -> Result<(), IoError>,
) -> Result<(), IoError> {
    let doc = &data.document;
    let max_depth = doc.nodes().len();
    for root in scene_roots(doc) {
        visit(data.path(), root, max_depth, each)?;
    }
    Ok(())
}

/// Reads the static (rest-state) mesh of a glTF or GLB file; see the module docs.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be read, [`IoError::MissingReference`] when an external
/// buffer is missing, [`IoError::Malformed`] naming the accessor, primitive or node at fault.
pub fn read_gltf(path: &Path) -> Result<TriMesh, IoError> {
    let data = GltfData::open(path)?;
    let out = gather(&data, false)?;
    let bad = |e: crate::mesh::MeshError| IoError::malformed(path, "mesh", e.to_string());
    let has = out.primitives > 0;
    let mut mesh = TriMesh::try_new(out.positions, out.triangles).map_err(bad)?;
    if has && out.all_normals {
        mesh = mesh.with_normals(out.normals).map_err(bad)?;
    }
    if has && out.all_uvs {
        mesh = mesh.with_uvs(out.uvs).map_err(bad)?;
    }
    if has && out.all_colors {
        mesh = mesh.with_colors(out.colors).map_err(bad)?;
    }
    Ok(mesh)
}

/// Every triangle primitive of the scene read, in order (module docs), with the per-triangle
/// base-colour inputs when `surface` is set.
pub(super) fn gather(data: &GltfData, surface: bool) -> Result<Gathered, IoError> {
    let path = data.path();
    let mut out = Gathered {
        all_normals: true,
        all_uvs: true,
        all_colors: true,
        surface: surface.then(SurfaceParts::default),
        ..Gathered::default()
    };
    for_each_instance(data, &mut |mesh, world| {
        for prim in mesh.primitives() {
            add_primitive(path, &mut out, mesh, &prim, world, data)?;
        }
        Ok(())
    })?;
    Ok(out)
}

/// A glTF/GLB file opened for readers of other crates (the Gaussian splats reader of
/// `trisplat-splat`): the document's JSON, its accessors decoded with the checks of this
/// module, and its mesh instances with their world transforms.
pub struct GltfFile {
    data: GltfData,
}

/// What an accessor holds (before decoding).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AccessorInfo {
    /// The glTF component type code (5120 byte ... 5126 float).
    pub component_type: u32,
    /// Whether integer components are normalised.
    pub normalized: bool,
    /// Components per element (1 for SCALAR, 3 for VEC3, ...).
    pub components: usize,
    /// Elements.
    pub count: usize,
}

impl GltfFile {
    /// Opens `path` (`.gltf` with data-URI or external buffers, or `.glb`) and loads every
    /// buffer.
    ///
    /// # Errors
    /// As [`read_gltf`].
    pub fn open(path: &Path) -> Result<Self, IoError> {
        Ok(Self {
            data: GltfData::open(path)?,
        })
    }

    /// The file's path.
    #[must_use]
    pub fn path(&self) -> &Path {
        self.data.path()
    }

    /// The document's JSON (as in the file).
    #[must_use]
    pub fn json(&self) -> &serde_json::Value {
        &self.data.json
    }

    /// What accessor `index` holds, `None` when the file has no such accessor.
    #[must_use]
    pub fn accessor_info(&self, index: usize) -> Option<AccessorInfo> {
        let a = self.data.document.accessors().nth(index)?;
        Some(AccessorInfo {
            component_type: a.data_type().as_gl_enum(),
            normalized: a.normalized(),
            components: a.dimensions().multiplicity(),
            count: a.count(),
        })
    }

    /// Accessor `index` decoded as `count × components` f64 values (normalised integers per
    /// the glTF spec, sparse substitution applied; f32 values exactly; non-finite floats
    /// refused), every offset, stride and count checked against the bytes present.
    ///
    /// # Errors
    /// [`IoError::Malformed`] naming the accessor.
    pub fn read_accessor(&self, index: usize) -> Result<Vec<f64>, IoError> {
        let Some(a) = self.data.document.accessors().nth(index) else {
            return Err(IoError::malformed(
                self.path(),
                format!("accessor {index}"),
                "the file has no such accessor",
            ));
        };
        Ok(self.data.read(&a)?)
    }

    /// Every mesh instance of the scene read (the same nodes and order as [`read_gltf`]): the
    /// mesh index and its node's world transform.
    ///
    /// # Errors
    /// [`IoError::Malformed`] when the node hierarchy has a cycle.
    pub fn mesh_instances(&self) -> Result<Vec<(usize, DMat4)>, IoError> {
        let mut out = Vec::new();
        for_each_instance(&self.data, &mut |mesh, world| {
            out.push((mesh.index(), *world));
            Ok(())
        })?;
        Ok(out)
    }
}

// ---------------------------------------------------------------------------------------------
// Writing

/// Builds the JSON document and the single binary buffer for `mesh`.
fn build(mesh: &TriMesh) -> (serde_json::Value, Vec<u8>) {
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut attributes = serde_json::Map::new();
    let n = mesh.vertex_count();
    let mut add = |bin: &mut Vec<u8>,
                   data: Vec<f32>,
                   kind: &str,
                   target: u32,
                   extra: Option<(Vec<f32>, Vec<f32>)>|
     -> usize {
        let offset = bin.len();
        for x in &data {
            bin.extend_from_slice(&x.to_le_bytes());
        }
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len() * 4, "target": target}));
        let mut acc = json!({
            "bufferView": views.len() - 1, "componentType": FLOAT, "count": n, "type": kind,
        });
        if let Some((min, max)) = extra {
            acc["min"] = json!(min);
            acc["max"] = json!(max);
        }
        accessors.push(acc);
        accessors.len() - 1
    };
    if n > 0 {
        // glTF positions are f32 (the accessor's min/max are those of the values written).
        let p = mesh.positions_f32();
        let (lo, hi) = p.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &q| (lo.min(q), hi.max(q)),
        );
        let flat = p.iter().flat_map(|v| v.to_array()).collect();
        let i = add(
            &mut bin,
            flat,
            "VEC3",
            ARRAY_BUFFER,
            Some((lo.to_array().to_vec(), hi.to_array().to_vec())),
        );
        attributes.insert("POSITION".into(), json!(i));
        if let Some(normals) = mesh.normals() {
            // glTF wants unit normals: zero ones (degenerate) become +z.
            let flat = normals
                .iter()
                .flat_map(|v| v.try_normalize().unwrap_or(Vec3::Z).to_array())
                .collect();
            let i = add(&mut bin, flat, "VEC3", ARRAY_BUFFER, None);
            attributes.insert("NORMAL".into(), json!(i));
        }
        if let Some(uvs) = mesh.uvs() {
            let flat = uvs.iter().flat_map(|v| v.to_array()).collect();
            let i = add(&mut bin, flat, "VEC2", ARRAY_BUFFER, None);
            attributes.insert("TEXCOORD_0".into(), json!(i));
        }
        if let Some(colors) = mesh.colors() {
            let flat = colors
                .iter()
                .flat_map(|c| c.map(|x| x.clamp(0.0, 1.0)))
                .collect();
            let i = add(&mut bin, flat, "VEC4", ARRAY_BUFFER, None);
            attributes.insert("COLOR_0".into(), json!(i));
        }
    }
    let mut primitive = json!({"attributes": attributes});
    if mesh.triangle_count() > 0 {
        let offset = bin.len();
        for i in mesh.triangles().iter().flatten() {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        views.push(json!({"buffer": 0, "byteOffset": offset,
            "byteLength": bin.len() - offset, "target": ELEMENT_ARRAY_BUFFER}));
        accessors.push(
            json!({"bufferView": views.len() - 1, "componentType": UNSIGNED_INT,
            "count": mesh.triangle_count() * 3, "type": "SCALAR"}),
        );
        primitive["indices"] = json!(accessors.len() - 1);
        primitive["mode"] = json!(4);
    } else {
        primitive["mode"] = json!(0);
    }
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "trisplat"},
        "scene": 0,
    });
    if n == 0 {
        doc["scenes"] = json!([{"nodes": []}]);
    } else {
        doc["scenes"] = json!([{"nodes": [0]}]);
        doc["nodes"] = json!([{"mesh": 0}]);
        doc["meshes"] = json!([{"primitives": [primitive]}]);
        doc["accessors"] = json!(accessors);
        doc["bufferViews"] = json!(views);
        doc["buffers"] = json!([{"byteLength": bin.len()}]);
    }
    (doc, bin)
}

/// Writes `mesh` as `.glb` bytes.
///
/// # Errors
/// [`IoError::Unsupported`] when the buffer exceeds the 4 GiB a GLB can hold.
pub fn glb_bytes(path: &Path, mesh: &TriMesh) -> Result<Vec<u8>, IoError> {
    let (doc, bin) = build(mesh);
    glb_from_parts(path, &doc, bin)
}

/// A GLB file of a JSON document and the binary chunk holding its buffer 0 (`bin`, padded
/// here to 4 bytes; none when empty). `path` only names the file in errors.
///
/// # Errors
/// [`IoError::Unsupported`] when the file would exceed the 4 GiB a GLB can hold.
pub fn glb_from_parts(
    path: &Path,
    doc: &serde_json::Value,
    mut bin: Vec<u8>,
) -> Result<Vec<u8>, IoError> {
    let mut json = doc.to_string().into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let has_bin = !bin.is_empty();
    let total = 12 + 8 + json.len() + if has_bin { 8 + bin.len() } else { 0 };
    let too_big = || IoError::Unsupported {
        path: path.to_path_buf(),
        what: format!("a {total}-byte GLB (the format holds at most 4 GiB)"),
    };
    let total32 = u32::try_from(total).map_err(|_| too_big())?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total32.to_le_bytes());
    let json_len = u32::try_from(json.len()).map_err(|_| too_big())?;
    out.extend_from_slice(&json_len.to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    if has_bin {
        let bin_len = u32::try_from(bin.len()).map_err(|_| too_big())?;
        out.extend_from_slice(&bin_len.to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    Ok(out)
}

/// Writes `mesh` as `.gltf` JSON text with the buffer embedded as a base64 data URI.
#[must_use]
pub fn gltf_text(mesh: &TriMesh) -> String {
    let (doc, bin) = build(mesh);
    gltf_text_from_parts(doc, &bin)
}

/// `.gltf` JSON text of a document whose buffer 0 (if it has `buffers`) is `bin`, embedded as
/// a base64 data URI.
#[must_use]
pub fn gltf_text_from_parts(mut doc: serde_json::Value, bin: &[u8]) -> String {
    if doc.get("buffers").is_some() {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(bin)
        );
        doc["buffers"] = json!([{"byteLength": bin.len(), "uri": uri}]);
    }
    doc.to_string()
}
