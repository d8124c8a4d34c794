//! `trisplat fit --appearance mlp`: the neural appearance fit (`pipeline::fit::fit_neural`),
//! writing the set unchanged and its weights beside it (`OUT.safetensors`).

use std::path::Path;

use anyhow::{Context as _, bail};
use trisplat_geometry::TriMesh;
use trisplat_geometry::glam::DVec3;
use trisplat_pipeline::fit::Checkpoint;
use trisplat_pipeline::fit::{CommonOptions, FitFrame, FitOptions, NeuralFitOptions, fit_neural};
use trisplat_splat::GaussianSet;
use trisplat_splat::neural::{NeuralLearningRates, weights_path, write_weights};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};

use super::{Context, UsageError, refuse_to_overwrite};

/// The files of a `fit` run.
pub struct MlpPaths<'a> {
    /// The bound Gaussians.
    pub gaussians: &'a Path,
    /// The template.
    pub template: &'a Path,
    /// The training cameras.
    pub cameras: &'a Path,
    /// The output PLY (the weights go beside it).
    pub output: &'a Path,
}

/// Runs the MLP fit with the options `fit` parsed (`origin`: where the fit's coordinates start
/// in the world).
///
/// # Errors
/// Options that only the SH fit takes, a failed fit or write (nothing is left half-written:
/// the weights are removed when the PLY cannot be written).
#[expect(clippy::too_many_arguments, reason = "what `fit` has read, handed on")]
pub fn run_mlp(
    args: &MlpPaths,
    lr: NeuralLearningRates,
    ctx: &Context,
    set: &GaussianSet,
    template: &TriMesh,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    options: &FitOptions,
    origin: DVec3,
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
            "{name} changes the geometry; --appearance mlp fits the appearance only (use \
             --appearance sh)"
        ))
        .into());
    }
    let weights = weights_path(args.output);
    for input in [args.gaussians, args.template, args.cameras] {
        refuse_to_overwrite(input, &weights)?;
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
    let neural = NeuralFitOptions {
        lr,
        origin,
        ..NeuralFitOptions::default()
    };
    let started = std::time::Instant::now();
    let bar = ctx.progress.bar(options.iterations as u64, "fitting (mlp)");
    let json = ctx.json;
    let fitted = fit_neural(set, template, frames, held_out, &common, &neural, |c| {
        bar.set_position(c.iteration as u64);
        if !json {
            bar.suspend(|| print_checkpoint(c));
        }
    })
    .with_context(|| {
        format!(
            "{} (template {})",
            args.gaussians.display(),
            args.template.display()
        )
    });
    bar.finish_and_clear();
    let fitted = fitted?;
    write_weights(&weights, &fitted.model, set.len())?;
    if let Err(e) = write_gaussians(args.output, set, &PlyWriteOptions::default()) {
        let _ = std::fs::remove_file(&weights);
        bail!(e);
    }
    let seconds = started.elapsed().as_secs_f64();
    if !json {
        println!(
            "fit (mlp): {} Gaussians, {} iterations{}, {:.1} ms per iteration, {seconds:.2} s; \
             wrote {} and {}",
            set.len(),
            fitted.iterations,
            if fitted.out_of_time {
                " (the time budget ran out)"
            } else {
                ""
            },
            fitted.seconds_per_iteration * 1e3,
            args.output.display(),
            weights.display()
        );
    }
    ctx.emit(
        "fit",
        serde_json::json!({
            "output": args.output,
            "weights": weights,
            "appearance": "mlp",
            "template": args.template,
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

/// Prints one checkpoint (the SH and the MLP fit alike).
pub(crate) fn print_checkpoint(c: &Checkpoint) {
    let opt = |v: Option<f64>, p: usize| v.map_or_else(|| "-".to_string(), |v| format!("{v:.p$}"));
    println!(
        "iteration {}: loss {}, train PSNR {} dB; held-out PSNR {} dB, SSIM {}, depth L1 {}, \
         normal {}°; {} Gaussians, SH degree {}, {:.1} s",
        c.iteration,
        opt(c.loss, 5),
        opt(c.train_psnr, 2),
        opt(c.eval_psnr, 2),
        opt(c.eval_ssim, 4),
        opt(c.eval_depth_l1, 5),
        opt(c.eval_normal_deg, 2),
        c.gaussians,
        c.sh_degree,
        c.seconds
    );
}
