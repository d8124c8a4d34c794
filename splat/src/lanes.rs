//! The `jacobian`-mode kernel: covariance axes `L = M R_local S` of [`LANES`] Gaussians at once
//! and their SVD rotation and log-scales, in `f32` lanes the compiler vectorises (SSE2).
//!
//! The factorisation is the one-sided Jacobi of [`crate::deform::rotation_and_scales`] (pairs of
//! columns rotated until orthogonal; `σ_i = |c_i|`, relative accuracy for small columns), with:
//! - every lane pre-scaled by an exact power of two so that its largest column has length ~1
//!   (tiny Gaussians neither underflow nor lose bits);
//! - the rotation from `ζ = (b - a) / 2g` (ratios only: no squares of squared norms);
//! - a lane whose columns span more than [`MAX_COLUMN_RATIO`] (a Gaussian flat beyond what
//!   squared `f32` norms resolve) computed by the `f64` factorisation instead.
//!
//! Stored results are `f32`; the kernel's own error is a few `f32` ulps per rotation (~1e-6 on
//! covariances, tested against the `f64` factorisation).

use glam::{DMat3, Mat3, Vec3};

use crate::deform::{MIN_OUTPUT_SCALE, rotation_and_scales};
use crate::gaussians::{quat_from_rotation, to_wxyz};

/// Gaussians per kernel call (two SSE vectors of four `f32`).
pub const LANES: usize = 8;

/// Largest ratio between a Gaussian's longest and shortest covariance axis (after `M`) that the
/// `f32` kernel handles; beyond it (2⁴⁰, e^27.7) squared norms would leave the `f32` exponent
/// range and the lane is factorised in `f64`. The shortest axis of a surfel (0) does not count.
pub const MAX_COLUMN_RATIO: f32 = 1.099_511_6e12;

/// Relative orthogonality below which a column pair is left alone (a few `f32` ulps).
const PAIR_TOL: f32 = 1e-6;

/// A sweep whose rotations all have `|tan θ|` below this ends the iteration: the remaining
/// non-orthogonality (`O(θ²)` = 1e-7) is at the `f32` rounding level.
const SMALL_ROTATION: f32 = 3e-4;

/// Sweep limit (quadratic convergence needs 3-6).
const MAX_SWEEPS: usize = 16;

/// The input of one lane: `M` (row-major would do as well; columns here), the raw local
/// quaternion `[w, x, y, z]` and the activated scales (third 0 for surfels).
#[derive(Clone, Copy, Debug, Default)]
pub struct LaneInput {
    /// `M = J k_c R_c` of the Gaussian's triangle.
    pub m: Mat3,
    /// Raw local rotation `[w, x, y, z]` (normalised here; zero gives the identity).
    pub rotation: [f32; 4],
    /// Local scales.
    pub scale: Vec3,
    /// Factorise this lane in `f64` (see [`needs_f64`]).
    pub exact: bool,
}

/// Largest Frobenius condition number `|M|_F |M⁻¹|_F` of a triangle's `M` for which the `f32`
/// kernel is used (3 for a similarity). The kernel's error grows like `ε_f32 κ`: measured
/// ≤ 2e-6 on log-scales for κ < 10 and ≤ 5e-6 for κ < 100; above this bound the `f64`
/// factorisation keeps every Gaussian, tiny axes included, to ≤ 1e-5.
pub const MAX_CONDITION: f64 = 30.0;

/// Whether Gaussians on a triangle with this `M` need the `f64` factorisation (ill-conditioned
/// or singular `M`: strong anisotropic stretch, collapsed triangles).
#[must_use]
pub fn needs_f64(m: DMat3) -> bool {
    let frob = |m: DMat3| m.to_cols_array().iter().map(|v| v * v).sum::<f64>().sqrt();
    let det = m.determinant().abs();
    let kappa = frob(m) * frob(crate::frames::cofactor(m));
    // κ = |M|_F |cof M|_F / |det M|; compared without dividing (det may be 0).
    !(kappa <= MAX_CONDITION * det && det.is_finite())
}

/// Rotation `[w, x, y, z]` (`w ≥ 0`) and log-scales (shortest axis last) of `L = M R S` for
/// each lane.
#[must_use]
pub fn factor_lanes(input: &[LaneInput; LANES]) -> [([f32; 4], Vec3); LANES] {
    // c[k][d][lane]: component d of column k of L, pre-scaled.
    let mut c = [[[0.0f32; LANES]; 3]; 3];
    let mut unscale = [1.0f32; LANES];
    let mut use_f64 = [false; LANES];
    for (lane, g) in input.iter().enumerate() {
        let [w, x, y, z] = g.rotation;
        let n2 = w * w + x * x + y * y + z * z;
        let r = if n2 > 0.0 && n2.is_finite() {
            let q = glam::Quat::from_xyzw(x, y, z, w) * n2.sqrt().recip();
            Mat3::from_quat(q)
        } else {
            Mat3::IDENTITY
        };
        let a = g.m * r;
        let cols = [
            a.x_axis * g.scale.x,
            a.y_axis * g.scale.y,
            a.z_axis * g.scale.z,
        ];
        let len = cols.map(Vec3::length);
        let big = len[0].max(len[1]).max(len[2]);
        let small = len
            .iter()
            .copied()
            .filter(|&l| l > 0.0)
            .fold(f32::INFINITY, f32::min);
        if g.exact
            || !(big.is_finite() && big >= f32::MIN_POSITIVE)
            || big > small * MAX_COLUMN_RATIO
        {
            use_f64[lane] = true;
            continue;
        }
        // An exact power of two near 1 / big, from the exponent bits (big is normal here).
        let e = (((big.to_bits() >> 23) & 0xff) as i32 - 127).clamp(-126, 126);
        let s = f32::from_bits(((127 - e) as u32) << 23);
        unscale[lane] = f32::from_bits(((127 + e) as u32) << 23);
        for (k, col) in cols.iter().enumerate() {
            c[k][0][lane] = col.x * s;
            c[k][1][lane] = col.y * s;
            c[k][2][lane] = col.z * s;
        }
    }
    for _ in 0..MAX_SWEEPS {
        let mut largest = [0.0f32; LANES];
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let mut cs = [1.0f32; LANES];
            let mut sn = [0.0f32; LANES];
            for lane in 0..LANES {
                let (cp, cq) = (&c[p], &c[q]);
                let a = cp[0][lane] * cp[0][lane]
                    + cp[1][lane] * cp[1][lane]
                    + cp[2][lane] * cp[2][lane];
                let b = cq[0][lane] * cq[0][lane]
                    + cq[1][lane] * cq[1][lane]
                    + cq[2][lane] * cq[2][lane];
                let g = cp[0][lane] * cq[0][lane]
                    + cp[1][lane] * cq[1][lane]
                    + cp[2][lane] * cq[2][lane];
                let zeta = (b - a) / (2.0 * g);
                let t = 1.0f32.copysign(zeta) / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                // Orthogonal enough, a zero column, or ζ beyond f32 (t ≈ 1 / 2ζ ≈ 0).
                let skip = g.abs() <= PAIR_TOL * a.sqrt() * b.sqrt() || !t.is_finite();
                let t = if skip { 0.0 } else { t };
                largest[lane] = largest[lane].max(t.abs());
                let cos = (1.0 + t * t).sqrt().recip();
                cs[lane] = cos;
                sn[lane] = cos * t;
            }
            // p < q: borrow both columns.
            let (lo, hi) = c.split_at_mut(q);
            for (rp, rq) in lo[p].iter_mut().zip(hi[0].iter_mut()) {
                for lane in 0..LANES {
                    let (x, y) = (rp[lane], rq[lane]);
                    rp[lane] = x * cs[lane] - y * sn[lane];
                    rq[lane] = x * sn[lane] + y * cs[lane];
                }
            }
        }
        if largest.iter().all(|&t| t < SMALL_ROTATION) {
            break;
        }
    }
    let mut out = finish_lanes(&c, &unscale);
    for (lane, o) in out.iter_mut().enumerate() {
        if use_f64[lane] {
            *o = factor_f64(&input[lane]);
        }
    }
    out
}

/// Rotation and log-scales of every lane from its orthogonal (pre-scaled) columns, without
/// data-dependent branches (lane selects the compiler vectorises). The axes are output in the
/// cyclic order that puts the shortest last (`k+1, k+2, k` for the shortest `k`): a proper
/// rotation whose third axis is the normal of a flat Gaussian (the surfel convention); the two
/// longer axes keep their relative order (no sorting: INRIA files do not require it).
fn finish_lanes(c: &[[[f32; LANES]; 3]; 3], unscale: &[f32; LANES]) -> [([f32; 4], Vec3); LANES] {
    let min_ln = (MIN_OUTPUT_SCALE as f32).ln();
    std::array::from_fn(|lane| {
        let col = |k: usize| Vec3::new(c[k][0][lane], c[k][1][lane], c[k][2][lane]);
        let (c0, c1, c2) = (col(0), col(1), col(2));
        let (l0, l1, l2) = (c0.length(), c1.length(), c2.length());
        // Cyclic shift putting the shortest column last (selects, not branches).
        let k2_is_min = l2 <= l0 && l2 <= l1;
        let k1_is_min = !k2_is_min && l1 <= l0;
        let sel = |m: bool, a: Vec3, b: Vec3| Vec3::select(glam::BVec3::splat(m), a, b);
        let self_ = |m: bool, a: f32, b: f32| if m { a } else { b };
        // Order (a, b, short): k=2 -> (0, 1, 2); k=1 -> (2, 0, 1); k=0 -> (1, 2, 0).
        let a = sel(k2_is_min, c0, sel(k1_is_min, c2, c1));
        let b = sel(k2_is_min, c1, sel(k1_is_min, c0, c2));
        let la = self_(k2_is_min, l0, self_(k1_is_min, l2, l1));
        let lb = self_(k2_is_min, l1, self_(k1_is_min, l0, l2));
        let ls = self_(k2_is_min, l2, self_(k1_is_min, l1, l0));
        // The longer of a, b defines the first axis exactly; the other is orthogonalised.
        let a_first = la >= lb;
        let (p, q, lp) = (
            sel(a_first, a, b),
            sel(a_first, b, a),
            self_(a_first, la, lb),
        );
        let up = p * (1.0 / lp);
        let rq = q - up * up.dot(q);
        let lq = rq.length();
        let uq = if lq > 0.0 && up.is_finite() {
            rq * (1.0 / lq)
        } else {
            up.any_orthonormal_vector()
        };
        // Back to (a, b) order; the third axis completes a proper rotation.
        let ua = sel(a_first, up, uq);
        let ub = sel(a_first, uq, up);
        let un = ua.cross(ub);
        let ok = lp > 0.0 && ua.is_finite() && ub.is_finite();
        let q = if ok {
            quat_from_columns(ua, ub, un)
        } else {
            [1.0, 0.0, 0.0, 0.0]
        };
        let u = unscale[lane];
        let ln = |l: f32| {
            if ok {
                (l * u).max(MIN_OUTPUT_SCALE as f32).ln()
            } else {
                min_ln
            }
        };
        (q, Vec3::new(ln(la), ln(lb), ln(ls)))
    })
}

/// Shepperd's method in `f32` for orthonormal columns, with selects instead of branches:
/// `[w, x, y, z]`, unit, `w ≥ 0`.
fn quat_from_columns(c0: Vec3, c1: Vec3, c2: Vec3) -> [f32; 4] {
    // m[row][col] = col.row
    let (m00, m11, m22) = (c0.x, c1.y, c2.z);
    let (m01, m02, m10, m12, m20, m21) = (c1.x, c2.x, c0.y, c2.y, c0.z, c1.z);
    let trace = m00 + m11 + m22;
    // The largest of 4w², 4x², 4y², 4z² (minus 1) picks the stable formula.
    let use_w = trace > 0.0;
    let use_x = !use_w && m00 > m11 && m00 > m22;
    let use_y = !use_w && !use_x && m11 > m22;
    let t = if use_w {
        1.0 + trace
    } else if use_x {
        1.0 + m00 - m11 - m22
    } else if use_y {
        1.0 + m11 - m00 - m22
    } else {
        1.0 + m22 - m00 - m11
    };
    let r = t.max(0.0).sqrt() * 2.0;
    let inv = 1.0 / r;
    let (d1, d2, d3) = ((m21 - m12) * inv, (m02 - m20) * inv, (m10 - m01) * inv);
    let (s1, s2, s3) = ((m01 + m10) * inv, (m02 + m20) * inv, (m12 + m21) * inv);
    let big = 0.25 * r;
    let q = if use_w {
        [big, d1, d2, d3]
    } else if use_x {
        [d1, big, s1, s2]
    } else if use_y {
        [d2, s1, big, s3]
    } else {
        [d3, s2, s3, big]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let f = if q[0] < 0.0 { -1.0 } else { 1.0 } / n;
    q.map(|v| v * f)
}

/// The `f64` factorisation of one lane (strongly graded Gaussians).
fn factor_f64(g: &LaneInput) -> ([f32; 4], Vec3) {
    let [w, x, y, z] = g.rotation.map(f64::from);
    let n = (w * w + x * x + y * y + z * z).sqrt();
    let r = if n > 0.0 && n.is_finite() {
        DMat3::from_quat(glam::DQuat::from_xyzw(x / n, y / n, z / n, w / n))
    } else {
        DMat3::IDENTITY
    };
    let a = g.m.as_dmat3() * r;
    let s = g.scale.as_dvec3();
    let l = DMat3::from_cols(a.x_axis * s.x, a.y_axis * s.y, a.z_axis * s.z);
    let (rot, sigma) = rotation_and_scales(l);
    let ln = |v: f64| v.max(MIN_OUTPUT_SCALE).ln() as f32;
    (
        to_wxyz(quat_from_rotation(rot)),
        Vec3::new(ln(sigma.x), ln(sigma.y), ln(sigma.z)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::rng::Rng;

    fn cov(q: [f32; 4], ls: Vec3) -> DMat3 {
        let [w, x, y, z] = q.map(f64::from);
        let r = DMat3::from_quat(glam::DQuat::from_xyzw(x, y, z, w).normalize());
        let s = ls.as_dvec3().exp();
        r * DMat3::from_diagonal(s * s) * r.transpose()
    }

    #[test]
    fn lanes_match_the_f64_factorisation() {
        let mut rng = Rng::new(31);
        let mut u = move || rng.uniform_f32() - 0.5;
        let (mut worst_cov, mut worst_ls) = (0.0f64, 0.0f64);
        let mut fallbacks = 0;
        let mut bins = [0.0f64; 6];
        let frob = |m: DMat3| m.to_cols_array().iter().map(|v| v * v).sum::<f64>().sqrt();
        for case in 0..3000 {
            let input: [LaneInput; LANES] = std::array::from_fn(|lane| {
                let noise = Mat3::from_cols_array(&[0; 9].map(|_: i32| u()));
                let m = if lane % 2 == 0 {
                    Mat3::IDENTITY * 0.01 + noise * 0.002
                } else {
                    noise
                };
                let tiny = if lane == 3 { -29.0 } else { 0.0 };
                let mut ls = Vec3::new(u() * 4.0, u() * 4.0, u() * 4.0 + tiny);
                if case % 7 == 0 {
                    ls = Vec3::splat(ls.x);
                }
                let mut scale = ls.exp();
                if case % 5 == 0 {
                    scale.z = 0.0;
                }
                LaneInput {
                    m,
                    rotation: [u() + 1.0, u(), u(), u()],
                    scale,
                    exact: needs_f64(m.as_dmat3()),
                }
            });
            let got = factor_lanes(&input);
            for (g, (q, ls)) in input.iter().zip(got) {
                let (wq, wls) = factor_f64(g);
                let surfel = g.scale.z == 0.0;
                if surfel {
                    // Compare the two real axes through the projected covariance.
                    assert!(ls.z <= (MIN_OUTPUT_SCALE as f32).ln() + 1e-3);
                }
                let (a, b) = (cov(q, ls), cov(wq, wls));
                let size = b.to_cols_array().iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let err = (a - b)
                    .to_cols_array()
                    .iter()
                    .fold(0.0f64, |m, v| m.max(v.abs()));
                worst_cov = worst_cov.max(err / size);
                let md = g.m.as_dmat3();
                let kappa = frob(md) * frob(crate::frames::cofactor(md)) / md.determinant().abs();
                let bin = (kappa.log10().max(0.0) as usize).min(5);
                // The kernel does not sort the two longer axes.
                let mut sorted = ls.to_array();
                sorted.sort_by(|a, b| b.total_cmp(a));
                assert_eq!(ls.z, sorted[2], "shortest axis last");
                for k in 0..3 {
                    if !(surfel && k == 2) {
                        let e = f64::from((sorted[k] - wls[k]).abs());
                        worst_ls = worst_ls.max(e);
                        bins[bin] = bins[bin].max(e);
                    }
                }
                let [w, x, y, z] = q;
                assert!(w >= 0.0 && ((w * w + x * x + y * y + z * z) - 1.0).abs() < 1e-5);
            }
            fallbacks += input
                .iter()
                .filter(|g| {
                    let s = g.scale;
                    s.max_element() > MAX_COLUMN_RATIO * 0.1 * s.min_element().max(1e-38)
                })
                .count();
        }
        println!(
            "lanes vs f64 (worst log-scale by log10 κ: {bins:?}): covariance {worst_cov:.1e}, log-scales {worst_ls:.1e}, {fallbacks} graded lanes"
        );
        // f32 arithmetic through ~9 rotations.
        // Both sides store f32 log-scales (an ulp of ln σ ≈ 5 is 5e-7, doubled in σ²): the
        // covariance bound is the storage's, the log-scale bound a few ulps of ln σ ≈ 30.
        assert!(worst_cov < 1e-5, "{worst_cov}");
        assert!(worst_ls < 1e-5, "{worst_ls}");
    }

    #[test]
    fn degenerate_lanes_are_finite() {
        let mut input = [LaneInput::default(); LANES];
        input[1].m = Mat3::IDENTITY;
        input[1].scale = Vec3::new(1.0, 0.0, 0.0);
        input[2].m = Mat3::IDENTITY;
        input[2].scale = Vec3::new(1e30, 1e-30, 1.0);
        input[3].m = Mat3::IDENTITY * 1e-20;
        input[3].scale = Vec3::splat(1e-20);
        input[4].m = Mat3::IDENTITY;
        input[4].scale = Vec3::ONE;
        input[4].rotation = [0.0; 4];
        for (q, ls) in factor_lanes(&input) {
            assert!(
                q.iter().all(|v| v.is_finite()) && ls.is_finite(),
                "{q:?} {ls}"
            );
        }
    }
}
