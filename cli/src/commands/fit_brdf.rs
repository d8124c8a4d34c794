//! `trisplat fit --appearance brdf --env MAP.hdr [--env-rotation DEG] [--env-intensity X]
//! [--fit-normals]`: the relightable-material fit (`pipeline::fit::fit_brdf`), writing the set
//! with its fitted materials (`albedo_0..2`, `roughness`, `reflectance`).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::TriMesh;
use trisplat_geometry::envmap::EnvMap;
use trisplat_pipeline::fit::{
    BrdfFitOptions, BrdfLearningRates, CommonOptions, FitFrame, FitOptions, fit_brdf,
};
use trisplat_splat::GaussianSet;
use trisplat_splat::material::{EnvOptions, Environment};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};

use super::fit_neural::{MlpPaths, print_checkpoint};
use super::{Context, UsageError};

/// The options of `fit --appearance brdf`.
#[derive(Debug, clap::Args)]
pub struct BrdfArgs {
    /// --appearance brdf: the environment map the targets are lit by (an equirectangular
    /// Radiance .hdr, 2:1, +Y up; docs/conventions.md §5 "Relighting").
    #[arg(long, value_name = "MAP.hdr")]
    pub env: Option<PathBuf>,
    /// Turn of the environment about +Y, degrees (as `render --env-rotation`).
    #[arg(
        long,
        value_name = "DEG",
        requires = "env",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub env_rotation: f64,
    /// Factor on the environment's radiance (as `render --env-intensity`).
    #[arg(long, value_name = "X", requires = "env", default_value_t = 1.0)]
    pub env_intensity: f32,
    /// Also fit the shading normals: the rotations and log-scales.
    #[arg(long, requires = "env")]
    pub fit_normals: bool,
    /// Adam's learning rate of the albedo logits.
    #[arg(long, value_name = "LR", default_value_t = BrdfLearningRates::default().albedo)]
    pub lr_albedo: f64,
    /// Adam's learning rate of the roughness logits.
    #[arg(long, value_name = "LR", default_value_t = BrdfLearningRates::default().roughness)]
    pub lr_roughness: f64,
    /// Adam's learning rate of the F0 logits.
    #[arg(long, value_name = "LR", default_value_t = BrdfLearningRates::default().f0)]
    pub lr_f0: f64,
    /// --fit-normals: Adam's learning rate of the raw local quaternions.
    #[arg(long, value_name = "LR", default_value_t = BrdfLearningRates::default().rotations)]
    pub lr_normal: f64,
    /// --fit-normals: Adam's learning rate of the local log-scales.
    #[arg(long, value_name = "LR", default_value_t = BrdfLearningRates::default().log_scales)]
    pub lr_normal_scales: f64,
}

/// The environment of a brdf fit, read and prepared before anything else (exit 1 naming the
/// file when it is not a valid map; a usage error when `--env` is missing or given to another
/// appearance, or its placement is out of range).
///
/// # Errors
/// As above.
pub fn open_environment(args: &BrdfArgs, brdf: bool) -> anyhow::Result<Option<Environment>> {
    let Some(path) = &args.env else {
        if brdf {
            return Err(UsageError(
                "--appearance brdf needs --env MAP.hdr, the environment the targets are lit by"
                    .into(),
            )
            .into());
        }
        return Ok(None);
    };
    if !brdf {
        return Err(UsageError(
            "--env lights a material fit: use it with --appearance brdf".into(),
        )
        .into());
    }
    if !args.env_rotation.is_finite() {
        return Err(UsageError(format!(
            "--env-rotation {}: expected a finite number",
            args.env_rotation
        ))
        .into());
    }
    if !(args.env_intensity.is_finite() && args.env_intensity >= 0.0) {
        return Err(UsageError(format!(
            "--env-intensity {}: expected a finite number >= 0",
            args.env_intensity
        ))
        .into());
    }
    let map = EnvMap::read(path)?;
    let env = Environment::new(
        &map,
        EnvOptions {
            rotation_deg: args.env_rotation,
            intensity: args.env_intensity,
        },
    )
    .with_context(|| format!("{}: --env-intensity {}", path.display(), args.env_intensity))?;
    Ok(Some(env))
}

/// Runs the brdf fit with the options `fit` parsed and writes the set with its materials.
///
/// # Errors
/// Options that only the SH fit takes, a failed fit or write (nothing is written then).
#[expect(clippy::too_many_arguments, reason = "what `fit` has read, handed on")]
pub fn run_brdf(
    paths: &MlpPaths,
    args: &BrdfArgs,
    env: &Environment,
    ctx: &Context,
    set: &GaussianSet,
    template: &TriMesh,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    options: &FitOptions,
) -> anyhow::Result<()> {
    let sh_only = [
        ("--densify", options.densify.is_some()),
        ("--refine-every", options.refine_every.is_some()),
        ("--sh-up-every", options.sh_up_every.is_some()),
        ("--depth-weight", options.depth_weight > 0.0),
        ("--normal-weight", options.normal_weight > 0.0),
        ("--distortion-weight", options.distortion_weight > 0.0),
    ];
    if let Some((name, _)) = sh_only.iter().find(|(_, on)| *on) {
        return Err(UsageError(format!(
            "{name} is an option of the SH fit; --appearance brdf fits the materials (and with \
             --fit-normals the rotations and scales) only"
        ))
        .into());
    }
    let common = CommonOptions {
        iterations: options.iterations,
        lambda_dssim: options.lambda_dssim,
        alpha_weight: options.alpha_weight,
        render: options.render,
        seed: options.seed,
        eval_every: options.eval_every,
        time_budget: options.time_budget,
    };
    let brdf = BrdfFitOptions {
        lr: BrdfLearningRates {
            albedo: args.lr_albedo,
            roughness: args.lr_roughness,
            f0: args.lr_f0,
            rotations: args.lr_normal,
            log_scales: args.lr_normal_scales,
        },
        normals: args.fit_normals,
    };
    let started = std::time::Instant::now();
    let bar = ctx
        .progress
        .bar(options.iterations as u64, "fitting (brdf)");
    let json = ctx.json;
    let fitted = fit_brdf(set, template, frames, held_out, env, &common, &brdf, |c| {
        bar.set_position(c.iteration as u64);
        if !json {
            bar.suspend(|| print_checkpoint(c));
        }
    })
    .with_context(|| {
        format!(
            "{} (template {})",
            paths.gaussians.display(),
            paths.template.display()
        )
    });
    bar.finish_and_clear();
    let fitted = fitted?;
    if !fitted.set.is_empty() && fitted.set.binding().is_none() {
        bail!("internal: the fitted set lost its binding");
    }
    write_gaussians(paths.output, &fitted.set, &PlyWriteOptions::default())?;
    let seconds = started.elapsed().as_secs_f64();
    if !json {
        println!(
            "fit (brdf{}): {} Gaussians, {} iterations{}, {:.1} ms per iteration, {seconds:.2} s; \
             wrote {}",
            if args.fit_normals { ", normals" } else { "" },
            set.len(),
            fitted.iterations,
            if fitted.out_of_time {
                " (the time budget ran out)"
            } else {
                ""
            },
            fitted.seconds_per_iteration * 1e3,
            paths.output.display()
        );
    }
    ctx.emit(
        "fit",
        serde_json::json!({
            "output": paths.output,
            "appearance": "brdf",
            "env": args.env.as_deref().map(Path::to_path_buf),
            "fit_normals": args.fit_normals,
            "template": paths.template,
            "gaussians": set.len(),
            "iterations": fitted.iterations,
            "out_of_time": fitted.out_of_time,
            "frames": frames.iter().map(|f| f.frame).collect::<Vec<_>>(),
            "ms_per_iteration": fitted.seconds_per_iteration * 1e3,
            "seconds": seconds,
            "checkpoints": fitted.checkpoints,
        }),
    )
}
