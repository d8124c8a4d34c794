//! The `jacobian`-mode kernel: the SVD rotation and log-scales of the covariance axes
//! `L = M R_local S` of [`LANES`] Gaussians at once, in `f32` lanes the compiler vectorises
//! (SSE2; no `unsafe`, no intrinsics).
//!
//! **Warm start.** Per triangle (in `f64`, [`TriangleFactor::new`]), `M = J k_c R_c` is split
//! as `M = ν U Q` with `U` the rotation of its polar decomposition (a few Newton steps) and
//! `ν = |M|_F`, so `Q = Uᵀ M / ν` is close to a multiple of the identity whenever `J` is close
//! to a similarity (the common case in animation). Per Gaussian, in the basis `B = U R_local`,
//! `Bᵀ L / (ν s_max) = R_localᵀ Q R_local diag(s / s_max)` has nearly orthogonal columns, so
//! the one-sided Jacobi iteration of [`crate::svd::rotation_and_scales`] (pairs of columns
//! rotated until orthogonal; `σ_i = |c_i|`, relative accuracy for small columns) needs fewer
//! sweeps (2.7 per 8-lane batch on the benchmark, the confirming sweep included), most pairs
//! after the first sweep rotated by a division-only series; the output rotation is the quaternion product
//! `q_U ⊗ q_local ⊗ q_W` (`q_W` from the orthonormalised columns) and the output log-scale is
//! `ln|c_i| + ln s_max + ln ν`. The warm start changes only the iteration count: a lane that
//! needs more sweeps gets them (up to [`MAX_SWEEPS`]), and results do not depend on `U` beyond
//! rounding.
//!
//! **Lane arithmetic.** Scales enter as `exp(log_s - max log_s)` and leave as `½ ln |c|²` through
//! the polynomial [`exp_lanes`] / [`ln_lanes`] (no scalar `libm` calls in the loop; their error,
//! ≤ 2 `f32` ulps, is tested against `f64`). Rotations come from `h = (b - a) / 2` and the
//! column product `g` (scaled by `2⁴⁰` before squaring, so tiny columns neither
//! underflow nor need square roots in the orthogonality test).
//!
//! **Fallback to `f64`** ([`factor_f64`], the caller's job, flagged per lane): Gaussians on
//! triangles with `needs_f64` (ill-conditioned or singular `M`: strong anisotropic stretch,
//! collapsed or inverted triangles) and Gaussians whose log-scales span more than
//! [`MAX_LOG_SCALE_SPREAD`] (flat beyond what squared `f32` norms resolve). A surfel's third
//! axis (scale 0) does not count.
//!
//! **Accuracy** (test `lanes_match_the_f64_factorisation`, random and adversarial inputs:
//! near-singular `M` up to the condition bound, repeated scales, anisotropy up to the spread
//! bound, log-scales down to −29): covariance entries within `COVARIANCE_TOL` of the largest
//! entry and log-scales within `LOG_SCALE_TOL` of the `f64` factorisation; measured worst
//! 3.6e-6 (covariance) and 1.9e-6 (log-scales, one ulp of `ln σ ≈ 30`). On the benchmark's
//! 99,552 Gaussians (`trisplat-bench deform --check`) the deformed covariances are within
//! 2.8e-6 (largest entry error / largest entry) and 2.4e-6 (Frobenius) of `Σ' = M Σ Mᵀ` in
//! `f64`, `f32` storage of the inputs and outputs included.
//!
//! **Speed** (`cargo run --release -p trisplat-bench -- deform`, 2 cores, 99,552 Gaussians,
//! template evaluation included): median 3.63 ms, best 3.46 ms per frame (two runs at load
//! ~3.4; 6.3 ms median in a third under heavier load), 6.3-6.8 ms CPU per frame
//! (`perf stat -e task-clock`, both threads summed; 14.6 ms for the previous 8-lane kernel
//! without warm start, whose wall median was 7.6 ms).

// Lane loops index several arrays by the same lane (the form LLVM vectorises).
#![allow(clippy::needless_range_loop)]

use glam::{DMat3, DQuat, DVec3};

use crate::frames::cofactor;
use crate::gaussians::{quat_from_rotation, to_wxyz};
use crate::svd::{MIN_OUTPUT_SCALE, rotation_and_scales};

/// Gaussians per kernel call: eight SSE vectors of four `f32` per quantity. Larger batches
/// amortise the per-batch work (gathers, branches on whole batches) better than they lose
/// to running every lane for the slowest lane's sweep count: measured 8.4 (8 lanes), 7.7
/// (16), 7.1 (32) and 7.9 (64) ms CPU per frame on the benchmark.
pub const LANES: usize = 32;

/// Values of one quantity for the [`LANES`] Gaussians of a batch.
pub type Lanes = [f32; LANES];

/// Largest difference between a Gaussian's largest and smallest log-scale (the surfel's third
/// axis excluded) that the `f32` kernel handles (e^24 ≈ 2.6e10; times the condition bound
/// [`MAX_CONDITION`] the columns stay within 2⁴⁰ of each other, so their squared norms stay
/// far inside the `f32` exponent range); beyond it the Gaussian is factorised in `f64`.
pub const MAX_LOG_SCALE_SPREAD: f32 = 24.0;

/// Largest Frobenius condition number `|M|_F |M⁻¹|_F` of a triangle's `M` for which the `f32`
/// kernel is used (3 for a similarity). The kernel's error grows like `ε_f32 κ`: measured
/// ≤ 2e-6 on log-scales for κ < 10 and ≤ 5e-6 for κ < 100; above this bound the `f64`
/// factorisation keeps every Gaussian, tiny axes included, to ≤ 1e-5.
pub const MAX_CONDITION: f64 = 30.0;

/// Relative orthogonality below which a column pair is left alone (a few `f32` ulps).
const PAIR_TOL: f32 = 1e-6;

/// A sweep whose rotations all have `|sin θ|` below this ends the iteration: the remaining
/// non-orthogonality is of the order of products of that sweep's angles (≤ 1e-6), below the
/// kernel's tolerances (3e-4 measured the same errors and 1% more time).
const SMALL_ROTATION: f32 = 1e-3;

/// Sweep limit (quadratic convergence needs 3-6 from a cold start, 1-3 warm).
pub const MAX_SWEEPS: usize = 16;

/// Newton step (Frobenius norm, `X` is near-orthogonal) below which the polar rotation of a
/// triangle's `M` is taken as converged (its error is then about half the step squared,
/// 5e-3, far below the anisotropy the Jacobi sweeps remove anyway: one step for a mild
/// deformation). It only has to be a good warm start: `Q` is computed from the rotation
/// actually used (see the module docs).
const POLAR_TOL: f64 = 0.1;

/// Newton steps at most for the polar rotation (a near-similarity needs 1-3; an
/// ill-conditioned `M` stopped early is still a valid, only poorer, warm start).
const POLAR_MAX_STEPS: usize = 6;

/// `κ_F = |M|_F |cof M|_F / |det M| ≤ MAX_CONDITION`, from the squares (no roots, no division:
/// `det` may be 0).
fn well_conditioned(frob2_m: f64, frob2_cof: f64, abs_det: f64) -> bool {
    frob2_m * frob2_cof <= MAX_CONDITION * MAX_CONDITION * abs_det * abs_det
        && (frob2_m * frob2_cof).is_finite()
}

/// Squared Frobenius norm.
fn frob2(m: DMat3) -> f64 {
    m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()
}

#[cfg(test)]
fn frob(m: DMat3) -> f64 {
    frob2(m).sqrt()
}

/// The per-triangle data of the kernel: `M = ν U Q` (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleFactor {
    /// `Q = Uᵀ M / ν`, column-major.
    pub q: [f32; 9],
    /// `U` as a quaternion `[w, x, y, z]`.
    pub u: [f32; 4],
    /// `ln ν`.
    pub ln_norm: f32,
    /// Factorise this triangle's Gaussians in `f64` (`needs_f64`, or no proper polar
    /// rotation).
    pub exact: bool,
}

impl Default for TriangleFactor {
    fn default() -> Self {
        Self {
            q: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            u: [1.0, 0.0, 0.0, 0.0],
            ln_norm: 0.0,
            exact: true,
        }
    }
}

impl TriangleFactor {
    /// The kernel data of a triangle with `M = J k_c R_c`.
    #[must_use]
    pub fn new(m: DMat3) -> Self {
        let cof = cofactor(m);
        let det = m.x_axis.dot(cof.x_axis);
        let f2 = frob2(m);
        // Ill-conditioned, flat or inverted (no proper polar rotation): f64 factorisation.
        if !(det > 0.0 && well_conditioned(f2, frob2(cof), det)) {
            return Self::default();
        }
        let nu = f2.sqrt();
        let inv_nu = 1.0 / nu;
        let Some(x) = polar_rotation(m * inv_nu, cof * (inv_nu * inv_nu), det * inv_nu.powi(3))
        else {
            return Self::default();
        };
        let qn = quat_from_rotation(x).normalize();
        // Q from the f64 rotation; the kernel composes with its f32 rounding (a mismatch of
        // ~6e-8 in the rotation, ~1e-7 relative in Σ').
        let q = (DMat3::from_quat(qn).transpose() * (m * inv_nu))
            .as_mat3()
            .to_cols_array();
        // f32 is enough for the stored ln ν (f2 is finite here; f32 only if it is normal).
        let f2_32 = f2 as f32;
        let ln_norm = if f2_32.is_normal() {
            0.5 * f2_32.ln()
        } else {
            (0.5 * f2.ln()) as f32
        };
        let exact = !(q.iter().all(|v| v.is_finite()) && ln_norm.is_finite());
        Self {
            q,
            u: to_wxyz(qn),
            ln_norm,
            exact,
        }
    }
}

/// An approximation of the rotation of the polar decomposition of `m` (`|m|_F = 1`, with its
/// cofactor matrix and determinant `det > 0`): Newton's iteration `X ← (X + X⁻ᵀ) / 2` from
/// `X = √3 m` (exact at once for a similarity), stopped once a step is below [`POLAR_TOL`]
/// (the error is then about its square); `None` if it leaves the proper rotations.
fn polar_rotation(m: DMat3, cof: DMat3, det: f64) -> Option<DMat3> {
    const S: f64 = 1.732_050_807_568_877_2;
    let mut x = m * S;
    // cof(s m) = s² cof m, det(s m) = s³ det m: X⁻ᵀ = cof / det.
    let mut inv_t = cof * (1.0 / (S * det));
    for step in 0..POLAR_MAX_STEPS {
        if step > 0 {
            let cof = cofactor(x);
            let det = x.x_axis.dot(cof.x_axis);
            if !(det > 0.0 && det.is_finite()) {
                return None;
            }
            inv_t = cof * (1.0 / det);
        }
        let next = (x + inv_t) * 0.5;
        let step2 = frob2(next - x);
        x = next;
        if step2 <= POLAR_TOL * POLAR_TOL {
            break;
        }
    }
    x.is_finite().then_some(x)
}

/// Input of one kernel call: [`LANES`] Gaussians with their triangles' [`TriangleFactor`]s,
/// one quantity per array of lanes.
#[derive(Clone, Copy, Debug)]
pub struct LaneBatch {
    /// Raw local quaternions `[w, x, y, z]` (normalised here; zero gives the identity).
    pub rotation: [Lanes; 4],
    /// Local log-scales.
    pub log_scale: [Lanes; 3],
    /// The triangles' `Q`, column-major.
    pub q: [Lanes; 9],
    /// The triangles' polar rotations `[w, x, y, z]`.
    pub u: [Lanes; 4],
    /// The triangles' `ln ν`.
    pub ln_norm: Lanes,
    /// The triangles' `exact` flags.
    pub exact: [bool; LANES],
}

impl Default for LaneBatch {
    fn default() -> Self {
        let t = TriangleFactor::default();
        Self {
            rotation: [[1.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]],
            log_scale: [[0.0; LANES]; 3],
            q: t.q.map(|v| [v; LANES]),
            u: t.u.map(|v| [v; LANES]),
            ln_norm: [0.0; LANES],
            exact: [false; LANES],
        }
    }
}

impl LaneBatch {
    /// Sets lane `l` to a Gaussian with raw rotation `rotation`, log-scales `log_scale`, on a
    /// triangle with data `t`.
    pub fn set(&mut self, l: usize, rotation: [f32; 4], log_scale: [f32; 3], t: &TriangleFactor) {
        for k in 0..4 {
            self.rotation[k][l] = rotation[k];
            self.u[k][l] = t.u[k];
        }
        for k in 0..3 {
            self.log_scale[k][l] = log_scale[k];
        }
        for k in 0..9 {
            self.q[k][l] = t.q[k];
        }
        self.ln_norm[l] = t.ln_norm;
        self.exact[l] = t.exact;
    }
}

/// Output of one kernel call.
#[derive(Clone, Copy, Debug)]
pub struct LaneFactors {
    /// Unit rotations `[w, x, y, z]`, `w ≥ 0`.
    pub rotation: [Lanes; 4],
    /// Log-scales, shortest axis last ([`MIN_OUTPUT_SCALE`]'s log for a zero axis).
    pub log_scale: [Lanes; 3],
    /// Lanes the kernel did not compute: factorise them with [`factor_f64`].
    pub needs_f64: [bool; LANES],
}

impl Default for LaneFactors {
    fn default() -> Self {
        Self {
            rotation: [[1.0; LANES], [0.0; LANES], [0.0; LANES], [0.0; LANES]],
            log_scale: [[0.0; LANES]; 3],
            needs_f64: [true; LANES],
        }
    }
}

/// `acc[l] = max(acc[l], v[l])` without the NaN rules of `f32::max` (vectorises to `maxps`).
#[inline(always)]
fn vmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

#[inline(always)]
fn vmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// `exp(x)` for every lane with `x ∈ [-87, 0]` (clamped to it): Cody-Waite reduction by
/// `ln 2` and a degree-7 Taylor polynomial on `|r| ≤ ln 2 / 2` (truncation 5e-9 relative).
#[must_use]
pub fn exp_lanes(x: Lanes) -> Lanes {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5 · 2²³: adding it rounds to an integer held in the low mantissa bits.
    const MAGIC: f32 = 12_582_912.0;
    let mut out = [0.0f32; LANES];
    for l in 0..LANES {
        let x = vmin(vmax(x[l], -87.0), 0.0);
        let shifted = x * LOG2E + MAGIC;
        let k = shifted - MAGIC;
        let r = (x - k * LN2_HI) - k * LN2_LO;
        let p = 1.0 / 5040.0;
        let p = p * r + 1.0 / 720.0;
        let p = p * r + 1.0 / 120.0;
        let p = p * r + 1.0 / 24.0;
        let p = p * r + 1.0 / 6.0;
        let p = p * r + 0.5;
        let p = p * r + 1.0;
        let p = p * r + 1.0;
        // 2^k from the integer in the low bits of `shifted` (k ∈ [-126, 0]).
        let bits = shifted
            .to_bits()
            .wrapping_sub(MAGIC.to_bits())
            .wrapping_add(127)
            << 23;
        out[l] = p * f32::from_bits(bits);
    }
    out
}

/// `ln(y)` for every lane with a normal, finite, positive `y`: `y = m 2^e` with
/// `m ∈ [√½, √2)` (integer arithmetic on the bits), `ln m = 2 atanh((m - 1) / (m + 1))` by its series to `u⁹`
/// (truncation 7e-10), `e ln 2` in two parts.
#[must_use]
pub fn ln_lanes(y: Lanes) -> Lanes {
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let mut out = [0.0f32; LANES];
    // √½ in bits: subtracting it puts the exponent of y / √½ in the top bits.
    const OFF: u32 = 0x3f35_04f3;
    for l in 0..LANES {
        let ix = y[l].to_bits().wrapping_sub(OFF);
        let e = ((ix as i32) >> 23) as f32;
        let m = f32::from_bits((ix & 0x007f_ffff) + OFF);
        let u = (m - 1.0) / (m + 1.0);
        let u2 = u * u;
        let p = 1.0 / 9.0;
        let p = p * u2 + 1.0 / 7.0;
        let p = p * u2 + 1.0 / 5.0;
        let p = p * u2 + 1.0 / 3.0;
        let p = p * u2 + 1.0;
        let ln_m = 2.0 * u * p;
        out[l] = e * LN2_HI + (e * LN2_LO + ln_m);
    }
    out
}

/// `a ⊗ b` for quaternions `[w, x, y, z]` in lanes.
#[inline(always)]
fn qmul(a: &[Lanes; 4], b: &[Lanes; 4]) -> [Lanes; 4] {
    let mut o = [[0.0f32; LANES]; 4];
    for l in 0..LANES {
        let (aw, ax, ay, az) = (a[0][l], a[1][l], a[2][l], a[3][l]);
        let (bw, bx, by, bz) = (b[0][l], b[1][l], b[2][l], b[3][l]);
        o[0][l] = aw * bw - ax * bx - ay * by - az * bz;
        o[1][l] = aw * bx + ax * bw + ay * bz - az * by;
        o[2][l] = aw * by - ax * bz + ay * bw + az * bx;
        o[3][l] = aw * bz + ax * by - ay * bx + az * bw;
    }
    o
}

/// `if c { a } else { b }` on `f32` (a lane select).
#[inline(always)]
fn sel(c: bool, a: f32, b: f32) -> f32 {
    if c { a } else { b }
}

/// Rotations and log-scales of the lanes of `b` (surfels: `flat`, third scale 0) into `out`;
/// lanes flagged in its `needs_f64` are left for [`factor_f64`].
///
/// Every stage is a loop over lanes of scalar arithmetic and selects (no calls, no arrays
/// chosen by branches), which LLVM turns into SSE2 code.
pub fn factor_lanes(b: &LaneBatch, flat: bool, out: &mut LaneFactors) {
    let zero = [0.0f32; LANES];
    // Normalised local quaternion (identity for zero or non-finite ones).
    let mut qr = [zero; 4];
    for l in 0..LANES {
        let (w, x, y, z) = (
            b.rotation[0][l],
            b.rotation[1][l],
            b.rotation[2][l],
            b.rotation[3][l],
        );
        let n2 = w * w + x * x + y * y + z * z;
        let valid = (n2 > 0.0) & (n2 < f32::INFINITY);
        let inv = sel(valid, 1.0 / n2.sqrt(), 0.0);
        qr[0][l] = sel(valid, w * inv, 1.0);
        qr[1][l] = x * inv;
        qr[2][l] = y * inv;
        qr[3][l] = z * inv;
    }
    // Relative scales s_k = exp(log_s_k - max), the spread check, the log offset.
    let mut rel = [zero; 3];
    let mut offset = zero;
    let mut fallback = [false; LANES];
    for l in 0..LANES {
        let (x, y, z) = (b.log_scale[0][l], b.log_scale[1][l], b.log_scale[2][l]);
        let z_hi = sel(flat, x, z);
        let hi = vmax(vmax(x, y), z_hi);
        let lo = vmin(vmin(x, y), z_hi);
        let spread = hi - lo;
        fallback[l] = (spread > MAX_LOG_SCALE_SPREAD) | spread.is_nan() | b.exact[l];
        rel[0][l] = x - hi;
        rel[1][l] = y - hi;
        rel[2][l] = z - hi;
        offset[l] = hi + b.ln_norm[l];
    }
    let s0 = exp_lanes(rel[0]);
    let s1 = exp_lanes(rel[1]);
    let mut s2 = exp_lanes(rel[2]);
    if flat {
        s2 = zero;
    }
    // c[k][d]: component d of column k of Rᵀ Q R diag(s).
    let mut c = [[zero; 3]; 3];
    for l in 0..LANES {
        let (w, x, y, z) = (qr[0][l], qr[1][l], qr[2][l], qr[3][l]);
        // R[k][d]: column k, component d (glam's Mat3::from_quat).
        let (x2, y2, z2) = (x + x, y + y, z + z);
        let (xx, xy, xz) = (x * x2, x * y2, x * z2);
        let (yy, yz, zz) = (y * y2, y * z2, z * z2);
        let (wx, wy, wz) = (w * x2, w * y2, w * z2);
        let r00 = 1.0 - (yy + zz);
        let (r01, r02) = (xy + wz, xz - wy);
        let (r10, r11, r12) = (xy - wz, 1.0 - (xx + zz), yz + wx);
        let (r20, r21, r22) = (xz + wy, yz - wx, 1.0 - (xx + yy));
        let q = &b.q;
        let (q00, q01, q02) = (q[0][l], q[1][l], q[2][l]);
        let (q10, q11, q12) = (q[3][l], q[4][l], q[5][l]);
        let (q20, q21, q22) = (q[6][l], q[7][l], q[8][l]);
        let sk = [s0[l], s1[l], s2[l]];
        let r = [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]];
        for k in 0..3 {
            let [rk0, rk1, rk2] = r[k];
            // t = Q r_k, then c_k = Rᵀ t s_k.
            let t0 = q00 * rk0 + q10 * rk1 + q20 * rk2;
            let t1 = q01 * rk0 + q11 * rk1 + q21 * rk2;
            let t2 = q02 * rk0 + q12 * rk1 + q22 * rk2;
            for d in 0..3 {
                c[k][d][l] = (r[d][0] * t0 + r[d][1] * t1 + r[d][2] * t2) * sk[k];
            }
        }
    }
    jacobi(&mut c);
    let (qw, len2) = finish_lanes(&c);
    // q = q_U ⊗ q_local ⊗ q_W, normalised, w ≥ 0.
    let q = qmul(&qmul(&b.u, &qr), &qw);
    let rotation = &mut out.rotation;
    for l in 0..LANES {
        let n2 = q[0][l] * q[0][l] + q[1][l] * q[1][l] + q[2][l] * q[2][l] + q[3][l] * q[3][l];
        let inv = 1.0 / n2.sqrt();
        let inv = sel(q[0][l] < 0.0, -inv, inv);
        rotation[0][l] = q[0][l] * inv;
        rotation[1][l] = q[1][l] * inv;
        rotation[2][l] = q[2][l] * inv;
        rotation[3][l] = q[3][l] * inv;
    }
    let min_ln = (MIN_OUTPUT_SCALE as f32).ln();
    let log_scale = &mut out.log_scale;
    for k in 0..3 {
        let mut y = zero;
        for l in 0..LANES {
            y[l] = vmax(len2[k][l], f32::MIN_POSITIVE);
        }
        let ln = ln_lanes(y);
        for l in 0..LANES {
            let v = 0.5 * ln[l] + offset[l];
            log_scale[k][l] = sel(len2[k][l] > 0.0, vmax(v, min_ln), min_ln);
        }
    }
    for l in 0..LANES {
        let mut sum = 0.0f32;
        for v in out.rotation.iter().chain(&out.log_scale) {
            sum += v[l] * 0.0;
        }
        // NaN or infinity anywhere makes `0 * v` NaN.
        out.needs_f64[l] = fallback[l] | sum.is_nan();
    }
}

/// `2⁴⁰`: squared column norms (≥ 2e-24, see [`MAX_LOG_SCALE_SPREAD`]) times this stay normal
/// `f32` when multiplied together, so the orthogonality test needs no square roots.
const TEST_SCALE: f32 = 1_099_511_627_776.0;

/// Largest `|g / (b - a)|` (over the lanes of a batch) for which a pair's rotation is taken
/// (one division) from the series `tan θ = x (1 - x² + 2x⁴)`, `cos θ = 1 - t²/2 + 3t⁴/8` (`x = g / (b - a)`,
/// truncation below 1e-10) instead of square roots and divisions: the later sweeps of a
/// warm-started iteration.
const SERIES_LIMIT: f32 = 0.03;

/// Lane-wise operations as plain loops over [`LANES`] values (each one vectorises on its own,
/// whatever the code around it); masks are all-ones / all-zeros bit patterns.
mod v {
    use crate::lanes::{LANES, Lanes};

    /// A lane mask: `u32::MAX` where true.
    pub type Mask = [u32; LANES];

    #[inline(always)]
    pub fn zip(a: &Lanes, b: &Lanes, f: impl Fn(f32, f32) -> f32) -> Lanes {
        let mut o = [0.0f32; LANES];
        for l in 0..LANES {
            o[l] = f(a[l], b[l]);
        }
        o
    }

    #[inline(always)]
    pub fn map(a: &Lanes, f: impl Fn(f32) -> f32) -> Lanes {
        let mut o = [0.0f32; LANES];
        for l in 0..LANES {
            o[l] = f(a[l]);
        }
        o
    }

    #[inline(always)]
    pub fn cmp(a: &Lanes, b: &Lanes, f: impl Fn(f32, f32) -> bool) -> Mask {
        let mut o = [0u32; LANES];
        for l in 0..LANES {
            o[l] = if f(a[l], b[l]) { u32::MAX } else { 0 };
        }
        o
    }

    /// `m ? a : b` by bits.
    #[inline(always)]
    pub fn select(m: &Mask, a: &Lanes, b: &Lanes) -> Lanes {
        let mut o = [0.0f32; LANES];
        for l in 0..LANES {
            o[l] = f32::from_bits((a[l].to_bits() & m[l]) | (b[l].to_bits() & !m[l]));
        }
        o
    }

    /// `a · b` for 3-vectors of lanes.
    #[inline(always)]
    pub fn dot(a: &[Lanes; 3], b: &[Lanes; 3]) -> Lanes {
        let mut o = [0.0f32; LANES];
        for l in 0..LANES {
            o[l] = a[0][l] * b[0][l] + a[1][l] * b[1][l] + a[2][l] * b[2][l];
        }
        o
    }
}

/// One-sided Jacobi on the columns `c[k][d]` of every lane until all are orthogonal.
fn jacobi(c: &mut [[Lanes; 3]; 3]) {
    const TOL2: f32 = PAIR_TOL * PAIR_TOL;
    let zero = [0.0f32; LANES];
    let one = [1.0f32; LANES];
    for _ in 0..MAX_SWEEPS {
        let mut largest = zero;
        // Squared column norms, recomputed every sweep and updated exactly after each rotation
        // within it (they only choose angles; the results come from the columns).
        let mut n = [
            v::dot(&c[0], &c[0]),
            v::dot(&c[1], &c[1]),
            v::dot(&c[2], &c[2]),
        ];
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let (a, b) = (n[p], n[q]);
            let g = v::dot(&c[p], &c[q]);
            // |g| ≤ tol |c_p| |c_q| without square roots (scaled against underflow).
            let gs = v::map(&g, |x| x * TEST_SCALE);
            let lhs = v::zip(&gs, &gs, |x, y| x * y);
            let rhs = v::zip(&a, &b, |x, y| TOL2 * (x * TEST_SCALE) * (y * TEST_SCALE));
            let orthogonal = v::cmp(&lhs, &rhs, |x, y| x <= y);
            // g = 0 marks a pair left alone.
            let g = v::select(&orthogonal, &zero, &g);
            let h = v::zip(&b, &a, |x, y| (x - y) * 0.5);
            let small = v::zip(&g, &h, |g, h| {
                if g.abs() <= SERIES_LIMIT * 2.0 * h.abs() {
                    0.0
                } else {
                    1.0
                }
            });
            let (cs, sn) = if small.iter().sum::<f32>() == 0.0 {
                let x = v::zip(&g, &h, |g, h| g / (2.0 * h));
                let x = v::select(&v::cmp(&g, &zero, |g, z| g == z), &zero, &x);
                let t = v::map(&x, |x| {
                    let x2 = x * x;
                    x * (1.0 - x2 + 2.0 * x2 * x2)
                });
                let cos = v::map(&t, |t| {
                    let t2 = t * t;
                    1.0 - 0.5 * t2 + 0.375 * t2 * t2
                });
                (cos, v::zip(&cos, &t, |c, t| c * t))
            } else {
                // tan θ = t = g / (h + sign(h) r), r = √(h² + g²) (the root of smaller
                // magnitude of t² + 2 (h / g) t - 1 = 0); with d = |h| + r,
                // cos θ = d / √(d² + g²) = d / √(2 r d), sin θ = sign(h) g / √(2 r d).
                // Scaled against underflow (only ratios matter).
                // `g` (not the `gs` of the test above): a pair left alone has g = 0 here, so
                // r = |h| and the rotation is exactly the identity.
                let gs = v::map(&g, |x| x * TEST_SCALE);
                let hs = v::map(&h, |x| x * TEST_SCALE);
                let r = v::zip(&hs, &gs, |h, g| (h * h + g * g).sqrt());
                let d = v::zip(&hs, &r, |h, r| h.abs() + r);
                let inv = v::zip(&r, &d, |r, d| 1.0 / (2.0 * r * d).sqrt());
                // h = g = 0 (or a pair left alone): nothing to do (inv = ∞ or g = 0).
                let keep = v::cmp(&inv, &zero, |i, _| i < f32::INFINITY);
                let sg = v::zip(&gs, &hs, |g, h| if h < 0.0 { -g } else { g });
                let sin = v::zip(&sg, &inv, |g, i| g * i);
                let cos = v::zip(&d, &inv, |d, i| d * i);
                (v::select(&keep, &cos, &one), v::select(&keep, &sin, &zero))
            };
            largest = v::zip(&largest, &sn, |m, s| vmax(m, s.abs()));
            for l in 0..LANES {
                let (cs, sn, g) = (cs[l], sn[l], g[l]);
                let cross = 2.0 * cs * sn * g;
                n[p][l] = cs * cs * a[l] - cross + sn * sn * b[l];
                n[q][l] = sn * sn * a[l] + cross + cs * cs * b[l];
            }
            // p < q: borrow both columns.
            let (lo, hi) = c.split_at_mut(q);
            for (rp, rq) in lo[p].iter_mut().zip(hi[0].iter_mut()) {
                for l in 0..LANES {
                    let (x, y) = (rp[l], rq[l]);
                    rp[l] = x * cs[l] - y * sn[l];
                    rq[l] = x * sn[l] + y * cs[l];
                }
            }
        }
        if largest.iter().all(|&t| t < SMALL_ROTATION) {
            break;
        }
    }
}

/// Rotation (as a quaternion) and squared lengths of every lane's orthogonal columns.
/// The axes are output in the cyclic order that puts the shortest last (`k+1, k+2, k` for the
/// shortest `k`): a proper rotation whose third axis is the normal of a flat Gaussian (the
/// surfel convention); the two longer axes keep their relative order (INRIA files do not
/// require sorted scales). Quaternions are Shepperd's, from the largest of `4w², 4x², 4y²,
/// 4z²`. A lane without a nonzero column gets the identity.
fn finish_lanes(c: &[[Lanes; 3]; 3]) -> ([Lanes; 4], [Lanes; 3]) {
    let zero = [0.0f32; LANES];
    let mut q = [zero; 4];
    let mut sorted = [zero; 3];
    for l in 0..LANES {
        let c0 = [c[0][0][l], c[0][1][l], c[0][2][l]];
        let c1 = [c[1][0][l], c[1][1][l], c[1][2][l]];
        let c2 = [c[2][0][l], c[2][1][l], c[2][2][l]];
        let n0 = c0[0] * c0[0] + c0[1] * c0[1] + c0[2] * c0[2];
        let n1 = c1[0] * c1[0] + c1[1] * c1[1] + c1[2] * c1[2];
        let n2 = c2[0] * c2[0] + c2[1] * c2[1] + c2[2] * c2[2];
        let k2 = (n2 <= n0) & (n2 <= n1);
        let k1 = !k2 & (n1 <= n0);
        // k = 2 -> (0, 1 | 2); k = 1 -> (2, 0 | 1); k = 0 -> (1, 2 | 0).
        let pick = |x2: f32, x1: f32, x0: f32| sel(k2, x2, sel(k1, x1, x0));
        let (la2, lb2) = (pick(n0, n2, n1), pick(n1, n0, n2));
        sorted[0][l] = la2;
        sorted[1][l] = lb2;
        sorted[2][l] = pick(n2, n1, n0);
        // The longer of a, b is normalised as is, the other orthogonalised against it.
        let a_first = la2 >= lb2;
        let mut p = [0.0f32; 3];
        let mut v = [0.0f32; 3];
        for d in 0..3 {
            let a = pick(c0[d], c2[d], c1[d]);
            let b = pick(c1[d], c0[d], c2[d]);
            p[d] = sel(a_first, a, b);
            v[d] = sel(a_first, b, a);
        }
        let lp2 = sel(a_first, la2, lb2);
        let ip = 1.0 / lp2.sqrt();
        let up = [p[0] * ip, p[1] * ip, p[2] * ip];
        let dot = up[0] * v[0] + up[1] * v[1] + up[2] * v[2];
        let rq = [v[0] - up[0] * dot, v[1] - up[1] * dot, v[2] - up[2] * dot];
        let lq2 = rq[0] * rq[0] + rq[1] * rq[1] + rq[2] * rq[2];
        // Fallback for a vanishing second axis: up crossed with the axis least aligned.
        let (ax, ay, az) = (up[0].abs(), up[1].abs(), up[2].abs());
        let fx = (ax <= ay) & (ax <= az);
        let fy = !fx & (ay <= az);
        let e = [sel(fx, 1.0, 0.0), sel(fy, 1.0, 0.0), sel(fx | fy, 0.0, 1.0)];
        let f = cross(up, e);
        let lf2 = f[0] * f[0] + f[1] * f[1] + f[2] * f[2];
        let use_rq = lq2 > 0.0;
        let il = 1.0 / sel(use_rq, lq2, lf2).sqrt();
        let mut ua = [0.0f32; 3];
        let mut ub = [0.0f32; 3];
        for d in 0..3 {
            let uq = sel(use_rq, rq[d], f[d]) * il;
            ua[d] = sel(a_first, up[d], uq);
            ub[d] = sel(a_first, uq, up[d]);
        }
        let un = cross(ua, ub);
        let ok = (lp2 > 0.0) & (ip < f32::INFINITY) & (il < f32::INFINITY);
        // Shepperd with selects; m[row][col] = column col, component row.
        let (m00, m11, m22) = (ua[0], ub[1], un[2]);
        let (m01, m02, m10) = (ub[0], un[0], ua[1]);
        let (m12, m20, m21) = (un[1], ua[2], ub[2]);
        let trace = m00 + m11 + m22;
        let use_w = trace > 0.0;
        let use_x = !use_w & (m00 > m11) & (m00 > m22);
        let use_y = !use_w & !use_x & (m11 > m22);
        let t = sel(
            use_w,
            1.0 + trace,
            sel(
                use_x,
                1.0 + m00 - m11 - m22,
                sel(use_y, 1.0 + m11 - m00 - m22, 1.0 + m22 - m00 - m11),
            ),
        );
        let r = vmax(t, f32::MIN_POSITIVE).sqrt() * 2.0;
        let inv = 1.0 / r;
        let (d1, d2, d3) = ((m21 - m12) * inv, (m02 - m20) * inv, (m10 - m01) * inv);
        let (s1, s2, s3) = ((m01 + m10) * inv, (m02 + m20) * inv, (m12 + m21) * inv);
        let big = 0.25 * r;
        let case = |w: f32, x: f32, y: f32, z: f32| sel(use_w, w, sel(use_x, x, sel(use_y, y, z)));
        q[0][l] = sel(ok, case(big, d1, d2, d3), 1.0);
        q[1][l] = sel(ok, case(d1, big, s1, s2), 0.0);
        q[2][l] = sel(ok, case(d2, s1, big, s3), 0.0);
        q[3][l] = sel(ok, case(d3, s2, s3, big), 0.0);
    }
    (q, sorted)
}

#[inline(always)]
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The `f64` factorisation of one Gaussian on a triangle with `M = m`: raw local rotation
/// `[w, x, y, z]`, local log-scales (the third ignored for a `flat` surfel). Returns the
/// rotation `[w, x, y, z]` (`w ≥ 0`) and the log-scales (shortest last).
#[must_use]
pub fn factor_f64(
    m: DMat3,
    rotation: [f32; 4],
    log_scale: [f32; 3],
    flat: bool,
) -> ([f32; 4], [f32; 3]) {
    let [w, x, y, z] = rotation.map(f64::from);
    let n = (w * w + x * x + y * y + z * z).sqrt();
    let r = if n > 0.0 && n.is_finite() {
        DMat3::from_quat(DQuat::from_xyzw(x / n, y / n, z / n, w / n))
    } else {
        DMat3::IDENTITY
    };
    let a = m * r;
    let s = DVec3::from_array(log_scale.map(f64::from)).exp();
    let s = if flat { DVec3::new(s.x, s.y, 0.0) } else { s };
    let l = DMat3::from_cols(a.x_axis * s.x, a.y_axis * s.y, a.z_axis * s.z);
    let (rot, sigma) = rotation_and_scales(l);
    let ln = |v: f64| v.max(MIN_OUTPUT_SCALE).ln() as f32;
    (
        to_wxyz(quat_from_rotation(rot)),
        [ln(sigma.x), ln(sigma.y), ln(sigma.z)],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::rng::Rng;

    /// Tolerance of the kernel against the `f64` factorisation on covariance entries, relative to
    /// the largest entry (tested; see the module docs for the measured worst case).
    const COVARIANCE_TOL: f64 = 1e-5;

    /// Tolerance of the kernel against the `f64` factorisation on log-scales (absolute; the `f32`
    /// storage of `ln σ ≈ 30` alone is 2e-6 per rounding).
    const LOG_SCALE_TOL: f64 = 1e-5;

    fn cov(q: [f32; 4], ls: [f32; 3]) -> DMat3 {
        let [w, x, y, z] = q.map(f64::from);
        let r = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w).normalize());
        let s = DVec3::from_array(ls.map(f64::from)).exp();
        r * DMat3::from_diagonal(s * s) * r.transpose()
    }

    fn random_rotation(u: &mut impl FnMut() -> f64) -> DMat3 {
        let q = DQuat::from_xyzw(u(), u(), u(), u() + 0.01).normalize();
        DMat3::from_quat(q)
    }

    /// Runs the kernel on `cases` (M, raw quaternion, log-scales), substituting the `f64`
    /// factorisation for flagged lanes as the deformer does; returns the worst covariance
    /// error (relative to the largest entry), the worst log-scale error and the fallbacks.
    fn compare(cases: &[(DMat3, [f32; 4], [f32; 3])], flat: bool) -> (f64, f64, usize) {
        let (mut worst_cov, mut worst_ls, mut fallbacks) = (0.0f64, 0.0f64, 0);
        for group in cases.chunks(LANES) {
            let mut batch = LaneBatch::default();
            for (l, (m, q, ls)) in group.iter().enumerate() {
                batch.set(l, *q, *ls, &TriangleFactor::new(*m));
            }
            let mut got = LaneFactors::default();
            factor_lanes(&batch, flat, &mut got);
            for (l, (m, q, ls)) in group.iter().enumerate() {
                let (wq, wls) = factor_f64(*m, *q, *ls, flat);
                let (gq, gls) = if got.needs_f64[l] {
                    fallbacks += 1;
                    (wq, wls)
                } else {
                    (
                        [0, 1, 2, 3].map(|k| got.rotation[k][l]),
                        [0, 1, 2].map(|k| got.log_scale[k][l]),
                    )
                };
                let [w, x, y, z] = gq;
                assert!(w >= 0.0 && ((w * w + x * x + y * y + z * z) - 1.0).abs() < 1e-6);
                let mut sorted = gls;
                sorted.sort_by(|a, b| b.total_cmp(a));
                assert_eq!(gls[2], sorted[2], "shortest axis last");
                let mut want_sorted = wls;
                want_sorted.sort_by(|a, b| b.total_cmp(a));
                for k in 0..if flat { 2 } else { 3 } {
                    worst_ls = worst_ls.max(f64::from((sorted[k] - want_sorted[k]).abs()));
                }
                if flat {
                    assert!(gls[2] <= (MIN_OUTPUT_SCALE as f32).ln() + 1e-3);
                }
                let (a, b) = (cov(gq, gls), cov(wq, wls));
                let size = b.to_cols_array().iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let err = (a - b)
                    .to_cols_array()
                    .iter()
                    .fold(0.0f64, |m, v| m.max(v.abs()));
                worst_cov = worst_cov.max(err / size);
            }
        }
        (worst_cov, worst_ls, fallbacks)
    }

    #[test]
    fn lanes_match_the_f64_factorisation() {
        let mut rng = Rng::new(31);
        let mut u = move || rng.uniform_f64() - 0.5;
        let mut report = Vec::new();
        // Near-similarities (animation), general matrices, ill-conditioned ones up to the
        // condition bound, each with random, repeated and strongly graded scales; kind 4
        // mixes, in every batch, isotropic Gaussians on near-exact similarities (a translated
        // frame: columns orthogonal and of equal length up to f32 rounding) with general
        // lanes that force the square-root rotations on the whole batch.
        for kind in 0..5 {
            for flat in [false, true] {
                let cases: Vec<_> = (0..4000)
                    .map(|case| {
                        let rot = random_rotation(&mut u);
                        let m = match kind {
                            0 => {
                                let noise = DMat3::from_cols_array(&[0; 9].map(|_: i32| u()));
                                (rot + noise * 0.1) * 0.01
                            }
                            1 => DMat3::from_cols_array(&[0; 9].map(|_: i32| u())),
                            2 => {
                                // Singular values 1, 1/a, 1/b with κ_F up to ~30.
                                let d = DVec3::new(1.0, 0.2 + u(), 1.0 / (9.0 + 10.0 * u()));
                                rot * DMat3::from_diagonal(d) * random_rotation(&mut u)
                            }
                            3 => rot * (1e3 * (u() + 0.6)),
                            _ if case % 2 == 0 => {
                                let noise = DMat3::from_cols_array(&[0; 9].map(|_: i32| u()));
                                (rot + noise * 1e-6) * 0.03
                            }
                            _ => DMat3::from_cols_array(&[0; 9].map(|_: i32| u())),
                        };
                        let mut ls = [u() * 8.0, u() * 8.0, u() * 8.0].map(|v| v as f32);
                        match case % 6 {
                            _ if kind == 4 && case % 2 == 0 => ls = [ls[0]; 3],
                            0 => ls = [ls[0]; 3],
                            1 => ls[1] = ls[0],
                            2 => ls[2] -= 29.0,
                            3 => {
                                // Spread near and beyond MAX_LOG_SCALE_SPREAD.
                                ls = [0.0, -12.0, -20.0 - 8.0 * (u() as f32 + 0.5)];
                            }
                            _ => {}
                        }
                        let q = [u() + 0.6, u(), u(), u()].map(|v| v as f32);
                        let q = if case % 97 == 0 { [0.0; 4] } else { q };
                        (m, q, ls)
                    })
                    .collect();
                let (c, l, f) = compare(&cases, flat);
                report.push(format!(
                    "kind {kind} flat {flat}: covariance {c:.1e}, log-scales {l:.1e}, {f} in f64"
                ));
                assert!(c < COVARIANCE_TOL, "{report:?}");
                assert!(l < LOG_SCALE_TOL, "{report:?}");
            }
        }
        println!("lanes vs f64:\n{}", report.join("\n"));
    }

    #[test]
    fn only_documented_lanes_fall_back() {
        let m = DMat3::from_diagonal(DVec3::new(1.0, 1.1, 0.9));
        let batch_for = |ls: [f32; 3], m: DMat3| {
            let mut b = LaneBatch::default();
            for l in 0..LANES {
                b.set(l, [1.0, 0.1, 0.2, 0.3], ls, &TriangleFactor::new(m));
            }
            let mut out = LaneFactors::default();
            factor_lanes(&b, false, &mut out);
            out.needs_f64
        };
        assert_eq!(batch_for([0.0, -5.0, -29.0], m), [true; LANES]);
        assert_eq!(batch_for([-2.0, -5.0, -25.0], m), [false; LANES]);
        let singular = DMat3::from_diagonal(DVec3::new(1.0, 1.0, 0.0));
        assert_eq!(batch_for([0.0; 3], singular), [true; LANES]);
        let inverted = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
        assert_eq!(batch_for([0.0; 3], inverted), [true; LANES]);
    }

    #[test]
    fn polar_rotation_warm_starts() {
        let mut rng = Rng::new(4);
        let mut u = move || rng.uniform_f64() - 0.5;
        for _ in 0..1000 {
            let rot = random_rotation(&mut u);
            let p = DMat3::from_cols_array(&[0; 9].map(|_: i32| u() * 0.2));
            let p = DMat3::IDENTITY + (p + p.transpose()) * 0.5;
            let t = TriangleFactor::new(rot * p * 3.0);
            assert!(!t.exact);
            let q = DMat3::from_cols_array(&t.q.map(f64::from));
            let [w, x, y, z] = t.u.map(f64::from);
            let u = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w).normalize());
            // Exact: ν U Q = M to f32 rounding (what the kernel relies on).
            let m = rot * p * 3.0;
            let back = u * q * f64::from(t.ln_norm).exp();
            assert!(frob(back - m) < 1e-6 * frob(m), "{back} {m}");
            // Warm start: U is the polar rotation and Q symmetric up to the documented
            // error of the stopped Newton iteration (half the square of a step ≤ POLAR_TOL).
            assert!(frob(u - rot) < POLAR_TOL * POLAR_TOL, "{u} {rot}");
            assert!(frob(q - q.transpose()) < POLAR_TOL * POLAR_TOL, "{q}");
        }
    }

    #[test]
    fn polynomial_exp_and_ln_are_accurate() {
        let (mut worst_exp, mut worst_ln) = (0.0f64, 0.0f64);
        for i in 0..320_000 / LANES {
            let x: Lanes = std::array::from_fn(|l| -87.0 * (i * LANES + l) as f32 / 320_000.0);
            let e = exp_lanes(x);
            for l in 0..LANES {
                let want = f64::from(x[l]).exp();
                worst_exp = worst_exp.max((f64::from(e[l]) - want).abs() / want);
            }
            let y: Lanes = std::array::from_fn(|l| {
                f32::MIN_POSITIVE * 1.0003f32.powi((i * LANES + l) as i32) * 3.3
            });
            let y = y.map(|v| if v.is_finite() { v } else { 1.0 });
            let g = ln_lanes(y);
            for l in 0..LANES {
                let want = f64::from(y[l]).ln();
                // Absolute error, relative to the ulp of the result's magnitude (≥ 1).
                worst_ln = worst_ln.max((f64::from(g[l]) - want).abs() / want.abs().max(1.0));
            }
        }
        println!("exp {worst_exp:.1e}, ln {worst_ln:.1e} (relative)");
        assert!(worst_exp < 3e-7, "{worst_exp}");
        assert!(worst_ln < 2e-7, "{worst_ln}");
    }

    #[test]
    fn degenerate_lanes_are_finite() {
        let mut b = LaneBatch::default();
        let cases = [
            (DMat3::IDENTITY, [1.0, 0.0, 0.0, 0.0], [0.0, -80.0, -80.0]),
            (DMat3::IDENTITY, [1.0, 0.0, 0.0, 0.0], [60.0, -60.0, 0.0]),
            (DMat3::IDENTITY * 1e-20, [1.0, 0.0, 0.0, 0.0], [-46.0; 3]),
            (DMat3::IDENTITY, [0.0; 4], [0.0; 3]),
            (DMat3::ZERO, [1.0, 0.0, 0.0, 0.0], [0.0; 3]),
            (DMat3::IDENTITY * 1e30, [1.0, 2.0, 0.0, 0.0], [80.0; 3]),
        ];
        for (l, (m, q, ls)) in cases.iter().enumerate() {
            b.set(l, *q, *ls, &TriangleFactor::new(*m));
        }
        for flat in [false, true] {
            let mut got = LaneFactors::default();
            factor_lanes(&b, flat, &mut got);
            for (l, (m, q, ls)) in cases.iter().enumerate() {
                let (q, ls) = if got.needs_f64[l] {
                    factor_f64(*m, *q, *ls, flat)
                } else {
                    (
                        [0, 1, 2, 3].map(|k| got.rotation[k][l]),
                        [0, 1, 2].map(|k| got.log_scale[k][l]),
                    )
                };
                assert!(
                    q.iter().chain(&ls).all(|v| v.is_finite()),
                    "{l}: {q:?} {ls:?}"
                );
            }
        }
    }
}
