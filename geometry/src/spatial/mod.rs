//! Spatial indexes: a k-d tree over points ([`PointIndex`], kiddo's immutable tree) and a BVH
//! over a mesh's triangles ([`TriangleBvh`], obvhs) with exact closest-point and ray queries.
//!
//! Both search in f32 and report distances recomputed in f64 from the f32 input coordinates.
//! Coordinates must be finite and at most [`MAX_COORDINATE`] in magnitude (f32 squared distances
//! overflow beyond that); both constructors check it and return a [`SpatialError`].

pub mod bvh;
pub mod kdtree;

pub use bvh::{
    Candidate, ClosestPoint, RayHit, TriangleBvh, box_distance_sq, closest_point_on_triangle,
};
pub use kdtree::{Nearest, PointIndex, distance_f64};

use glam::Vec3;
use rayon::prelude::*;

/// Largest coordinate magnitude the indexes accept: squared f32 distances between points this
/// far apart (`3 * (2e18)^2 = 1.2e37`) stay below `f32::MAX` (3.4e38).
pub const MAX_COORDINATE: f32 = 1e18;

/// Why a spatial index could not be built or queried.
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum SpatialError {
    /// A point index needs at least one point.
    #[error("no points to index")]
    Empty,
    /// A coordinate is NaN or infinite.
    #[error("point {index} has a non-finite coordinate")]
    NonFinite {
        /// Index of the point (or query, or vertex).
        index: usize,
    },
    /// A coordinate exceeds [`MAX_COORDINATE`] in magnitude.
    #[error("point {index} has a coordinate beyond 1e18 in magnitude")]
    TooLarge {
        /// Index of the point (or query, or vertex).
        index: usize,
    },
    /// A triangle names a vertex past the end of the positions.
    #[error("triangle {triangle} names a vertex past the {vertex_count} vertices")]
    BadIndex {
        /// Index of the triangle.
        triangle: usize,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// More points than `u32` indices can address.
    #[error("{count} points do not fit in u32 indices")]
    TooMany {
        /// Number of points.
        count: usize,
    },
    /// The k-d tree library refused the input.
    #[error("cannot build the k-d tree: {message}")]
    Build {
        /// The library's message.
        message: String,
    },
}

/// Checks finiteness and [`MAX_COORDINATE`] for every point, naming the first bad one.
pub(crate) fn check_points(points: &[Vec3]) -> Result<(), SpatialError> {
    let bad = points
        .par_iter()
        .with_min_len(4096)
        .position_first(|p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE);
    match bad {
        None => Ok(()),
        Some(index) if points[index].is_finite() => Err(SpatialError::TooLarge { index }),
        Some(index) => Err(SpatialError::NonFinite { index }),
    }
}

/// [`check_points`] for f64 points (mesh vertices).
pub(crate) fn check_dpoints(points: &[glam::DVec3]) -> Result<(), SpatialError> {
    let limit = f64::from(MAX_COORDINATE);
    let bad = points
        .par_iter()
        .with_min_len(4096)
        .position_first(|p| !p.is_finite() || p.abs().max_element() > limit);
    match bad {
        None => Ok(()),
        Some(index) if points[index].is_finite() => Err(SpatialError::TooLarge { index }),
        Some(index) => Err(SpatialError::NonFinite { index }),
    }
}

/// Spreads the low 21 bits of `v` to every third bit (for 63-bit Morton codes).
fn spread_bits(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// Indices of `points` (finite) sorted along a Morton (Z-order) curve over their bounds, ties by
/// index: nearby queries end up next to each other, so tree searches reuse cached nodes.
pub(crate) fn morton_order(points: &[Vec3]) -> Vec<u32> {
    let Some(bounds) = crate::mesh::Aabb::from_points(points) else {
        return Vec::new();
    };
    let lo = bounds.min;
    let extent = (bounds.max - lo).max_element();
    let scale = if extent > 0.0 {
        f64::from((1u32 << 21) - 1) / extent
    } else {
        0.0
    };
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = ((p.as_dvec3() - lo) * scale).max(glam::DVec3::ZERO);
            let code = spread_bits(c.x as u64)
                | (spread_bits(c.y as u64) << 1)
                | (spread_bits(c.z as u64) << 2);
            // Point counts are checked against u32 by the callers' indices.
            (code, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_order_is_a_permutation() {
        let points: Vec<Vec3> = (0..1000)
            .map(|i| Vec3::new((i % 10) as f32, (i / 10 % 10) as f32, (i / 100) as f32))
            .collect();
        let mut order = morton_order(&points);
        assert_eq!(order[0], 0);
        order.sort_unstable();
        assert!(order.iter().enumerate().all(|(i, &o)| o as usize == i));
        assert!(morton_order(&[]).is_empty());
        assert_eq!(morton_order(&[Vec3::ONE; 3]), vec![0, 1, 2]);
    }
}
