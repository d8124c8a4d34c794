//! Spatial indexes: an exact k-d tree over points ([`PointIndex`], `point_tree`) and a BVH
//! over a mesh's triangles ([`TriangleBvh`], obvhs) with exact closest-point and ray queries.
//!
//! The k-d tree ranks candidates by f64 distances from the f32 coordinates (exact, ties by
//! index); the BVH searches in f32 and reports distances recomputed in f64.
//! Coordinates must be finite and at most [`MAX_COORDINATE`] in magnitude (f32 squared distances
//! overflow beyond that); both constructors check it and return a [`SpatialError`].

pub mod bvh;
pub(crate) mod error;
pub mod kdtree;
mod limits;
mod morton;
mod point_tree;
pub mod surface;

pub use bvh::{
    Candidate, ClosestPoint, RayHit, TriangleBvh, box_distance_sq, closest_point_on_triangle,
};
pub use error::SpatialError;
pub use kdtree::{Nearest, PointIndex, distance_f64};
pub use limits::MAX_COORDINATE;
pub use surface::{SurfaceHit, SurfaceIndex};
