//! What the three fits of `trisplat fit` (SH, `--appearance brdf`, `--appearance mlp`) share
//! around the pipeline's fitters: the files of a run, the progress bar with the checkpoints
//! printed as they come, and the refusal of the SH fit's options by the appearance fits.

use std::path::Path;

use anyhow::Context as _;
use trisplat_pipeline::fit::{Checkpoint, FitOptions};

use super::{Context, UsageError};

/// The files of a `fit` run.
pub struct MlpPaths<'a> {
    /// The bound Gaussians.
    pub gaussians: &'a Path,
    /// The template.
    pub template: &'a Path,
    /// The training cameras.
    pub cameras: &'a Path,
    /// The output PLY (the weights or the fitted environment go beside it).
    pub output: &'a Path,
}

/// Runs `fit` (which reports each checkpoint to the callback it is given) behind a progress bar
/// of `iterations` steps labelled `label`, printing each checkpoint unless `--json`; a failure
/// names the Gaussians and the template.
///
/// # Errors
/// What `fit` returns, with the files named.
pub fn with_progress<T, E>(
    ctx: &Context,
    iterations: u64,
    label: &str,
    gaussians: &Path,
    template: &Path,
    fit: impl FnOnce(&mut dyn FnMut(&Checkpoint)) -> Result<T, E>,
) -> anyhow::Result<T>
where
    E: std::error::Error + Send + Sync + 'static,
{
    let bar = ctx.progress.bar(iterations, label);
    let json = ctx.json;
    let fitted = fit(&mut |c| {
        bar.set_position(c.iteration as u64);
        if !json {
            bar.suspend(|| print_checkpoint(c));
        }
    })
    .with_context(|| format!("{} (template {})", gaussians.display(), template.display()));
    bar.finish_and_clear();
    fitted
}

/// A usage error for the first SH-fit option an appearance fit was given (`why`: what that
/// fit does instead, ending the message).
///
/// # Errors
/// [`UsageError`] naming the option.
pub fn refuse_sh_options(options: &FitOptions, why: &str) -> anyhow::Result<()> {
    match options.sh_only_option() {
        Some(name) => Err(UsageError(format!("{name} {why}")).into()),
        None => Ok(()),
    }
}

/// ` (the time budget ran out)` when it did, else nothing: for the closing line.
#[must_use]
pub fn out_of_time_note(out_of_time: bool) -> &'static str {
    if out_of_time {
        " (the time budget ran out)"
    } else {
        ""
    }
}

/// Prints one checkpoint (every fit alike).
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
