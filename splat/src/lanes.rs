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
    // Gather into lanes: m[col][row][lane], the quaternion, the scales.
    let zero = [0.0f32; LANES];
    let mut m = [[zero; 3]; 3];
    let mut q = [zero; 4];
    let mut sc = [zero; 3];
    let mut use_f64 = [false; LANES];
    for (l, g) in input.iter().enumerate() {
        for (k, col) in [g.m.x_axis, g.m.y_axis, g.m.z_axis].iter().enumerate() {
            m[k][0][l] = col.x;
            m[k][1][l] = col.y;
            m[k][2][l] = col.z;
        }
        for (k, v) in g.rotation.iter().enumerate() {
            q[k][l] = *v;
        }
        sc[0][l] = g.scale.x;
        sc[1][l] = g.scale.y;
        sc[2][l] = g.scale.z;
        use_f64[l] = g.exact;
    }
    // c[k][d][lane]: component d of column k of L = M R S, then pre-scaled.
    let mut c = [[zero; 3]; 3];
    let mut unscale = [1.0f32; LANES];
    for l in 0..LANES {
        let n2 = q[0][l] * q[0][l] + q[1][l] * q[1][l] + q[2][l] * q[2][l] + q[3][l] * q[3][l];
        let valid = n2 > 0.0 && n2.is_finite();
        let inv = if valid { 1.0 / n2.sqrt() } else { 0.0 };
        let w = if valid { q[0][l] * inv } else { 1.0 };
        let (x, y, z) = (q[1][l] * inv, q[2][l] * inv, q[3][l] * inv);
        // R columns (glam's Mat3::from_quat).
        let (x2, y2, z2) = (x + x, y + y, z + z);
        let (xx, xy, xz) = (x * x2, x * y2, x * z2);
        let (yy, yz, zz) = (y * y2, y * z2, z * z2);
        let (wx, wy, wz) = (w * x2, w * y2, w * z2);
        let r = [
            [1.0 - (yy + zz), xy + wz, xz - wy],
            [xy - wz, 1.0 - (xx + zz), yz + wx],
            [xz + wy, yz - wx, 1.0 - (xx + yy)],
        ];
        let mut len2 = [0.0f32; 3];
        for k in 0..3 {
            for d in 0..3 {
                let v =
                    (m[0][d][l] * r[k][0] + m[1][d][l] * r[k][1] + m[2][d][l] * r[k][2]) * sc[k][l];
                c[k][d][l] = v;
                len2[k] += v * v;
            }
        }
        let big2 = len2[0].max(len2[1]).max(len2[2]);
        let inf = f32::INFINITY;
        let small2 = (if len2[0] > 0.0 { len2[0] } else { inf })
            .min(if len2[1] > 0.0 { len2[1] } else { inf })
            .min(if len2[2] > 0.0 { len2[2] } else { inf });
        let big = big2.sqrt();
        let bad = !(big.is_finite() && big >= f32::MIN_POSITIVE)
            || big > small2.sqrt() * MAX_COLUMN_RATIO;
        use_f64[l] |= bad;
        // An exact power of two near 1 / big, from the exponent bits.
        let e = (((big.to_bits() >> 23) & 0xff) as i32 - 127).clamp(-126, 126);
        let s = if bad {
            0.0
        } else {
            f32::from_bits(((127 - e) as u32) << 23)
        };
        unscale[l] = f32::from_bits(((127 + e) as u32) << 23);
        for col in &mut c {
            for comp in col.iter_mut() {
                comp[l] *= s;
            }
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

/// Rotation and log-scales of every lane from its orthogonal (pre-scaled) columns, written as
/// loops over lanes with selects instead of branches so that the compiler vectorises them. The
/// axes are output in the cyclic order that puts the shortest last (`k+1, k+2, k` for the
/// shortest `k`): a proper rotation whose third axis is the normal of a flat Gaussian (the
/// surfel convention); the two longer axes keep their relative order (INRIA files do not
/// require sorted scales). Quaternions are Shepperd's, from the largest of `4w², 4x², 4y²,
/// 4z²`; orthonormal columns make them unit to `f32` rounding.
fn finish_lanes(c: &[[[f32; LANES]; 3]; 3], unscale: &[f32; LANES]) -> [([f32; 4], Vec3); LANES] {
    type Lanes = [f32; LANES];
    let zero = [0.0f32; LANES];
    let mut len = [zero; 3];
    for k in 0..3 {
        for l in 0..LANES {
            let v = [c[k][0][l], c[k][1][l], c[k][2][l]];
            len[k][l] = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        }
    }
    // a, b: the two longer columns in cyclic order; their lengths and the shortest length.
    let (mut a, mut b) = ([zero; 3], [zero; 3]);
    let (mut la, mut lb, mut ls): (Lanes, Lanes, Lanes) = (zero, zero, zero);
    for l in 0..LANES {
        let k2 = len[2][l] <= len[0][l] && len[2][l] <= len[1][l];
        let k1 = !k2 && len[1][l] <= len[0][l];
        // k = 2 -> (0, 1 | 2); k = 1 -> (2, 0 | 1); k = 0 -> (1, 2 | 0).
        for d in 0..3 {
            a[d][l] = if k2 {
                c[0][d][l]
            } else if k1 {
                c[2][d][l]
            } else {
                c[1][d][l]
            };
            b[d][l] = if k2 {
                c[1][d][l]
            } else if k1 {
                c[0][d][l]
            } else {
                c[2][d][l]
            };
        }
        la[l] = if k2 {
            len[0][l]
        } else if k1 {
            len[2][l]
        } else {
            len[1][l]
        };
        lb[l] = if k2 {
            len[1][l]
        } else if k1 {
            len[0][l]
        } else {
            len[2][l]
        };
        ls[l] = if k2 {
            len[2][l]
        } else if k1 {
            len[1][l]
        } else {
            len[0][l]
        };
    }
    // The longer of a, b is normalised as is, the other orthogonalised against it.
    let (mut ua, mut ub, mut un) = ([zero; 3], [zero; 3], [zero; 3]);
    let mut ok = [false; LANES];
    for l in 0..LANES {
        let a_first = la[l] >= lb[l];
        let p = [0, 1, 2].map(|d| if a_first { a[d][l] } else { b[d][l] });
        let q = [0, 1, 2].map(|d| if a_first { b[d][l] } else { a[d][l] });
        let lp = if a_first { la[l] } else { lb[l] };
        let ip = 1.0 / lp;
        let up = p.map(|v| v * ip);
        let dot = up[0] * q[0] + up[1] * q[1] + up[2] * q[2];
        let rq = [0, 1, 2].map(|d| q[d] - up[d] * dot);
        let lq = (rq[0] * rq[0] + rq[1] * rq[1] + rq[2] * rq[2]).sqrt();
        // Fallback for a vanishing second axis: up crossed with the axis least aligned.
        let ax = if up[0].abs() <= up[1].abs() && up[0].abs() <= up[2].abs() {
            [1.0, 0.0, 0.0]
        } else if up[1].abs() <= up[2].abs() {
            [0.0, 1.0, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
        let f = cross(up, ax);
        let lf = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        let use_rq = lq > 0.0;
        let il = 1.0 / if use_rq { lq } else { lf };
        let uq = [0, 1, 2].map(|d| if use_rq { rq[d] } else { f[d] } * il);
        for d in 0..3 {
            ua[d][l] = if a_first { up[d] } else { uq[d] };
            ub[d][l] = if a_first { uq[d] } else { up[d] };
        }
        let n = cross(
            [ua[0][l], ua[1][l], ua[2][l]],
            [ub[0][l], ub[1][l], ub[2][l]],
        );
        for d in 0..3 {
            un[d][l] = n[d];
        }
        ok[l] = lp > 0.0 && ip.is_finite() && il.is_finite();
    }
    // Shepperd with selects; m[row][col] = column col, component row.
    let mut q = [zero; 4];
    for l in 0..LANES {
        let (m00, m11, m22) = (ua[0][l], ub[1][l], un[2][l]);
        let (m01, m02, m10) = (ub[0][l], un[0][l], ua[1][l]);
        let (m12, m20, m21) = (un[1][l], ua[2][l], ub[2][l]);
        let trace = m00 + m11 + m22;
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
        let r = t.max(f32::MIN_POSITIVE).sqrt() * 2.0;
        let inv = 1.0 / r;
        let (d1, d2, d3) = ((m21 - m12) * inv, (m02 - m20) * inv, (m10 - m01) * inv);
        let (s1, s2, s3) = ((m01 + m10) * inv, (m02 + m20) * inv, (m12 + m21) * inv);
        let big = 0.25 * r;
        let v = if use_w {
            [big, d1, d2, d3]
        } else if use_x {
            [d1, big, s1, s2]
        } else if use_y {
            [d2, s1, big, s3]
        } else {
            [d3, s2, s3, big]
        };
        let sign = if v[0] < 0.0 { -1.0 } else { 1.0 };
        for (qc, vc) in q.iter_mut().zip(v) {
            qc[l] = if ok[l] { vc * sign } else { 0.0 };
        }
        q[0][l] = if ok[l] { q[0][l] } else { 1.0 };
    }
    let min_ln = (MIN_OUTPUT_SCALE as f32).ln();
    std::array::from_fn(|l| {
        let u = unscale[l];
        let ln = |x: f32| {
            if ok[l] {
                (x * u).max(MIN_OUTPUT_SCALE as f32).ln()
            } else {
                min_ln
            }
        };
        (
            [q[0][l], q[1][l], q[2][l], q[3][l]],
            Vec3::new(ln(la[l]), ln(lb[l]), ln(ls[l])),
        )
    })
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
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
