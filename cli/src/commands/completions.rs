//! `trisplat completions SHELL`: a completion script generated from the command-line definition.

use clap::CommandFactory;
use clap_complete::Shell;

/// Arguments of `trisplat completions`.
#[derive(Debug, clap::Args)]
#[command(after_help = "Install, e.g. for bash: trisplat completions bash > \
    ~/.local/share/bash-completion/completions/trisplat")]
pub struct CompletionsArgs {
    /// The shell to write the script for.
    #[arg(value_enum)]
    pub shell: Shell,
}

/// Writes the completion script to stdout.
///
/// # Errors
/// None: writing to stdout is the only effect (a closed stdout ends the run quietly).
pub fn run(args: &CompletionsArgs) -> anyhow::Result<()> {
    let mut cmd = crate::Cli::command();
    clap_complete::generate(args.shell, &mut cmd, "trisplat", &mut std::io::stdout());
    Ok(())
}
