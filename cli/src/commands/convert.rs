//! `trisplat convert` (in progress).

use super::Context;

/// Arguments of `trisplat convert`.
#[derive(Debug, clap::Args)]
pub struct ConvertArgs {}

/// Runs `trisplat convert`.
///
/// # Errors
/// Always, until implemented.
pub fn run(args: ConvertArgs, ctx: &Context) -> anyhow::Result<()> {
    let _ = (args, ctx);
    anyhow::bail!("trisplat convert is not implemented yet")
}
