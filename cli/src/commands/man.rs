//! `trisplat man [COMMAND]`: the manual page (roff), generated from the command-line definition.

use anyhow::Context as _;
use clap::CommandFactory;

/// Arguments of `trisplat man`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Read it with: trisplat man | man -l -   (or: trisplat man eval | man -l -)"
)]
pub struct ManArgs {
    /// A command (e.g. `extract`) for its own page; without one, the page of trisplat.
    #[arg(value_name = "COMMAND")]
    pub command: Option<String>,
}

/// Writes the page to stdout (with `--json`: `{"page"}`).
///
/// # Errors
/// An unknown command name; a failed write.
pub fn run(args: &ManArgs, ctx: &super::Context) -> anyhow::Result<()> {
    let root = crate::Cli::command();
    let cmd = match &args.command {
        None => root,
        Some(name) => {
            let names: Vec<String> = root
                .get_subcommands()
                .map(|c| c.get_name().to_owned())
                .collect();
            let sub = root.find_subcommand(name).cloned().with_context(|| {
                format!("man {name}: no such command (one of: {})", names.join(", "))
            })?;
            sub.bin_name(format!("trisplat {name}"))
                .display_name(format!("trisplat-{name}"))
        }
    };
    if ctx.json {
        let mut page = Vec::new();
        clap_mangen::Man::new(cmd).render(&mut page)?;
        return ctx.emit(
            "man",
            serde_json::json!({ "page": String::from_utf8(page)? }),
        );
    }
    let mut out = std::io::stdout().lock();
    match clap_mangen::Man::new(cmd).render(&mut out) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            // `trisplat man | head`: the reader has gone, as for every other command.
            std::process::exit(crate::CLOSED_STDOUT_EXIT)
        }
        result => result.context("writing the manual page"),
    }
}
