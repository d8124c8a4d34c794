//! `trisplat fit --appearance brdf (--env MAP.hdr | --env-fit) [--env-rotation DEG]
//! [--env-intensity X] [--fit-normals] [--env-fit [--env-fit-width W] [--lr-env LR]]`: the
//! relightable-material fit (`pipeline::fit::fit_brdf`), writing the set with its fitted
//! materials (`albedo_0..2`, `roughness`, `reflectance`) and, with `--env-fit`, the fitted
//! environment beside it (`OUT.env.hdr`).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::TriMesh;
use trisplat_geometry::envmap::EnvMap;
use trisplat_pipeline::fit::{
    BrdfFitOptions, BrdfLearningRates, DEFAULT_ENV_FIT_GREY, DEFAULT_ENV_FIT_LR,
    DEFAULT_ENV_FIT_WIDTH, EnvFit, FitFrame, FitOptions, MAX_ENV_FIT_WIDTH, fit_brdf,
};
use trisplat_splat::GaussianSet;
use trisplat_splat::material::{EnvOptions, Environment};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};

use super::fit_run::{MlpPaths, out_of_time_note, refuse_sh_options, with_progress};
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
    #[arg(long)]
    pub fit_normals: bool,
    /// Also fit the environment map (its texels' log-radiance), from --env's map downsampled
    /// to --env-fit-width, or without --env from a uniform grey one; written as OUT.env.hdr.
    #[arg(long)]
    pub env_fit: bool,
    /// --env-fit: width of the fitted map in texels (even, 8 to 128; height half of it).
    #[arg(long, value_name = "W", requires = "env_fit", default_value_t = DEFAULT_ENV_FIT_WIDTH)]
    pub env_fit_width: u32,
    /// --env-fit: Adam's learning rate of the fitted map's log-radiance.
    #[arg(long, value_name = "LR", requires = "env_fit", default_value_t = DEFAULT_ENV_FIT_LR)]
    pub lr_env: f64,
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

/// The environment of a brdf fit: the known one, or the start of the fitted one.
pub struct BrdfEnv {
    /// The environment the fit shades with (the start of the fitted one with --env-fit).
    pub env: Environment,
    /// With --env-fit: the fitted map's start and placement.
    pub fit: Option<EnvFit>,
}

/// The environment of a brdf fit, read and prepared before anything else (exit 1 naming the
/// file when it is not a valid map; a usage error when `--env` and `--env-fit` are both
/// missing, or given to another appearance, or the placement or width is out of range).
///
/// # Errors
/// As above.
pub fn open_environment(args: &BrdfArgs, brdf: bool) -> anyhow::Result<Option<BrdfEnv>> {
    if !brdf {
        let given = [
            ("--env", args.env.is_some()),
            ("--env-fit", args.env_fit),
            ("--fit-normals", args.fit_normals),
        ];
        if let Some((name, _)) = given.iter().find(|(_, on)| *on) {
            return Err(UsageError(format!(
                "{name} belongs to a material fit: use it with --appearance brdf"
            ))
            .into());
        }
        return Ok(None);
    }
    if args.env.is_none() && !args.env_fit {
        return Err(UsageError(
            "--appearance brdf needs --env MAP.hdr, the environment the targets are lit by, or \
             --env-fit to estimate it"
                .into(),
        )
        .into());
    }
    let w = args.env_fit_width;
    if args.env_fit && (!(8..=MAX_ENV_FIT_WIDTH).contains(&w) || !w.is_multiple_of(2)) {
        return Err(UsageError(format!(
            "--env-fit-width {w}: expected an even number from 8 to {MAX_ENV_FIT_WIDTH}"
        ))
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
    let options = EnvOptions {
        rotation_deg: args.env_rotation,
        intensity: args.env_intensity,
    };
    let (map, name) = match &args.env {
        Some(path) => (EnvMap::read(path)?, path.display().to_string()),
        None => (
            EnvMap::uniform(w / 2, [DEFAULT_ENV_FIT_GREY; 3])?,
            "the uniform grey start of --env-fit".into(),
        ),
    };
    let map = if args.env_fit {
        map.downsampled(w)
    } else {
        map
    };
    if args.env_fit && args.env_intensity == 0.0 {
        return Err(UsageError("--env-fit needs --env-intensity > 0".into()).into());
    }
    let env = Environment::new(&map, options)
        .with_context(|| format!("{name}: --env-intensity {}", args.env_intensity))?;
    let fit = args.env_fit.then_some(EnvFit {
        initial: map,
        options,
        lr: args.lr_env,
    });
    Ok(Some(BrdfEnv { env, fit }))
}

/// Where the fitted environment of `output` goes: `OUT.env.hdr` beside it.
#[must_use]
pub fn env_output_path(output: &Path) -> PathBuf {
    output.with_extension("env.hdr")
}

/// Runs the brdf fit with the options `fit` parsed and writes the set with its materials.
///
/// # Errors
/// Options that only the SH fit takes, a failed fit or write (nothing is written then).
#[expect(clippy::too_many_arguments, reason = "what `fit` has read, handed on")]
pub fn run_brdf(
    paths: &MlpPaths,
    args: &BrdfArgs,
    env: &BrdfEnv,
    ctx: &Context,
    set: &GaussianSet,
    template: &TriMesh,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    options: &FitOptions,
) -> anyhow::Result<()> {
    refuse_sh_options(
        options,
        "is an option of the SH fit; --appearance brdf fits the materials (and with \
         --fit-normals the rotations and scales) only",
    )?;
    let common = options.common();
    let brdf = BrdfFitOptions {
        lr: BrdfLearningRates {
            albedo: args.lr_albedo,
            roughness: args.lr_roughness,
            f0: args.lr_f0,
            rotations: args.lr_normal,
            log_scales: args.lr_normal_scales,
        },
        normals: args.fit_normals,
        env_fit: env.fit.clone(),
    };
    let env_path = env_output_path(paths.output);
    if env.fit.is_some() && args.env.as_deref() == Some(env_path.as_path()) {
        bail!(
            "{}: the fitted environment would be written over --env; choose another -o",
            env_path.display()
        );
    }
    let started = std::time::Instant::now();
    let fitted = with_progress(
        ctx,
        options.iterations as u64,
        "fitting (brdf)",
        paths.gaussians,
        paths.template,
        |on_checkpoint| {
            fit_brdf(
                set,
                template,
                frames,
                held_out,
                &env.env,
                &common,
                &brdf,
                on_checkpoint,
            )
        },
    )?;
    if !fitted.set.is_empty() && fitted.set.binding().is_none() {
        bail!("internal: the fitted set lost its binding");
    }
    write_gaussians(paths.output, &fitted.set, &PlyWriteOptions::default())?;
    if let Some(map) = &fitted.env
        && let Err(e) = map.write(&env_path)
    {
        // Nothing half-written: the PLY goes too.
        let _ = std::fs::remove_file(paths.output);
        return Err(e.into());
    }
    let seconds = started.elapsed().as_secs_f64();
    if !ctx.json {
        println!(
            "fit (brdf{}): {} Gaussians, {} iterations{}, {:.1} ms per iteration, {seconds:.2} s; \
             wrote {}",
            if args.fit_normals { ", normals" } else { "" },
            set.len(),
            fitted.iterations,
            out_of_time_note(fitted.out_of_time),
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
            "env_fit": fitted.env.as_ref().map(|_| &env_path),
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
