//! The backward pass of the 3DGS and 2DGS renderers: gradients of a loss on the rgb, alpha and
//! expected-depth images (2DGS: also the normal image and the depth distortion) with respect to
//! every Gaussian's mean, log-scales, raw quaternion, opacity logit and SH coefficients
//! (docs/conventions.md §5 "Gradients"). The 3DGS tile loops are below; the 2DGS ones are in
//! [`surfel`] (which shares [`slots`], the per-pixel rules and the colour and quaternion VJPs).
//!
//! Two calls, as in gsplat and the 3DGS reference code:
//! 1. [`render_with_grad`] renders rgb, alpha and expected depth by the rules of
//!    [`super::render`] (3DGS mode, gsplat's or the original rules; 2DGS mode) and keeps what the backward
//!    pass needs: the projected splats in depth order, the tile lists, and per pixel the final
//!    transmittance, the depth sum and the number of tile-list entries up to the last one that
//!    contributed. The plain [`super::render`] is untouched and stores none of it.
//! 2. [`backward`] (or [`backward_into`], which accumulates over views) takes the loss's
//!    gradients with respect to the images ([`ImageGrads`]) and walks each tile's list back to
//!    front from the last contributor, recovering every splat's transmittance from the final one
//!    (`T_k = T_{k+1} / (1 − α_k)`), so no per-splat state is stored. Tile rows run in parallel;
//!    each tile writes per-(tile, splat) sums in `f64` into its own slots of one buffer, which
//!    are then reduced per splat in tile order (so gradients do not depend on the thread
//!    count) and carried through the projection ([`project`]) to the raw parameters.
//!
//! The per-pixel arithmetic is generic over [`Real`]: `f32` recomputes exactly the alphas of the
//! forward (the production path), `f64` serves finite-difference checks
//! (with [`GaussianParams`]).

mod params;
mod project;
mod slots;
mod surfel;
mod surfel_project;

use std::any::{Any, TypeId};

use glam::Vec4;

use rayon::prelude::*;
use trisplat_geometry::Camera;

pub use params::{DiffParams, GaussianGrads, GaussianParams, Real};
pub use surfel::{DIST_FAR, DIST_NEAR};

use self::project::{ScreenGrad, View};
use self::slots::SlotBuffer;
use super::RenderError;
use super::composite::{CompositeRules, RenderStats};
use super::options::{Outputs, RenderMode, RenderOptions, Rules};
use super::project::{SPAN_MARGIN, exp_neg4};
use super::screen::{ScreenEntry, ScreenSplats, gather_visible};
use super::tiles::{TILE_SIZE, TileBins, TileRect, depth_order};
use crate::gaussians::sh_coeffs_per_channel;

/// Pixels per tile.
const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;
/// gsplat's floor of the accumulated alpha in the expected depth `Σ w z / max(alpha, 1e-10)`.
const DEPTH_ALPHA_FLOOR: f64 = 1e-10;

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
    /// The forward pass is asked for ray depth ([`super::SplatDepth::Ray`]), which has no
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

/// One visible splat's screen data in the precision of the per-pixel loops.
#[derive(Clone, Copy, Debug, Default)]
struct Splat<F> {
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

/// The images of a differentiable render and what its backward pass needs (module
/// documentation). Images are row-major, `rgb` interleaved `[H, W, 3]`.
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
    /// 2DGS mode: the normal image `Σ w n`, `[H, W, 3]`, as [`super::render`]'s normal output
    /// (unit normals facing the camera, not renormalised, in `options.normal_frame`). Empty in
    /// 3DGS mode.
    pub normal: Vec<F>,
    /// 2DGS mode: the depth distortion per pixel, `Σ_{i<j} w_i w_j (m_i − m_j)²` with `m` the
    /// intersection depth mapped by [`DIST_NEAR`] and [`DIST_FAR`] (docs/conventions.md §5),
    /// `[H, W]`. Empty in 3DGS mode.
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
    surfels: Vec<surfel::GradSurfel<F>>,
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
}

/// Gradients of a loss with respect to the images of a [`GradRender`] (each `None` counts as
/// zero), laid out like the images, and the weight of the 2DGS depth-distortion loss. Write
/// `ImageGrads { rgb: Some(..), ..ImageGrads::default() }`: more fields may come.
#[derive(Clone, Copy, Debug)]
pub struct ImageGrads<'a, F> {
    /// d loss / d rgb, `[H, W, 3]`.
    pub rgb: Option<&'a [F]>,
    /// d loss / d alpha, `[H, W]`.
    pub alpha: Option<&'a [F]>,
    /// d loss / d expected depth, `[H, W]`.
    pub depth: Option<&'a [F]>,
    /// 2DGS mode only: d loss / d normal image ([`GradRender::normal`]: same frame and sign),
    /// `[H, W, 3]`.
    pub normal: Option<&'a [F]>,
    /// 2DGS mode only: weight `λ` of the depth-distortion loss `λ Σ_pixels distortion`
    /// ([`GradRender::distortion`]); 0 = off.
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

fn check<P: DiffParams + ?Sized>(
    params: &P,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<CompositeRules, GradError> {
    if options.mode == RenderMode::Perspective {
        return Err(GradError::UnsupportedMode(options.mode));
    }
    if options.mode == RenderMode::Gaussian3d && options.splat_depth != super::SplatDepth::Mean {
        return Err(GradError::RayDepth);
    }
    if !params.is_world() {
        return Err(RenderError::LocalParameters.into());
    }
    let (near, far) = (options.near, options.far);
    if !(near > 0.0 && far > near && near.is_finite()) {
        return Err(RenderError::BadClipPlanes { near, far }.into());
    }
    if !options.background.iter().all(|v| v.is_finite()) {
        return Err(RenderError::BadBackground(options.background).into());
    }
    if u64::from(camera.width) * u64::from(camera.height) > super::MAX_PIXELS {
        return Err(RenderError::ImageTooLarge {
            width: camera.width,
            height: camera.height,
        }
        .into());
    }
    Ok(match (options.mode, options.rules) {
        (RenderMode::Surfel2d, _) => super::surfel::SURFEL_RULES,
        (_, Rules::Gsplat) => CompositeRules::GSPLAT,
        (_, Rules::Original3dgs) => CompositeRules::ORIGINAL_3DGS,
    })
}

/// Renders rgb, alpha and expected depth of `params` (world space) seen by `camera` in 3DGS or
/// 2DGS mode (`options.mode`; 2DGS also makes [`GradRender::normal`] in
/// `options.normal_frame` and [`GradRender::distortion`]; `options.outputs` is ignored: these
/// are always made) and keeps what [`backward`] needs. With `F = f32` and the same Gaussians the
/// images equal those of [`super::render`] up to the rounding of the activations (which
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
    if options.mode == RenderMode::Surfel2d {
        return Ok(surfel::render_with_grad(params, camera, options));
    }
    let start = std::time::Instant::now();
    let view = View::new(camera, options.rules);
    let outputs = Outputs::NONE;
    let (screen, splats) = gather_visible(params.len(), outputs, |i| {
        let s = project::project(params, i, &view, options)?;
        let center = [s.mean[0] as f32, s.mean[1] as f32];
        let radius = [s.radius[0] as f32, s.radius[1] as f32];
        let entry = ScreenEntry {
            id: i as u32,
            center,
            radius,
            depth: s.depth as f32,
            color: [0.0; 3],
            normal: [0.0; 3],
        };
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
    });
    let mut stats = RenderStats {
        project_s: start.elapsed().as_secs_f64(),
        ..RenderStats::default()
    };
    let (splats, ids, bins) = order_and_bin(
        &screen,
        &splats,
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
        normal: Vec::new(),
        distortion: Vec::new(),
        stats,
        mode: options.mode,
        n_gaussians: params.len(),
        ids,
        splats,
        surfels: Vec::new(),
        bins,
        final_t: vec![F::ONE; pixels],
        depth_sum: vec![F::ZERO; pixels],
        moments: Vec::new(),
        last: vec![0; pixels],
        rules,
        background: options.background.map(|v| F::of(f64::from(v))),
    };
    let band = TILE_SIZE as usize * width as usize;
    let ctx = Ctx {
        splats: &out.splats,
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
        .zip(out.final_t.par_chunks_mut(band))
        .zip(out.depth_sum.par_chunks_mut(band))
        .zip(out.last.par_chunks_mut(band))
        .enumerate()
        .for_each(
            |(ty, (((((rgb, alpha), depth), final_t), depth_sum), last))| {
                let mut s = ForwardTile::<F>::default();
                let mut band = ForwardBand {
                    rgb,
                    alpha,
                    depth,
                    final_t,
                    depth_sum,
                    last,
                };
                for tx in 0..ctx.bins.tiles_x {
                    ctx.forward_tile(tx, ty as u32, &mut band, &mut s);
                }
            },
        );
    out.stats.composite_s = start.elapsed().as_secs_f64();
    Ok(out)
}

/// The visible items (3DGS splats or 2DGS surfels, as `gather_visible` made them) in depth
/// order, their Gaussian ids, and the tile lists of their screen boxes (`place` gives an item's
/// box centre and half extents); the time and counts go into `stats`.
pub(super) fn order_and_bin<T: Copy>(
    screen: &ScreenSplats,
    items: &[T],
    place: impl Fn(&T) -> ([f32; 2], [f32; 2]),
    camera: &Camera,
    rect: TileRect,
    stats: &mut RenderStats,
) -> (Vec<T>, Vec<u32>, TileBins) {
    let start = std::time::Instant::now();
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
    let start = std::time::Instant::now();
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
        return Ok(surfel::backward_into(
            params, camera, options, forward, grads, out,
        ));
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

    // Per (tile, splat) sums, back to front per tile (module documentation).
    let bins = &forward.bins;
    let slots = SlotBuffer::<SLOT>::new(
        forward.splats.par_iter().map(|s| (s.center, s.radius)),
        forward.rules.tile_rect,
        bins,
    );
    let ctx = Ctx {
        splats: &forward.splats,
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
    // Reduce per splat, in tile order.
    let view = View::new(camera, options.rules);
    let screen_grads: Vec<ScreenGrad> = slots
        .reduce()
        .into_par_iter()
        .map(|sum| ScreenGrad {
            mean: [sum[0], sum[1]],
            conic: [sum[2], sum[3], sum[4]],
            opacity: sum[5],
            depth: sum[6],
            color: [sum[7], sum[8], sum[9]],
        })
        .collect();
    stats.reduce_s = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();

    // Through the projection, per Gaussian.
    // Screen gradients moved to Gaussian order (the loop below reads them in memory order).
    let mut by_id: Vec<Option<ScreenGrad>> = vec![None; params.len()];
    for (&id, g) in forward.ids.iter().zip(&screen_grads) {
        by_id[id as usize] = Some(*g);
    }
    drop(screen_grads);
    accumulate(out, k, |i| {
        let g = by_id[i].as_ref()?;
        project::project_vjp(params, i, &view, options, g).map(|p| (p, g.mean))
    });
    stats.project_s = start.elapsed().as_secs_f64();
    Ok(stats)
}

/// Adds every Gaussian's parameter gradients and screen-space gradient (`grad(i)`; `None` for
/// culled ones) into `out` (`k` SH coefficients per Gaussian), in parallel over Gaussians.
fn accumulate(
    out: &mut GaussianGrads,
    k: usize,
    grad: impl Fn(usize) -> Option<(project::ParamGrad, [f64; 2])> + Sync,
) {
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
                let Some((p, screen)) = grad(i) else {
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
}

/// Pixels evaluated together in the backward row loop.
const LANES: usize = 4;

/// Values per (tile, splat) slot: d/d mean (2), conic (3), opacity, depth, colour (3).
const SLOT: usize = 10;

/// What both tile loops read.
struct Ctx<'a, F> {
    splats: &'a [Splat<F>],
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
    final_t: &'a mut [F],
    depth_sum: &'a mut [F],
    last: &'a mut [u32],
}

/// Per-pixel accumulators of one tile in the forward pass (reused across tiles).
struct ForwardTile<F> {
    t: [F; TILE_PIXELS],
    rgb: [[F; TILE_PIXELS]; 3],
    depth: [F; TILE_PIXELS],
    last: [u32; TILE_PIXELS],
    alive: [bool; TILE_PIXELS],
}

impl<F: Real> Default for ForwardTile<F> {
    fn default() -> Self {
        Self {
            t: [F::ONE; TILE_PIXELS],
            rgb: [[F::ZERO; TILE_PIXELS]; 3],
            depth: [F::ZERO; TILE_PIXELS],
            last: [0; TILE_PIXELS],
            alive: [true; TILE_PIXELS],
        }
    }
}

/// Per-pixel state of one tile in the backward pass (reused across tiles).
struct BackwardTile<F> {
    /// Transmittance before the splat being processed (starts at the final one).
    t: [F; TILE_PIXELS],
    /// `Σ_{j behind} w_j q_j + (d loss / d T_final) T_final` (see [`Ctx::backward_tile`]).
    behind: [F; TILE_PIXELS],
    g_rgb: [[F; TILE_PIXELS]; 3],
    /// d loss / d (Σ w z).
    g_depth: [F; TILE_PIXELS],
    last: [u32; TILE_PIXELS],
}

impl<F: Real> Default for BackwardTile<F> {
    fn default() -> Self {
        Self {
            t: [F::ONE; TILE_PIXELS],
            behind: [F::ZERO; TILE_PIXELS],
            g_rgb: [[F::ZERO; TILE_PIXELS]; 3],
            g_depth: [F::ZERO; TILE_PIXELS],
            last: [0; TILE_PIXELS],
        }
    }
}

/// The per-pixel rules in the loops' precision.
#[derive(Clone, Copy)]
struct PixelRules<F> {
    max_alpha: F,
    min_alpha: F,
    /// Stop when `next_T < stop_below`.
    stop_below: F,
    offset: f32,
}

impl<F: Real> PixelRules<F> {
    fn new(r: &CompositeRules) -> Self {
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

/// First local index `>= floor(v − start)`, clamped to `0..=n` (as the plain compositor).
#[inline(always)]
fn lo(v: f32, start: u32, n: usize) -> usize {
    ((v - start as f32).max(0.0) as usize).min(n)
}

/// One past a local index `>= ceil(v − start)`, clamped to `0..=n` (as the plain compositor).
#[inline(always)]
fn hi(v: f32, start: u32, n: usize) -> usize {
    let x = v - start as f32 + 1.0;
    if x > 0.0 { (x as usize + 1).min(n) } else { 0 }
}

/// The local pixel columns of row `ly` inside splat `s`'s row span, within `lx0..lx1` (the
/// plain compositor's [`super::screen::SplatKernel::row_span`] for the EWA kernel).
#[inline(always)]
fn row_span<F: Real>(
    s: &Splat<F>,
    g: &TileGeom,
    ly: usize,
    off: f32,
    (lx0, lx1): (usize, usize),
) -> (usize, usize) {
    let py = (g.y0 as usize + ly) as f32 + off;
    let [p, q, r] = s.span;
    let dy = s.center[1] - py;
    let root_sq = q * dy * dy + r;
    let center = s.center[0] + p * dy;
    let root = if root_sq < 0.0 { 0.0 } else { root_sq.sqrt() };
    let (a, b) = (center - root - SPAN_MARGIN, center + root + SPAN_MARGIN);
    (
        lo(a - off, g.x0, g.tw).max(lx0),
        hi(b - off, g.x0, g.tw).min(lx1),
    )
}

/// One splat over its pixels of one tile in the backward pass, pixel by pixel: returns its
/// slot `[d/d mean (2), conic (3), opacity, depth, colour (3)]` and updates the pixels'
/// transmittance and `behind` sums (module documentation). Row sums (at most 16 terms) in `F`,
/// then `f64`: with dy fixed on a row, the conic and mean gradients need only `Σ g_σ`,
/// `Σ g_σ dx` and `Σ g_σ dx²`.
#[inline(always)]
fn backward_splat<F: Real>(
    sp: &Splat<F>,
    s: &mut BackwardTile<F>,
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
            let ra = F::ONE / (F::ONE - alpha);
            let t = s.t[p] * ra;
            let wgt = alpha * t;
            let (gr, gg, gb) = (s.g_rgb[0][p], s.g_rgb[1][p], s.g_rgb[2][p]);
            let gd = s.g_depth[p];
            let qk = gr * sp.color[0] + gg * sp.color[1] + gb * sp.color[2] + gd * sp.depth;
            let g_alpha = t * qk - ra * s.behind[p];
            s.behind[p] += wgt * qk;
            s.t[p] = t;
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
/// alphas are those of the plain compositor's [`super::project::EwaKernel::sample4`] bit for
/// bit (same operations, same `exp`). Each lane sums at most 64 terms of one (tile, splat) pair
/// in `f32`; the lanes are added in `f64`.
#[inline(always)]
fn backward_splat_f32(
    sp: &Splat<f32>,
    s: &mut BackwardTile<f32>,
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

/// The tile's geometry: origin, size in pixels.
struct TileGeom {
    x0: u32,
    y0: u32,
    tw: usize,
    th: usize,
}

impl TileGeom {
    /// Tile `(tx, ty)` of a `width` × `height` image.
    fn new(tx: u32, ty: u32, width: u32, height: u32) -> Self {
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

/// `sigma = ½(a dx² + c dy²) + b dx dy` with `d = mean − pixel`, in the operation order of
/// [`super::project::EwaKernel`], so `f32` gives the plain forward's values.
#[inline(always)]
fn sigma_of<F: Real>(s: &Splat<F>, dx: F, dy: F) -> F {
    let [a, b, c] = s.conic;
    F::of(0.5) * (a * dx * dx + c * dy * dy) + b * dx * dy
}

impl<F: Real> Ctx<'_, F> {
    fn geom(&self, tx: u32, ty: u32) -> TileGeom {
        TileGeom::new(tx, ty, self.width, self.height)
    }

    /// The local pixel rectangle of splat `s` in the tile (the plain compositor's).
    fn pixel_range(&self, s: &Splat<F>, g: &TileGeom) -> (usize, usize, usize, usize) {
        if self.rules.clip_to_box {
            let off = self.rules.pixel_offset;
            let (c, r) = (s.center, s.radius);
            (
                lo(c[0] - r[0] - off, g.x0, g.tw),
                hi(c[0] + r[0] - off, g.x0, g.tw),
                lo(c[1] - r[1] - off, g.y0, g.th),
                hi(c[1] + r[1] - off, g.y0, g.th),
            )
        } else {
            (0, g.tw, 0, g.th)
        }
    }

    fn forward_tile(
        &self,
        tx: u32,
        ty: u32,
        band: &mut ForwardBand<'_, F>,
        s: &mut ForwardTile<F>,
    ) {
        let ts = TILE_SIZE as usize;
        let g = self.geom(tx, ty);
        let r = PixelRules::<F>::new(self.rules);
        s.t.fill(F::ONE);
        for c in &mut s.rgb {
            c.fill(F::ZERO);
        }
        s.depth.fill(F::ZERO);
        s.last.fill(0);
        for (p, alive) in s.alive.iter_mut().enumerate() {
            *alive = p % ts < g.tw && p / ts < g.th;
        }
        let mut remaining = g.tw * g.th;
        for (k, &entry) in self.bins.tile(tx, ty).iter().enumerate() {
            if remaining == 0 {
                break;
            }
            let sp = &self.splats[entry as usize];
            let (lx0, lx1, ly0, ly1) = self.pixel_range(sp, &g);
            for ly in ly0..ly1 {
                let (sx0, sx1) = row_span(sp, &g, ly, r.offset, (lx0, lx1));
                let py = F::of(f64::from((g.y0 as usize + ly) as f32 + r.offset));
                let dy = sp.mean[1] - py;
                for lx in sx0..sx1 {
                    let p = ly * ts + lx;
                    if !s.alive[p] {
                        continue;
                    }
                    let px = F::of(f64::from((g.x0 as usize + lx) as f32 + r.offset));
                    let dx = sp.mean[0] - px;
                    let sigma = sigma_of(sp, dx, dy);
                    if sigma < F::ZERO {
                        continue;
                    }
                    let alpha = (sp.opacity * sigma.exp_neg()).min(r.max_alpha);
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
                    }
                    s.depth[p] += w * sp.depth;
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
                }
                band.alpha[q] = acc;
                band.depth[q] = if acc > F::ZERO {
                    s.depth[p] / acc.max(F::of(DEPTH_ALPHA_FLOOR))
                } else {
                    F::ZERO
                };
                band.final_t[q] = t;
                band.depth_sum[q] = s.depth[p];
                band.last[q] = s.last[p];
            }
        }
    }

    /// Back to front over the tile's list. Per pixel, with `q_k = g_rgb · c_k + g_D z_k`
    /// (`g_D` = d loss / d Σ w z) and `behind` = `Σ_{j > k} w_j q_j + g_T T_final`
    /// (`g_T` = d loss / d T_final): `d loss / d α_k = T_k q_k − behind / (1 − α_k)`.
    fn backward_tile(
        &self,
        fwd: &GradRender<F>,
        grads: &ImageGrads<'_, F>,
        (tx, ty): (u32, u32),
        slots: &SlotBuffer<SLOT>,
        s: &mut BackwardTile<F>,
    ) {
        let ts = TILE_SIZE as usize;
        let g = self.geom(tx, ty);
        let r = PixelRules::<F>::new(self.rules);
        let w = self.width as usize;
        let floor = F::of(DEPTH_ALPHA_FLOOR);
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
                s.t[p] = t_final;
                s.behind[p] = g_t * t_final;
                s.last[p] = fwd.last[q];
                max_last = max_last.max(fwd.last[q]);
            }
        }
        let entries = self.bins.tile(tx, ty);
        let r32 = PixelRules::<f32>::new(self.rules);
        for k in (0..max_last as usize).rev() {
            let j = entries[k] as usize;
            let sp = &self.splats[j];
            let (lx0, lx1, ly0, ly1) = self.pixel_range(sp, &g);
            // f32: four pixels at a time in SSE lanes (the type test is resolved at compile
            // time); f64 pixel by pixel.
            let sum = if TypeId::of::<F>() == TypeId::of::<f32>() {
                let sp32 = (sp as &dyn Any).downcast_ref::<Splat<f32>>();
                let s32 = (&mut *s as &mut dyn Any).downcast_mut::<BackwardTile<f32>>();
                match (sp32, s32) {
                    (Some(sp32), Some(s32)) => {
                        backward_splat_f32(sp32, s32, &g, (lx0, lx1, ly0, ly1), k as u32, &r32)
                    }
                    _ => unreachable!("F is f32"),
                }
            } else {
                backward_splat(sp, s, &g, (lx0, lx1, ly0, ly1), k as u32, &r)
            };
            slots.store(j, (tx, ty), sum);
        }
    }
}
