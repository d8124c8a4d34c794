//! The `f64` factorisation of covariance axes into a rotation and scales (one-sided Jacobi, with
//! nalgebra's SVD as its reference): the exact path of deformation ([`crate::deform`]) and the
//! fallback of its `f32` lane kernel ([`crate::lanes`]).

use glam::{DMat3, DVec3};
use nalgebra::Matrix3;

/// Smallest output scale (a collapsed axis): `f32::MIN_POSITIVE`, whose log (≈ −87.3) is finite
/// and whose `exp` in `f32` is still positive.
pub const MIN_OUTPUT_SCALE: f64 = f32::MIN_POSITIVE as f64;

/// Relative orthogonality at which one-sided Jacobi stops rotating a column pair
/// (`|c_p · c_q| ≤ tol |c_p| |c_q|`): ~45 `f64` ulps, above the rounding noise of the dot
/// product (a bound at the noise level makes the iteration chase rounding for every sweep).
pub const JACOBI_TOL: f64 = 1e-14;

/// A sweep whose rotations all have `|tan θ|` below this ends the iteration (the next sweep
/// would find off-diagonal terms of order `θ²`, below [`JACOBI_TOL`]).
pub const JACOBI_SMALL_ROTATION: f64 = 1e-8;

/// Sweep limit of one-sided Jacobi; quadratic convergence needs ~3-6 sweeps for any 3×3 matrix,
/// 1-2 when the columns start nearly orthogonal (mild deformations).
pub const JACOBI_MAX_SWEEPS: usize = 24;

/// Rotation `U` (`det U = +1`) and singular values (descending) of `l`, in `f64`, so that
/// `U diag(σ)² Uᵀ = l lᵀ`: the polar/SVD factor of the covariance axes.
///
/// One-sided (Hestenes) Jacobi on the columns of `l`: pairs of columns are rotated until they
/// are orthogonal; then `σ_i = |c_i|` with relative accuracy even for tiny columns (no squaring,
/// unlike an eigen-decomposition of `l lᵀ`), `u_i = c_i / σ_i` for the two largest and
/// `u_2 = u_0 × u_1`, which also covers rank-deficient `l` (surfels, collapsed triangles).
/// Checked against nalgebra's SVD in the tests.
#[must_use]
pub fn rotation_and_scales(l: DMat3) -> (DMat3, DVec3) {
    let mut c = [l.x_axis, l.y_axis, l.z_axis];
    jacobi_orthogonalise(&mut c, None);
    finish(c)
}

/// One-sided (Hestenes) Jacobi sweeps: rotates pairs of the columns `c` until they are
/// orthogonal (to [`JACOBI_TOL`]), at most [`JACOBI_MAX_SWEEPS`] sweeps; `along`, when given,
/// takes the same rotations (it accumulates the right factor of the SVD when it starts as the
/// identity).
pub(crate) fn jacobi_orthogonalise(c: &mut [DVec3; 3], mut along: Option<&mut [DVec3; 3]>) {
    for _sweep in 0..JACOBI_MAX_SWEEPS {
        #[cfg(test)]
        SWEEPS.with(|s| s.set(s.get() + 1));
        let mut largest_t = 0.0f64;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let a = c[p].length_squared();
            let b = c[q].length_squared();
            let g = c[p].dot(c[q]);
            if g * g <= JACOBI_TOL * JACOBI_TOL * a * b {
                continue;
            }
            let zeta = (b - a) / (2.0 * g);
            let t = if zeta.abs() > 1e100 {
                0.5 / zeta
            } else {
                zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt())
            };
            largest_t = largest_t.max(t.abs());
            let cs = 1.0 / (1.0 + t * t).sqrt();
            let sn = cs * t;
            let rotate = |m: &mut [DVec3; 3]| {
                let (mp, mq) = (m[p], m[q]);
                m[p] = mp * cs - mq * sn;
                m[q] = mp * sn + mq * cs;
            };
            rotate(c);
            if let Some(m) = along.as_deref_mut() {
                rotate(m);
            }
        }
        // Rotations this small leave off-diagonal terms of order t² (below JACOBI_TOL): the
        // columns are orthogonal without another checking sweep.
        if largest_t < JACOBI_SMALL_ROTATION {
            break;
        }
    }
}

/// Rotation and descending singular values from mutually orthogonal columns.
fn finish(c: [DVec3; 3]) -> (DMat3, DVec3) {
    let len = c.map(DVec3::length);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| len[b].total_cmp(&len[a]));
    let s = DVec3::new(len[order[0]], len[order[1]], len[order[2]]);
    let Some(u0) = c[order[0]].try_normalize() else {
        return (DMat3::IDENTITY, DVec3::ZERO);
    };
    let u1 = (c[order[1]] - u0 * u0.dot(c[order[1]]))
        .try_normalize()
        .unwrap_or_else(|| any_orthogonal(u0));
    let rot = DMat3::from_cols(u0, u1, u0.cross(u1));
    if rot.is_finite() && s.is_finite() {
        (rot, s)
    } else {
        (DMat3::IDENTITY, DVec3::ZERO)
    }
}

#[cfg(test)]
thread_local! {
    static SWEEPS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// A unit vector orthogonal to the unit vector `a`.
fn any_orthogonal(a: DVec3) -> DVec3 {
    let axis = if a.x.abs() <= a.y.abs() && a.x.abs() <= a.z.abs() {
        DVec3::X
    } else if a.y.abs() <= a.z.abs() {
        DVec3::Y
    } else {
        DVec3::Z
    };
    a.cross(axis).normalize_or(DVec3::Y)
}

/// The same factorisation by nalgebra's SVD (the reference for [`rotation_and_scales`]).
#[must_use]
pub fn rotation_and_scales_svd(l: DMat3) -> (DMat3, DVec3) {
    let m = Matrix3::from_column_slice(&l.to_cols_array());
    let svd = m.svd(true, false);
    let (Some(u), sigma) = (svd.u, svd.singular_values) else {
        return (DMat3::IDENTITY, DVec3::ZERO);
    };
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| sigma[b].total_cmp(&sigma[a]));
    let col = |k: usize| DVec3::new(u[(0, k)], u[(1, k)], u[(2, k)]);
    let (c0, c1, mut c2) = (col(order[0]), col(order[1]), col(order[2]));
    if c0.cross(c1).dot(c2) < 0.0 {
        c2 = -c2;
    }
    let rot = DMat3::from_cols(c0, c1, c2);
    let s = DVec3::new(sigma[order[0]], sigma[order[1]], sigma[order[2]]);
    if rot.is_finite() && s.is_finite() {
        (rot, s)
    } else {
        (DMat3::IDENTITY, DVec3::ZERO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::rng::Rng;

    #[test]
    fn jacobi_matches_nalgebra_svd_and_keeps_tiny_scales() {
        let mut rng = Rng::new(9);
        let mut worst_ours = [0.0f64; 3];
        let mut worst_theirs = [0.0f64; 3];
        for case in 0..3000 {
            let a = crate::test_util::random_matrix(&mut rng);
            // Column scales spanning LAM's range (exp(-30)..1), and exact zeros.
            let s = DVec3::new(
                (rng.uniform_f64() * -30.0).exp(),
                (rng.uniform_f64() * -30.0).exp(),
                if case % 7 == 0 {
                    0.0
                } else {
                    (rng.uniform_f64() * -30.0).exp()
                },
            );
            let l = DMat3::from_cols(a.x_axis * s.x, a.y_axis * s.y, a.z_axis * s.z);
            let (u, sig) = rotation_and_scales(l);
            let (v, sig_ref) = rotation_and_scales_svd(l);
            assert!(
                (u.transpose() * u - DMat3::IDENTITY)
                    .to_cols_array()
                    .iter()
                    .all(|e| e.abs() < 1e-12)
            );
            assert!((u.determinant() - 1.0).abs() < 1e-12);
            // The singular values are checked through the invariants they must reproduce,
            // each computed directly from `l` (accurate even for graded columns):
            // σ0σ1σ2 = |det l|, Σ_{i<j} σi²σj² = |cof l|², Σ σi² = |l|².
            let f2 = |m: DMat3| m.to_cols_array().iter().map(|e| e * e).sum::<f64>();
            let inv = |g: DVec3| {
                let q = g * g;
                [
                    g.x * g.y * g.z,
                    q.x * q.y + q.x * q.z + q.y * q.z,
                    q.x + q.y + q.z,
                ]
            };
            let truth = [l.determinant().abs(), f2(crate::frames::cofactor(l)), f2(l)];
            let (ours, theirs) = (inv(sig), inv(sig_ref));
            for k in 0..3 {
                let rel = |x: f64| {
                    if truth[k] == 0.0 {
                        x
                    } else {
                        (x - truth[k]).abs() / truth[k]
                    }
                };
                worst_ours[k] = worst_ours[k].max(rel(ours[k]));
                worst_theirs[k] = worst_theirs[k].max(rel(theirs[k]));
            }
            // The covariance the output means equals l lᵀ.
            let back = u * DMat3::from_diagonal(sig * sig) * u.transpose();
            let want = l * l.transpose();
            let scale = want
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, e| m.max(e.abs()));
            let err = (back - want)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, e| m.max(e.abs()));
            assert!(err <= 1e-13 * scale, "{case}: {err} vs {scale}");
            let _ = v;
        }
        println!("invariant errors: jacobi {worst_ours:?}, nalgebra {worst_theirs:?}");
        let sweeps = SWEEPS.with(std::cell::Cell::get) as f64 / 3002.0;
        println!("sweeps per call: {sweeps}");
        // Quadratic convergence: a tolerance at the rounding-noise level would run every sweep.
        assert!(sweeps < 5.0, "{sweeps}");
        // Relative accuracy of the three invariants from one-sided Jacobi (nalgebra's SVD loses
        // the small singular values of graded matrices: ~40% on the second invariant here).
        const INVARIANT_TOL: f64 = 1e-11;
        assert!(
            worst_ours.iter().all(|&e| e < INVARIANT_TOL),
            "{worst_ours:?}"
        );
        // Degenerate inputs.
        assert_eq!(
            rotation_and_scales(DMat3::ZERO),
            (DMat3::IDENTITY, DVec3::ZERO)
        );
        let (u, s) =
            rotation_and_scales(DMat3::from_cols(DVec3::X * 2.0, DVec3::ZERO, DVec3::ZERO));
        assert_eq!(s, DVec3::new(2.0, 0.0, 0.0));
        assert!((u.determinant() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn rotation_and_scales_reconstructs() {
        let mut rng = Rng::new(5);
        for _ in 0..1000 {
            let l = crate::test_util::random_matrix(&mut rng);
            let (u, s) = rotation_and_scales(l);
            assert!((u.determinant() - 1.0).abs() < 1e-12);
            assert!(s.x >= s.y && s.y >= s.z && s.z >= 0.0);
            let sig = DMat3::from_diagonal(s * s);
            let back = u * sig * u.transpose();
            let want = l * l.transpose();
            let err = (back - want)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(err < 1e-12, "{err}");
        }
    }
}
