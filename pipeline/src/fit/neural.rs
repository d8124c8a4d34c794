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
use trisplat_splat::GaussianSet;
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, to_world};
use trisplat_splat::neural::{
    Aabb, Appearance, NeuralAdam, NeuralAppearance, NeuralConfig, NeuralGrads, NeuralInputs,
    NeuralLearningRates, Workspace, appearance_grads, backward, bake_params, forward,
    inputs_from_params,
};
use trisplat_splat::render::{GaussianGrads, GaussianParams};

use super::checkpoint::Checkpoint;
use super::inputs::{FitError, FitFrame};
use super::step::{
    CommonOptions, Running, StepBuffers, check_rates, draw, held_out_scores, photometric_step,
    render_rgb, training_pairs,
};

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

fn check(o: &CommonOptions, neural: &NeuralFitOptions) -> Result<(), FitError> {
    o.check()?;
    check_rates(&[("mlp-lr", neural.lr.mlp), ("hash-lr", neural.lr.tables)])?;
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
    step: StepBuffers,
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
    let mut running = Running::default();
    let mut train_s = 0.0;
    let mut checkpoints = Vec::new();
    let mut score = |model: &NeuralAppearance<f32>,
                     b: &mut Buffers,
                     running: &mut Running,
                     iteration: usize,
                     seconds: f64|
     -> Result<Checkpoint, FitError> {
        let eval = held_out_scores(held_out, |f, t| {
            b.place(
                &bound,
                &eval_frames[f],
                model,
                neural.origin,
                t.camera.position(),
            )?;
            Ok(render_rgb(&b.world, t, &options.render))
        })?;
        let c = running.checkpoint(iteration, eval, bound.len(), seconds);
        on_checkpoint(&c);
        Ok(c)
    };
    checkpoints.push(score(&model, &mut b, &mut running, 0, 0.0)?);
    let mut last = options.iterations;
    let mut out_of_time = false;
    for it in 0..options.iterations {
        let start = Instant::now();
        let (f, v) = draw(&mut rng, &pairs);
        let target = &frames[f].targets[v];
        let camera = &target.camera;
        b.place(
            &bound,
            &train_frames[f],
            &model,
            neural.origin,
            camera.position(),
        )?;
        let step = photometric_step(&b.world, target, options, it, &mut b.step, &mut b.g_world)?;
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
        running.add(step);
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
            checkpoints.push(score(&model, &mut b, &mut running, done, train_s)?);
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
