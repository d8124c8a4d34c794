//! Random inputs shared by the unit tests.

use glam::{DMat3, DQuat};
use trisplat_geometry::rng::Rng;

/// A unit quaternion from four uniform draws in ±½ (x, y, z, w, in that order), normalised.
pub(crate) fn random_rotation(rng: &mut Rng) -> DQuat {
    DQuat::from_xyzw(
        rng.uniform_f64() - 0.5,
        rng.uniform_f64() - 0.5,
        rng.uniform_f64() - 0.5,
        rng.uniform_f64() - 0.5,
    )
    .normalize()
}

/// A matrix of nine uniform draws in ±½ (column-major order).
pub(crate) fn random_matrix(rng: &mut Rng) -> DMat3 {
    DMat3::from_cols_array(&[0; 9].map(|_: i32| rng.uniform_f64() - 0.5))
}
