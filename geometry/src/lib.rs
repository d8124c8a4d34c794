//! Geometry core of trisplat: indexed triangle meshes and point clouds, their validation and
//! clean-up, mesh I/O (PLY, OBJ, glTF/GLB; glTF base-colour textures), spatial indexes (k-d tree, triangle BVH), metrics
//! with trimesh/Open3D definitions, smoothing and sampling.
//!
//! This crate knows nothing of Gaussians; see `trisplat-splat` for those.
//!
//! # Layout of the API
//! The types every caller meets (meshes, point clouds, cameras and rigs, base colours and
//! textures, the mesh renderer, mesh statistics, outlier removal) are re-exported here at the
//! root; the modules that define them are private. Families of functions and constants that
//! are addressed through their module stay public namespaces:
//!
//! - [`io`]: file formats (PLY, OBJ, glTF/GLB, NPY) and frame sequences;
//! - [`animation`]: animated templates (glTF clips, mesh sequences, blendshapes);
//! - [`spatial`]: the k-d tree and the triangle BVH;
//! - [`metrics`]: Chamfer, F-score and normal metrics;
//! - [`sampling`], [`smoothing`]: surface sampling and mesh smoothing with their defaults;
//! - [`topology`], [`cleanup`], [`subdivide`]: mesh connectivity and its repairs;
//! - [`rng`]: the deterministic random streams.
//!
//! Inside the crate, code imports from the module that defines an item, never through these
//! re-exports, so that no file imports back from one that imports it.

/// The vector types of the API (positions are `glam::DVec3`, bulk data `glam::Vec3`).
pub use glam;

pub mod animation;
mod base_color;
mod camera;
pub mod cleanup;
mod color;
mod ids;
pub mod io;
mod mesh;
mod mesh_render;
mod mesh_stats;
pub mod metrics;
mod outliers;
mod points;
pub mod rng;
pub mod sampling;
pub mod smoothing;
pub mod spatial;
pub mod subdivide;
mod texture;
pub mod topology;
mod validation;

pub use base_color::{BaseColor, BaseColorError, Material, MaterialTexture};
pub use camera::{
    Camera, CameraError, ROTATION_TOLERANCE, bounding_sphere, orbit_rig, parse_cameras_json,
    parse_transforms_json, read_cameras_json, read_transforms_json, sphere_rig, write_cameras_json,
};
pub use color::Rgba;
pub use ids::{TriId, VertexId};
pub use mesh::{Aabb, LOCAL_ORIGIN_REACH, MeshError, TriMesh};
pub use mesh_render::{
    MeshMaps, MeshRenderOptions, MeshRenderer, NO_TRIANGLE, NormalFrame, NormalSource,
};
pub use mesh_stats::MeshStats;
pub use outliers::{OutlierError, statistical_outliers};
pub use points::PointCloud;
pub use texture::{Filter, Sampler, Texture, TextureError, Wrap, linear_to_srgb, srgb_to_linear};
pub use validation::MeshReport;
