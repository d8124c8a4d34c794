//! `trisplat fit --appearance brdf`: fitting each Gaussian's material (albedo, roughness, F0;
//! docs/conventions.md §5 "Relighting") and, when asked, its shading normal (rotation and
//! log-scales) to target images lit by a known environment map.
//!
//! Per iteration one (frame, view) pair drawn with the seed, as the SH fit does; the bound set
//! placed with that frame's triangle frames ([`to_world`]); every Gaussian shaded by the split
//! sum from that camera ([`shade_params`]: shortest-axis normal facing the camera); the colours
//! rendered as degree-0 SH by the 3DGS (or 2DGS) renderer and its backward pass in `f32`; the
//! loss `(1 − λ) L1 + λ D-SSIM` on rgb ([`super::photometric`]) plus `w_alpha` × the alpha L1;
//! the renderer's colour gradients (`∂L/∂f_dc / SH_C0`) carried through the shading
//! ([`relit_backward`]) to the materials and, with `normals`, added to the renderer's own
//! rotation and log-scale gradients, carried to the local parameters ([`grads_to_local`]); one
//! Adam step (β 0.9, 0.999, ε 1e-15 as 3DGS). Means and opacities are held fixed.
//!
//! **Ranges**: each material attribute is `sigmoid(ℓ)` of an unconstrained logit `ℓ` (so always
//! strictly inside 0..1; the initial value, clamped to `[1e-4, 1 − 1e-4]`, gives `ℓ₀`), the
//! gradient `∂L/∂ℓ = ∂L/∂x · x (1 − x)`. Initial materials: the set's own, else albedo from its
//! degree-0 colour with roughness 0.9 and F0 0.04 (HRAvatar's), as `render --env` shades a set
//! without materials.
//!
//! **A jointly estimated environment** ([`EnvFit`], `--env-fit`): the map's texels are fitted too,
//! as `T = exp(θ)` per texel and channel (positive; Adam on `θ`, started from the given map or
//! a uniform grey one at a low resolution, at most [`MAX_ENV_FIT_WIDTH`] wide). Each step the
//! environment (irradiance, prefiltered chain) is prepared again from the current texels
//! ([`Environment::set_map`]), and the same colour gradients that reach the materials are
//! carried through the shading to the irradiance coefficients and the prefiltered texels
//! ([`relit_env_backward`]) and back through the preparation, linear in the texels, to `T`
//! ([`EnvGrad::to_texels`]); `∂L/∂θ = ∂L/∂T · T`. Albedo and light share a scale (and, per
//! channel, a tint): the split sum cannot tell a brighter light on a darker albedo apart, so the
//! fitted map and albedo are determined up to that factor (docs/benchmarks.md, "Relightable
//! fit", says how it is normalised when scored).

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::envmap::EnvMap;
use trisplat_geometry::rng::Rng;
use trisplat_splat::GaussianSet;
use trisplat_splat::SH_C0;
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, grads_to_local, to_world};
use trisplat_splat::material::{
    EnvGrad, EnvOptions, Environment, Material, MaterialEdits, color_grads_from_sh,
    effective_material, relit_backward, relit_env_backward, shade_params,
};
use trisplat_splat::render::{GaussianGrads, GaussianParams};

use super::checkpoint::Checkpoint;
use super::inputs::{FitError, FitFrame};
use super::step::{
    CommonOptions, Running, StepBuffers, check_rates, draw, held_out_scores, photometric_step,
    render_rgb, training_pairs,
};

/// Adam's learning rates of the BRDF fit (material logits; local rotations and log-scales).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrdfLearningRates {
    /// Albedo logits.
    pub albedo: f64,
    /// Roughness logits.
    pub roughness: f64,
    /// F0 logits.
    pub f0: f64,
    /// Raw local quaternions (with `normals`).
    pub rotations: f64,
    /// Local log-scales (with `normals`).
    pub log_scales: f64,
}

impl Default for BrdfLearningRates {
    fn default() -> Self {
        Self {
            albedo: 0.05,
            roughness: 0.05,
            f0: 0.05,
            rotations: 0.005,
            log_scales: 0.005,
        }
    }
}

/// Widest environment map [`EnvFit`] fits (the transposed prefilter costs the product of the
/// levels' texel counts per step).
pub const MAX_ENV_FIT_WIDTH: u32 = 128;

/// Default width of a fitted environment map (`--env-fit-width`).
pub const DEFAULT_ENV_FIT_WIDTH: u32 = 32;

/// Default radiance of the uniform grey map a fit starts from without `--env`.
pub const DEFAULT_ENV_FIT_GREY: f32 = 0.5;

/// Default Adam learning rate of the fitted map's log-radiance (`--lr-env`).
pub const DEFAULT_ENV_FIT_LR: f64 = 0.02;

/// Smallest radiance a fitted texel starts from (its log is the parameter).
const MIN_ENV_TEXEL: f32 = 1e-4;

/// A jointly estimated environment (module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvFit {
    /// The map the fit starts from, at the resolution it is fitted at (2:1, at most
    /// [`MAX_ENV_FIT_WIDTH`] wide); texels below 1e-4 start at 1e-4.
    pub initial: EnvMap,
    /// Its placement: rotation about +Y, and the intensity, a factor on the fitted texels.
    pub options: EnvOptions,
    /// Adam's learning rate of the texels' log-radiance.
    pub lr: f64,
}

/// What the BRDF fit needs besides the common options.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BrdfFitOptions {
    /// Adam's learning rates.
    pub lr: BrdfLearningRates,
    /// Also fit the shading normal: the local rotations and log-scales (through the shading and
    /// the renderer's footprint alike).
    pub normals: bool,
    /// Also fit the environment map, from this start (then the `env` given to [`fit_brdf`] is
    /// not read).
    pub env_fit: Option<EnvFit>,
}

/// The result of [`fit_brdf`].
#[derive(Clone, Debug)]
pub struct BrdfFitted {
    /// The bound set with its fitted material (and rotations and scales with `normals`).
    pub set: GaussianSet,
    /// Checkpoints in order (held-out PSNR and SSIM of the relit render).
    pub checkpoints: Vec<Checkpoint>,
    /// Iterations run.
    pub iterations: usize,
    /// Whether the time budget ended the fit.
    pub out_of_time: bool,
    /// Seconds per iteration (optimisation only).
    pub seconds_per_iteration: f64,
    /// The fitted environment map (with [`BrdfFitOptions::env_fit`]), at its fitted
    /// resolution, before its intensity.
    pub env: Option<EnvMap>,
}

/// Adam on a flat parameter vector, one learning rate per column of `width`.
struct FlatAdam {
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl FlatAdam {
    fn new(n: usize) -> Self {
        Self {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }

    /// One step; non-finite parameters (a surfel's `−∞` log-scale) are left as they are.
    fn step(&mut self, p: &mut [f64], g: &[f64], lr: &[f64]) {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        const EPS: f64 = 1e-15;
        self.t = self.t.saturating_add(1);
        let corr = (1.0 - B2.powi(self.t)).sqrt() / (1.0 - B1.powi(self.t));
        let w = lr.len();
        p.par_iter_mut()
            .zip(g.par_iter())
            .zip(self.m.par_iter_mut().zip(self.v.par_iter_mut()))
            .enumerate()
            .with_min_len(4096)
            .for_each(|(j, ((p, &g), (m, v)))| {
                if !p.is_finite() || !g.is_finite() {
                    return;
                }
                *m = B1 * *m + (1.0 - B1) * g;
                *v = B2 * *v + (1.0 - B2) * g * g;
                *p -= lr[j % w] * corr * *m / (v.sqrt() + EPS);
            });
    }
}

fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

fn logit(x: f32) -> f64 {
    let x = f64::from(x).clamp(1e-4, 1.0 - 1e-4);
    (x / (1.0 - x)).ln()
}

/// Material logits, 5 per Gaussian: albedo r, g, b, roughness, F0.
fn logits_of(m: &Material) -> Vec<f64> {
    (0..m.albedo.len())
        .flat_map(|i| {
            let a = m.albedo[i];
            [
                logit(a[0]),
                logit(a[1]),
                logit(a[2]),
                logit(m.roughness[i]),
                logit(m.f0[i]),
            ]
        })
        .collect()
}

fn activate(logits: &[f64], out: &mut Material) {
    let n = logits.len() / 5;
    out.albedo.resize(n, [0.0; 3]);
    out.roughness.resize(n, 0.0);
    out.f0.resize(n, 0.0);
    for (i, l) in logits.chunks_exact(5).enumerate() {
        out.albedo[i] = std::array::from_fn(|c| sigmoid(l[c]) as f32);
        out.roughness[i] = sigmoid(l[3]) as f32;
        out.f0[i] = sigmoid(l[4]) as f32;
    }
}

fn check(o: &CommonOptions, b: &BrdfFitOptions) -> Result<(), FitError> {
    let bad = |m: String| Err(FitError::BadOption(m));
    o.check()?;
    let lr = b.lr;
    check_rates(&[
        ("lr-albedo", lr.albedo),
        ("lr-roughness", lr.roughness),
        ("lr-f0", lr.f0),
        ("lr-rotations", lr.rotations),
        ("lr-scales", lr.log_scales),
    ])?;
    if let Some(e) = &b.env_fit {
        check_rates(&[("lr-env", e.lr)])?;
        if e.initial.width() > MAX_ENV_FIT_WIDTH {
            return bad(format!(
                "the environment to fit is {} texels wide; at most {MAX_ENV_FIT_WIDTH}",
                e.initial.width()
            ));
        }
        let i = e.options.intensity;
        if !(i.is_finite() && i > 0.0 && e.options.rotation_deg.is_finite()) {
            return bad(format!(
                "the fitted environment's intensity {i} must be finite and > 0, its rotation \
                 finite"
            ));
        }
    }
    Ok(())
}

/// The fitted map's texels `exp(θ)` (finite: θ is checked finite).
fn env_map_of(theta: &[f64], width: u32) -> Result<EnvMap, FitError> {
    let texels = theta
        .chunks_exact(3)
        .map(|t| std::array::from_fn(|c| t[c].exp().min(f64::from(f32::MAX)) as f32))
        .collect();
    EnvMap::try_new(width, width / 2, texels)
        .map_err(|e| FitError::BadOption(format!("the fitted environment: {e}")))
}

/// Reused buffers of one iteration.
#[derive(Default)]
struct Buffers {
    world: GaussianParams,
    material: Material,
    g_world: GaussianGrads,
    g_local: GaussianGrads,
    step: StepBuffers,
    d_colors: Vec<[f32; 3]>,
    g_logits: Vec<f64>,
}

impl Buffers {
    /// Places the set with `frames` and writes its colours relit from `eye` as degree-0 SH.
    fn place(
        &mut self,
        bound: &BoundParams,
        frames: &TriangleFrames,
        logits: &[f64],
        eye: DVec3,
        env: &Environment,
    ) {
        to_world(bound, frames, &mut self.world);
        activate(logits, &mut self.material);
        let relit = shade_params(&self.world, &self.material, eye, env);
        self.world.sh_degree = 0;
        self.world.sh.clear();
        self.world.sh.extend(
            relit
                .colors
                .iter()
                .flat_map(|c| c.map(|v| (f64::from(v) - 0.5) / SH_C0)),
        );
    }
}

/// Fits the materials (and with `brdf.normals` the rotations and scales) of `set` (bound to
/// `template`) to the targets of `frames` lit by `env`, scoring `held_out` by PSNR and SSIM
/// at checkpoints.
///
/// # Errors
/// [`FitError`]: bad options, a set that cannot be fitted, no training views, targets that do
/// not fit their cameras, a renderer failure, non-finite parameters.
#[expect(
    clippy::too_many_arguments,
    reason = "the fit's inputs, as the other fits take them"
)]
pub fn fit_brdf(
    set: &GaussianSet,
    template: &TriMesh,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    env: &Environment,
    options: &CommonOptions,
    brdf: &BrdfFitOptions,
    mut on_checkpoint: impl FnMut(&Checkpoint),
) -> Result<BrdfFitted, FitError> {
    check(options, brdf)?;
    let pairs = training_pairs(set, frames, held_out, options)?;
    // The environment: as given, or the one being fitted (its log-texels `env_theta`).
    let mut fitted_env = None;
    let mut env_theta = Vec::new();
    if let Some(e) = &brdf.env_fit {
        fitted_env = Some(
            Environment::new(&e.initial, e.options)
                .map_err(|err| FitError::BadOption(format!("the environment to fit: {err}")))?,
        );
        env_theta = e
            .initial
            .texels()
            .iter()
            .flat_map(|t| t.map(|v| f64::from(v.max(MIN_ENV_TEXEL)).ln()))
            .collect();
    }
    let mut env_map = brdf
        .env_fit
        .as_ref()
        .map(|e| env_map_of(&env_theta, e.initial.width()))
        .transpose()?;
    if let (Some(map), Some(fit), Some(current)) = (&env_map, &brdf.env_fit, &mut fitted_env) {
        current
            .set_map(map, fit.options.intensity)
            .map_err(|err| FitError::BadOption(format!("the environment to fit: {err}")))?;
    }
    let mut adam_env = FlatAdam::new(env_theta.len());
    let mut g_env = Vec::new();
    let mut bound = BoundParams::from_set(set, template.triangle_count())?;
    if bound.is_empty() {
        return Err(FitError::BadOption("the set has no Gaussians".into()));
    }
    let n = bound.len();
    let frames_of = |f: &FitFrame| TriangleFrames::binding(template, &f.positions);
    let train_frames: Vec<TriangleFrames> = frames.iter().map(frames_of).collect();
    let eval_frames: Vec<TriangleFrames> = held_out.iter().map(frames_of).collect();
    let mut logits = logits_of(&effective_material(set, &MaterialEdits::default()));
    let lr = brdf.lr;
    let material_lr = [lr.albedo, lr.albedo, lr.albedo, lr.roughness, lr.f0];
    let mut adam_material = FlatAdam::new(logits.len());
    let mut adam_rotations = FlatAdam::new(4 * n);
    let mut adam_scales = FlatAdam::new(3 * n);
    let mut b = Buffers::default();
    let mut rng = Rng::new(options.seed);
    let mut running = Running::default();
    let mut train_s = 0.0;
    let mut checkpoints = Vec::new();
    let mut score = |bound: &BoundParams,
                     logits: &[f64],
                     env: &Environment,
                     b: &mut Buffers,
                     running: &mut Running,
                     iteration: usize,
                     seconds: f64|
     -> Result<Checkpoint, FitError> {
        let eval = held_out_scores(held_out, |f, t| {
            b.place(bound, &eval_frames[f], logits, t.camera.position(), env);
            Ok(render_rgb(&b.world, t, &options.render))
        })?;
        let c = running.checkpoint(iteration, eval, bound.len(), seconds);
        on_checkpoint(&c);
        Ok(c)
    };
    checkpoints.push(score(
        &bound,
        &logits,
        fitted_env.as_ref().unwrap_or(env),
        &mut b,
        &mut running,
        0,
        0.0,
    )?);
    let mut last = options.iterations;
    let mut out_of_time = false;
    for it in 0..options.iterations {
        let start = Instant::now();
        let (f, v) = draw(&mut rng, &pairs);
        let target = &frames[f].targets[v];
        let eye = target.camera.position();
        let env_now = fitted_env.as_ref().unwrap_or(env);
        b.place(&bound, &train_frames[f], &logits, eye, env_now);
        let step = photometric_step(&b.world, target, options, it, &mut b.step, &mut b.g_world)?;
        color_grads_from_sh(&b.g_world.sh, &mut b.d_colors);
        let grads = relit_backward(
            &b.world,
            &b.material,
            eye,
            env_now,
            &b.d_colors,
            &mut b.g_world,
        );
        if let (Some(fit), Some(map)) = (&brdf.env_fit, &env_map) {
            let mut acc = EnvGrad::zeros(env_now);
            relit_env_backward(&b.world, &b.material, eye, env_now, &b.d_colors, &mut acc);
            g_env.clear();
            g_env.extend(
                acc.to_texels(map, fit.options)
                    .iter()
                    .zip(map.texels())
                    .flat_map(|(g, t)| {
                        std::array::from_fn::<f64, 3, _>(|c| g[c] * f64::from(t[c]))
                    }),
            );
            adam_env.step(&mut env_theta, &g_env, &[fit.lr]);
            if env_theta.iter().any(|v| !v.is_finite()) {
                return Err(FitError::NonFinite(it + 1));
            }
            let next = env_map_of(&env_theta, map.width())?;
            if let Some(current) = &mut fitted_env {
                current
                    .set_map(&next, fit.options.intensity)
                    .map_err(|err| FitError::BadOption(format!("the fitted environment: {err}")))?;
            }
            env_map = Some(next);
        }
        // Through the sigmoids.
        b.g_logits.clear();
        b.g_logits.extend((0..n).flat_map(|i| {
            let m = &b.material;
            let d = |x: f32, g: f32| f64::from(g) * f64::from(x) * (1.0 - f64::from(x));
            let a = m.albedo[i];
            let ga = grads.albedo[i];
            [
                d(a[0], ga[0]),
                d(a[1], ga[1]),
                d(a[2], ga[2]),
                d(m.roughness[i], grads.roughness[i]),
                d(m.f0[i], grads.f0[i]),
            ]
        }));
        adam_material.step(&mut logits, &b.g_logits, &material_lr);
        if brdf.normals {
            grads_to_local(&bound, &train_frames[f], &b.g_world, &mut b.g_local);
            adam_rotations.step(
                bound.local.rotations.as_flattened_mut(),
                b.g_local.rotations.as_flattened(),
                &[lr.rotations],
            );
            adam_scales.step(
                bound.local.log_scales.as_flattened_mut(),
                b.g_local.log_scales.as_flattened(),
                &[lr.log_scales],
            );
        }
        running.add(step);
        train_s += start.elapsed().as_secs_f64();
        let done = it + 1;
        if options.time_budget.is_some_and(|t| train_s >= t) {
            last = done;
            out_of_time = true;
        }
        if done % options.eval_every == 0 || done == last {
            let finite = logits.iter().all(|v| v.is_finite())
                && bound
                    .local
                    .rotations
                    .as_flattened()
                    .iter()
                    .all(|v| v.is_finite())
                && bound
                    .local
                    .log_scales
                    .as_flattened()
                    .iter()
                    .all(|v| v.is_finite() || *v == f64::NEG_INFINITY);
            if !finite {
                return Err(FitError::NonFinite(done));
            }
            checkpoints.push(score(
                &bound,
                &logits,
                fitted_env.as_ref().unwrap_or(env),
                &mut b,
                &mut running,
                done,
                train_s,
            )?);
        }
        if out_of_time {
            break;
        }
    }
    let mut out = bound.write_into(set);
    let mut material = Material::default();
    activate(&logits, &mut material);
    out.set_material(Some(material))
        .map_err(|e| FitError::BadOption(format!("the fitted material: {e}")))?;
    Ok(BrdfFitted {
        set: out,
        checkpoints,
        iterations: last,
        out_of_time,
        seconds_per_iteration: train_s / last as f64,
        env: env_map,
    })
}
