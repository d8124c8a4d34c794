//! The 2-Wasserstein distance between Gaussians in the residual (Procrustes) form (docs/conventions.md §4,
//! the GSDHuman densification gate).
//!
//! `W2² = |mu1 - mu2|² + B²`, `B² = min over orthogonal U of ‖L1 - L2 U‖_F²` with covariance
//! axes `L_i = R_i diag(s_i)` (`Σ_i = L_i L_iᵀ`); the minimiser is `U = P Qᵀ` from the SVD
//! `L2ᵀ L1 = P S Qᵀ`. The residual matrix is formed explicitly, so there is no cancellation: the
//! textbook trace form `tr Σ1 + tr Σ2 - 2 tr((Σ1^½ Σ2 Σ1^½)^½)` subtracts nearly equal numbers
//! for similar Gaussians and loses several percent in `f32`. Everything is computed in `f64`.

use glam::{DMat3, DVec3};

use crate::gaussians::GaussianSet;
use crate::svd::jacobi_orthogonalise;

/// Covariance axes `L = R diag(s)` of Gaussian `i` (activated scales and rotation, `f64`).
///
/// # Panics
/// If `i >= set.len()`.
#[must_use]
pub fn covariance_axes(set: &GaussianSet, i: usize) -> DMat3 {
    let r = set.rotation_matrix(i);
    let s = set.scale(i).as_dvec3();
    DMat3::from_cols(r.x_axis * s.x, r.y_axis * s.y, r.z_axis * s.z)
}

/// The Bures part `B² = min_U ‖l1 - l2 U‖_F²` over orthogonal `U` (reflections included, as the
/// Wasserstein distance requires), by the explicit residual.
#[must_use]
pub fn bures_sq(l1: DMat3, l2: DMat3) -> f64 {
    let u = polar_factor(l2.transpose() * l1);
    let r = l1 - l2 * u;
    r.to_cols_array().iter().map(|v| v * v).sum()
}

/// An orthogonal `U` maximising `tr(Uᵀ k)`: the polar factor `P Qᵀ` of the SVD `k = P S Qᵀ`
/// (identity for a non-finite `k`).
///
/// One-sided Jacobi on the columns of `k` (the iteration of
/// [`crate::svd::rotation_and_scales`]) with the rotations accumulated in `Q`, so that
/// `k Q = [σ_i p_i]`. For nearly singular covariances `k = L2ᵀ L1` is strongly graded; a
/// bidiagonalising SVD (nalgebra's) is accurate to `ε σ_max` absolute only, which garbles the
/// smallest singular triple and cost `B²` up to 1.6e-4 relative for Gaussians with scale ratio
/// 1e8 differing by 1e-6, where this keeps ~1e-10 (docs/numerics.md, `w2` rows).
fn polar_factor(k: DMat3) -> DMat3 {
    if !k.is_finite() {
        return DMat3::IDENTITY;
    }
    let mut c = [k.x_axis, k.y_axis, k.z_axis];
    let mut q = [DVec3::X, DVec3::Y, DVec3::Z];
    jacobi_orthogonalise(&mut c, Some(&mut q));
    // p_i = c_i / σ_i, largest first; vanishing columns are completed orthonormally (their
    // singular value is 0, so their sign does not change tr(Uᵀ k)).
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| c[b].length_squared().total_cmp(&c[a].length_squared()));
    let [i0, i1, i2] = order;
    let p0 = c[i0].try_normalize().unwrap_or(DVec3::X);
    let p1 = (c[i1] - p0 * p0.dot(c[i1]))
        .try_normalize()
        .unwrap_or_else(|| p0.any_orthonormal_vector());
    let n = p0.cross(p1);
    let p2 = if n.dot(c[i2]) < 0.0 { -n } else { n };
    let outer = |p: DVec3, q: DVec3| DMat3::from_cols(p * q.x, p * q.y, p * q.z);
    outer(p0, q[i0]) + outer(p1, q[i1]) + outer(p2, q[i2])
}

/// `W2²` between the Gaussians `(mu1, l1)` and `(mu2, l2)`.
#[must_use]
pub fn w2_sq(mu1: DVec3, l1: DMat3, mu2: DVec3, l2: DMat3) -> f64 {
    (mu1 - mu2).length_squared() + bures_sq(l1, l2)
}

/// `W2²` between Gaussian `i` of `a` and Gaussian `j` of `b` (both in the same frame: world
/// sets, or local parameters of the same triangle).
///
/// # Panics
/// If `i >= a.len()` or `j >= b.len()`.
#[must_use]
pub fn gaussian_w2_sq(a: &GaussianSet, i: usize, b: &GaussianSet, j: usize) -> f64 {
    w2_sq(
        a.means()[i].as_dvec3(),
        covariance_axes(a, i),
        b.means()[j].as_dvec3(),
        covariance_axes(b, j),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;
    use trisplat_geometry::rng::Rng;

    fn axes(q: DQuat, s: DVec3) -> DMat3 {
        let r = DMat3::from_quat(q);
        DMat3::from_cols(r.x_axis * s.x, r.y_axis * s.y, r.z_axis * s.z)
    }

    /// Commuting covariances (same axes): `B² = Σ (s1_i - s2_i)²` exactly.
    #[test]
    fn same_axes_closed_form() {
        let q = DQuat::from_rotation_y(0.7) * DQuat::from_rotation_x(-0.2);
        let s1 = DVec3::new(1.0, 0.5, 0.01);
        for eps in [1e-1, 1e-4, 1e-7] {
            let s2 = s1 * (1.0 + eps) + DVec3::new(0.0, eps, 0.0);
            let want = (s1 - s2).length_squared();
            let got = bures_sq(axes(q, s1), axes(q, s2));
            assert!((got - want).abs() <= 1e-8 * want, "{eps}: {got} vs {want}");
        }
        // A sign flip of an axis is the same Gaussian: distance 0.
        let l = axes(q, s1);
        let flipped = DMat3::from_cols(-l.x_axis, l.y_axis, l.z_axis);
        assert!(bures_sq(l, flipped) < 1e-28);
    }

    /// Symmetry, zero distance to itself, and optimality against `U = I`.
    #[test]
    fn symmetric_and_zero_on_itself() {
        let mut rng = Rng::new(4);
        for _ in 0..200 {
            let q1 = DQuat::from_xyzw(rng.uniform_f64(), rng.uniform_f64(), rng.uniform_f64(), 1.0)
                .normalize();
            let q2 = DQuat::from_xyzw(rng.uniform_f64(), rng.uniform_f64(), rng.uniform_f64(), 1.0)
                .normalize();
            let s1 = DVec3::new(rng.uniform_f64(), rng.uniform_f64(), rng.uniform_f64()) + 0.01;
            let s2 = DVec3::new(rng.uniform_f64(), rng.uniform_f64(), rng.uniform_f64()) + 0.01;
            let (l1, l2) = (axes(q1, s1), axes(q2, s2));
            let ab = bures_sq(l1, l2);
            let ba = bures_sq(l2, l1);
            assert!((ab - ba).abs() <= 1e-12 * ab.max(1e-300));
            assert!(bures_sq(l1, l1) <= 1e-28);
            // Any orthogonal U gives a larger residual than the optimum.
            let r = l1 - l2;
            let naive: f64 = r.to_cols_array().iter().map(|v| v * v).sum();
            assert!(ab <= naive + 1e-15);
        }
    }
}
