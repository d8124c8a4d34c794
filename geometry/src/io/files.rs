//! Whole mesh and point files, the format chosen by extension: [`read_mesh`], [`write_mesh`],
//! [`read_points`], [`write_points`] and their options.

use std::path::Path;

use glam::DVec3;

use super::atomic::write_atomically;
use super::error::IoError;
use super::format::Format;
use super::obj::ObjVertices;
use super::ply::{PlyEncoding, PlyExtras};
use super::{gltf, obj, ply};
use crate::mesh::{MeshError, TriMesh};
use crate::points::PointCloud;

/// Options for writing files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriteOptions {
    /// Write PLY as ascii instead of binary little-endian.
    pub ascii: bool,
}

impl WriteOptions {
    fn ply_encoding(self) -> PlyEncoding {
        if self.ascii {
            PlyEncoding::Ascii
        } else {
            PlyEncoding::BinaryLittleEndian
        }
    }
}

/// Options for reading meshes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// How OBJ corners become vertices: the file's own vertex order (default) or trimesh's
    /// split-at-seams layout. See [`obj`](super::obj).
    pub obj_vertices: ObjVertices,
}

/// Reads a triangle mesh (PLY, OBJ, glTF/GLB in its rest state), chosen by extension.
///
/// OBJ files keep their vertex order ([`ObjVertices::Positions`]); use [`read_mesh_with`] for
/// trimesh's layout.
///
/// # Errors
/// [`IoError`] naming the file and the element at fault.
pub fn read_mesh(path: &Path) -> Result<TriMesh, IoError> {
    read_mesh_with(path, ReadOptions::default())
}

/// Reads a triangle mesh with explicit [`ReadOptions`].
///
/// # Errors
/// [`IoError`] naming the file and the element at fault.
pub fn read_mesh_with(path: &Path, options: ReadOptions) -> Result<TriMesh, IoError> {
    match Format::from_path(path)? {
        Format::Ply => ply::read_ply_mesh(path).map(|(mesh, _)| mesh),
        Format::Obj => obj::read_obj(path, options.obj_vertices),
        Format::Gltf | Format::Glb => gltf::read_gltf(path),
    }
}

/// Writes a triangle mesh atomically, format by extension.
///
/// PLY: binary little-endian unless `options.ascii`, `face` as `list uchar int vertex_indices`,
/// normals, uvs (`s t`) and colours (`red green blue alpha` uchar) when present.
///
/// # Errors
/// [`IoError`] when the file cannot be written.
pub fn write_mesh(path: &Path, mesh: &TriMesh, options: WriteOptions) -> Result<(), IoError> {
    match Format::from_path(path)? {
        Format::Ply => {
            ply::write_ply_mesh(path, mesh, &PlyExtras::default(), options.ply_encoding())
        }
        Format::Obj => write_atomically(path, |w| obj::write_obj_to(path, w, mesh)),
        Format::Gltf => {
            let text = gltf::gltf_text(mesh);
            write_atomically(path, |w| {
                w.write_all(text.as_bytes())
                    .map_err(|e| IoError::os(path, e))
            })
        }
        Format::Glb => {
            let bytes = gltf::glb_bytes(path, mesh)?;
            write_atomically(path, |w| {
                w.write_all(&bytes).map_err(|e| IoError::os(path, e))
            })
        }
    }
}

/// Reads a point cloud: a PLY `vertex` element with optional normals and colours, or the
/// vertices of any mesh file (with its area-weighted vertex normals when the file has none).
///
/// # Errors
/// [`IoError`] naming the file and the element at fault.
pub fn read_points(path: &Path) -> Result<PointCloud, IoError> {
    read_points_around(path, false).map(|(cloud, _)| cloud)
}

/// [`read_points`] with the positions relative to a local origin, returned beside them: the
/// points' [`crate::Aabb::local_origin`] (zero unless they are far from the world origin),
/// subtracted in `f64` before the positions are stored in `f32`. What is built from the
/// points (an alpha shape, say) is moved back by `+origin` in `f64`.
///
/// # Errors
/// As [`read_points`].
pub fn read_points_local(path: &Path) -> Result<(PointCloud, DVec3), IoError> {
    read_points_around(path, true)
}

fn read_points_around(path: &Path, local: bool) -> Result<(PointCloud, DVec3), IoError> {
    if Format::from_path(path)? == Format::Ply {
        let doc = ply::read_ply_document(path)?;
        let has_faces = doc.element("face").is_some_and(|f| f.count > 0)
            || doc.element("tristrips").is_some_and(|f| f.count > 0);
        let (cloud, _, origin) = if local {
            ply::ply_to_points_local(path, &doc)?
        } else {
            let (cloud, extras) = ply::ply_to_points(path, &doc)?;
            (cloud, extras, DVec3::ZERO)
        };
        if cloud.normals().is_some() || !has_faces {
            return Ok((cloud, origin));
        }
        let (mesh, _) = ply::ply_to_mesh(path, &doc)?;
        return mesh_points(path, mesh, local);
    }
    mesh_points(path, read_mesh(path)?, local)
}

/// The vertices of `mesh` as points, with its normals (area-weighted ones when it has none),
/// relative to its local origin when `local` (returned), else to the world origin.
fn mesh_points(
    path: &Path,
    mut mesh: TriMesh,
    local: bool,
) -> Result<(PointCloud, DVec3), IoError> {
    let origin = if local {
        mesh.bounds().map_or(DVec3::ZERO, |b| b.local_origin())
    } else {
        DVec3::ZERO
    };
    mesh.translate(-origin);
    let normals = match mesh.normals() {
        Some(n) => n.to_vec(),
        None => mesh.vertex_normals(),
    };
    let (positions, _, _, _, colors) = mesh.into_parts();
    let bad = |e: MeshError| IoError::malformed(path, "vertices", e.to_string());
    let positions = positions.iter().map(|p| p.as_vec3()).collect();
    let mut cloud = PointCloud::try_new(positions)
        .map_err(bad)?
        .with_normals(normals)
        .map_err(bad)?;
    if let Some(c) = colors {
        cloud = cloud.with_colors(c).map_err(bad)?;
    }
    Ok((cloud, origin))
}

/// Writes a point cloud as PLY (binary unless `options.ascii`), atomically.
///
/// # Errors
/// [`IoError`] when the file cannot be written, [`IoError::Unsupported`] for a non-PLY path.
pub fn write_points(
    path: &Path,
    points: &PointCloud,
    options: WriteOptions,
) -> Result<(), IoError> {
    write_points_at(path, points, DVec3::ZERO, options)
}

/// [`write_points`] for points stored relative to `origin` (as [`read_points_local`] gives
/// them, or sampled from a mesh moved to its local origin): written at `p + origin`, computed
/// in f64, `double` unless every coordinate is an f32 value.
///
/// # Errors
/// As [`write_points`].
pub fn write_points_at(
    path: &Path,
    points: &PointCloud,
    origin: DVec3,
    options: WriteOptions,
) -> Result<(), IoError> {
    if Format::from_path(path)? != Format::Ply {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: "point clouds are written as .ply only".into(),
        });
    }
    ply::write_ply_points_at(
        path,
        points,
        origin,
        &PlyExtras::default(),
        options.ply_encoding(),
    )
}
