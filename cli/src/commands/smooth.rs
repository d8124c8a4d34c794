//! `trisplat smooth` (in progress).

use super::Context;

/// Arguments of `trisplat smooth`.
#[derive(Debug, clap::Args)]
pub struct SmoothArgs {}

/// Runs `trisplat smooth`.
///
/// # Errors
/// Always, until implemented.
pub fn run(args: SmoothArgs, ctx: &Context) -> anyhow::Result<()> {
    let _ = (args, ctx);
    anyhow::bail!("trisplat smooth is not implemented yet")
}
