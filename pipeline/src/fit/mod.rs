//! `trisplat fit`: fitting bound Gaussians to target images (docs/conventions.md §5 "Fitting").
//!
//! The parameters are the bound set's local ones ([`BoundParams`], `f64`); per iteration one
//! (frame, view) pair is drawn (seeded), the set is placed with that frame's triangle frames
//! ([`to_world`]), rendered with the backward pass of its mode (3DGS, or 2DGS surfels) in
//! `f32`, and the loss `(1 − λ) L1 + λ D-SSIM` on rgb, plus `w_depth` × the depth L1 against
//! the target depth (weighted by the target's alpha) and `w_alpha` × the L1 of alpha against
//! the target mask, and in 2DGS mode `w_normal` × 2DGS's depth–normal consistency and
//! `w_distortion` × its depth distortion (mean over the pixels), is carried back to the local parameters ([`grads_to_local`]) and one Adam step taken. The
//! means' learning rate decays exponentially to `means_lr_final` × itself over the run (3DGS).
//! With a `time_budget` the fit stops after the iteration that spends it (a fixed-time
//! comparison), and the run's progress is the larger of the iterations' and the time's share.
//!
//! With `refine_every = N`, every N iterations (not after the last) the set goes through one
//! round of [`crate::refine`] (surface-guided re-initialisation with binding inheritance) on
//! the template's rest pose, and Adam's state starts afresh (every Gaussian is new: refine
//! gives no old-to-new map).
//!
//! With `densify` set, 3DGS's adaptive density control runs on the bound set as GaussianAvatars
//! does ([`trisplat_splat::fit::density`]): screen-space gradient statistics per Gaussian,
//! clone / split / prune every `every` iterations between `from` and `until` (children keep
//! their parent's triangle, a triangle's last Gaussian is never pruned, Adam's moments follow
//! the survivors and start at zero for new Gaussians), opacities reset every
//! `opacity_reset_every` iterations. With `sh_up_every = N` the render uses SH bands up to an
//! active degree that starts at 0 and rises by one every N iterations
//! ([`trisplat_splat::fit::sh_schedule`]); the inactive bands get no gradient. Per iteration
//! the order is: step, densify, opacity reset, refine, checkpoint.
//!
//! Targets are mesh renders of the posed template ([`mesh_targets`]: rgb from vertex colours,
//! else the world normal as colour `(n + 1) / 2`, depth, camera-frame normals, the hit mask as
//! alpha) or user images ([`read_image_targets`]). Held-out views are scored at every checkpoint
//! by PSNR and SSIM (3DGS's) and, with mesh targets, by depth and normal error inside the mask.

use std::time::Instant;

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::mesh_render::NormalFrame;
use trisplat_geometry::rng::{Rng, splitmix64};
use trisplat_splat::fit::adam::{Adam, LearningRates};
use trisplat_splat::fit::bound::{
    BoundParams, TriangleFrames, all_finite, grads_to_local, to_world,
};
use trisplat_splat::fit::density::{
    DensityStats, RESET_OPACITY, camera_extent, densify_and_prune, reset_opacity,
};
use trisplat_splat::fit::loss::{DEFAULT_LAMBDA_DSSIM, DepthNormal, l1, masked_l1, psnr};
use trisplat_splat::fit::sh_schedule::{active_degree, expand_sh_grads, truncate_sh};
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, ImageGrads, RenderMode, RenderOptions, backward_into,
    render_with_grad,
};
use trisplat_splat::{GaussianSet, ScaleDims};

use crate::refine::{RefineOptions, refine};

mod brdf;
mod brdf_score;
mod checkpoint;
mod inputs;
mod neural;
mod photometric;
mod score;
mod step;
mod synthetic;
mod targets;

pub use brdf::{
    BrdfFitOptions, BrdfFitted, BrdfLearningRates, DEFAULT_ENV_FIT_GREY, DEFAULT_ENV_FIT_LR,
    DEFAULT_ENV_FIT_WIDTH, EnvFit, MAX_ENV_FIT_WIDTH, fit_brdf,
};
pub use brdf_score::{LMSE_WINDOW, MaterialScores, lmse, material_scores};
pub use checkpoint::Checkpoint;
pub use inputs::{FitError, FitFrame, Target};
pub use neural::{NeuralFitOptions, NeuralFitted, fit_neural};
use photometric::{SsimCache, photometric_loss};
use score::evaluate;
pub use step::CommonOptions;
pub use synthetic::{rest_world, synthetic_materials, synthetic_scores};
pub use targets::{TargetColor, mesh_targets, read_image_targets};
pub use trisplat_splat::fit::density::DensifyOptions;

/// Options of [`fit`].
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Optimisation steps (one view each).
    pub iterations: usize,
    /// Adam's learning rates (bound parameters).
    pub lr: LearningRates,
    /// The means' learning rate at the last iteration, as a fraction of the first (3DGS:
    /// 1.6e-6 / 1.6e-4 = 0.01).
    pub means_lr_final: f64,
    /// `λ` of D-SSIM ([`DEFAULT_LAMBDA_DSSIM`]).
    pub lambda_dssim: f64,
    /// Weight of the depth L1 (needs target depths).
    pub depth_weight: f64,
    /// Weight of the alpha L1 against the target mask (needs target alphas).
    pub alpha_weight: f64,
    /// Weight of 2DGS's depth–normal consistency (2DGS mode only).
    pub normal_weight: f64,
    /// Weight of 2DGS's depth distortion, a mean over the pixels (a renderer term; 2DGS mode
    /// only).
    pub distortion_weight: f64,
    /// Refine every N iterations (`None`: never).
    pub refine_every: Option<usize>,
    /// The refine round's options (`rounds` is forced to 1 per interleaved call).
    pub refine: RefineOptions,
    /// Renderer options (3DGS mode).
    pub render: RenderOptions,
    /// Seed of the view order.
    pub seed: u64,
    /// Score the held-out views every N iterations (and at 0 and the end).
    pub eval_every: usize,
    /// Adaptive density control (`None`: the count changes only by refine rounds).
    pub densify: Option<DensifyOptions>,
    /// Raise the active SH degree by one every N iterations, from 0 up to the set's degree
    /// (`None`: every band from the start).
    pub sh_up_every: Option<usize>,
    /// Stop once this many seconds of optimisation are spent (render, losses, backward, step,
    /// densify and refine; scoring excluded), or at `iterations`, whichever comes first; the
    /// means' learning rate then decays with the larger of the two fractions done.
    pub time_budget: Option<f64>,
}

impl FitOptions {
    /// The options the appearance fits ([`fit_brdf`], [`fit_neural`]) share with this one.
    #[must_use]
    pub fn common(&self) -> CommonOptions {
        CommonOptions {
            iterations: self.iterations,
            lambda_dssim: self.lambda_dssim,
            alpha_weight: self.alpha_weight,
            render: self.render,
            seed: self.seed,
            eval_every: self.eval_every,
            time_budget: self.time_budget,
        }
    }

    /// The first option set that only the SH fit takes (the appearance fits refuse it), by its
    /// command-line name.
    #[must_use]
    pub fn sh_only_option(&self) -> Option<&'static str> {
        [
            ("--densify", self.densify.is_some()),
            ("--refine-every", self.refine_every.is_some()),
            ("--sh-up-every", self.sh_up_every.is_some()),
            ("--depth-weight", self.depth_weight > 0.0),
            ("--normal-weight", self.normal_weight > 0.0),
            ("--distortion-weight", self.distortion_weight > 0.0),
        ]
        .into_iter()
        .find_map(|(name, on)| on.then_some(name))
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            iterations: 1000,
            lr: LearningRates::BOUND,
            means_lr_final: 0.01,
            lambda_dssim: DEFAULT_LAMBDA_DSSIM,
            depth_weight: 0.0,
            alpha_weight: 0.0,
            normal_weight: 0.0,
            distortion_weight: 0.0,
            refine_every: None,
            refine: RefineOptions::default(),
            render: RenderOptions::default(),
            seed: 0,
            eval_every: 100,
            densify: None,
            sh_up_every: None,
            time_budget: None,
        }
    }
}

/// One interleaved refine round.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RefineEvent {
    /// After this many iterations.
    pub iteration: usize,
    /// Gaussians before and after.
    pub before: usize,
    /// After.
    pub after: usize,
    /// Milliseconds.
    pub ms: f64,
}

/// One densification step (clone, split, prune) of a fit.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DensifyEvent {
    /// After this many iterations.
    pub iteration: usize,
    /// Gaussians cloned.
    pub cloned: usize,
    /// Gaussians split (each replaced by 2 children).
    pub split: usize,
    /// Gaussians pruned.
    pub pruned: usize,
    /// Flagged for pruning but kept as their triangle's last.
    pub spared: usize,
    /// Gaussians after.
    pub gaussians: usize,
    /// Milliseconds.
    pub ms: f64,
}

/// Milliseconds per iteration of each stage (means over the run).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageMs {
    /// Placing the set with the frame's triangle frames.
    pub place: f64,
    /// The differentiable render.
    pub render: f64,
    /// The losses and their image gradients.
    pub loss: f64,
    /// The backward pass.
    pub backward: f64,
    /// The chain rule to the local parameters and the Adam step.
    pub step: f64,
}

/// The result of [`fit`].
#[derive(Clone, Debug)]
pub struct Fitted {
    /// The fitted bound set.
    pub set: GaussianSet,
    /// Checkpoints in order.
    pub checkpoints: Vec<Checkpoint>,
    /// Refine rounds in order.
    pub refines: Vec<RefineEvent>,
    /// Iterations run (fewer than asked when the time budget ran out).
    pub iterations: usize,
    /// Whether the time budget ended the fit.
    pub out_of_time: bool,
    /// Densification steps in order (empty without `densify`).
    pub densify: Vec<DensifyEvent>,
    /// Iterations after which the opacities were reset.
    pub opacity_resets: Vec<usize>,
    /// Seconds per iteration (optimisation only: render, loss, backward, step).
    pub seconds_per_iteration: f64,
    /// The stages of an iteration, mean milliseconds.
    pub stage_ms: StageMs,
}

fn check_options(o: &FitOptions) -> Result<(), FitError> {
    let bad = |m: String| Err(FitError::BadOption(m));
    if o.iterations == 0 {
        return bad("--iterations must be at least 1".into());
    }
    if o.render.mode == RenderMode::Perspective {
        return bad(
            "fitting in perspective mode is not supported (no backward pass): use 3dgs or 2dgs"
                .into(),
        );
    }
    for (name, v) in [
        ("lambda-dssim", o.lambda_dssim),
        ("depth-weight", o.depth_weight),
        ("alpha-weight", o.alpha_weight),
        ("normal-weight", o.normal_weight),
        ("distortion-weight", o.distortion_weight),
        ("means-lr-final", o.means_lr_final),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("--{name} {v}: expected a finite number >= 0"));
        }
    }
    if o.lambda_dssim > 1.0 {
        return bad(format!("--lambda-dssim {}: expected 0..1", o.lambda_dssim));
    }
    let lr = o.lr;
    for v in [
        lr.means,
        lr.log_scales,
        lr.rotations,
        lr.opacities,
        lr.sh_dc,
        lr.sh_rest,
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("learning rate {v}: expected a finite number >= 0"));
        }
    }
    let surfels = o.render.mode == RenderMode::Surfel2d;
    if o.normal_weight > 0.0 && !surfels {
        return bad(
            "--normal-weight: the depth-normal consistency term needs the surfels' normal image \
             (--mode 2dgs); 3dgs renders none"
                .into(),
        );
    }
    if o.distortion_weight > 0.0 && !surfels {
        return bad(
            "--distortion-weight: the depth-distortion term is 2DGS's (--mode 2dgs)".into(),
        );
    }
    if o.refine_every == Some(0) || o.eval_every == 0 {
        return bad("--refine-every and --eval-every must be at least 1".into());
    }
    if let Some(t) = o.time_budget
        && !(t.is_finite() && t > 0.0)
    {
        return bad(format!(
            "--time-budget {t}: expected a number of seconds > 0"
        ));
    }
    if o.sh_up_every == Some(0) {
        return bad("--sh-up-every must be at least 1".into());
    }
    if let Some(d) = &o.densify {
        d.check().map_err(FitError::BadOption)?;
    }
    Ok(())
}

fn check_target(t: &Target, what: &str, o: &FitOptions) -> Result<(), FitError> {
    let px = t.camera.width as usize * t.camera.height as usize;
    let name = &t.camera.name;
    let size = |got: usize, want: usize, image: &str| {
        if got == want {
            Ok(())
        } else {
            Err(FitError::Target(format!(
                "{what} view '{name}': the {image} image has {got} values, the camera wants {want}"
            )))
        }
    };
    size(t.rgb.len(), 3 * px, "rgb")?;
    if let Some(a) = &t.alpha {
        size(a.len(), px, "alpha")?;
    }
    if let Some(d) = &t.depth {
        size(d.len(), px, "depth")?;
    }
    if o.depth_weight > 0.0 && (t.depth.is_none() || t.alpha.is_none()) {
        return Err(FitError::Target(format!(
            "{what} view '{name}': --depth-weight needs target depth and alpha"
        )));
    }
    if o.alpha_weight > 0.0 && t.alpha.is_none() {
        return Err(FitError::Target(format!(
            "{what} view '{name}': --alpha-weight needs a target mask"
        )));
    }
    Ok(())
}

/// Per-view image buffers reused across iterations.
#[derive(Default)]
struct Buffers {
    g_rgb: Vec<f32>,
    g_alpha: Vec<f32>,
    g_depth: Vec<f32>,
    g_normal: Vec<f32>,
    depth_normal: DepthNormal,
}

/// Fits `set` (bound to `template`, GaussianAvatars binding mode) to the targets of `frames`,
/// scoring `held_out` at checkpoints; `on_checkpoint` is called with each checkpoint as it is
/// made (progress).
///
/// # Errors
/// [`FitError`]: bad options, a set that cannot be fitted, targets that do not fit their
/// cameras, a renderer or refine failure, non-finite parameters.
pub fn fit(
    set: &GaussianSet,
    template: &TriMesh,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    options: &FitOptions,
    mut on_checkpoint: impl FnMut(&Checkpoint),
) -> Result<Fitted, FitError> {
    check_options(options)?;
    if set.scale_dims() == ScaleDims::Two && options.render.mode != RenderMode::Surfel2d {
        return Err(FitError::BadOption(
            "the Gaussians are 2-scale surfels: fit them in 2dgs mode (--mode 2dgs)".into(),
        ));
    }
    // The depth-normal term compares camera-frame normals.
    let mut render_options = options.render;
    render_options.normal_frame = NormalFrame::Camera;
    let options = &FitOptions {
        render: render_options,
        ..options.clone()
    };
    if frames.iter().all(|f| f.targets.is_empty()) {
        return Err(FitError::Target("no training views".into()));
    }
    for f in frames {
        for t in &f.targets {
            check_target(t, "training", options)?;
        }
    }
    for f in held_out {
        for t in &f.targets {
            check_target(t, "held-out", &FitOptions::default())?;
        }
    }
    let ntri = template.triangle_count();
    let mut bound = BoundParams::from_set(set, ntri)?;
    if bound.is_empty() {
        return Err(FitError::BadOption("the set has no Gaussians".into()));
    }
    let mut current = set.clone();
    let frames_of = |f: &FitFrame| TriangleFrames::binding(template, &f.positions);
    let train_frames: Vec<TriangleFrames> = frames.iter().map(frames_of).collect();
    let eval_frames: Vec<TriangleFrames> = held_out.iter().map(frames_of).collect();
    let pairs: Vec<(usize, usize)> = frames
        .iter()
        .enumerate()
        .flat_map(|(f, fr)| (0..fr.targets.len()).map(move |v| (f, v)))
        .collect();

    let full_degree = bound.local.sh_degree.min(3);
    // Densification: the template's rest frames (the size rule), the 3DGS camera extent.
    let rest_frames = TriangleFrames::binding(template, template.positions());
    let extent = scene_extent(frames, template);
    let mut stats = DensityStats::new(if options.densify.is_some() {
        bound.len()
    } else {
        0
    });
    let mut densify_events = Vec::new();
    let mut opacity_resets = Vec::new();
    let mut densify_s = 0.0;

    let mut adam = Adam::new(options.lr, bound.len(), bound.local.sh_per_gaussian());
    let mut rng = Rng::new(options.seed);
    let mut world = GaussianParams::default();
    let mut g_world = GaussianGrads::default();
    let mut g_local = GaussianGrads::default();
    let mut buffers = Buffers::default();
    // One SSIM workspace, remade when the image size changes.
    let mut ssim = SsimCache::default();
    let mut checkpoints = Vec::new();
    let mut refines = Vec::new();
    let mut train_s = 0.0;
    let mut stage = StageMs::default();
    let mut refine_s = 0.0;
    let (mut acc_loss, mut acc_l1, mut acc_psnr, mut acc_n) = (0.0, 0.0, 0.0, 0usize);

    let mut score =
        |bound: &BoundParams, iteration: usize, seconds: f64, acc: (f64, f64, f64, usize)| {
            let (loss, l1v, ps, n) = acc;
            let mean = |v: f64| (n > 0).then(|| v / n as f64);
            // Held-out views are rendered with the bands the training render uses.
            let sh_degree = active_degree(iteration, options.sh_up_every, full_degree);
            let cut;
            let scored = if sh_degree < full_degree {
                let mut b = bound.clone();
                truncate_sh(&mut b.local, sh_degree);
                cut = b;
                &cut
            } else {
                bound
            };
            let scores = evaluate(scored, held_out, &eval_frames, &options.render);
            let c = Checkpoint {
                iteration,
                loss: mean(loss),
                train_l1: mean(l1v),
                train_psnr: mean(ps),
                eval_psnr: scores.psnr,
                eval_ssim: scores.ssim,
                eval_depth_l1: scores.depth_l1,
                eval_normal_deg: scores.normal_deg,
                gaussians: bound.len(),
                sh_degree,
                seconds,
            };
            on_checkpoint(&c);
            c
        };
    checkpoints.push(score(&bound, 0, 0.0, (0.0, 0.0, 0.0, 0)));

    let base_lr = options.lr.means;
    // The iterations run, and the last one: `options.iterations`, or the one that used up the
    // time budget.
    let mut last = options.iterations;
    let mut out_of_time = false;
    for it in 0..options.iterations {
        let start = Instant::now();
        let spent = train_s + refine_s + densify_s;
        let progress = (it as f64 / (options.iterations.max(2) - 1) as f64)
            .max(options.time_budget.map_or(0.0, |b| spent / b))
            .min(1.0);
        adam.lr.means = base_lr * options.means_lr_final.powf(progress);
        let (f, v) =
            pairs[((rng.uniform_f64() * pairs.len() as f64) as usize).min(pairs.len() - 1)];
        let target = &frames[f].targets[v];
        let camera = &target.camera;
        let mut lap = Instant::now();
        let mut tick = |slot: &mut f64| {
            *slot += lap.elapsed().as_secs_f64() * 1e3;
            lap = Instant::now();
        };
        to_world(&bound, &train_frames[f], &mut world);
        let sh_active = active_degree(it + 1, options.sh_up_every, full_degree);
        truncate_sh(&mut world, sh_active);
        tick(&mut stage.place);
        let render_err = |source| FitError::Render {
            iteration: it,
            view: camera.name.clone(),
            source,
        };
        let fwd =
            render_with_grad::<f32, _>(&world, camera, &options.render).map_err(render_err)?;
        tick(&mut stage.render);
        let b = &mut buffers;
        let size = (camera.width as usize, camera.height as usize);
        let px = size.0 * size.1;
        let photometric = photometric_loss(
            &fwd.rgb,
            &target.rgb,
            size,
            options.lambda_dssim,
            &mut ssim,
            &mut b.g_rgb,
        );
        let mut loss = photometric.loss;
        // Each term adds its gradient into its image's buffer; the buffers are lent to the
        // backward pass once all are made.
        let depth_term = options.depth_weight > 0.0;
        let normal_term = options.normal_weight > 0.0;
        if depth_term || normal_term {
            reset(&mut b.g_depth, px);
        }
        if depth_term && let (Some(d), Some(a)) = (&target.depth, &target.alpha) {
            loss += options.depth_weight
                * masked_l1(&fwd.depth, d, a, options.depth_weight, &mut b.g_depth);
        }
        if options.alpha_weight > 0.0 {
            reset(&mut b.g_alpha, px);
            if let Some(a) = &target.alpha {
                loss +=
                    options.alpha_weight * l1(&fwd.alpha, a, options.alpha_weight, &mut b.g_alpha);
            }
        }
        if normal_term {
            // 2DGS's depth-normal consistency on the rendered depth and normal images,
            // weighted by the rendered alpha (held fixed).
            reset(&mut b.g_normal, 3 * px);
            loss += options.normal_weight
                * b.depth_normal.loss(
                    camera,
                    &fwd.depth,
                    &fwd.normal,
                    &fwd.alpha,
                    options.normal_weight,
                    Some(&mut b.g_depth),
                    Some(&mut b.g_normal),
                );
        }
        // The distortion is the renderer's own term (its value comes with the forward, its
        // gradient with the backward pass), as a mean over the pixels like 2DGS's
        // `rend_dist.mean()`.
        let distortion = options.distortion_weight / px as f64;
        if distortion > 0.0 {
            loss += distortion * fwd.distortion_total();
        }
        let grads = ImageGrads {
            rgb: Some(&b.g_rgb[..]),
            depth: (depth_term || normal_term).then_some(&b.g_depth[..]),
            alpha: (options.alpha_weight > 0.0).then_some(&b.g_alpha[..]),
            normal: normal_term.then_some(&b.g_normal[..]),
            distortion: distortion as f32,
        };
        tick(&mut stage.loss);
        if g_world.len() != bound.len() || g_world.sh.len() != world.sh.len() {
            g_world = GaussianGrads::zeros(bound.len(), world.sh_degree);
        } else {
            g_world.clear();
        }
        backward_into(&world, camera, &options.render, &fwd, &grads, &mut g_world)
            .map_err(render_err)?;
        tick(&mut stage.backward);
        if let Some(d) = &options.densify
            && d.gathers(it + 1)
        {
            stats.add_view(
                &g_world.means2d,
                fwd.visible_ids(),
                camera.width,
                camera.height,
            );
        }
        grads_to_local(&bound, &train_frames[f], &g_world, &mut g_local);
        expand_sh_grads(&mut g_local.sh, bound.len(), sh_active, full_degree);
        adam.step(&mut bound.local, &g_local);
        tick(&mut stage.step);
        acc_loss += loss;
        acc_l1 += photometric.l1;
        acc_psnr += psnr(&fwd.rgb, &target.rgb);
        acc_n += 1;
        train_s += start.elapsed().as_secs_f64();

        let done = it + 1;
        if options
            .time_budget
            .is_some_and(|b| train_s + refine_s + densify_s >= b)
        {
            last = done;
            out_of_time = true;
        }
        if let Some(d) = &options.densify {
            if d.densifies_at(done, last) {
                let start = Instant::now();
                // One sampling seed per event.
                let seed = splitmix64(options.seed ^ splitmix64(done as u64));
                let step = densify_and_prune(
                    &mut bound,
                    &mut adam,
                    &stats,
                    &rest_frames,
                    extent,
                    d,
                    !opacity_resets.is_empty(),
                    seed,
                )
                .map_err(|source| FitError::Densify {
                    iteration: done,
                    source,
                })?;
                current = current.select(&step.origins);
                stats.reset(bound.len());
                let ms = start.elapsed().as_secs_f64() * 1e3;
                densify_s += ms / 1e3;
                let c = step.counts;
                densify_events.push(DensifyEvent {
                    iteration: done,
                    cloned: c.cloned,
                    split: c.split,
                    pruned: c.pruned,
                    spared: c.spared,
                    gaussians: c.count,
                    ms,
                });
            }
            if d.resets_opacity_at(done, last) {
                reset_opacity(&mut bound, &mut adam, RESET_OPACITY);
                opacity_resets.push(done);
            }
        }
        if let Some(every) = options.refine_every
            && done % every == 0
            && done < last
        {
            let start = Instant::now();
            let before = bound.len();
            let as_set = bound.write_into(&current);
            let round = RefineOptions {
                rounds: 1,
                ..options.refine.clone()
            };
            let refined = refine(&as_set, template, &round, |_, _| {}).map_err(|source| {
                FitError::Refine {
                    iteration: done,
                    source,
                }
            })?;
            current = refined.set;
            bound = BoundParams::from_set(&current, ntri)?;
            adam.reset(bound.len());
            if options.densify.is_some() {
                stats.reset(bound.len());
            }
            let ms = start.elapsed().as_secs_f64() * 1e3;
            refine_s += ms / 1e3;
            refines.push(RefineEvent {
                iteration: done,
                before,
                after: bound.len(),
                ms,
            });
        }
        if done % options.eval_every == 0 || done == last {
            if !all_finite(&bound.local) {
                return Err(FitError::NonFinite(done));
            }
            let acc = (acc_loss, acc_l1, acc_psnr, acc_n);
            checkpoints.push(score(&bound, done, train_s + refine_s + densify_s, acc));
            (acc_loss, acc_l1, acc_psnr, acc_n) = (0.0, 0.0, 0.0, 0);
        }
        if out_of_time {
            break;
        }
    }
    let n = last as f64;
    Ok(Fitted {
        set: bound.write_into(&current),
        checkpoints,
        refines,
        iterations: last,
        out_of_time,
        densify: densify_events,
        opacity_resets,
        seconds_per_iteration: train_s / n,
        stage_ms: StageMs {
            place: stage.place / n,
            render: stage.render / n,
            loss: stage.loss / n,
            backward: stage.backward / n,
            step: stage.step / n,
        },
    })
}

/// 3DGS's camera extent ([`camera_extent`]) of the training cameras; with one camera position,
/// 1.1 × its distance to the template's centroid.
fn scene_extent(frames: &[FitFrame], template: &TriMesh) -> f64 {
    let centres: Vec<DVec3> = frames
        .iter()
        .flat_map(|f| f.targets.iter().map(|t| t.camera.position()))
        .collect();
    let extent = camera_extent(&centres);
    if extent > 0.0 {
        return extent;
    }
    let p = template.positions();
    let centroid = p.iter().copied().sum::<DVec3>() / p.len().max(1) as f64;
    centres
        .first()
        .map_or(1.0, |c| 1.1 * c.distance(centroid))
        .max(f64::MIN_POSITIVE)
}

fn reset(v: &mut Vec<f32>, n: usize) {
    v.clear();
    v.resize(n, 0.0);
}
