//! `trisplat fit --appearance mlp`: the neural appearance fit (`pipeline::fit::fit_neural`),
//! writing the set unchanged and its weights beside it (`OUT.safetensors`).

use anyhow::bail;
use trisplat_geometry::TriMesh;
use trisplat_geometry::glam::DVec3;
use trisplat_pipeline::fit::{FitFrame, FitOptions, NeuralFitOptions, fit_neural};
use trisplat_splat::GaussianSet;
use trisplat_splat::neural::{NeuralLearningRates, weights_path, write_weights};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};

use super::fit_run::{MlpPaths, out_of_time_note, refuse_sh_options, with_progress};
use super::{Context, refuse_to_overwrite};

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
    refuse_sh_options(
        options,
        "changes the geometry; --appearance mlp fits the appearance only (use --appearance sh)",
    )?;
    let weights = weights_path(args.output);
    for input in [args.gaussians, args.template, args.cameras] {
        refuse_to_overwrite(input, &weights)?;
    }
    let common = options.common();
    let neural = NeuralFitOptions {
        lr,
        origin,
        ..NeuralFitOptions::default()
    };
    let started = std::time::Instant::now();
    let fitted = with_progress(
        ctx,
        options.iterations as u64,
        "fitting (mlp)",
        args.gaussians,
        args.template,
        |on_checkpoint| {
            fit_neural(
                set,
                template,
                frames,
                held_out,
                &common,
                &neural,
                on_checkpoint,
            )
        },
    )?;
    write_weights(&weights, &fitted.model, set.len())?;
    if let Err(e) = write_gaussians(args.output, set, &PlyWriteOptions::default()) {
        let _ = std::fs::remove_file(&weights);
        bail!(e);
    }
    let seconds = started.elapsed().as_secs_f64();
    if !ctx.json {
        println!(
            "fit (mlp): {} Gaussians, {} iterations{}, {:.1} ms per iteration, {seconds:.2} s; \
             wrote {} and {}",
            set.len(),
            fitted.iterations,
            out_of_time_note(fitted.out_of_time),
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
