//! `trisplat fit --appearance mlp`: fitting a neural appearance model (docs/conventions.md §5
//! "Neural appearance") to target images, the Gaussians' geometry held fixed.
//!
//! Per iteration one (frame, view) pair drawn with the seed, as the SH fit does; the bound set
//! placed with that frame's triangle frames; the model's opacity and view-dependent colour for
//! that camera ([`trisplat_splat::neural::forward`]) written as degree-0 SH and opacity logits;
//! the 3DGS (or 2DGS) render and backward pass in `f32`; the loss `(1 − λ) L1 + λ D-SSIM` on
//! rgb plus `w_alpha` × the alpha L1; the renderer's colour and opacity gradients carried into
//! the model ([`trisplat_splat::neural::backward`]) and one Adam step on the MLP weights and the
//! touched hash-table rows. The positions the hash grid encodes are the placed world positions
//! (the fit's coordinates plus `origin`), normalised into the box of the set at the template's
//! rest pose.

use std::time::Instant;

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::rng::Rng;
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, to_world};
use trisplat_splat::fit::loss::{Ssim, l1, psnr};
use trisplat_splat::neural::{
    Aabb, Appearance, NeuralAdam, NeuralAppearance, NeuralConfig, NeuralGrads, NeuralInputs,
    NeuralLearningRates, Workspace, appearance_grads, backward, bake_params, forward,
    inputs_from_params,
};
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, ImageGrads, RenderMode, RenderOptions, backward_into,
    render_with_grad,
};
use trisplat_splat::{GaussianSet, ScaleDims};

use super::checkpoint::Checkpoint;
use super::inputs::{FitError, FitFrame};
use super::photometric::{SsimCache, photometric_loss};

/// What the neural fit needs besides the common options (`FitOptions`).
#[derive(Clone, Debug)]
pub struct NeuralFitOptions {
    /// The model's shape.
    pub config: NeuralConfig,
    /// Adam's learning rates.
    pub lr: NeuralLearningRates,
    /// Where the fit's coordinate origin is in the world (the frame reference the cameras were
    /// moved by); the model encodes world positions.
    pub origin: DVec3,
}

impl Default for NeuralFitOptions {
    fn default() -> Self {
        Self {
            config: NeuralConfig::default(),
            lr: NeuralLearningRates::default(),
            origin: DVec3::ZERO,
        }
    }
}

/// The result of [`fit_neural`].
#[derive(Clone, Debug)]
pub struct NeuralFitted {
    /// The fitted model.
    pub model: NeuralAppearance<f32>,
    /// Checkpoints in order (held-out PSNR and SSIM; no depth or normal scores).
    pub checkpoints: Vec<Checkpoint>,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the time budget ended the fit.
    pub out_of_time: bool,
    /// Seconds per iteration (optimisation only).
    pub seconds_per_iteration: f64,
}

/// The common options the neural fit takes, and those it refuses.
#[derive(Clone, Debug)]
pub struct CommonOptions {
    /// Optimisation steps.
    pub iterations: usize,
    /// `λ` of D-SSIM.
    pub lambda_dssim: f64,
    /// Weight of the alpha L1 against the target mask.
    pub alpha_weight: f64,
    /// Renderer options.
    pub render: RenderOptions,
    /// Seed of the view order and of the model's initialisation.
    pub seed: u64,
    /// Score the held-out views every N iterations.
    pub eval_every: usize,
    /// Stop after the iteration that spends this many seconds.
    pub time_budget: Option<f64>,
}

fn check(o: &CommonOptions, neural: &NeuralFitOptions) -> Result<(), FitError> {
    let bad = |m: String| Err(FitError::BadOption(m));
    if o.iterations == 0 || o.eval_every == 0 {
        return bad("--iterations and --eval-every must be at least 1".into());
    }
    if o.render.mode == RenderMode::Perspective {
        return bad("fitting in perspective mode is not supported: use 3dgs or 2dgs".into());
    }
    if !(o.lambda_dssim.is_finite() && (0.0..=1.0).contains(&o.lambda_dssim)) {
        return bad(format!("--lambda-dssim {}: expected 0..1", o.lambda_dssim));
    }
    if !(o.alpha_weight.is_finite() && o.alpha_weight >= 0.0) {
        return bad(format!("--alpha-weight {}: expected >= 0", o.alpha_weight));
    }
    if let Some(t) = o.time_budget
        && !(t.is_finite() && t > 0.0)
    {
        return bad(format!(
            "--time-budget {t}: expected a number of seconds > 0"
        ));
    }
    for (name, v) in [("mlp-lr", neural.lr.mlp), ("hash-lr", neural.lr.tables)] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("--{name} {v}: expected a finite number >= 0"));
        }
    }
    neural
        .config
        .check()
        .map_err(|e| FitError::BadOption(e.to_string()))
}

/// Reused buffers of one iteration.
#[derive(Default)]
struct Buffers {
    world: GaussianParams,
    inputs: NeuralInputs,
    app: Appearance<f32>,
    ws: Workspace<f32>,
    g_world: GaussianGrads,
    g_rgb: Vec<f32>,
    g_alpha: Vec<f32>,
    d_logits: Vec<f64>,
    d_rgb: Vec<[f64; 3]>,
}

impl Buffers {
    /// Places the set with `frames` and bakes the model's appearance for `camera` into it.
    fn place(
        &mut self,
        bound: &BoundParams,
        frames: &TriangleFrames,
        model: &NeuralAppearance<f32>,
        origin: DVec3,
        camera: DVec3,
    ) -> Result<(), FitError> {
        to_world(bound, frames, &mut self.world);
        inputs_from_params(&self.world, origin, model.aabb(), &mut self.inputs)
            .map_err(|e| FitError::BadOption(e.to_string()))?;
        forward(
            model,
            &self.inputs,
            camera + origin,
            &mut self.app,
            &mut self.ws,
        );
        bake_params(&self.app, &mut self.world);
        Ok(())
    }
}

/// Fits a neural appearance model for `set` (bound to `template`; its geometry held fixed) to
/// the targets of `frames`, scoring `held_out` by PSNR and SSIM at checkpoints.
///
/// # Errors
/// [`FitError`]: bad options, a set that cannot be fitted, no training views, a renderer
/// failure, non-finite parameters.
pub fn fit_neural(
    set: &GaussianSet,
    template: &TriMesh,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    options: &CommonOptions,
    neural: &NeuralFitOptions,
    mut on_checkpoint: impl FnMut(&Checkpoint),
) -> Result<NeuralFitted, FitError> {
    check(options, neural)?;
    let pairs = training_pairs(set, frames, held_out, options)?;
    let bound = BoundParams::from_set(set, template.triangle_count())?;
    if bound.is_empty() {
        return Err(FitError::BadOption("the set has no Gaussians".into()));
    }
    let frames_of = |f: &FitFrame| TriangleFrames::binding(template, &f.positions);
    let train_frames: Vec<TriangleFrames> = frames.iter().map(frames_of).collect();
    let eval_frames: Vec<TriangleFrames> = held_out.iter().map(frames_of).collect();
    // The normalisation box: the set at the template's rest pose, in world coordinates.
    let mut rest = GaussianParams::default();
    to_world(
        &bound,
        &TriangleFrames::binding(template, template.positions()),
        &mut rest,
    );
    let aabb = Aabb::of_points(
        rest.means
            .iter()
            .map(|m| (DVec3::from_array(*m) + neural.origin).to_array()),
    )
    .map_err(|e| FitError::BadOption(e.to_string()))?;
    let mut model = NeuralAppearance::<f32>::new(neural.config, aabb, options.seed)
        .map_err(|e| FitError::BadOption(e.to_string()))?;
    let mut adam = NeuralAdam::new(neural.lr, &model);
    let mut grads = NeuralGrads::new(&model);
    let mut b = Buffers::default();
    let mut rng = Rng::new(options.seed);
    let mut ssim = SsimCache::default();
    let (mut acc_loss, mut acc_l1, mut acc_psnr, mut acc_n) = (0.0, 0.0, 0.0, 0usize);
    let mut train_s = 0.0;
    let mut checkpoints = Vec::new();
    let mut score = |model: &NeuralAppearance<f32>,
                     b: &mut Buffers,
                     iteration: usize,
                     seconds: f64,
                     acc: (f64, f64, f64, usize)|
     -> Result<Checkpoint, FitError> {
        let (mut ps, mut ss, mut count) = (0.0, 0.0, 0usize);
        for (f, fr) in held_out.iter().enumerate() {
            for t in &fr.targets {
                b.place(
                    &bound,
                    &eval_frames[f],
                    model,
                    neural.origin,
                    t.camera.position(),
                )?;
                let Ok(out) = render_with_grad::<f32, _>(&b.world, &t.camera, &options.render)
                else {
                    continue;
                };
                ps += psnr(&out.rgb, &t.rgb);
                let mut s = Ssim::new(t.camera.width as usize, t.camera.height as usize);
                ss += s.ssim(&out.rgb, &t.rgb, 3, 0.0, None);
                count += 1;
            }
        }
        let (loss, l1v, p, n) = acc;
        let mean = |v: f64, n: usize| (n > 0).then(|| v / n as f64);
        let c = Checkpoint {
            iteration,
            loss: mean(loss, n),
            train_l1: mean(l1v, n),
            train_psnr: mean(p, n),
            eval_psnr: mean(ps, count),
            eval_ssim: mean(ss, count),
            eval_depth_l1: None,
            eval_normal_deg: None,
            gaussians: bound.len(),
            sh_degree: 0,
            seconds,
        };
        on_checkpoint(&c);
        Ok(c)
    };
    checkpoints.push(score(&model, &mut b, 0, 0.0, (0.0, 0.0, 0.0, 0))?);
    let mut last = options.iterations;
    let mut out_of_time = false;
    for it in 0..options.iterations {
        let start = Instant::now();
        let (f, v) =
            pairs[((rng.uniform_f64() * pairs.len() as f64) as usize).min(pairs.len() - 1)];
        let target = &frames[f].targets[v];
        let camera = &target.camera;
        b.place(
            &bound,
            &train_frames[f],
            &model,
            neural.origin,
            camera.position(),
        )?;
        let render_err = |source| FitError::Render {
            iteration: it,
            view: camera.name.clone(),
            source,
        };
        let fwd =
            render_with_grad::<f32, _>(&b.world, camera, &options.render).map_err(render_err)?;
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
        let alpha_term = options.alpha_weight > 0.0;
        if alpha_term && let Some(a) = &target.alpha {
            b.g_alpha.clear();
            b.g_alpha.resize(px, 0.0);
            loss += options.alpha_weight * l1(&fwd.alpha, a, options.alpha_weight, &mut b.g_alpha);
        }
        let image_grads = ImageGrads {
            rgb: Some(&b.g_rgb[..]),
            alpha: alpha_term.then_some(&b.g_alpha[..]),
            ..ImageGrads::default()
        };
        if b.g_world.len() != bound.len() || b.g_world.sh.len() != 3 * bound.len() {
            b.g_world = GaussianGrads::zeros(bound.len(), 0);
        } else {
            b.g_world.clear();
        }
        backward_into(
            &b.world,
            camera,
            &options.render,
            &fwd,
            &image_grads,
            &mut b.g_world,
        )
        .map_err(render_err)?;
        appearance_grads(&b.g_world, &mut b.d_logits, &mut b.d_rgb);
        backward(
            &model,
            &b.inputs,
            camera.position() + neural.origin,
            &b.d_logits,
            &b.d_rgb,
            &mut grads,
            &mut b.ws,
        );
        adam.step(&mut model, &grads);
        grads.clear(model.config().features_per_level);
        acc_loss += loss;
        acc_l1 += photometric.l1;
        acc_psnr += psnr(&fwd.rgb, &target.rgb);
        acc_n += 1;
        train_s += start.elapsed().as_secs_f64();
        let done = it + 1;
        if options.time_budget.is_some_and(|t| train_s >= t) {
            last = done;
            out_of_time = true;
        }
        if done % options.eval_every == 0 || done == last {
            if !model
                .mlp()
                .iter()
                .chain(model.tables())
                .all(|v| v.is_finite())
            {
                return Err(FitError::NonFinite(done));
            }
            let acc = (acc_loss, acc_l1, acc_psnr, acc_n);
            checkpoints.push(score(&model, &mut b, done, train_s, acc)?);
            (acc_loss, acc_l1, acc_psnr, acc_n) = (0.0, 0.0, 0.0, 0);
        }
        if out_of_time {
            break;
        }
    }
    Ok(NeuralFitted {
        model,
        checkpoints,
        iterations: last,
        out_of_time,
        seconds_per_iteration: train_s / last as f64,
    })
}

/// The (frame, view) pairs a fit trains on, after checking what every fit needs: surfels fitted
/// in 2dgs mode, at least one training view, and each target (training or held out) fitting its
/// camera, with a mask when `--alpha-weight` asks for one.
///
/// # Errors
/// [`FitError::BadOption`] for 2-scale surfels outside 2dgs mode, [`FitError::Target`] for no
/// training view or a target that does not fit.
pub(super) fn training_pairs(
    set: &GaussianSet,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    options: &CommonOptions,
) -> Result<Vec<(usize, usize)>, FitError> {
    if set.scale_dims() == ScaleDims::Two && options.render.mode != RenderMode::Surfel2d {
        return Err(FitError::BadOption(
            "the Gaussians are 2-scale surfels: fit them in 2dgs mode (--mode 2dgs)".into(),
        ));
    }
    let pairs: Vec<(usize, usize)> = frames
        .iter()
        .enumerate()
        .flat_map(|(f, fr)| (0..fr.targets.len()).map(move |v| (f, v)))
        .collect();
    if pairs.is_empty() {
        return Err(FitError::Target("no training views".into()));
    }
    for fr in frames.iter().chain(held_out) {
        for t in &fr.targets {
            let px = t.camera.width as usize * t.camera.height as usize;
            if t.rgb.len() != 3 * px || t.alpha.as_ref().is_some_and(|a| a.len() != px) {
                return Err(FitError::Target(format!(
                    "view '{}': the images do not fit the camera",
                    t.camera.name
                )));
            }
            if options.alpha_weight > 0.0 && t.alpha.is_none() {
                return Err(FitError::Target(format!(
                    "view '{}': --alpha-weight needs a target mask",
                    t.camera.name
                )));
            }
        }
    }
    Ok(pairs)
}
