//! Geometry core of trisplat: indexed triangle meshes and point clouds, their validation and
//! clean-up, mesh I/O (PLY, OBJ, glTF/GLB; glTF base-colour textures), spatial indexes (k-d tree, triangle BVH), metrics
//! with trimesh/Open3D definitions, smoothing and sampling.
//!
//! This crate knows nothing of Gaussians; see `trisplat-splat` for those.

/// The vector types of the API (positions are `glam::DVec3`, bulk data `glam::Vec3`).
pub use glam;

pub mod animation;
pub mod base_color;
pub mod camera;
pub mod cleanup;
mod color;
pub mod ids;
pub mod io;
pub mod mesh;
pub mod mesh_render;
pub mod mesh_stats;
pub mod metrics;
pub mod outliers;
pub mod points;
pub mod rng;
pub mod sampling;
pub mod smoothing;
pub mod spatial;
pub mod subdivide;
pub mod texture;
pub mod topology;
pub mod validation;

pub use camera::{Camera, bounding_sphere};
pub use color::Rgba;
pub use ids::{TriId, VertexId};
pub use mesh::{Aabb, MeshError, TriMesh};
pub use points::PointCloud;
pub use validation::MeshReport;
