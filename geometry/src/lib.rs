//! Geometry core of trisplat: indexed triangle meshes and point clouds, their validation and
//! clean-up, mesh I/O (PLY, OBJ, glTF/GLB; glTF base-colour textures), spatial indexes (k-d tree, triangle BVH), metrics
//! with trimesh/Open3D definitions, smoothing and sampling.
//!
//! This crate knows nothing of Gaussians; see `trisplat-splat` for those.
//!
//! # Layout of the API
//! The core types (meshes and their errors and reports, point clouds, colours, typed ids,
//! cameras with their file formats and rigs) are re-exported here at the root; the modules
//! that define them are private. The rest are public namespaces, addressed through their
//! module, each documented there:
//!
//! - [`io`]: file formats (PLY, OBJ, glTF/GLB, NPY) and frame sequences;
//! - [`animation`]: animated templates (glTF clips, mesh sequences, blendshapes);
//! - [`spatial`]: the k-d tree and the triangle BVH;
//! - [`metrics`]: Chamfer, F-score and normal metrics; [`mesh_stats`]: mesh structure;
//! - [`sampling`], [`smoothing`]: surface sampling and mesh smoothing with their defaults;
//! - [`simplify`]: decimation through meshoptimizer, with the error it costs;
//! - [`topology`], [`cleanup`], [`subdivide`], [`outliers`]: connectivity and repairs;
//! - [`base_color`], [`texture`]: glTF base colours and their textures; [`envmap`]:
//!   equirectangular environment maps (read from Radiance `.hdr` by [`io::hdr`]);
//! - [`mesh_render`]: depth, normal and mask maps of a mesh by ray casting;
//! - [`rng`]: the deterministic random streams.
//!
//! Inside the crate, code imports from the module that defines an item, never through these
//! re-exports, so that no file imports back from one that imports it.

/// The vector types of the API (positions are `glam::DVec3`, bulk data `glam::Vec3`).
pub use glam;

pub mod animation;
pub mod base_color;
mod camera;
pub mod cleanup;
mod color;
pub mod envmap;
mod ids;
pub mod io;
mod mesh;
pub mod mesh_render;
pub mod mesh_stats;
pub mod metrics;
pub mod outliers;
mod points;
pub mod rng;
pub mod sampling;
pub mod simplify;
pub mod smoothing;
pub mod spatial;
pub mod subdivide;
#[cfg(test)]
mod test_meshes;
pub mod texture;
pub mod topology;
mod validation;

pub use camera::{
    Camera, CameraError, ROTATION_TOLERANCE, bounding_sphere, orbit_rig, parse_cameras_json,
    parse_transforms_json, read_cameras_json, read_transforms_json, sphere_rig, write_cameras_json,
};
pub use color::Rgba;
pub use ids::{TriId, VertexId};
pub use mesh::{Aabb, LOCAL_ORIGIN_REACH, MeshError, TriMesh};
pub use points::PointCloud;
pub use validation::MeshReport;
