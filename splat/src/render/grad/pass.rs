//! The two calls of the differentiable renderer, [`render_with_grad`] and [`backward`] /
//! [`backward_into`] (module documentation of [`super`]): they check the inputs, project with
//! the mode's kernel ([`super::ewa`] for 3DGS, [`super::surfel`] for 2DGS), sort and bin, run
//! the shared tile loops of [`super::tile`], reduce the (tile, splat) slots and carry the sums
//! through the projection to the raw parameters.

use std::time::Instant;

use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::ewa::{self, EwaGrad, Splat};
use super::params::{DiffParams, GaussianGrads, Real};
use super::project::{self, ParamGrad};
use super::slots::SlotBuffer;
use super::surfel::{self, GradSurfel, SurfelGrad};
use super::surfel_project::{self, SurfelScreenGrad};
use super::tile::{BackwardTile, ForwardBand, ForwardTile, Frame, GradKernel, ImageGrads, Kept};
use super::tile::{backward_tile, forward_tile};
use crate::render::composite::{CompositeRules, RenderStats};
use crate::render::inputs::{RenderError, check_view};
use crate::render::options::{RenderMode, RenderOptions, Rules, SplatDepth};
use crate::render::screen::ScreenSplats;
use crate::render::surfel::SURFEL_RULES;
use crate::render::tiles::{TILE_SIZE, TileBins, TileRect, depth_order};
use crate::sh::sh_coeffs_per_channel;

/// Why a differentiable render or its backward pass cannot be done.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GradError {
    /// The inputs the renderer itself refuses.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The mode has no backward pass (perspective mode).
    #[error("the backward pass supports 3DGS and 2DGS modes only, not {0:?}")]
    UnsupportedMode(RenderMode),
    /// An image gradient the mode does not render (the normal image and the depth distortion
    /// are 2DGS-only).
    #[error("{what} is rendered in 2DGS mode only, not {mode:?}")]
    NotInMode {
        /// Which image gradient.
        what: &'static str,
        /// The forward's mode.
        mode: RenderMode,
    },
    /// The backward pass is asked for another mode than its forward pass was made in.
    #[error(
        "the forward pass was made in {forward:?} mode, the backward pass asks for {backward:?}"
    )]
    ModeMismatch {
        /// The forward's mode.
        forward: RenderMode,
        /// The options' mode.
        backward: RenderMode,
    },
    /// The forward pass is asked for ray depth ([`SplatDepth::Ray`]), which has no
    /// backward pass.
    #[error("the backward pass supports the mean's depth only (SplatDepth::Mean), not ray depth")]
    RayDepth,
    /// The distortion weight is not finite.
    #[error("the distortion weight {0} is not finite")]
    BadDistortionWeight(f64),
    /// An image gradient or the parameters do not match the forward pass.
    #[error("{what} has {got} values, expected {expected}")]
    Size {
        /// Which input.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The length the forward pass implies.
        expected: usize,
    },
}

/// The images of a differentiable render and what its backward pass needs (module
/// documentation of [`super`]). Images are row-major, `rgb` interleaved `[H, W, 3]`.
#[derive(Clone, Debug)]
pub struct GradRender<F: Real> {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// `Σ w c + T background`, `[H, W, 3]`.
    pub rgb: Vec<F>,
    /// `1 − T`, `[H, W]`.
    pub alpha: Vec<F>,
    /// Expected z-depth `Σ w z / max(alpha, 1e-10)`, 0 where alpha = 0, `[H, W]` (2DGS: `z`
    /// the ray-surfel intersection's).
    pub depth: Vec<F>,
    /// 2DGS mode: the normal image `Σ w n`, `[H, W, 3]`, as [`crate::render::render`]'s normal
    /// output (unit normals facing the camera, not renormalised, in `options.normal_frame`).
    /// Empty in 3DGS mode.
    pub normal: Vec<F>,
    /// 2DGS mode: the depth distortion per pixel, `Σ_{i<j} w_i w_j (m_i − m_j)²` with `m` the
    /// intersection depth mapped by [`super::DIST_NEAR`] and [`super::DIST_FAR`]
    /// (docs/conventions.md §5), `[H, W]`. Empty in 3DGS mode.
    pub distortion: Vec<F>,
    /// Stage timings and counts of the forward pass.
    pub stats: RenderStats,
    mode: RenderMode,
    n_gaussians: usize,
    /// Gaussian index of each visible splat, in depth order.
    ids: Vec<u32>,
    /// 3DGS mode: the splats in depth order (empty in 2DGS mode).
    splats: Vec<Splat<F>>,
    /// 2DGS mode: the surfels in depth order (empty in 3DGS mode).
    surfels: Vec<GradSurfel<F>>,
    bins: TileBins,
    final_t: Vec<F>,
    depth_sum: Vec<F>,
    /// 2DGS mode: per pixel the distortion's moments `Σ w`, `Σ w m`, `Σ w m²` (empty in 3DGS
    /// mode).
    moments: Vec<[f64; 3]>,
    /// Per pixel: 1 + the tile-list position of the last contributing splat, 0 for none.
    last: Vec<u32>,
    rules: CompositeRules,
    background: [F; 3],
}

impl<F: Real> GradRender<F> {
    /// Number of visible splats.
    #[must_use]
    pub fn visible(&self) -> usize {
        self.ids.len()
    }

    /// The Gaussian index of each visible splat (those the projection did not cull: 3DGS's
    /// `radii > 0`), in depth order; each Gaussian at most once.
    #[must_use]
    pub fn visible_ids(&self) -> &[u32] {
        &self.ids
    }

    /// Final transmittance per pixel.
    #[must_use]
    pub fn final_transmittance(&self) -> &[F] {
        &self.final_t
    }

    /// The mode of the forward pass.
    #[must_use]
    pub fn mode(&self) -> RenderMode {
        self.mode
    }

    /// The depth distortion summed over the pixels, in `f64` (0 in 3DGS mode): the loss that
    /// [`ImageGrads::distortion`] weights.
    #[must_use]
    pub fn distortion_total(&self) -> f64 {
        self.distortion.iter().map(|v| v.wide()).sum()
    }

    /// What both tile loops read besides the kernel and its items.
    fn frame(&self) -> Frame<'_, F> {
        Frame {
            bins: &self.bins,
            background: self.background,
            width: self.width,
            height: self.height,
        }
    }
}

fn check<P: DiffParams + ?Sized>(
    params: &P,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<CompositeRules, GradError> {
    if options.mode == RenderMode::Perspective {
        return Err(GradError::UnsupportedMode(options.mode));
    }
    if options.mode == RenderMode::Gaussian3d && options.splat_depth != SplatDepth::Mean {
        return Err(GradError::RayDepth);
    }
    check_view(params.is_world(), camera, options)?;
    Ok(match (options.mode, options.rules) {
        (RenderMode::Surfel2d, _) => SURFEL_RULES,
        (_, Rules::Gsplat) => CompositeRules::GSPLAT,
        (_, Rules::Original3dgs) => CompositeRules::ORIGINAL_3DGS,
    })
}

/// Renders rgb, alpha and expected depth of `params` (world space) seen by `camera` in 3DGS or
/// 2DGS mode (`options.mode`; 2DGS also makes [`GradRender::normal`] in
/// `options.normal_frame` and [`GradRender::distortion`]; `options.outputs` is ignored: these
/// are always made) and keeps what [`backward`] needs. With `F = f32` and the same Gaussians the
/// images equal those of [`crate::render::render`] up to the rounding of the activations (which
/// `render` does partly in `f32`).
///
/// # Errors
/// [`GradError::UnsupportedMode`] for perspective mode; the renderer's own [`RenderError`]s.
pub fn render_with_grad<F: Real, P: DiffParams + ?Sized>(
    params: &P,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<GradRender<F>, GradError> {
    let rules = check(params, camera, options)?;
    let start = Instant::now();
    Ok(if options.mode == RenderMode::Surfel2d {
        let view = crate::render::surfel::View::new(
            camera,
            f64::from(options.near),
            f64::from(options.far),
        );
        let size = (camera.width, camera.height);
        let (screen, surfels) = surfel::gather(params, &view, options, &rules, size);
        let kernel = SurfelGrad::new(rules);
        let (out, surfels) = forward(&kernel, &screen, &surfels, camera, options, params, start);
        GradRender { surfels, ..out }
    } else {
        let view = project::View::new(camera, options.rules);
        let (screen, splats) = ewa::gather(params, &view, options);
        let kernel = EwaGrad::new(rules);
        let (out, splats) = forward(&kernel, &screen, &splats, camera, options, params, start);
        GradRender { splats, ..out }
    })
}

/// The sort and the forward tile loops of one mode after its projection (started at `start`):
/// the images (with no items; the caller stores them) and the items in depth order.
fn forward<F: Real, K: GradKernel<F, N>, const N: usize, P: DiffParams + ?Sized>(
    kernel: &K,
    screen: &ScreenSplats,
    items: &[K::Item],
    camera: &Camera,
    options: &RenderOptions,
    params: &P,
    start: Instant,
) -> (GradRender<F>, Vec<K::Item>) {
    let rules = *kernel.rules();
    let mut stats = RenderStats {
        project_s: start.elapsed().as_secs_f64(),
        ..RenderStats::default()
    };
    let (items, ids, bins) =
        order_and_bin(screen, items, K::place, camera, rules.tile_rect, &mut stats);
    let (width, height) = (camera.width, camera.height);

    let start = Instant::now();
    let pixels = width as usize * height as usize;
    let surfel = options.mode == RenderMode::Surfel2d;
    let only_surfel = |len: usize| if surfel { len } else { 0 };
    let mut out = GradRender {
        width,
        height,
        rgb: vec![F::ZERO; 3 * pixels],
        alpha: vec![F::ZERO; pixels],
        depth: vec![F::ZERO; pixels],
        normal: vec![F::ZERO; only_surfel(3 * pixels)],
        distortion: vec![F::ZERO; only_surfel(pixels)],
        stats,
        mode: options.mode,
        n_gaussians: params.len(),
        ids,
        splats: Vec::new(),
        surfels: Vec::new(),
        bins,
        final_t: vec![F::ONE; pixels],
        depth_sum: vec![F::ZERO; pixels],
        moments: vec![[0.0; 3]; only_surfel(pixels)],
        last: vec![0; pixels],
        rules,
        background: options.background.map(|v| F::of(f64::from(v))),
    };
    {
        let band = TILE_SIZE as usize * width as usize;
        let n = out.bins.tiles_y as usize;
        let frame = Frame {
            bins: &out.bins,
            background: out.background,
            width,
            height,
        };
        let mut rgb = bands(&mut out.rgb, 3 * band, n);
        let mut alpha = bands(&mut out.alpha, band, n);
        let mut depth = bands(&mut out.depth, band, n);
        let mut final_t = bands(&mut out.final_t, band, n);
        let mut depth_sum = bands(&mut out.depth_sum, band, n);
        let mut last = bands(&mut out.last, band, n);
        let mut normal = bands(&mut out.normal, 3 * band, n);
        let mut distortion = bands(&mut out.distortion, band, n);
        let mut moments = bands(&mut out.moments, band, n);
        let rows: Vec<ForwardBand<'_, F>> = (0..n)
            .map(|_| ForwardBand {
                rgb: rgb.next().unwrap_or_default(),
                alpha: alpha.next().unwrap_or_default(),
                depth: depth.next().unwrap_or_default(),
                final_t: final_t.next().unwrap_or_default(),
                depth_sum: depth_sum.next().unwrap_or_default(),
                last: last.next().unwrap_or_default(),
                normal: normal.next().unwrap_or_default(),
                distortion: distortion.next().unwrap_or_default(),
                moments: moments.next().unwrap_or_default(),
            })
            .collect();
        rows.into_par_iter().enumerate().for_each(|(ty, mut band)| {
            let mut s = ForwardTile::new(kernel.forward_extra());
            for tx in 0..frame.bins.tiles_x {
                forward_tile(kernel, &items, &frame, (tx, ty as u32), &mut band, &mut s);
            }
        });
    }
    out.stats.composite_s = start.elapsed().as_secs_f64();
    (out, items)
}

/// `buf` cut into tile rows of `len` values (the last may be shorter; none for an empty `buf`).
fn bands<T>(buf: &mut [T], len: usize, n: usize) -> impl Iterator<Item = &mut [T]> {
    buf.chunks_mut(len.max(1)).take(n)
}

/// The visible items (3DGS splats or 2DGS surfels, as `gather_visible` made them) in depth
/// order, their Gaussian ids, and the tile lists of their screen boxes (`place` gives an item's
/// box centre and half extents); the time and counts go into `stats`.
fn order_and_bin<T: Copy>(
    screen: &ScreenSplats,
    items: &[T],
    place: impl Fn(&T) -> ([f32; 2], [f32; 2]),
    camera: &Camera,
    rect: TileRect,
    stats: &mut RenderStats,
) -> (Vec<T>, Vec<u32>, TileBins) {
    let start = Instant::now();
    let order = depth_order(&screen.depths);
    let items: Vec<T> = order.iter().map(|&k| items[k as usize]).collect();
    let ids: Vec<u32> = order.iter().map(|&k| screen.ids[k as usize]).collect();
    let (centers, radii): (Vec<[f32; 2]>, Vec<[f32; 2]>) = items.iter().map(place).unzip();
    let bins = TileBins::bin(&centers, &radii, camera.width, camera.height, rect);
    stats.sort_s = start.elapsed().as_secs_f64();
    stats.visible = items.len();
    stats.intersections = bins.intersections();
    (items, ids, bins)
}

/// The gradients of a loss with respect to the parameters of `params`, given its gradients with
/// respect to the images of `forward` (made by [`render_with_grad`] from the same `params`,
/// `camera` and `options`). Gaussians culled by the projection get zero gradients.
///
/// # Errors
/// As [`render_with_grad`]; [`GradError::Size`] when an image gradient or `params` does not
/// match `forward`; [`GradError::ModeMismatch`] when `options.mode` is not `forward`'s;
/// [`GradError::NotInMode`] for a normal gradient or a non-zero distortion weight in 3DGS mode;
/// [`GradError::BadDistortionWeight`] for a non-finite one.
pub fn backward<F: Real, P: DiffParams + ?Sized>(
    params: &P,
    camera: &Camera,
    options: &RenderOptions,
    forward: &GradRender<F>,
    grads: &ImageGrads<'_, F>,
) -> Result<GaussianGrads, GradError> {
    let mut out = GaussianGrads::zeros(params.len(), params.sh_degree());
    backward_into(params, camera, options, forward, grads, &mut out)?;
    Ok(out)
}

/// Wall-clock seconds of the stages of one backward pass.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BackwardStats {
    /// The per-tile back-to-front loops.
    pub composite_s: f64,
    /// The per-splat reduction of the (tile, splat) sums.
    pub reduce_s: f64,
    /// The projection's vector-Jacobian products, per Gaussian.
    pub project_s: f64,
}

/// [`backward`] adding into `out` (for losses over several views); returns the stage timings.
///
/// # Errors
/// As [`backward`]; also [`GradError::Size`] when `out` does not fit `params`.
pub fn backward_into<F: Real, P: DiffParams + ?Sized>(
    params: &P,
    camera: &Camera,
    options: &RenderOptions,
    forward: &GradRender<F>,
    grads: &ImageGrads<'_, F>,
    out: &mut GaussianGrads,
) -> Result<BackwardStats, GradError> {
    check(params, camera, options)?;
    let mut stats = BackwardStats::default();
    let start = Instant::now();
    let pixels = forward.width as usize * forward.height as usize;
    let size = |what, got, expected| {
        if got == expected {
            Ok(())
        } else {
            Err(GradError::Size {
                what,
                got,
                expected,
            })
        }
    };
    size("the parameters", params.len(), forward.n_gaussians)?;
    size(
        "the camera's image",
        camera.width as usize * camera.height as usize,
        pixels,
    )?;
    let k = 3 * sh_coeffs_per_channel(params.sh_degree());
    size("the gradient buffers", out.len(), params.len())?;
    size("the SH gradient buffer", out.sh.len(), params.len() * k)?;
    for (what, buf, per) in [
        ("d loss / d rgb", grads.rgb, 3),
        ("d loss / d alpha", grads.alpha, 1),
        ("d loss / d depth", grads.depth, 1),
        ("d loss / d normal", grads.normal, 3),
    ] {
        if let Some(buf) = buf {
            size(what, buf.len(), per * pixels)?;
        }
    }
    if forward.mode != options.mode {
        return Err(GradError::ModeMismatch {
            forward: forward.mode,
            backward: options.mode,
        });
    }
    let lambda = grads.distortion.wide();
    if !lambda.is_finite() {
        return Err(GradError::BadDistortionWeight(lambda));
    }
    if options.mode == RenderMode::Surfel2d {
        let kernel = SurfelGrad::new(forward.rules);
        let sums = backward_sums(&kernel, &forward.surfels, forward, grads);
        stats.composite_s = start.elapsed().as_secs_f64();
        let view = crate::render::surfel::View::new(
            camera,
            f64::from(options.near),
            f64::from(options.far),
        );
        carry(
            out,
            (k, &forward.ids, sums),
            SurfelScreenGrad::from_slot,
            |i, g| surfel_project::project_vjp(params, i, &view, options.normal_frame, g),
            &mut stats,
        );
        return Ok(stats);
    }
    for (what, given) in [
        ("d loss / d normal", grads.normal.is_some()),
        ("the distortion weight", lambda != 0.0),
    ] {
        if given {
            return Err(GradError::NotInMode {
                what,
                mode: options.mode,
            });
        }
    }
    let kernel = EwaGrad::new(forward.rules);
    let sums = backward_sums(&kernel, &forward.splats, forward, grads);
    stats.composite_s = start.elapsed().as_secs_f64();
    let view = project::View::new(camera, options.rules);
    carry(
        out,
        (k, &forward.ids, sums),
        ewa::screen_grad,
        |i, g| project::project_vjp(params, i, &view, options, g).map(|p| (p, g.mean)),
        &mut stats,
    );
    Ok(stats)
}

/// The backward tile loops of one mode: per (tile, splat) sums, back to front per tile (module
/// documentation of [`super`]), reduced per splat in tile order.
fn backward_sums<F: Real, K: GradKernel<F, N>, const N: usize>(
    kernel: &K,
    items: &[K::Item],
    forward: &GradRender<F>,
    grads: &ImageGrads<'_, F>,
) -> Vec<[f64; N]> {
    let bins = &forward.bins;
    let slots = SlotBuffer::<N>::new(
        items.par_iter().map(K::place),
        forward.rules.tile_rect,
        bins,
    );
    let frame = forward.frame();
    let kept = Kept {
        final_t: &forward.final_t,
        depth_sum: &forward.depth_sum,
        last: &forward.last,
        moments: &forward.moments,
    };
    (0..bins.tiles_y).into_par_iter().for_each(|ty| {
        let mut s = BackwardTile::new(kernel.backward_extra());
        for tx in 0..bins.tiles_x {
            backward_tile(
                kernel,
                items,
                &frame,
                &kept,
                grads,
                (tx, ty),
                &slots,
                &mut s,
            );
        }
    });
    slots.reduce()
}

/// Reduces the visible splats' slots (`sums`, in depth order with Gaussian ids `ids`) to screen
/// gradients (`screen_grad`) and adds every Gaussian's parameter and screen-space gradients
/// (`vjp(i, g)`: `None` for culled ones) into `out` (`k` SH coefficients per Gaussian), in
/// parallel over Gaussians; the times go into `stats`.
fn carry<G: Copy + Send + Sync, const N: usize>(
    out: &mut GaussianGrads,
    (k, ids, sums): (usize, &[u32], Vec<[f64; N]>),
    screen_grad: impl Fn(&[f64; N]) -> G + Send + Sync,
    vjp: impl Fn(usize, &G) -> Option<(ParamGrad, [f64; 2])> + Sync,
    stats: &mut BackwardStats,
) {
    let start = Instant::now();
    let screen_grads: Vec<G> = sums.par_iter().map(screen_grad).collect();
    drop(sums);
    stats.reduce_s = start.elapsed().as_secs_f64();
    let start = Instant::now();
    // Screen gradients moved to Gaussian order (the loop below reads them in memory order).
    let mut by_id: Vec<Option<G>> = vec![None; out.len()];
    for (&id, g) in ids.iter().zip(&screen_grads) {
        by_id[id as usize] = Some(*g);
    }
    drop(screen_grads);
    let GaussianGrads {
        means,
        log_scales,
        rotations,
        opacity_logits,
        sh,
        means2d,
    } = out;
    means
        .par_iter_mut()
        .zip(log_scales.par_iter_mut())
        .zip(rotations.par_iter_mut())
        .zip(opacity_logits.par_iter_mut())
        .zip(means2d.par_iter_mut())
        .zip(sh.par_chunks_mut(k.max(1)))
        .enumerate()
        .for_each(
            |(i, (((((mean, log_scale), rotation), opacity), mean2d), sh))| {
                let Some((p, screen)) = by_id[i].as_ref().and_then(|g| vjp(i, g)) else {
                    return;
                };
                for m in 0..3 {
                    mean[m] += p.mean[m];
                    log_scale[m] += p.log_scale[m];
                }
                for (a, b) in rotation.iter_mut().zip(p.rotation) {
                    *a += b;
                }
                *opacity += p.opacity_logit;
                mean2d[0] += screen[0];
                mean2d[1] += screen[1];
                for (a, b) in sh.iter_mut().zip(&p.sh) {
                    *a += b;
                }
            },
        );
    stats.project_s = start.elapsed().as_secs_f64();
}
