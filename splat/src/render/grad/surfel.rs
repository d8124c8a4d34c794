//! The 2DGS surfel mode of the differentiable renderer (docs/conventions.md §5 "Gradients") as a
//! [`GradKernel`] of the shared tile loops: the forward keeps, besides the shared per-pixel
//! state, the rendered normal image and the moments of the depth-distortion loss; the backward
//! uses the same transmittance recovery and (tile, splat) slots as the 3DGS mode, with the
//! surfel kernel's own per-pixel vector-Jacobian product ([`kernel_vjp`]) and
//! [`super::surfel_project`] after the reduction.
//!
//! The kernel is evaluated in `f64` by the plain renderer's own [`SurfelSplat::evaluate`] (its
//! [`SurfelSplat::hit`], which also keeps the intermediates); compositing sums are in `F`, so with
//! `F = f32` the images are those of [`crate::render::render`] in 2DGS mode.
//!
//! **Depth distortion** (2DGS's `render_dist`): per pixel `Σ_{i<j} w_i w_j (m_i − m_j)²` over
//! the contributing surfels, with `m = f/(f − n) (1 − n/z)` the intersection depth `z` mapped to
//! `[0, 1)` by hbb1's constants `n = 0.2`, `f = 100` ([`DIST_NEAR`], [`DIST_FAR`]). With
//! `A = Σ w`, `M1 = Σ w m`, `M2 = Σ w m²` (summed in `f64` whatever `F`: the value is a small
//! difference of terms near 1) it equals `A M2 − M1²`; with `μ = M1 / A` and
//! `S = M2 − M1² / A` its derivatives are `d/dw_k = A (m_k − μ)² + S` and
//! `d/dm_k = 2 A w_k (m_k − μ)`, written so that nothing cancels.

use glam::{DVec2, DVec3};

use super::params::{DiffParams, Real};
use super::surfel_project::{self, SURFEL_SLOT};
use super::tile::{BackwardTile, ForwardBand, GradKernel, ImageGrads, Kept, PixelRules};
use super::tile::{TILE_PIXELS, TileGeom, unblend};
use crate::render::composite::CompositeRules;
use crate::render::options::{Outputs, RenderOptions};
use crate::render::screen::{ScreenEntry, ScreenSplats, gather_visible};
use crate::render::surfel::{FILTER_INV_SQUARE, SurfelHit, SurfelSplat, View};
use crate::render::tiles::{TILE_SIZE, TileRect, tile_range};

/// hbb1's near plane of the distortion's depth mapping (`near_n`).
pub const DIST_NEAR: f64 = 0.2;
/// hbb1's far plane of the distortion's depth mapping (`far_n`).
pub const DIST_FAR: f64 = 100.0;

/// The distortion's mapped depth `m(z)` and `dm/dz`.
#[inline(always)]
fn mapped_depth(z: f64) -> (f64, f64) {
    let scale = DIST_FAR / (DIST_FAR - DIST_NEAR);
    (scale * (1.0 - DIST_NEAR / z), scale * DIST_NEAR / (z * z))
}

/// One visible surfel in the loops: the plain renderer's per-pixel data, its colour and normal
/// in `F`, its screen box as binned.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GradSurfel<F> {
    splat: SurfelSplat,
    color: [F; 3],
    normal: [F; 3],
    center: [f32; 2],
    radius: [f32; 2],
    /// Pixel coordinates `[x0, x1, y0, y1]` outside of which the surfel's alpha is below the
    /// skip threshold ([`SurfelSplat::contributing_box`]).
    bounds: [f64; 4],
}

/// The local pixel rectangle `(lx0, lx1, ly0, ly1)` of tile `g` inside `bounds` (pixel
/// coordinates `g.x0 + lx + offset`).
fn local_range(bounds: &[f64; 4], g: &TileGeom, offset: f64) -> (usize, usize, usize, usize) {
    let first = |lo: f64, start: u32, n: usize| {
        let v = (lo - offset - f64::from(start)).ceil();
        if v <= 0.0 { 0 } else { (v as usize).min(n) }
    };
    let end = |hi: f64, start: u32, n: usize| {
        let v = (hi - offset - f64::from(start)).floor() + 1.0;
        if v <= 0.0 { 0 } else { (v as usize).min(n) }
    };
    (
        first(bounds[0], g.x0, g.tw),
        end(bounds[1], g.x0, g.tw),
        first(bounds[2], g.y0, g.th),
        end(bounds[3], g.y0, g.th),
    )
}

/// Adds the gradient of one pixel's `rho` (`g_rho`) and intersection depth (`g_z`) with
/// respect to the rows (`sum[0..9]`) and the filter centre (`sum[9..11]`).
#[inline(always)]
fn kernel_vjp(
    sp: &SurfelSplat,
    h: &SurfelHit,
    (x, y): (f64, f64),
    (g_rho, g_z): (f64, f64),
    sum: &mut [f64; SURFEL_SLOT],
) {
    let tw = sp.rows[2];
    if h.on_disc {
        // rho = |s|², z = s.x Tw.x + s.y Tw.y + Tw.z, s = p.xy / p.z, p = k × l.
        let g_s = 2.0 * g_rho * h.s + g_z * DVec2::new(tw.x, tw.y);
        let inv = 1.0 / h.p.z;
        let g_p = DVec3::new(g_s.x * inv, g_s.y * inv, -g_s.dot(h.s) * inv);
        let g_k = h.l.cross(g_p);
        let g_l = g_p.cross(h.k);
        let g_tw = x * g_k + y * g_l + g_z * DVec3::new(h.s.x, h.s.y, 1.0);
        for c in 0..3 {
            sum[c] -= g_k[c];
            sum[3 + c] -= g_l[c];
            sum[6 + c] += g_tw[c];
        }
    } else {
        // rho = 2 |centre − pixel|², z = Tw.z.
        let d = sp.center - DVec2::new(x, y);
        let g = 2.0 * FILTER_INV_SQUARE * g_rho;
        sum[9] += g * d.x;
        sum[10] += g * d.y;
        sum[8] += g_z;
    }
}

/// Projects every Gaussian of `params` as a surfel (culled ones and those off the tile grid
/// dropped): the surfels in Gaussian order and their screen entries.
pub(super) fn gather<F: Real, P: DiffParams + ?Sized>(
    params: &P,
    view: &View,
    options: &RenderOptions,
    rules: &CompositeRules,
    (width, height): (u32, u32),
) -> (ScreenSplats, Vec<GradSurfel<F>>) {
    let tiles = (width.div_ceil(TILE_SIZE), height.div_ceil(TILE_SIZE));
    gather_visible(params.len(), Outputs::NONE, |i| {
        let s = surfel_project::project(params, i, view, options.normal_frame)?;
        let center = [s.splat.center.x as f32, s.splat.center.y as f32];
        let radius = [s.radius as f32; 2];
        let (x0, x1, y0, y1) = tile_range(rules.tile_rect, center, radius, tiles.0, tiles.1);
        if x0 >= x1 || y0 >= y1 {
            return None;
        }
        let entry = ScreenEntry::unshaded(i, center, radius, s.depth);
        let surfel = GradSurfel {
            splat: s.splat,
            color: s.color.map(F::of),
            normal: s.normal.to_array().map(F::of),
            center,
            radius,
            bounds: s.splat.contributing_box(),
        };
        Some((entry, surfel))
    })
}

/// The 2DGS kernel of the tile loops (hbb1's rules: every pixel of the tile is a candidate, no
/// box clip; the contributing box bounds the pixels instead).
pub(super) struct SurfelGrad<F> {
    rules: CompositeRules,
    r: PixelRules<F>,
}

impl<F: Real> SurfelGrad<F> {
    pub(super) fn new(rules: CompositeRules) -> Self {
        debug_assert!(!rules.clip_to_box && rules.tile_rect == TileRect::Original3dgs);
        Self {
            rules,
            r: PixelRules::new(&rules),
        }
    }
}

/// Per-pixel accumulators of the 2DGS forward beyond colour and depth.
pub(super) struct ForwardExtra<F> {
    normal: [[F; TILE_PIXELS]; 3],
    /// `Σ w`, `Σ w m`, `Σ w m²` (the distortion's moments).
    moments: [[f64; 3]; TILE_PIXELS],
}

/// Per-pixel state of the 2DGS backward beyond the shared one.
pub(super) struct BackwardExtra<F> {
    g_normal: [[F; TILE_PIXELS]; 3],
    /// `λ A`, `μ`, `λ S` of the distortion (module documentation), `λ` its weight.
    dist: [[f64; 3]; TILE_PIXELS],
}

impl<F: Real> GradKernel<F, SURFEL_SLOT> for SurfelGrad<F> {
    type Item = GradSurfel<F>;
    /// Pixel coordinates `(x, y)`.
    type Pixel = (f64, f64);
    type Hit = SurfelHit;
    type ForwardExtra = ForwardExtra<F>;
    type BackwardExtra = BackwardExtra<F>;

    fn rules(&self) -> &CompositeRules {
        &self.rules
    }

    fn forward_extra(&self) -> ForwardExtra<F> {
        ForwardExtra {
            normal: [[F::ZERO; TILE_PIXELS]; 3],
            moments: [[0.0; 3]; TILE_PIXELS],
        }
    }

    fn backward_extra(&self) -> BackwardExtra<F> {
        BackwardExtra {
            g_normal: [[F::ZERO; TILE_PIXELS]; 3],
            dist: [[0.0; 3]; TILE_PIXELS],
        }
    }

    fn place(item: &GradSurfel<F>) -> ([f32; 2], [f32; 2]) {
        (item.center, item.radius)
    }

    #[inline(always)]
    fn for_each_pixel(
        &self,
        sp: &GradSurfel<F>,
        g: &TileGeom,
        mut f: impl FnMut(usize, (f64, f64)),
    ) {
        let ts = TILE_SIZE as usize;
        let offset = f64::from(self.r.offset);
        let (lx0, lx1, ly0, ly1) = local_range(&sp.bounds, g, offset);
        for ly in ly0..ly1 {
            let y = f64::from(g.y0 + ly as u32) + offset;
            for lx in lx0..lx1 {
                let x = f64::from(g.x0 + lx as u32) + offset;
                f(ly * ts + lx, (x, y));
            }
        }
    }

    #[inline(always)]
    fn eval(&self, sp: &GradSurfel<F>, (x, y): (f64, f64)) -> Option<(F, SurfelHit)> {
        sp.splat.hit(x, y).map(|h| (F::of(h.alpha), h))
    }

    #[inline(always)]
    fn color(item: &GradSurfel<F>) -> &[F; 3] {
        &item.color
    }

    #[inline(always)]
    fn depth(_: &GradSurfel<F>, h: &SurfelHit) -> F {
        F::of(h.depth)
    }

    fn forward_reset(e: &mut ForwardExtra<F>) {
        for c in &mut e.normal {
            c.fill(F::ZERO);
        }
        e.moments.fill([0.0; 3]);
    }

    #[inline(always)]
    fn forward_add(sp: &GradSurfel<F>, h: &SurfelHit, w: F, p: usize, e: &mut ForwardExtra<F>) {
        for c in 0..3 {
            e.normal[c][p] += w * sp.normal[c];
        }
        let m = mapped_depth(h.depth).0;
        let w64 = w.wide();
        let [a, m1, m2] = &mut e.moments[p];
        *a += w64;
        *m1 += w64 * m;
        *m2 += w64 * m * m;
    }

    #[inline(always)]
    fn forward_write(e: &ForwardExtra<F>, p: usize, q: usize, band: &mut ForwardBand<'_, F>) {
        for c in 0..3 {
            band.normal[3 * q + c] = e.normal[c][p];
        }
        let [a, m1, m2] = e.moments[p];
        band.distortion[q] = F::of(a * m2 - m1 * m1);
        band.moments[q] = e.moments[p];
    }

    #[inline(always)]
    fn backward_init(
        e: &mut BackwardExtra<F>,
        p: usize,
        q: usize,
        kept: &Kept<'_, F>,
        grads: &ImageGrads<'_, F>,
    ) {
        for c in 0..3 {
            e.g_normal[c][p] = grads.normal.map_or(F::ZERO, |v| v[3 * q + c]);
        }
        let lambda = grads.distortion.wide();
        let [a, m1, m2] = kept.moments[q];
        e.dist[p] = if a > 0.0 {
            [lambda * a, m1 / a, lambda * (m2 - m1 * m1 / a)]
        } else {
            [0.0; 3]
        };
    }

    /// The per-pixel recursion is the 3DGS path's, with
    /// `q_k = g_rgb · c_k + g_D z_k + g_N · n_k + λ (A m_k² − 2 M1 m_k)`.
    #[inline(always)]
    fn backward_item(
        &self,
        sp: &GradSurfel<F>,
        s: &mut BackwardTile<F, BackwardExtra<F>>,
        g: &TileGeom,
        k: u32,
    ) -> [f64; SURFEL_SLOT] {
        let r = &self.r;
        let mut sum = [0.0f64; SURFEL_SLOT];
        self.for_each_pixel(sp, g, |p, (x, y)| {
            if k >= s.last[p] {
                return;
            }
            let Some((raw, h)) = self.eval(sp, (x, y)) else {
                return;
            };
            let alpha = raw.min(r.max_alpha);
            if alpha < r.min_alpha {
                return;
            }
            let z = F::of(h.depth);
            let (m, dm_dz) = mapped_depth(h.depth);
            let [dist_a, mean_m, dist_s] = s.extra.dist[p];
            let dm = m - mean_m;
            let mut qk = s.g_depth[p] * z + F::of(dist_a * dm * dm + dist_s);
            for c in 0..3 {
                qk += s.g_rgb[c][p] * sp.color[c] + s.extra.g_normal[c][p] * sp.normal[c];
            }
            let (wgt, g_alpha) = unblend(s, p, alpha, qk);
            for c in 0..3 {
                sum[12 + c] += (s.g_rgb[c][p] * wgt).wide();
                sum[15 + c] += (s.extra.g_normal[c][p] * wgt).wide();
            }
            let w64 = wgt.wide();
            let g_z = (s.g_depth[p] * wgt).wide() + 2.0 * w64 * dist_a * dm * dm_dz;
            let mut g_rho = 0.0;
            if raw <= r.max_alpha {
                let ga = g_alpha.wide();
                sum[11] += h.falloff * ga;
                g_rho = -0.5 * h.alpha * ga;
            }
            if g_rho != 0.0 || g_z != 0.0 {
                kernel_vjp(&sp.splat, &h, (x, y), (g_rho, g_z), &mut sum);
            }
        });
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::Camera;

    /// Every pixel whose alpha passes the skip threshold lies in
    /// [`SurfelSplat::contributing_box`]: random
    /// surfels (tilted up to edge-on, large and tiny, near and far) seen by one camera.
    #[test]
    fn the_contributing_box_holds_every_contributing_pixel() {
        use trisplat_geometry::rng::Rng;
        let camera = Camera::look_at(
            "box",
            DVec3::new(0.2, -0.1, -2.5),
            DVec3::ZERO,
            DVec3::NEG_Y,
            (64, 48),
            60.0,
        )
        .unwrap();
        let mut rng = Rng::new(4);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform_f64();
        let (mut checked, mut bounded) = (0, 0);
        for _ in 0..300 {
            let q = glam::DQuat::from_xyzw(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0))
                .normalize();
            let mean = DVec3::new(u(-1.0, 1.0), u(-1.0, 1.0), u(-2.2, 1.5));
            let scale = glam::DVec2::new(u(-6.0, 0.0).exp(), u(-6.0, 0.0).exp());
            let Some(p) = crate::render::surfel::project_surfel(
                &camera,
                (mean, glam::DMat3::from_quat(q), scale, u(0.004, 1.0)),
                (0.2, 1e10),
            ) else {
                continue;
            };
            let b = p.splat.contributing_box();
            bounded += usize::from(b[0].is_finite());
            let threshold = f64::from(crate::render::composite::ALPHA_THRESHOLD);
            for y in -40..90 {
                for x in -40..110 {
                    let (x, y) = (f64::from(x), f64::from(y));
                    if let Some(h) = p.splat.hit(x, y)
                        && h.alpha.min(0.99) >= threshold * (1.0 - 1e-6)
                    {
                        checked += 1;
                        assert!(
                            x >= b[0] && x <= b[1] && y >= b[2] && y <= b[3],
                            "pixel ({x}, {y}) alpha {} outside {b:?}",
                            h.alpha
                        );
                    }
                }
            }
        }
        assert!(
            checked > 1000 && bounded > 100,
            "{checked} pixels, {bounded} boxes"
        );
    }

    #[test]
    fn hit_repeats_the_renderers_evaluation() {
        let sp = SurfelSplat {
            rows: [
                DVec3::new(30.0, -4.0, 100.0),
                DVec3::new(3.0, 25.0, 80.0),
                DVec3::new(0.2, 0.1, 3.0),
            ],
            center: DVec2::new(33.0, 27.0),
            opacity: 0.8,
            near: 0.2,
        };
        for y in 15..40 {
            for x in 20..45 {
                let (x, y) = (f64::from(x), f64::from(y));
                let a = sp.evaluate(x, y);
                let b = sp.hit(x, y);
                assert_eq!(a.is_some(), b.is_some());
                if let (Some(a), Some(b)) = (a, b) {
                    assert_eq!(a.alpha.to_bits(), b.alpha.to_bits());
                    assert_eq!(a.depth.to_bits(), b.depth.to_bits());
                }
            }
        }
    }
}
