//! The coordinates the indexes accept: finite and at most [`MAX_COORDINATE`] in magnitude,
//! checked in parallel naming the first bad point.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::error::SpatialError;

/// Largest coordinate magnitude the indexes accept: squared f32 distances between points this
/// far apart (`3 * (2e18)^2 = 1.2e37`) stay below `f32::MAX` (3.4e38).
pub const MAX_COORDINATE: f32 = 1e18;

/// Checks finiteness and [`MAX_COORDINATE`] for every point, naming the first bad one.
pub(crate) fn check_points(points: &[Vec3]) -> Result<(), SpatialError> {
    first_bad(
        points,
        |p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE,
        |p| p.is_finite(),
    )
}

/// [`check_points`] for f64 points (mesh vertices).
pub(crate) fn check_dpoints(points: &[DVec3]) -> Result<(), SpatialError> {
    let limit = f64::from(MAX_COORDINATE);
    first_bad(
        points,
        |p| !p.is_finite() || p.abs().max_element() > limit,
        |p| p.is_finite(),
    )
}

/// The first point that is `bad`, searched in parallel, as [`SpatialError::TooLarge`] when it
/// is `finite`, else [`SpatialError::NonFinite`].
fn first_bad<P: Sync>(
    points: &[P],
    bad: impl Fn(&P) -> bool + Sync + Send,
    finite: impl Fn(&P) -> bool,
) -> Result<(), SpatialError> {
    match points.par_iter().with_min_len(4096).position_first(bad) {
        None => Ok(()),
        Some(index) if finite(&points[index]) => Err(SpatialError::TooLarge { index }),
        Some(index) => Err(SpatialError::NonFinite { index }),
    }
}
