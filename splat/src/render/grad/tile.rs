//! The per-tile loops of the differentiable renderer, shared by its 3DGS and 2DGS modes and
//! generic over a mode's [`GradKernel`] (monomorphised, so each mode's loops compile as if
//! written out): the forward front to back (keeping per pixel what the backward pass needs) and
//! the backward back to front from each pixel's last contributor (module documentation of
//! [`super::pass`]), with the per-pixel state they run on.

use super::params::Real;
use super::slots::SlotBuffer;
use crate::render::composite::CompositeRules;
use crate::render::tiles::{TILE_SIZE, TileBins};

/// Pixels per tile.
pub(super) const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;
/// gsplat's floor of the accumulated alpha in the expected depth `Σ w z / max(alpha, 1e-10)`.
pub(super) const DEPTH_ALPHA_FLOOR: f64 = 1e-10;

/// Gradients of a loss with respect to the images of a [`super::GradRender`] (each `None`
/// counts as zero), laid out like the images, and the weight of the 2DGS depth-distortion loss.
/// Write `ImageGrads { rgb: Some(..), ..ImageGrads::default() }`: more fields may come.
#[derive(Clone, Copy, Debug)]
pub struct ImageGrads<'a, F> {
    /// d loss / d rgb, `[H, W, 3]`.
    pub rgb: Option<&'a [F]>,
    /// d loss / d alpha, `[H, W]`.
    pub alpha: Option<&'a [F]>,
    /// d loss / d expected depth, `[H, W]`.
    pub depth: Option<&'a [F]>,
    /// 2DGS mode only: d loss / d normal image ([`super::GradRender::normal`]: same frame and
    /// sign), `[H, W, 3]`.
    pub normal: Option<&'a [F]>,
    /// 2DGS mode only: weight `λ` of the depth-distortion loss `λ Σ_pixels distortion`
    /// ([`super::GradRender::distortion`]); 0 = off.
    pub distortion: F,
}

impl<F: Default> Default for ImageGrads<'_, F> {
    fn default() -> Self {
        Self {
            rgb: None,
            alpha: None,
            depth: None,
            normal: None,
            distortion: F::default(),
        }
    }
}

/// A mode of the differentiable renderer as the tile loops see it: its visible splats, where
/// and how they are evaluated at pixels, what the forward accumulates beyond colour and depth,
/// and the per-splat gradient sums of the backward (`N` values per (tile, splat) slot).
pub(super) trait GradKernel<F: Real, const N: usize>: Sync {
    /// One visible splat in the loops' precision.
    type Item: Copy + Send + Sync;
    /// A pixel's position as [`Self::for_each_pixel`] gives it to [`Self::eval`].
    type Pixel: Copy;
    /// What an evaluation at a pixel yields besides the raw alpha.
    type Hit;
    /// Per-pixel accumulators of the forward beyond colour and depth.
    type ForwardExtra: Send;
    /// Per-pixel state of the backward beyond the shared one.
    type BackwardExtra: Send;

    /// The rules the kernel was made for.
    fn rules(&self) -> &CompositeRules;
    /// Fresh forward accumulators.
    fn forward_extra(&self) -> Self::ForwardExtra;
    /// Fresh backward state.
    fn backward_extra(&self) -> Self::BackwardExtra;
    /// The item's screen box (centre, half extents), as binned.
    fn place(item: &Self::Item) -> ([f32; 2], [f32; 2]);
    /// Calls `f(p, pixel)` for every pixel `p` (local index in the tile) that `item` may cover.
    fn for_each_pixel(&self, item: &Self::Item, g: &TileGeom, f: impl FnMut(usize, Self::Pixel));
    /// The raw (unclamped) alpha of `item` at `pixel`; `None` when it does not cover it.
    fn eval(&self, item: &Self::Item, pixel: Self::Pixel) -> Option<(F, Self::Hit)>;
    /// The item's colour.
    fn color(item: &Self::Item) -> &[F; 3];
    /// The depth the expected-depth image sums at this hit.
    fn depth(item: &Self::Item, hit: &Self::Hit) -> F;
    /// Clears the forward accumulators for a new tile.
    fn forward_reset(extra: &mut Self::ForwardExtra);
    /// Adds a blended hit of weight `w` at pixel `p` to the forward accumulators.
    fn forward_add(
        item: &Self::Item,
        hit: &Self::Hit,
        w: F,
        p: usize,
        extra: &mut Self::ForwardExtra,
    );
    /// Writes pixel `p`'s accumulators to image pixel `q`.
    fn forward_write(extra: &Self::ForwardExtra, p: usize, q: usize, band: &mut ForwardBand<'_, F>);
    /// Sets pixel `p`'s extra backward state from image pixel `q`.
    fn backward_init(
        extra: &mut Self::BackwardExtra,
        p: usize,
        q: usize,
        kept: &Kept<'_, F>,
        grads: &ImageGrads<'_, F>,
    );
    /// Walks `item` (tile-list position `k`) over its pixels of the tile back to front
    /// ([`unblend`]) and returns its slot of gradient sums.
    fn backward_item(
        &self,
        item: &Self::Item,
        s: &mut BackwardTile<F, Self::BackwardExtra>,
        g: &TileGeom,
        k: u32,
    ) -> [f64; N];
}

/// The tile's geometry: origin, size in pixels.
pub(super) struct TileGeom {
    pub(super) x0: u32,
    pub(super) y0: u32,
    pub(super) tw: usize,
    pub(super) th: usize,
}

impl TileGeom {
    /// Tile `(tx, ty)` of a `width` × `height` image.
    pub(super) fn new(tx: u32, ty: u32, width: u32, height: u32) -> Self {
        let x0 = tx * TILE_SIZE;
        let y0 = ty * TILE_SIZE;
        Self {
            x0,
            y0,
            tw: (width - x0).min(TILE_SIZE) as usize,
            th: (height - y0).min(TILE_SIZE) as usize,
        }
    }
}

/// The per-pixel rules in the loops' precision.
#[derive(Clone, Copy)]
pub(super) struct PixelRules<F> {
    pub(super) max_alpha: F,
    pub(super) min_alpha: F,
    /// Stop when `next_T < stop_below`.
    pub(super) stop_below: F,
    pub(super) offset: f32,
}

impl<F: Real> PixelRules<F> {
    pub(super) fn new(r: &CompositeRules) -> Self {
        let stop = F::of(f64::from(r.stop_transmittance));
        Self {
            max_alpha: F::of(f64::from(r.max_alpha)),
            min_alpha: F::of(f64::from(r.min_alpha)),
            stop_below: if r.stop_inclusive {
                stop.next_up()
            } else {
                stop
            },
            offset: r.pixel_offset,
        }
    }
}

/// What both tile loops read besides the kernel and its items.
pub(super) struct Frame<'a, F> {
    pub(super) bins: &'a TileBins,
    pub(super) background: [F; 3],
    pub(super) width: u32,
    pub(super) height: u32,
}

/// One tile row's slices of the forward outputs (the 2DGS-only ones empty in 3DGS mode).
pub(super) struct ForwardBand<'a, F> {
    pub(super) rgb: &'a mut [F],
    pub(super) alpha: &'a mut [F],
    pub(super) depth: &'a mut [F],
    pub(super) final_t: &'a mut [F],
    pub(super) depth_sum: &'a mut [F],
    pub(super) last: &'a mut [u32],
    pub(super) normal: &'a mut [F],
    pub(super) distortion: &'a mut [F],
    pub(super) moments: &'a mut [[f64; 3]],
}

/// What the forward pass kept per pixel for the backward one.
pub(super) struct Kept<'a, F> {
    pub(super) final_t: &'a [F],
    pub(super) depth_sum: &'a [F],
    pub(super) last: &'a [u32],
    /// 2DGS mode: the distortion's moments (empty in 3DGS mode).
    pub(super) moments: &'a [[f64; 3]],
}

/// Per-pixel accumulators of one tile in the forward pass (reused across tiles).
pub(super) struct ForwardTile<F, E> {
    t: [F; TILE_PIXELS],
    rgb: [[F; TILE_PIXELS]; 3],
    depth: [F; TILE_PIXELS],
    last: [u32; TILE_PIXELS],
    alive: [bool; TILE_PIXELS],
    extra: E,
}

impl<F: Real, E> ForwardTile<F, E> {
    pub(super) fn new(extra: E) -> Self {
        Self {
            t: [F::ONE; TILE_PIXELS],
            rgb: [[F::ZERO; TILE_PIXELS]; 3],
            depth: [F::ZERO; TILE_PIXELS],
            last: [0; TILE_PIXELS],
            alive: [true; TILE_PIXELS],
            extra,
        }
    }
}

/// Per-pixel state of one tile in the backward pass (reused across tiles).
pub(super) struct BackwardTile<F, E> {
    /// Transmittance before the splat being processed (starts at the final one).
    pub(super) t: [F; TILE_PIXELS],
    /// `Σ_{j behind} w_j q_j + (d loss / d T_final) T_final` (see [`backward_tile`]).
    pub(super) behind: [F; TILE_PIXELS],
    pub(super) g_rgb: [[F; TILE_PIXELS]; 3],
    /// d loss / d (Σ w z).
    pub(super) g_depth: [F; TILE_PIXELS],
    pub(super) last: [u32; TILE_PIXELS],
    /// The mode's own state.
    pub(super) extra: E,
}

impl<F: Real, E> BackwardTile<F, E> {
    pub(super) fn new(extra: E) -> Self {
        Self {
            t: [F::ONE; TILE_PIXELS],
            behind: [F::ZERO; TILE_PIXELS],
            g_rgb: [[F::ZERO; TILE_PIXELS]; 3],
            g_depth: [F::ZERO; TILE_PIXELS],
            last: [0; TILE_PIXELS],
            extra,
        }
    }
}

/// One step of the back-to-front recursion at pixel `p` for a splat of alpha `alpha` whose
/// `q_k` is `qk`: recovers the transmittance before it (`T_k = T_{k+1} / (1 − α_k)`), moves it
/// into `behind`; returns its weight `w = α T_k` and `d loss / d α_k = T_k q_k − behind /
/// (1 − α_k)`.
#[inline(always)]
pub(super) fn unblend<F: Real, E>(s: &mut BackwardTile<F, E>, p: usize, alpha: F, qk: F) -> (F, F) {
    let ra = F::ONE / (F::ONE - alpha);
    let t = s.t[p] * ra;
    let wgt = alpha * t;
    let g_alpha = t * qk - ra * s.behind[p];
    s.behind[p] += wgt * qk;
    s.t[p] = t;
    (wgt, g_alpha)
}

/// Front to back over tile `(tx, ty)`'s list: composites rgb, alpha and expected depth (and the
/// kernel's extras) into `band`, keeping each pixel's final transmittance, depth sum and last
/// contributor.
#[inline(always)]
pub(super) fn forward_tile<F: Real, K: GradKernel<F, N>, const N: usize>(
    kernel: &K,
    items: &[K::Item],
    frame: &Frame<'_, F>,
    (tx, ty): (u32, u32),
    band: &mut ForwardBand<'_, F>,
    s: &mut ForwardTile<F, K::ForwardExtra>,
) {
    let ts = TILE_SIZE as usize;
    let g = TileGeom::new(tx, ty, frame.width, frame.height);
    let r = PixelRules::<F>::new(kernel.rules());
    s.t.fill(F::ONE);
    for c in &mut s.rgb {
        c.fill(F::ZERO);
    }
    s.depth.fill(F::ZERO);
    K::forward_reset(&mut s.extra);
    s.last.fill(0);
    for (p, alive) in s.alive.iter_mut().enumerate() {
        *alive = p % ts < g.tw && p / ts < g.th;
    }
    let mut remaining = g.tw * g.th;
    for (k, &entry) in frame.bins.tile(tx, ty).iter().enumerate() {
        if remaining == 0 {
            break;
        }
        let sp = &items[entry as usize];
        kernel.for_each_pixel(sp, &g, |p, pixel| {
            if !s.alive[p] {
                return;
            }
            let Some((raw, hit)) = kernel.eval(sp, pixel) else {
                return;
            };
            let alpha = raw.min(r.max_alpha);
            if alpha < r.min_alpha {
                return;
            }
            let t = s.t[p];
            let next = t * (F::ONE - alpha);
            if next < r.stop_below {
                s.alive[p] = false;
                remaining -= 1;
                return;
            }
            let w = alpha * t;
            for (rgb, &c) in s.rgb.iter_mut().zip(K::color(sp)) {
                rgb[p] += w * c;
            }
            s.depth[p] += w * K::depth(sp, &hit);
            K::forward_add(sp, &hit, w, p, &mut s.extra);
            s.t[p] = next;
            s.last[p] = k as u32 + 1;
        });
    }
    let w = frame.width as usize;
    for ly in 0..g.th {
        for lx in 0..g.tw {
            let p = ly * ts + lx;
            let q = ly * w + g.x0 as usize + lx;
            let t = s.t[p];
            let acc = F::ONE - t;
            for c in 0..3 {
                band.rgb[3 * q + c] = s.rgb[c][p] + t * frame.background[c];
            }
            band.alpha[q] = acc;
            band.depth[q] = if acc > F::ZERO {
                s.depth[p] / acc.max(F::of(DEPTH_ALPHA_FLOOR))
            } else {
                F::ZERO
            };
            K::forward_write(&s.extra, p, q, band);
            band.final_t[q] = t;
            band.depth_sum[q] = s.depth[p];
            band.last[q] = s.last[p];
        }
    }
}

/// Back to front over tile `(tx, ty)`'s list from each pixel's last contributor, storing every
/// splat's gradient sums in its (tile, splat) slot. Per pixel, with `q_k = g_rgb · c_k + g_D z_k`
/// (`g_D` = d loss / d Σ w z; the kernel may add terms) and `behind` =
/// `Σ_{j > k} w_j q_j + g_T T_final` (`g_T` = d loss / d T_final):
/// `d loss / d α_k = T_k q_k − behind / (1 − α_k)` ([`unblend`]).
#[inline(always)]
#[expect(
    clippy::too_many_arguments,
    reason = "the tile loop's inputs, borrowed separately so the kernel and the slots can be shared"
)]
pub(super) fn backward_tile<F: Real, K: GradKernel<F, N>, const N: usize>(
    kernel: &K,
    items: &[K::Item],
    frame: &Frame<'_, F>,
    kept: &Kept<'_, F>,
    grads: &ImageGrads<'_, F>,
    (tx, ty): (u32, u32),
    slots: &SlotBuffer<N>,
    s: &mut BackwardTile<F, K::BackwardExtra>,
) {
    let ts = TILE_SIZE as usize;
    let g = TileGeom::new(tx, ty, frame.width, frame.height);
    let w = frame.width as usize;
    let floor = F::of(DEPTH_ALPHA_FLOOR);
    let mut max_last = 0;
    s.last.fill(0);
    for ly in 0..g.th {
        for lx in 0..g.tw {
            let p = ly * ts + lx;
            let q = (g.y0 as usize + ly) * w + g.x0 as usize + lx;
            let t_final = kept.final_t[q];
            let acc = F::ONE - t_final;
            let mut g_t = F::ZERO;
            for c in 0..3 {
                let gc = grads.rgb.map_or(F::ZERO, |v| v[3 * q + c]);
                s.g_rgb[c][p] = gc;
                g_t += gc * frame.background[c];
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
                g_t += gd * kept.depth_sum[q] / (acc * acc);
            }
            K::backward_init(&mut s.extra, p, q, kept, grads);
            s.t[p] = t_final;
            s.behind[p] = g_t * t_final;
            s.last[p] = kept.last[q];
            max_last = max_last.max(kept.last[q]);
        }
    }
    let entries = frame.bins.tile(tx, ty);
    for k in (0..max_last as usize).rev() {
        let j = entries[k] as usize;
        let sum = kernel.backward_item(&items[j], s, &g, k as u32);
        slots.store(j, (tx, ty), sum);
    }
}
