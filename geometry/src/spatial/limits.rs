//! The coordinates the indexes accept: finite and at most [`MAX_COORDINATE`] in magnitude,
//! checked in parallel naming the first bad point.

use glam::Vec3;
use rayon::prelude::*;

use super::error::SpatialError;

/// Largest coordinate magnitude the indexes accept: squared f32 distances between points this
/// far apart (`3 * (2e18)^2 = 1.2e37`) stay below `f32::MAX` (3.4e38).
pub const MAX_COORDINATE: f32 = 1e18;

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
