//! 3DGS EWA projection (gsplat's `fully_fused_projection`, pinhole camera) and its per-pixel
//! kernel ([`EwaKernel`]).
//!
//! Per Gaussian, in `f64`: camera-space mean `t = Rᵀ(μ − c)`; cull unless `near < t.z < far`;
//! covariance `Σ = R S Sᵀ Rᵀ` (normalised quaternion, `exp` of the log-scales) to camera space;
//! Jacobian `J = [[fx/z, 0, −fx x'/z²], [0, fy/z, −fy y'/z²]]` with `x'/z`, `y'/z` clamped to the
//! view frustum widened by 0.3 tan(fov/2) on each side (gsplat: `[−cx/fx − 0.3 tan, (W − cx)/fx +
//! 0.3 tan]`, `tan = W / (2 fx)`); `Σ2D = J Σ Jᵀ + 0.3 I`; cull `det ≤ 0`. Then `f32` for the
//! per-pixel data: mean `(fx x/z + cx, fy y/z + cy)`, conic `Σ2D⁻¹`, opacity
//! `sigmoid(logit)` (× `sqrt(det(Σ2D − 0.3 I)/det Σ2D)` when antialiased).
//!
//! Screen boxes (gsplat's CUDA kernel): Gaussians with opacity below 1/255 are culled (they can
//! never pass the skip threshold); half sizes `ceil(e sqrt(Σ2D_xx))`, `ceil(e sqrt(Σ2D_yy))` with
//! `e = min(3.33, sqrt(2 ln(255 opacity)))` — outside that box `alpha < 1/255`, so the images
//! equal those of gsplat's plain 3.33σ boxes. Boxes entirely off the image are culled. The
//! original 3DGS rules use one radius `ceil(3 sqrt(λmax))` with `λmax` from
//! `mid + sqrt(max(0.1, mid² − det))`, symmetric limits `±1.3 tan(fov/2)`, and shift the means by
//! −0.5 px (its integer pixel centres).

use glam::{DMat3, DVec3, Vec4};
use trisplat_geometry::Camera;

use super::composite::ALPHA_THRESHOLD;
use super::options::{RenderOptions, Rules, SplatDepth};
use super::pinhole::Pinhole;
use super::screen::{
    Sample, ScreenEntry, ScreenSplats, SplatKernel, facing_normal, gather_visible, shade,
};
use crate::gaussians::GaussianSet;
use crate::gaussians::sigmoid;

/// gsplat's `eps2d`: the screen-space dilation added to `Σ2D`'s diagonal.
pub const EPS_2D: f64 = 0.3;
/// gsplat's box extent in standard deviations.
pub const GSPLAT_EXTENT: f64 = 3.33;
/// The original 3DGS radius in standard deviations.
pub const ORIGINAL_EXTENT: f64 = 3.0;
/// The frustum margin of the Jacobian clamp, as a fraction of tan(fov/2).
pub const FRUSTUM_MARGIN: f64 = 0.3;
/// The original 3DGS floor of `mid² − det` in the eigenvalue formula.
const ORIGINAL_EIGEN_FLOOR: f64 = 0.1;

/// Per-pixel data of one projected Gaussian, packed for the compositing loop.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct EwaSplat {
    /// Projected mean (pixel coordinates).
    pub mean: [f32; 2],
    /// Conic `(a, b, c)`: `Σ2D⁻¹ = [[a, b], [b, c]]`.
    pub conic: [f32; 3],
    /// Opacity (× compensation in antialiased mode).
    pub opacity: f32,
    /// Camera z of the mean.
    pub depth: f32,
    /// Depth change per pixel `(∂z/∂u, ∂z/∂v)` away from the mean ([`SplatDepth::Ray`]; zero
    /// for [`SplatDepth::Mean`]).
    pub depth_slope: [f32; 2],
    /// Largest offset from `depth` the slope may give (3 × the largest scale).
    pub depth_reach: f32,
    /// Row-span coefficients `(p, q, r)`: on the row at `dy = mean_y − py`, `alpha ≥ 1/255`
    /// only for `dx = mean_x − px` within `−p dy ± sqrt(q dy² + r)`; from
    /// `½ a dx² + b dx dy + ½ c dy² ≤ ln(255 opacity)`: `p = b/a`, `q = (b² − a c)/a²`,
    /// `r = 2 ln(255 opacity)/a`.
    pub span: [f32; 3],
}

/// The 3DGS EWA kernel: `sigma = ½(a dx² + c dy²) + b dx dy` with `d = mean − pixel`,
/// skipped when `sigma < 0`, `alpha = opacity exp(−sigma)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EwaKernel {
    /// One entry per visible splat, indexed like the [`ScreenSplats`].
    pub splats: Vec<EwaSplat>,
}

impl SplatKernel for EwaKernel {
    #[inline(always)]
    fn sample(&self, i: usize, px: f32, py: f32) -> Option<Sample> {
        let s = &self.splats[i];
        let dx = s.mean[0] - px;
        let dy = s.mean[1] - py;
        let sigma = 0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) + s.conic[1] * dx * dy;
        if sigma < 0.0 {
            return None;
        }
        Some(Sample {
            alpha: s.opacity * exp_f32(-sigma),
            depth: s.depth + depth_offset(s, dx, dy),
        })
    }

    #[inline(always)]
    fn sample_row(&self, i: usize, py: f32, px0: f32, alpha: &mut [f32], depth: &mut [f32]) {
        let s = &self.splats[i];
        let [a, b, c] = s.conic;
        let dy = s.mean[1] - py;
        let cdy2 = c * dy * dy;
        for (k, out) in alpha.iter_mut().enumerate() {
            let dx = s.mean[0] - (px0 + k as f32);
            let sigma = 0.5 * (a * dx * dx + cdy2) + b * dx * dy;
            let value = s.opacity * exp_f32(-sigma);
            *out = if sigma < 0.0 { 0.0 } else { value };
        }
        for (k, out) in depth.iter_mut().enumerate() {
            *out = s.depth + depth_offset(s, s.mean[0] - (px0 + k as f32), dy);
        }
    }

    #[inline(always)]
    fn sample4(&self, i: usize, py: f32, px0: f32) -> (Vec4, Vec4) {
        let s = &self.splats[i];
        let [a, b, c] = s.conic;
        let px = Vec4::splat(px0) + Vec4::new(0.0, 1.0, 2.0, 3.0);
        let dx = Vec4::splat(s.mean[0]) - px;
        let dy = s.mean[1] - py;
        let cdy2 = c * dy * dy;
        let sigma = 0.5 * (a * dx * dx + Vec4::splat(cdy2)) + b * dx * dy;
        let alpha = s.opacity * exp_neg4(sigma);
        // `pixel − mean = −d`; with a zero slope (SplatDepth::Mean) this is exactly `depth`.
        let [gu, gv] = s.depth_slope;
        let reach = Vec4::splat(s.depth_reach);
        let offset = (-(gu * dx + Vec4::splat(gv * dy))).clamp(-reach, reach);
        (
            Vec4::select(sigma.cmplt(Vec4::ZERO), Vec4::ZERO, alpha),
            Vec4::splat(s.depth) + offset,
        )
    }

    #[inline(always)]
    fn touch(&self, i: usize) -> f32 {
        self.splats.get(i).map_or(0.0, |s| s.mean[0] + s.span[2])
    }

    fn reordered(&self, order: &[u32]) -> Option<Self> {
        let splats = order
            .iter()
            .map(|&i| self.splats.get(i as usize).copied())
            .collect::<Option<Vec<_>>>()?;
        Some(Self { splats })
    }

    /// `−p dy ± sqrt(q dy² + r)` around `mean_x` (see [`EwaSplat::span`]), widened by a margin.
    #[inline(always)]
    fn row_span(&self, i: usize, py: f32) -> Option<(f32, f32)> {
        let s = &self.splats[i];
        Some(row_bounds(s.span, s.mean, py))
    }
}

/// The columns of row `py` a splat with row-span coefficients `span` ([`EwaSplat::span`]) and
/// projected mean `mean` can cover: `−p dy ± sqrt(q dy² + r)` around `mean_x`, widened by
/// [`SPAN_MARGIN`].
#[inline(always)]
pub(crate) fn row_bounds([p, q, r]: [f32; 3], mean: [f32; 2], py: f32) -> (f32, f32) {
    let dy = mean[1] - py;
    let root_sq = q * dy * dy + r;
    let center = mean[0] + p * dy;
    if root_sq < 0.0 {
        // Empty up to rounding: keep a margin around the vertex for safety.
        return (center - SPAN_MARGIN, center + SPAN_MARGIN);
    }
    let root = root_sq.sqrt();
    (center - root - SPAN_MARGIN, center + root + SPAN_MARGIN)
}

/// The depth offset of splat `s` at `d = mean − pixel` ([`EwaSplat::depth_slope`]): exactly 0
/// for a zero slope.
#[inline(always)]
fn depth_offset(s: &EwaSplat, dx: f32, dy: f32) -> f32 {
    (-(s.depth_slope[0] * dx + s.depth_slope[1] * dy)).clamp(-s.depth_reach, s.depth_reach)
}

/// The row-span coefficients of [`EwaSplat::span`] for conic `(a, b, c)` and `sigma_max`.
pub(crate) fn row_span_coefficients([a, b, c]: [f64; 3], sigma_max: f64) -> [f32; 3] {
    if a > 0.0 && a.is_finite() {
        [
            (b / a) as f32,
            ((b * b - a * c) / (a * a)) as f32,
            (2.0 * sigma_max / a) as f32,
        ]
    } else {
        // Never for a positive definite conic; an infinite span scans the whole box.
        [0.0, 0.0, f32::INFINITY]
    }
}

/// `e^x` in `f32` without a library call, so loops over pixels vectorise: Cody-Waite range
/// reduction `x = n ln 2 + r` and the Cephes `expf` polynomial on `|r| ≤ ln 2 / 2`
/// (about 1 ulp from the correctly rounded value; inputs clamped to [−87, 88], so the result is
/// finite and at least the smallest normal float).
#[inline(always)]
#[must_use]
pub fn exp_f32(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5 * 2^23: adding and subtracting rounds to the nearest integer.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let n = (x * LOG2E + ROUND) - ROUND;
    let r = x - n * LN2_HI - n * LN2_LO;
    let mut p = 1.987_569_1e-4_f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let e = p * r * r + r + 1.0;
    // 2^n from the bits of n + 127 (in 1..=254), read off the mantissa of n + 127 + 2^23
    // (no float-to-int conversion, so the loop vectorises).
    let biased = (n + (127.0 + 8_388_608.0)).to_bits() & 0x007f_ffff;
    let scale = f32::from_bits(biased << 23);
    e * scale
}

/// Four lanes of `e^(−sigma)` with the same range reduction and polynomial as [`exp_f32`], in
/// `glam::Vec4` (SSE2) arithmetic. `sigma` is clamped to `[−88, 30]`: beyond 30 the result
/// (`≈ 9e-14`) is far below any alpha threshold, and negative inputs are only ever discarded.
/// The power of two is assembled in the vector unit (`pow2_neg4`), so no lane leaves it.
#[inline(always)]
#[must_use]
pub fn exp_neg4(sigma: Vec4) -> Vec4 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    const ROUND: f32 = 12_582_912.0;
    let x = -sigma.clamp(Vec4::splat(-88.0), Vec4::splat(30.0));
    let n = (x * LOG2E + ROUND) - ROUND;
    let r = x - n * LN2_HI - n * LN2_LO;
    let mut p = Vec4::splat(1.987_569_1e-4);
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let e = p * r * r + r + 1.0;
    e * pow2_neg4(n)
}

/// `2^n` for the integer-valued lanes `n` in `[−44, 127]` of [`exp_neg4`], exact: the
/// exponent bits `n + 127` are read off the mantissa of `n + 127 + 2^23` and shifted into
/// place (bit casts and integer ops on four lanes, which the compiler keeps in the vector unit).
#[inline(always)]
fn pow2_neg4(n: Vec4) -> Vec4 {
    let biased = (n + Vec4::splat(127.0 + 8_388_608.0)).to_array();
    Vec4::from_array(biased.map(|v| f32::from_bits((v.to_bits() & 0x007f_ffff) << 23)))
}

/// Scales below this share of a Gaussian's largest scale count as this share in
/// [`ray_depth_slope`] (a zero scale would make `Σ` singular).
const RAY_DEPTH_SCALE_FLOOR: f64 = 1e-6;
/// Steepest [`SplatDepth::Ray`] slope, in reaches per pixel.
const MAX_SLOPE_PER_REACH: f64 = 1e3;
/// Bound of the [`SplatDepth::Ray`] reach and slopes, far inside `f32`'s range.
const MAX_DEPTH_OFFSET: f64 = 1e30;

/// [`SplatDepth::Ray`]'s `(∂z/∂u, ∂z/∂v)` and reach for a Gaussian with camera-space unit
/// axes `axes` (columns), scales `scales` and camera-space mean `t`, for focal lengths `f`.
///
/// The highest density on the ray `s (x, y, 1)` is at `s* = dᵀAt / dᵀAd` (`A = Σ⁻¹`); at the
/// mean's ray `d₀ = t / z` it is `z`, and `∂s*/∂(x, y) = −z² (At)_xy / tᵀAt`. `A` is used up to
/// a positive factor (the ratio does not see it): `A ∝ Σ_k (s_max/s_k)² a_k a_kᵀ`, each scale
/// floored at [`RAY_DEPTH_SCALE_FLOOR`] × `s_max`, so a zero scale gives its axis's plane.
fn ray_depth_slope(axes: DMat3, scales: DVec3, t: DVec3, [fx, fy]: [f64; 2]) -> ([f32; 2], f32) {
    let max_scale = scales.max_element();
    if !(max_scale > 0.0 && max_scale.is_finite()) {
        return ([0.0; 2], 0.0);
    }
    let floor = RAY_DEPTH_SCALE_FLOOR * max_scale;
    let mut at = DVec3::ZERO;
    let mut tat = 0.0;
    for (axis, scale) in [axes.x_axis, axes.y_axis, axes.z_axis]
        .into_iter()
        .zip(scales.to_array())
    {
        let weight = (max_scale / scale.max(floor)).powi(2);
        let along = axis.dot(t);
        at += axis * (weight * along);
        tat += weight * along * along;
    }
    let g = -t.z * t.z / tat;
    let slope = [g * at.x / fx, g * at.y / fy];
    if !(tat > 0.0 && slope[0].is_finite() && slope[1].is_finite()) {
        return ([0.0; 2], 0.0);
    }
    // A grazing Gaussian's slope is steep: bounded so that the products with pixel offsets
    // stay finite in f32 (the reach clamps the offset long before).
    let reach = (3.0 * max_scale).min(MAX_DEPTH_OFFSET);
    let steepest = (reach * MAX_SLOPE_PER_REACH).min(MAX_DEPTH_OFFSET);
    (
        slope.map(|v| v.clamp(-steepest, steepest) as f32),
        reach as f32,
    )
}

/// Pixels of rounding margin on each side of an analytic row span.
pub(crate) const SPAN_MARGIN: f32 = 0.5;

/// What a 3DGS projection needs to know of the camera, precomputed once.
pub(crate) struct View {
    pub(crate) cam: Pinhole,
    /// `(−lower, upper)` limits of x/z in the Jacobian clamp.
    pub(crate) lim_x: (f64, f64),
    pub(crate) lim_y: (f64, f64),
}

impl View {
    /// The view of `camera` under `rules`.
    pub(crate) fn new(camera: &Camera, rules: Rules) -> Self {
        let (width, height) = (f64::from(camera.width), f64::from(camera.height));
        let tan_x = 0.5 * width / camera.fx;
        let tan_y = 0.5 * height / camera.fy;
        let (lim_x, lim_y) = match rules {
            Rules::Gsplat => (
                (
                    camera.cx / camera.fx + FRUSTUM_MARGIN * tan_x,
                    (width - camera.cx) / camera.fx + FRUSTUM_MARGIN * tan_x,
                ),
                (
                    camera.cy / camera.fy + FRUSTUM_MARGIN * tan_y,
                    (height - camera.cy) / camera.fy + FRUSTUM_MARGIN * tan_y,
                ),
            ),
            Rules::Original3dgs => {
                let (lx, ly) = (
                    (1.0 + FRUSTUM_MARGIN) * tan_x,
                    (1.0 + FRUSTUM_MARGIN) * tan_y,
                );
                ((lx, lx), (ly, ly))
            }
        };
        Self {
            cam: Pinhole::of(camera),
            lim_x,
            lim_y,
        }
    }
}

/// One projected Gaussian before compaction.
struct Projected {
    id: u32,
    center: [f32; 2],
    radius: [f32; 2],
    splat: EwaSplat,
    color: [f32; 3],
    normal: [f32; 3],
}

/// Projects the Gaussians of `set` (world space) into `camera` with the 3DGS EWA rules of
/// `options` (module documentation). Colours are evaluated only when `options.outputs.rgb`,
/// normals only when `options.outputs.normal`.
#[must_use]
pub fn project_ewa(
    set: &GaussianSet,
    camera: &Camera,
    options: &RenderOptions,
) -> (ScreenSplats, EwaKernel) {
    let view = View::new(camera, options.rules);
    let (screen, splats) = gather_visible(set.len(), options.outputs, |i| {
        let p = project_one(set, i, &view, options)?;
        let entry = ScreenEntry {
            id: p.id,
            center: p.center,
            radius: p.radius,
            depth: p.splat.depth,
            color: p.color,
            normal: p.normal,
        };
        Some((entry, p.splat))
    });
    (screen, EwaKernel { splats })
}

/// The pixel-space centre and radii of a projected Gaussian with 2D covariance diagonal
/// `c00, c11` and determinant `det` (blur included) and projected centre `[u, w]`, by `rules`
/// (gsplat: extent `min(3, √(2 ln(255 opacity)))` σ per axis, culled below alpha 1/255; the
/// original rules: 3 √λ_max, centre moved by half a pixel), or `None` when it is culled or
/// entirely off the `size` image. Shared by the renderer and its gradient, so both keep the
/// same splats.
pub(crate) fn screen_footprint(
    rules: Rules,
    opacity: f64,
    log_ratio: f64,
    [c00, c11, det]: [f64; 3],
    [mut u, mut w]: [f64; 2],
    [width, height]: [f64; 2],
) -> Option<([f64; 2], [f64; 2])> {
    let radius = match rules {
        Rules::Gsplat => {
            if opacity < f64::from(ALPHA_THRESHOLD) {
                return None;
            }
            let extent = GSPLAT_EXTENT.min((2.0 * log_ratio).sqrt());
            let rx = (extent * c00.sqrt()).ceil();
            let ry = (extent * c11.sqrt()).ceil();
            if rx <= 0.0 && ry <= 0.0 {
                return None;
            }
            [rx, ry]
        }
        Rules::Original3dgs => {
            let mid = 0.5 * (c00 + c11);
            let root = (mid * mid - det).max(ORIGINAL_EIGEN_FLOOR).sqrt();
            let lambda = (mid + root).max(mid - root);
            let r = (ORIGINAL_EXTENT * lambda.sqrt()).ceil();
            u -= 0.5;
            w -= 0.5;
            [r, r]
        }
    };
    if u + radius[0] <= 0.0
        || u - radius[0] >= width
        || w + radius[1] <= 0.0
        || w - radius[1] >= height
        || !(u.is_finite() && w.is_finite())
    {
        return None;
    }
    Some(([u, w], radius))
}

/// A Gaussian's EWA screen footprint and the intermediates its vector-Jacobian product reuses.
pub(crate) struct EwaScreen {
    /// `x/z` and `y/z` clamped as in the Jacobian, times `z`.
    pub(crate) tx: f64,
    pub(crate) ty: f64,
    /// Whether `x/z` (`y/z`) lies inside the clamp.
    pub(crate) free: [bool; 2],
    /// Rows of the clamped Jacobian `J`.
    pub(crate) j0: DVec3,
    pub(crate) j1: DVec3,
    /// Rows of `J L`.
    pub(crate) a0: DVec3,
    pub(crate) a1: DVec3,
    /// `Σ2D = (J L)(J L)ᵀ` as `(c00, c01, c11)`, before the dilation.
    pub(crate) cov: [f64; 3],
    /// The dilated `Σ2D` as `(d00, c01, d11)` and its determinant.
    pub(crate) dil: [f64; 3],
    pub(crate) det: f64,
    /// The antialiasing compensation (1 when off).
    pub(crate) comp: f64,
    /// The opacity times the compensation.
    pub(crate) opacity: f64,
    /// Projected mean (pixels).
    pub(crate) mean: [f64; 2],
    /// Screen box half sizes.
    pub(crate) radius: [f64; 2],
    /// Conic `(a, b, c)`: the inverse of the dilated `Σ2D`.
    pub(crate) conic: [f64; 3],
    /// Row-span coefficients ([`EwaSplat::span`]).
    pub(crate) span: [f32; 3],
}

/// The EWA projection of a Gaussian at camera-space position `t` (`t.z` within the clip
/// planes) with camera-space covariance `l lᵀ` (`l = W R S`) and opacity `opacity`: the
/// clamped Jacobian, the dilated screen covariance, the antialiasing compensation and the
/// screen box by `o`'s rules; `None` when culled.
#[inline(always)]
pub(crate) fn ewa_screen(
    v: &View,
    o: &RenderOptions,
    t: DVec3,
    l: DMat3,
    opacity: f64,
) -> Option<EwaScreen> {
    let z = t.z;
    // Clamped Jacobian rows.
    let (rx, ry) = (t.x / z, t.y / z);
    let (cx, cy) = (
        rx.clamp(-v.lim_x.0, v.lim_x.1),
        ry.clamp(-v.lim_y.0, v.lim_y.1),
    );
    let (tx, ty) = (z * cx, z * cy);
    let j0 = DVec3::new(v.cam.fx / z, 0.0, -v.cam.fx * tx / (z * z));
    let j1 = DVec3::new(0.0, v.cam.fy / z, -v.cam.fy * ty / (z * z));
    // Rows of J L: Σ2D = (J L)(J L)ᵀ.
    let lt = l.transpose();
    let a0 = lt * j0;
    let a1 = lt * j1;
    let (c00, c01, c11) = (a0.dot(a0), a0.dot(a1), a1.dot(a1));
    let det_orig = c00 * c11 - c01 * c01;
    let (d00, d11) = (c00 + EPS_2D, c11 + EPS_2D);
    let det = d00 * d11 - c01 * c01;
    if det <= 0.0 || !det.is_finite() {
        return None;
    }
    let (comp, opacity) = if o.antialiased {
        let comp = (det_orig / det).max(0.0).sqrt();
        (comp, opacity * comp)
    } else {
        (1.0, opacity)
    };
    let u = v.cam.fx * t.x / z + v.cam.cx;
    let w = v.cam.fy * t.y / z + v.cam.cy;
    // `ln(255 opacity)`: the largest sigma with alpha >= 1/255 (negative, NaN or -inf for
    // opacities below 1/255, which gsplat culls and the original rules clamp to 0 below).
    let log_ratio = (opacity / f64::from(ALPHA_THRESHOLD)).ln();
    let (mean, radius) = screen_footprint(
        o.rules,
        opacity,
        log_ratio,
        [d00, d11, det],
        [u, w],
        [v.cam.width, v.cam.height],
    )?;
    let inv = 1.0 / det;
    let conic = [d11 * inv, -c01 * inv, d00 * inv];
    Some(EwaScreen {
        tx,
        ty,
        free: [rx == cx, ry == cy],
        j0,
        j1,
        a0,
        a1,
        cov: [c00, c01, c11],
        dil: [d00, c01, d11],
        det,
        comp,
        opacity,
        mean,
        radius,
        conic,
        span: row_span_coefficients(conic, log_ratio.max(0.0)),
    })
}

fn project_one(set: &GaussianSet, i: usize, v: &View, o: &RenderOptions) -> Option<Projected> {
    let mean = set.means()[i].as_dvec3();
    let t = v.cam.w2c * (mean - v.cam.position);
    let z = t.z;
    if !(z > f64::from(o.near) && z < f64::from(o.far)) {
        return None;
    }
    let opacity = f64::from(sigmoid(set.opacity_logits()[i]));
    if opacity <= 0.0 && o.rules == Rules::Gsplat {
        return None;
    }
    // Camera-space covariance as L Lᵀ with L = W R S (no cancellation for tiny scales).
    let rot = set.rotation_matrix(i);
    let s = set.scale(i).as_dvec3();
    let l = v.cam.w2c * DMat3::from_cols(rot.x_axis * s.x, rot.y_axis * s.y, rot.z_axis * s.z);
    let e = ewa_screen(v, o, t, l, opacity)?;
    let (slope, reach) = match o.splat_depth {
        SplatDepth::Mean => ([0.0; 2], 0.0),
        SplatDepth::Ray => ray_depth_slope(v.cam.w2c * rot, s, t, [v.cam.fx, v.cam.fy]),
    };
    let (color, normal) = shade(set, i, mean - v.cam.position, o.outputs, || {
        facing_normal(rot, s, mean - v.cam.position, v.cam.w2c, o.normal_frame)
    });
    let [u, w] = e.mean;
    Some(Projected {
        id: i as u32,
        center: [u as f32, w as f32],
        radius: [e.radius[0] as f32, e.radius[1] as f32],
        splat: EwaSplat {
            mean: [u as f32, w as f32],
            conic: e.conic.map(|c| c as f32),
            opacity: e.opacity as f32,
            depth: z as f32,
            depth_slope: slope,
            depth_reach: reach,
            span: e.span,
        },
        color,
        normal,
    })
}
