//! `trisplat sample` (in progress).

use super::Context;

/// Arguments of `trisplat sample`.
#[derive(Debug, clap::Args)]
pub struct SampleArgs {}

/// Runs `trisplat sample`.
///
/// # Errors
/// Always, until implemented.
pub fn run(args: SampleArgs, ctx: &Context) -> anyhow::Result<()> {
    let _ = (args, ctx);
    anyhow::bail!("trisplat sample is not implemented yet")
}
