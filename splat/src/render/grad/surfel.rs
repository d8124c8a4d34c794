//! The 2DGS surfel mode of the differentiable renderer (docs/conventions.md §5 "Gradients"):
//! the forward keeps, besides the 3DGS path's per-pixel state, the rendered normal image and the
//! moments of the depth-distortion loss; the backward walks each tile's list back to front like
//! the 3DGS path (same transmittance recovery, same (tile, splat) slots), with the surfel kernel's
//! own per-pixel vector-Jacobian product ([`kernel_vjp`]) and [`super::surfel_project`] after
//! the reduction.
//!
//! The kernel is evaluated in `f64` (as the plain renderer's [`SurfelSplat::evaluate`], whose
//! arithmetic [`hit`] repeats operation for operation); compositing sums are in `F`, so with
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
use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::params::{DiffParams, GaussianGrads, Real};
use super::slots::SlotBuffer;
use super::surfel_project::{self, SURFEL_SLOT, SurfelScreenGrad};
use super::{
    BackwardStats, DEPTH_ALPHA_FLOOR, GradRender, ImageGrads, PixelRules, Splat, TILE_PIXELS,
    TileGeom, accumulate,
};
use crate::gaussians::sh_coeffs_per_channel;
use crate::render::composite::{CompositeRules, RenderStats};
use crate::render::options::{Outputs, RenderOptions};
use crate::render::screen::{ScreenEntry, gather_visible};
use crate::render::surfel::{FILTER_INV_SQUARE, SURFEL_RULES, SurfelSplat, View};
use crate::render::tiles::{TILE_SIZE, TileBins, TileRect, tile_range};

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

/// A surfel met by a pixel's ray: [`SurfelSplat::evaluate`]'s values and the intermediates its
/// vector-Jacobian product needs.
struct Hit {
    /// `k = x Tw − Tu`, `l = y Tw − Tv`, `p = k × l`.
    k: DVec3,
    l: DVec3,
    p: DVec3,
    /// Surfel coordinates of the intersection.
    s: DVec2,
    /// Whether the ray-splat term won (`rho3d ≤ rho2d`).
    on_disc: bool,
    /// `exp(−rho / 2)`.
    falloff: f64,
    /// `opacity × falloff`, unclamped.
    alpha: f64,
    depth: f64,
}

/// [`SurfelSplat::evaluate`] with its intermediates (same operations, so the same values).
#[inline(always)]
fn hit(sp: &SurfelSplat, x: f64, y: f64) -> Option<Hit> {
    let [tu, tv, tw] = sp.rows;
    let k = x * tw - tu;
    let l = y * tw - tv;
    let p = k.cross(l);
    if p.z == 0.0 {
        return None;
    }
    let s = DVec2::new(p.x / p.z, p.y / p.z);
    let rho3d = s.length_squared();
    let rho2d = FILTER_INV_SQUARE * (sp.center - DVec2::new(x, y)).length_squared();
    let on_disc = rho3d <= rho2d;
    let (rho, depth) = if on_disc {
        (rho3d, s.x * tw.x + s.y * tw.y + tw.z)
    } else {
        (rho2d, tw.z)
    };
    if depth.is_nan() || depth < sp.near || !rho.is_finite() {
        return None;
    }
    let falloff = (-0.5 * rho).exp();
    Some(Hit {
        k,
        l,
        p,
        s,
        on_disc,
        falloff,
        alpha: sp.opacity * falloff,
        depth,
    })
}

/// Adds the gradient of one pixel's `rho` (`g_rho`) and intersection depth (`g_z`) with
/// respect to the rows (`sum[0..9]`) and the filter centre (`sum[9..11]`).
#[inline(always)]
fn kernel_vjp(
    sp: &SurfelSplat,
    h: &Hit,
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

/// Renders in 2DGS mode (rules checked by the caller) and keeps what the backward pass needs.
pub(crate) fn render_with_grad<F: Real, P: DiffParams + ?Sized>(
    params: &P,
    camera: &Camera,
    options: &RenderOptions,
) -> GradRender<F> {
    let rules = SURFEL_RULES;
    let start = std::time::Instant::now();
    let view = View::new(camera, f64::from(options.near), f64::from(options.far));
    let tiles = (
        camera.width.div_ceil(TILE_SIZE),
        camera.height.div_ceil(TILE_SIZE),
    );
    let (screen, surfels) = gather_visible(params.len(), Outputs::NONE, |i| {
        let s = surfel_project::project(params, i, &view, options.normal_frame)?;
        let center = [s.splat.center.x as f32, s.splat.center.y as f32];
        let radius = [s.radius as f32; 2];
        let (x0, x1, y0, y1) = tile_range(rules.tile_rect, center, radius, tiles.0, tiles.1);
        if x0 >= x1 || y0 >= y1 {
            return None;
        }
        let entry = ScreenEntry {
            id: i as u32,
            center,
            radius,
            depth: s.depth as f32,
            color: [0.0; 3],
            normal: [0.0; 3],
        };
        let surfel = GradSurfel {
            splat: s.splat,
            color: s.color.map(F::of),
            normal: s.normal.to_array().map(F::of),
            center,
            radius,
            bounds: s.splat.contributing_box(),
        };
        Some((entry, surfel))
    });
    let mut stats = RenderStats {
        project_s: start.elapsed().as_secs_f64(),
        ..RenderStats::default()
    };
    let (surfels, ids, bins) = super::order_and_bin(
        &screen,
        &surfels,
        |s| (s.center, s.radius),
        camera,
        rules.tile_rect,
        &mut stats,
    );
    let (width, height) = (camera.width, camera.height);

    let start = std::time::Instant::now();
    let pixels = width as usize * height as usize;
    let mut out = GradRender {
        width,
        height,
        rgb: vec![F::ZERO; 3 * pixels],
        alpha: vec![F::ZERO; pixels],
        depth: vec![F::ZERO; pixels],
        normal: vec![F::ZERO; 3 * pixels],
        distortion: vec![F::ZERO; pixels],
        stats,
        mode: options.mode,
        n_gaussians: params.len(),
        ids,
        splats: Vec::<Splat<F>>::new(),
        surfels,
        bins,
        final_t: vec![F::ONE; pixels],
        depth_sum: vec![F::ZERO; pixels],
        moments: vec![[0.0; 3]; pixels],
        last: vec![0; pixels],
        rules,
        background: options.background.map(|v| F::of(f64::from(v))),
    };
    let band = TILE_SIZE as usize * width as usize;
    let ctx = Ctx {
        surfels: &out.surfels,
        bins: &out.bins,
        rules: &out.rules,
        background: out.background,
        width,
        height,
    };
    out.rgb
        .par_chunks_mut(3 * band)
        .zip(out.alpha.par_chunks_mut(band))
        .zip(out.depth.par_chunks_mut(band))
        .zip(out.normal.par_chunks_mut(3 * band))
        .zip(out.distortion.par_chunks_mut(band))
        .zip(out.final_t.par_chunks_mut(band))
        .zip(out.depth_sum.par_chunks_mut(band))
        .zip(out.moments.par_chunks_mut(band))
        .zip(out.last.par_chunks_mut(band))
        .enumerate()
        .for_each(
            |(
                ty,
                (
                    (
                        ((((((rgb, alpha), depth), normal), distortion), final_t), depth_sum),
                        moments,
                    ),
                    last,
                ),
            )| {
                let mut s = ForwardTile::<F>::default();
                let mut band = ForwardBand {
                    rgb,
                    alpha,
                    depth,
                    normal,
                    distortion,
                    final_t,
                    depth_sum,
                    moments,
                    last,
                };
                for tx in 0..ctx.bins.tiles_x {
                    ctx.forward_tile(tx, ty as u32, &mut band, &mut s);
                }
            },
        );
    out.stats.composite_s = start.elapsed().as_secs_f64();
    out
}

/// The backward pass in 2DGS mode (inputs checked by the caller).
pub(crate) fn backward_into<F: Real, P: DiffParams + ?Sized>(
    params: &P,
    camera: &Camera,
    options: &RenderOptions,
    forward: &GradRender<F>,
    grads: &ImageGrads<'_, F>,
    out: &mut GaussianGrads,
) -> BackwardStats {
    let mut stats = BackwardStats::default();
    let start = std::time::Instant::now();
    let bins = &forward.bins;
    let slots = SlotBuffer::<SURFEL_SLOT>::new(
        forward.surfels.par_iter().map(|s| (s.center, s.radius)),
        forward.rules.tile_rect,
        bins,
    );
    let ctx = Ctx {
        surfels: &forward.surfels,
        bins,
        rules: &forward.rules,
        background: forward.background,
        width: forward.width,
        height: forward.height,
    };
    (0..bins.tiles_y).into_par_iter().for_each(|ty| {
        let mut s = BackwardTile::<F>::default();
        for tx in 0..bins.tiles_x {
            ctx.backward_tile(forward, grads, (tx, ty), &slots, &mut s);
        }
    });
    stats.composite_s = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    let sums = slots.reduce();
    let mut by_id: Vec<Option<SurfelScreenGrad>> = vec![None; params.len()];
    for (&id, sum) in forward.ids.iter().zip(&sums) {
        by_id[id as usize] = Some(SurfelScreenGrad::from_slot(sum));
    }
    drop(sums);
    stats.reduce_s = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    let view = View::new(camera, f64::from(options.near), f64::from(options.far));
    let k = 3 * sh_coeffs_per_channel(params.sh_degree());
    accumulate(out, k, |i| {
        let g = by_id[i].as_ref()?;
        surfel_project::project_vjp(params, i, &view, options.normal_frame, g)
    });
    stats.project_s = start.elapsed().as_secs_f64();
    stats
}

/// What both tile loops read.
struct Ctx<'a, F> {
    surfels: &'a [GradSurfel<F>],
    bins: &'a TileBins,
    rules: &'a CompositeRules,
    background: [F; 3],
    width: u32,
    height: u32,
}

/// One tile row's slices of the forward outputs.
struct ForwardBand<'a, F> {
    rgb: &'a mut [F],
    alpha: &'a mut [F],
    depth: &'a mut [F],
    normal: &'a mut [F],
    distortion: &'a mut [F],
    final_t: &'a mut [F],
    depth_sum: &'a mut [F],
    moments: &'a mut [[f64; 3]],
    last: &'a mut [u32],
}

/// Per-pixel accumulators of one tile in the forward pass (reused across tiles).
struct ForwardTile<F> {
    t: [F; TILE_PIXELS],
    rgb: [[F; TILE_PIXELS]; 3],
    normal: [[F; TILE_PIXELS]; 3],
    depth: [F; TILE_PIXELS],
    /// `Σ w`, `Σ w m`, `Σ w m²` (the distortion's moments).
    moments: [[f64; 3]; TILE_PIXELS],
    last: [u32; TILE_PIXELS],
    alive: [bool; TILE_PIXELS],
}

impl<F: Real> Default for ForwardTile<F> {
    fn default() -> Self {
        Self {
            t: [F::ONE; TILE_PIXELS],
            rgb: [[F::ZERO; TILE_PIXELS]; 3],
            normal: [[F::ZERO; TILE_PIXELS]; 3],
            depth: [F::ZERO; TILE_PIXELS],
            moments: [[0.0; 3]; TILE_PIXELS],
            last: [0; TILE_PIXELS],
            alive: [true; TILE_PIXELS],
        }
    }
}

/// Per-pixel state of one tile in the backward pass (reused across tiles).
struct BackwardTile<F> {
    /// Transmittance before the surfel being processed (starts at the final one).
    t: [F; TILE_PIXELS],
    /// `Σ_{j behind} w_j q_j + (d loss / d T_final) T_final`.
    behind: [F; TILE_PIXELS],
    g_rgb: [[F; TILE_PIXELS]; 3],
    g_normal: [[F; TILE_PIXELS]; 3],
    /// d loss / d (Σ w z).
    g_depth: [F; TILE_PIXELS],
    /// `λ A`, `μ`, `λ S` of the distortion (module documentation), `λ` its weight.
    dist: [[f64; 3]; TILE_PIXELS],
    last: [u32; TILE_PIXELS],
}

impl<F: Real> Default for BackwardTile<F> {
    fn default() -> Self {
        Self {
            t: [F::ONE; TILE_PIXELS],
            behind: [F::ZERO; TILE_PIXELS],
            g_rgb: [[F::ZERO; TILE_PIXELS]; 3],
            g_normal: [[F::ZERO; TILE_PIXELS]; 3],
            g_depth: [F::ZERO; TILE_PIXELS],
            dist: [[0.0; 3]; TILE_PIXELS],
            last: [0; TILE_PIXELS],
        }
    }
}

impl<F: Real> Ctx<'_, F> {
    fn geom(&self, tx: u32, ty: u32) -> TileGeom {
        TileGeom::new(tx, ty, self.width, self.height)
    }

    /// Front to back over the tile's list, every pixel of the tile (hbb1's rule; no box clip).
    fn forward_tile(
        &self,
        tx: u32,
        ty: u32,
        band: &mut ForwardBand<'_, F>,
        s: &mut ForwardTile<F>,
    ) {
        debug_assert!(!self.rules.clip_to_box && self.rules.tile_rect == TileRect::Original3dgs);
        let ts = TILE_SIZE as usize;
        let g = self.geom(tx, ty);
        let r = PixelRules::<F>::new(self.rules);
        let offset = f64::from(r.offset);
        s.t.fill(F::ONE);
        for c in 0..3 {
            s.rgb[c].fill(F::ZERO);
            s.normal[c].fill(F::ZERO);
        }
        s.depth.fill(F::ZERO);
        s.moments.fill([0.0; 3]);
        s.last.fill(0);
        for (p, alive) in s.alive.iter_mut().enumerate() {
            *alive = p % ts < g.tw && p / ts < g.th;
        }
        let mut remaining = g.tw * g.th;
        for (k, &entry) in self.bins.tile(tx, ty).iter().enumerate() {
            if remaining == 0 {
                break;
            }
            let sp = &self.surfels[entry as usize];
            let (lx0, lx1, ly0, ly1) = local_range(&sp.bounds, &g, offset);
            for ly in ly0..ly1 {
                let y = f64::from(g.y0 + ly as u32) + offset;
                for lx in lx0..lx1 {
                    let p = ly * ts + lx;
                    if !s.alive[p] {
                        continue;
                    }
                    let x = f64::from(g.x0 + lx as u32) + offset;
                    let Some(h) = hit(&sp.splat, x, y) else {
                        continue;
                    };
                    let alpha = F::of(h.alpha).min(r.max_alpha);
                    if alpha < r.min_alpha {
                        continue;
                    }
                    let t = s.t[p];
                    let next = t * (F::ONE - alpha);
                    if next < r.stop_below {
                        s.alive[p] = false;
                        remaining -= 1;
                        continue;
                    }
                    let w = alpha * t;
                    for c in 0..3 {
                        s.rgb[c][p] += w * sp.color[c];
                        s.normal[c][p] += w * sp.normal[c];
                    }
                    s.depth[p] += w * F::of(h.depth);
                    let m = mapped_depth(h.depth).0;
                    let w64 = w.wide();
                    let [a, m1, m2] = &mut s.moments[p];
                    *a += w64;
                    *m1 += w64 * m;
                    *m2 += w64 * m * m;
                    s.t[p] = next;
                    s.last[p] = k as u32 + 1;
                }
            }
        }
        let w = self.width as usize;
        for ly in 0..g.th {
            for lx in 0..g.tw {
                let p = ly * ts + lx;
                let q = ly * w + g.x0 as usize + lx;
                let t = s.t[p];
                let acc = F::ONE - t;
                for c in 0..3 {
                    band.rgb[3 * q + c] = s.rgb[c][p] + t * self.background[c];
                    band.normal[3 * q + c] = s.normal[c][p];
                }
                band.alpha[q] = acc;
                band.depth[q] = if acc > F::ZERO {
                    s.depth[p] / acc.max(F::of(DEPTH_ALPHA_FLOOR))
                } else {
                    F::ZERO
                };
                let [a, m1, m2] = s.moments[p];
                band.distortion[q] = F::of(a * m2 - m1 * m1);
                band.final_t[q] = t;
                band.depth_sum[q] = s.depth[p];
                band.moments[q] = s.moments[p];
                band.last[q] = s.last[p];
            }
        }
    }

    /// Back to front over the tile's list (module documentation; the per-pixel recursion is the
    /// 3DGS path's, with `q_k = g_rgb · c_k + g_D z_k + g_N · n_k + λ (A m_k² − 2 M1 m_k)`).
    fn backward_tile(
        &self,
        fwd: &GradRender<F>,
        grads: &ImageGrads<'_, F>,
        (tx, ty): (u32, u32),
        slots: &SlotBuffer<SURFEL_SLOT>,
        s: &mut BackwardTile<F>,
    ) {
        let ts = TILE_SIZE as usize;
        let g = self.geom(tx, ty);
        let r = PixelRules::<F>::new(self.rules);
        let offset = f64::from(r.offset);
        let w = self.width as usize;
        let floor = F::of(DEPTH_ALPHA_FLOOR);
        let lambda = grads.distortion.wide();
        let mut max_last = 0;
        s.last.fill(0);
        for ly in 0..g.th {
            for lx in 0..g.tw {
                let p = ly * ts + lx;
                let q = (g.y0 as usize + ly) * w + g.x0 as usize + lx;
                let t_final = fwd.final_t[q];
                let acc = F::ONE - t_final;
                let mut g_t = F::ZERO;
                for c in 0..3 {
                    let gc = grads.rgb.map_or(F::ZERO, |v| v[3 * q + c]);
                    s.g_rgb[c][p] = gc;
                    g_t += gc * self.background[c];
                    s.g_normal[c][p] = grads.normal.map_or(F::ZERO, |v| v[3 * q + c]);
                }
                if let Some(ga) = grads.alpha {
                    g_t += -ga[q];
                }
                let gd = grads.depth.map_or(F::ZERO, |v| v[q]);
                s.g_depth[p] = if acc > F::ZERO {
                    gd / acc.max(floor)
                } else {
                    F::ZERO
                };
                if acc > floor {
                    g_t += gd * fwd.depth_sum[q] / (acc * acc);
                }
                let [a, m1, m2] = fwd.moments[q];
                s.dist[p] = if a > 0.0 {
                    [lambda * a, m1 / a, lambda * (m2 - m1 * m1 / a)]
                } else {
                    [0.0; 3]
                };
                s.t[p] = t_final;
                s.behind[p] = g_t * t_final;
                s.last[p] = fwd.last[q];
                max_last = max_last.max(fwd.last[q]);
            }
        }
        let entries = self.bins.tile(tx, ty);
        for k in (0..max_last as usize).rev() {
            let j = entries[k] as usize;
            let sp = &self.surfels[j];
            let mut sum = [0.0f64; SURFEL_SLOT];
            let (lx0, lx1, ly0, ly1) = local_range(&sp.bounds, &g, offset);
            for ly in ly0..ly1 {
                let y = f64::from(g.y0 + ly as u32) + offset;
                for lx in lx0..lx1 {
                    let p = ly * ts + lx;
                    if k as u32 >= s.last[p] {
                        continue;
                    }
                    let x = f64::from(g.x0 + lx as u32) + offset;
                    let Some(h) = hit(&sp.splat, x, y) else {
                        continue;
                    };
                    let raw = F::of(h.alpha);
                    let alpha = raw.min(r.max_alpha);
                    if alpha < r.min_alpha {
                        continue;
                    }
                    let ra = F::ONE / (F::ONE - alpha);
                    let t = s.t[p] * ra;
                    let wgt = alpha * t;
                    let z = F::of(h.depth);
                    let (m, dm_dz) = mapped_depth(h.depth);
                    let [dist_a, mean_m, dist_s] = s.dist[p];
                    let dm = m - mean_m;
                    let mut qk = s.g_depth[p] * z + F::of(dist_a * dm * dm + dist_s);
                    for c in 0..3 {
                        qk += s.g_rgb[c][p] * sp.color[c] + s.g_normal[c][p] * sp.normal[c];
                    }
                    let g_alpha = t * qk - ra * s.behind[p];
                    s.behind[p] += wgt * qk;
                    s.t[p] = t;
                    for c in 0..3 {
                        sum[12 + c] += (s.g_rgb[c][p] * wgt).wide();
                        sum[15 + c] += (s.g_normal[c][p] * wgt).wide();
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
                }
            }
            slots.store(j, (tx, ty), sum);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
                    if let Some(h) = hit(&p.splat, x, y)
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
                let b = hit(&sp, x, y);
                assert_eq!(a.is_some(), b.is_some());
                if let (Some(a), Some(b)) = (a, b) {
                    assert_eq!(a.alpha.to_bits(), b.alpha.to_bits());
                    assert_eq!(a.depth.to_bits(), b.depth.to_bits());
                }
            }
        }
    }
}
