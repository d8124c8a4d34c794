//! `trisplat eval` (in progress).

use super::Context;

/// Arguments of `trisplat eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {}

/// Runs `trisplat eval`.
///
/// # Errors
/// Always, until implemented.
pub fn run(args: EvalArgs, ctx: &Context) -> anyhow::Result<()> {
    let _ = (args, ctx);
    anyhow::bail!("trisplat eval is not implemented yet")
}
