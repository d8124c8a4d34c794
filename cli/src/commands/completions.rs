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

/// Writes the completion script to stdout (with `--json`: `{"shell", "script"}`).
///
/// # Errors
/// A script that is not UTF-8 (a bug).
pub fn run(args: &CompletionsArgs, ctx: &super::Context) -> anyhow::Result<()> {
    let mut cmd = crate::Cli::command();
    if !ctx.json {
        clap_complete::generate(args.shell, &mut cmd, "trisplat", &mut std::io::stdout());
        return Ok(());
    }
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "trisplat", &mut script);
    ctx.emit(
        "completions",
        serde_json::json!({ "shell": args.shell.to_string(), "script": String::from_utf8(script)? }),
    )
}
