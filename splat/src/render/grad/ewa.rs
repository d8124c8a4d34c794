//! The 3DGS (EWA) mode of the differentiable renderer as a [`GradKernel`]: its visible splats,
//! their evaluation at pixels in the operation order of the plain forward's
//! [`crate::render::project::EwaKernel`], and the per-splat backward sums (`f64` pixel by pixel,
//! `f32` four pixels at a time in `glam::Vec4` lanes), carried to the raw parameters by
//! [`super::project`].

use std::any::{Any, TypeId};

use glam::Vec4;

use super::params::{DiffParams, Real};
use super::project::{self, ScreenGrad, View};
use super::tile::{BackwardTile, GradKernel, ImageGrads, Kept, PixelRules, TILE_PIXELS, TileGeom};
use super::tile::{ForwardBand, unblend};
use crate::render::composite::CompositeRules;
use crate::render::options::{Outputs, RenderOptions};
use crate::render::project::{exp_neg4, row_bounds};
use crate::render::screen::{ScreenEntry, ScreenSplats, gather_visible};
use crate::render::tiles::{TILE_SIZE, box_pixels, hi, lo};

/// Pixels evaluated together in the backward row loop.
const LANES: usize = 4;

/// Values per (tile, splat) slot: d/d mean (2), conic (3), opacity, depth, colour (3).
pub(super) const SLOT: usize = 10;

/// One visible splat's screen data in the precision of the per-pixel loops.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Splat<F> {
    mean: [F; 2],
    conic: [F; 3],
    opacity: F,
    depth: F,
    color: [F; 3],
    /// Screen box (for the pixel range), as binned.
    center: [f32; 2],
    radius: [f32; 2],
    /// Row-span coefficients (pixels outside them have alpha below the skip threshold).
    span: [f32; 3],
}

/// Projects every Gaussian of `params` (culled ones dropped): the splats in Gaussian order and
/// their screen entries.
pub(super) fn gather<F: Real, P: DiffParams + ?Sized>(
    params: &P,
    view: &View,
    options: &RenderOptions,
) -> (ScreenSplats, Vec<Splat<F>>) {
    gather_visible(params.len(), Outputs::NONE, |i| {
        let s = project::project(params, i, view, options)?;
        let center = [s.mean[0] as f32, s.mean[1] as f32];
        let radius = [s.radius[0] as f32, s.radius[1] as f32];
        let entry = ScreenEntry::unshaded(i, center, radius, s.depth);
        let splat = Splat {
            mean: s.mean.map(F::of),
            conic: s.conic.map(F::of),
            opacity: F::of(s.opacity),
            depth: F::of(s.depth),
            color: s.color.map(F::of),
            center,
            radius,
            span: s.span,
        };
        Some((entry, splat))
    })
}

/// A splat's reduced slot as the projection's screen gradient.
pub(super) fn screen_grad(sum: &[f64; SLOT]) -> ScreenGrad {
    ScreenGrad {
        mean: [sum[0], sum[1]],
        conic: [sum[2], sum[3], sum[4]],
        opacity: sum[5],
        depth: sum[6],
        color: [sum[7], sum[8], sum[9]],
    }
}

/// The 3DGS kernel of the tile loops, for one set of rules.
pub(super) struct EwaGrad<F> {
    rules: CompositeRules,
    r: PixelRules<F>,
    r32: PixelRules<f32>,
}

impl<F: Real> EwaGrad<F> {
    pub(super) fn new(rules: CompositeRules) -> Self {
        Self {
            rules,
            r: PixelRules::new(&rules),
            r32: PixelRules::new(&rules),
        }
    }

    /// The local pixel rectangle of splat `s` in the tile (the plain compositor's).
    #[inline(always)]
    fn pixel_range(&self, s: &Splat<F>, g: &TileGeom) -> (usize, usize, usize, usize) {
        box_pixels(
            self.rules.clip_to_box,
            s.center,
            s.radius,
            self.rules.pixel_offset,
            (g.x0, g.y0),
            (g.tw, g.th),
        )
    }
}

impl<F: Real> GradKernel<F, SLOT> for EwaGrad<F> {
    type Item = Splat<F>;
    /// `d = mean − pixel`.
    type Pixel = (F, F);
    type Hit = ();
    type ForwardExtra = ();
    type BackwardExtra = ();

    fn rules(&self) -> &CompositeRules {
        &self.rules
    }

    fn forward_extra(&self) {}

    fn backward_extra(&self) {}

    fn place(item: &Splat<F>) -> ([f32; 2], [f32; 2]) {
        (item.center, item.radius)
    }

    #[inline(always)]
    fn for_each_pixel(&self, sp: &Splat<F>, g: &TileGeom, mut f: impl FnMut(usize, (F, F))) {
        let ts = TILE_SIZE as usize;
        let off = self.r.offset;
        let (lx0, lx1, ly0, ly1) = self.pixel_range(sp, g);
        for ly in ly0..ly1 {
            let (sx0, sx1) = row_span(sp, g, ly, off, (lx0, lx1));
            let py = F::of(f64::from((g.y0 as usize + ly) as f32 + off));
            let dy = sp.mean[1] - py;
            for lx in sx0..sx1 {
                let px = F::of(f64::from((g.x0 as usize + lx) as f32 + off));
                f(ly * ts + lx, (sp.mean[0] - px, dy));
            }
        }
    }

    #[inline(always)]
    fn eval(&self, sp: &Splat<F>, (dx, dy): (F, F)) -> Option<(F, ())> {
        let sigma = sigma_of(sp, dx, dy);
        if sigma < F::ZERO {
            return None;
        }
        Some((sp.opacity * sigma.exp_neg(), ()))
    }

    #[inline(always)]
    fn color(item: &Splat<F>) -> &[F; 3] {
        &item.color
    }

    #[inline(always)]
    fn depth(item: &Splat<F>, (): &()) -> F {
        item.depth
    }

    fn forward_reset((): &mut ()) {}

    #[inline(always)]
    fn forward_add(_: &Splat<F>, (): &(), _: F, _: usize, (): &mut ()) {}

    #[inline(always)]
    fn forward_write((): &(), _: usize, _: usize, _: &mut ForwardBand<'_, F>) {}

    #[inline(always)]
    fn backward_init((): &mut (), _: usize, _: usize, _: &Kept<'_, F>, _: &ImageGrads<'_, F>) {}

    #[inline(always)]
    fn backward_item(
        &self,
        sp: &Splat<F>,
        s: &mut BackwardTile<F, ()>,
        g: &TileGeom,
        k: u32,
    ) -> [f64; SLOT] {
        let range = self.pixel_range(sp, g);
        // f32: four pixels at a time in SSE lanes (the type test is resolved at compile
        // time); f64 pixel by pixel.
        if TypeId::of::<F>() == TypeId::of::<f32>() {
            let sp32 = (sp as &dyn Any).downcast_ref::<Splat<f32>>();
            let s32 = (&mut *s as &mut dyn Any).downcast_mut::<BackwardTile<f32, ()>>();
            match (sp32, s32) {
                (Some(sp32), Some(s32)) => backward_splat_f32(sp32, s32, g, range, k, &self.r32),
                _ => unreachable!("F is f32"),
            }
        } else {
            backward_splat(sp, s, g, range, k, &self.r)
        }
    }
}

/// The local pixel columns of row `ly` inside splat `s`'s row span, within `lx0..lx1` (the
/// plain compositor's [`crate::render::screen::SplatKernel::row_span`] for the EWA kernel).
#[inline(always)]
fn row_span<F: Real>(
    s: &Splat<F>,
    g: &TileGeom,
    ly: usize,
    off: f32,
    (lx0, lx1): (usize, usize),
) -> (usize, usize) {
    let py = (g.y0 as usize + ly) as f32 + off;
    let (a, b) = row_bounds(s.span, s.center, py);
    (
        lo(a - off, g.x0, g.tw).max(lx0),
        hi(b - off, g.x0, g.tw).min(lx1),
    )
}

/// `sigma = ½(a dx² + c dy²) + b dx dy` with `d = mean − pixel`, in the operation order of
/// [`crate::render::project::EwaKernel`], so `f32` gives the plain forward's values.
#[inline(always)]
fn sigma_of<F: Real>(s: &Splat<F>, dx: F, dy: F) -> F {
    let [a, b, c] = s.conic;
    F::of(0.5) * (a * dx * dx + c * dy * dy) + b * dx * dy
}

/// One splat over its pixels of one tile in the backward pass, pixel by pixel: returns its
/// slot `[d/d mean (2), conic (3), opacity, depth, colour (3)]` and updates the pixels'
/// transmittance and `behind` sums ([`unblend`]). Row sums (at most 16 terms) in `F`, then
/// `f64`: with dy fixed on a row, the conic and mean gradients need only `Σ g_σ`, `Σ g_σ dx`
/// and `Σ g_σ dx²`.
#[inline(always)]
fn backward_splat<F: Real>(
    sp: &Splat<F>,
    s: &mut BackwardTile<F, ()>,
    g: &TileGeom,
    (lx0, lx1, ly0, ly1): (usize, usize, usize, usize),
    k: u32,
    r: &PixelRules<F>,
) -> [f64; SLOT] {
    let ts = TILE_SIZE as usize;
    let [a, b, c] = sp.conic.map(Real::wide);
    let mut sum = [0.0f64; SLOT];
    for ly in ly0..ly1 {
        let (sx0, sx1) = row_span(sp, g, ly, r.offset, (lx0, lx1));
        let py = F::of(f64::from((g.y0 as usize + ly) as f32 + r.offset));
        let dy = sp.mean[1] - py;
        let mut row = [F::ZERO; 8];
        for lx in sx0..sx1 {
            let p = ly * ts + lx;
            if k >= s.last[p] {
                continue;
            }
            let px = F::of(f64::from((g.x0 as usize + lx) as f32 + r.offset));
            let dx = sp.mean[0] - px;
            let sigma = sigma_of(sp, dx, dy);
            if sigma < F::ZERO {
                continue;
            }
            let falloff = sigma.exp_neg();
            let raw = sp.opacity * falloff;
            let alpha = raw.min(r.max_alpha);
            if alpha < r.min_alpha {
                continue;
            }
            let (gr, gg, gb) = (s.g_rgb[0][p], s.g_rgb[1][p], s.g_rgb[2][p]);
            let gd = s.g_depth[p];
            let qk = gr * sp.color[0] + gg * sp.color[1] + gb * sp.color[2] + gd * sp.depth;
            let (wgt, g_alpha) = unblend(s, p, alpha, qk);
            row[0] += gr * wgt;
            row[1] += gg * wgt;
            row[2] += gb * wgt;
            row[3] += gd * wgt;
            if raw <= r.max_alpha {
                row[4] += g_alpha * falloff;
                let g_sigma = -(g_alpha * raw);
                row[5] += g_sigma;
                row[6] += g_sigma * dx;
                row[7] += g_sigma * dx * dx;
            }
        }
        let dy = dy.wide();
        let [r_r, r_g, r_b, r_d, r_op, s0, s1, s2] = row.map(Real::wide);
        sum[7] += r_r;
        sum[8] += r_g;
        sum[9] += r_b;
        sum[6] += r_d;
        sum[5] += r_op;
        sum[0] += a * s1 + b * dy * s0;
        sum[1] += b * s1 + c * dy * s0;
        sum[2] += 0.5 * s2;
        sum[3] += dy * s1;
        sum[4] += 0.5 * dy * dy * s0;
    }
    sum
}

/// [`backward_splat`] in `f32`, four pixels at a time in `glam::Vec4` lanes, branch-free; the
/// alphas are those of the plain compositor's [`crate::render::project::EwaKernel::sample4`]
/// bit for bit (same operations, same `exp`). Each lane sums at most 64 terms of one (tile,
/// splat) pair in `f32`; the lanes are added in `f64`.
#[inline(always)]
fn backward_splat_f32(
    sp: &Splat<f32>,
    s: &mut BackwardTile<f32, ()>,
    g: &TileGeom,
    (lx0, lx1, ly0, ly1): (usize, usize, usize, usize),
    k: u32,
    r: &PixelRules<f32>,
) -> [f64; SLOT] {
    let ts = TILE_SIZE as usize;
    let [a, b, c] = sp.conic;
    let mut acc = [Vec4::ZERO; SLOT];
    let kf = Vec4::splat(k as f32);
    let (max_alpha, min_alpha) = (Vec4::splat(r.max_alpha), Vec4::splat(r.min_alpha));
    let lanes = Vec4::new(0.0, 1.0, 2.0, 3.0);
    for ly in ly0..ly1 {
        let (sx0, sx1) = row_span(sp, g, ly, r.offset, (lx0, lx1));
        let py = (g.y0 as usize + ly) as f32 + r.offset;
        let dy = sp.mean[1] - py;
        let cdy2 = c * dy * dy;
        let groups = sx1.saturating_sub(sx0).div_ceil(LANES);
        let gx0 = sx0.min(ts.saturating_sub(groups * LANES));
        for gi in 0..groups {
            let lx = gx0 + gi * LANES;
            let p0 = ly * ts + lx;
            let range = p0..p0 + LANES;
            if range.end > TILE_PIXELS {
                break;
            }
            let px = Vec4::splat((g.x0 as usize + lx) as f32 + r.offset) + lanes;
            let dx = Vec4::splat(sp.mean[0]) - px;
            let sigma = 0.5 * (a * dx * dx + Vec4::splat(cdy2)) + b * dx * dy;
            let falloff = exp_neg4(sigma);
            let raw = sp.opacity * falloff;
            let alpha = raw.min(max_alpha);
            let last = Vec4::from_array(
                <[u32; LANES]>::try_from(&s.last[range.clone()])
                    .unwrap_or([0; LANES])
                    .map(|v| v as f32),
            );
            let on = kf.cmplt(last) & sigma.cmpge(Vec4::ZERO) & alpha.cmpge(min_alpha);
            let ra = Vec4::ONE / (Vec4::ONE - alpha);
            let t_old = Vec4::from_slice(&s.t[range.clone()]);
            let behind = Vec4::from_slice(&s.behind[range.clone()]);
            let t = t_old * ra;
            let wgt = Vec4::select(on, alpha * t, Vec4::ZERO);
            let gr = Vec4::from_slice(&s.g_rgb[0][range.clone()]);
            let gg = Vec4::from_slice(&s.g_rgb[1][range.clone()]);
            let gb = Vec4::from_slice(&s.g_rgb[2][range.clone()]);
            let gd = Vec4::from_slice(&s.g_depth[range.clone()]);
            let qk = gr * sp.color[0] + gg * sp.color[1] + gb * sp.color[2] + gd * sp.depth;
            let g_alpha = t * qk - ra * behind;
            (behind + wgt * qk).write_to_slice(&mut s.behind[range.clone()]);
            Vec4::select(on, t, t_old).write_to_slice(&mut s.t[range.clone()]);
            acc[7] += gr * wgt;
            acc[8] += gg * wgt;
            acc[9] += gb * wgt;
            acc[6] += gd * wgt;
            let free = on & raw.cmple(max_alpha);
            let g_sigma = Vec4::select(free, -(g_alpha * raw), Vec4::ZERO);
            acc[5] += Vec4::select(free, g_alpha * falloff, Vec4::ZERO);
            // Σ g_σ dx, Σ g_σ dy, Σ g_σ dx², Σ g_σ dx dy, Σ g_σ dy²: the mean and conic
            // gradients follow per (tile, splat) pair, below.
            let gdx = g_sigma * dx;
            let gdy = g_sigma * dy;
            acc[0] += gdx;
            acc[1] += gdy;
            acc[2] += gdx * dx;
            acc[3] += gdx * dy;
            acc[4] += gdy * dy;
        }
    }
    let mut sum = acc.map(|v| v.to_array().iter().map(|&x| f64::from(x)).sum::<f64>());
    let [a, b, c] = sp.conic.map(f64::from);
    let (sdx, sdy) = (sum[0], sum[1]);
    sum[0] = a * sdx + b * sdy;
    sum[1] = b * sdx + c * sdy;
    sum[2] *= 0.5;
    sum[4] *= 0.5;
    sum
}
