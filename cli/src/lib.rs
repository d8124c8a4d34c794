//! The `trisplat` command line: argument parsing, progress and reporting over the libraries.
//!
//! Exit codes follow the CLI contract: 0 on success, 2 on bad usage (clap), 1 on bad input or
//! failure with one line on stderr that names the file and the problem.

mod commands;
mod progress;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Gaussian avatars on the explicit triangle mesh: conversion, metrics, smoothing, sampling.
#[derive(Debug, Parser)]
#[command(name = "trisplat", version, about, long_about = None)]
pub struct Cli {
    /// Options shared by every command.
    #[command(flatten)]
    pub global: GlobalArgs,
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// Options shared by every command.
#[derive(Debug, clap::Args)]
pub struct GlobalArgs {
    /// No progress bars.
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// The result as one JSON object on stdout (keys: docs/conventions.md §10) instead of text.
    #[arg(long, global = true)]
    pub json: bool,
    /// Worker threads (default: all cores, or RAYON_NUM_THREADS). Results do not depend on it.
    #[arg(long, global = true, value_name = "N")]
    pub threads: Option<std::num::NonZeroUsize>,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Compare a prediction with a ground truth (Chamfer, normal consistency, F-score).
    Eval(commands::eval::EvalArgs),
    /// Alpha shape of a point set (Open3D's definition), outward-oriented triangles.
    AlphaShape(commands::alpha_shape::AlphaShapeArgs),
    /// Fuse depth maps into a mesh (TSDF on sparse voxel blocks + marching cubes).
    Tsdf(commands::tsdf::TsdfArgs),
    /// Mesh the Gaussians' opacity field (GOF): Delaunay of centres and 3-sigma corners, marching tetrahedra.
    OpacityMesh(commands::opacity_mesh::OpacityMeshArgs),
    /// Convert between PLY, OBJ, glTF and GLB.
    Convert(commands::convert::ConvertArgs),
    /// Sample points on a mesh surface.
    Sample(commands::sample::SampleArgs),
    /// Smooth a mesh (Laplacian, Taubin, uniform, cotangent).
    Smooth(commands::smooth::SmoothArgs),
    /// Bind Gaussians to the triangles of a template mesh (new ones, or attach a 3DGS PLY).
    Bind(commands::bind::BindArgs),
    /// Deform bound Gaussians with an animated template: one world-space PLY per frame.
    Deform(commands::deform::DeformArgs),
    /// Clone or split Gaussians (binding inheritance, Wasserstein gate).
    Densify(commands::densify::DensifyArgs),
    /// Remove Gaussians by opacity, outlier distance, normal consistency or a mask.
    Prune(commands::prune::PruneArgs),
    /// Initialise Gaussians inside the visual hull carved from silhouette masks.
    Init(commands::init::InitArgs),
    /// Surface-guided re-initialisation of a bound avatar (VGA/GVA): alpha shape, smoothing, resampling.
    Refine(Box<commands::refine::RefineArgs>),
    /// Fit bound Gaussians to target images (mesh renders or user images): L1 + D-SSIM, Adam, refine interleaved.
    Fit(Box<commands::fit::FitArgs>),
    /// Render Gaussians (3DGS/2DGS/perspective-aware) or a mesh on the CPU: rgb, alpha, depth, normals.
    Render(commands::render::RenderArgs),
    /// Write a camera rig (sphere or orbit) around a mesh as cameras.json.
    Cameras(commands::cameras::CamerasArgs),
    /// The main job: per-frame meshes (tsdf, delaunay, alpha, opacity) of an animated avatar, report, plot.
    Extract(Box<commands::extract::ExtractArgs>),
    /// The main job on the bundled avatar fixture.
    Demo(commands::demo::DemoArgs),
    /// Join extract runs over disjoint frame ranges (shards) into one run folder.
    Merge(commands::merge::MergeArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(commands::completions::CompletionsArgs),
    /// Print the manual page (roff) of trisplat or of one command.
    Man(commands::man::ManArgs),
}

/// Runs the command line and maps errors to the exit codes of the CLI contract.
#[must_use]
pub fn main() -> ExitCode {
    quiet_on_closed_stdout();
    clean_up_on_interrupt();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the chain of causes joined by ": ".
            eprintln!("error: {e:#}");
            if e.downcast_ref::<commands::UsageError>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// Exit code of a run ended by Ctrl-C or SIGTERM: 128 + SIGINT, as shells report it.
pub const INTERRUPTED_EXIT: i32 = 130;

/// On Ctrl-C (SIGINT) or SIGTERM: no new output file is started, the temporary files of the
/// writes in progress are removed (so no `.trisplat-*.tmp` and no half-written output stays;
/// completed outputs are kept, and `extract --resume` continues the run), and the process
/// ends with [`INTERRUPTED_EXIT`].
fn clean_up_on_interrupt() {
    // Fails only when a handler is installed already (never here); the run then goes on
    // without the clean-up.
    let _ = ctrlc::set_handler(|| {
        let removed = trisplat_geometry::io::abandon_writes();
        eprintln!(
            "interrupted: {removed} unfinished file(s) removed, completed outputs kept \
             (extract: --resume continues the run)"
        );
        std::process::exit(INTERRUPTED_EXIT);
    });
}

/// Exit code of a run whose reader closed stdout early (`trisplat ... | head`): the code of a
/// process ended by SIGPIPE, as other Unix tools report it.
pub const CLOSED_STDOUT_EXIT: i32 = 141;

/// Makes a write to a closed stdout end the run quietly with [`CLOSED_STDOUT_EXIT`] instead of
/// a panic message: Rust ignores SIGPIPE, so `print!` into a pipe whose reader has gone panics
/// with "failed printing to stdout: Broken pipe". Every other panic is reported as before.
fn quiet_on_closed_stdout() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(CLOSED_STDOUT_EXIT);
        }
        default(info);
    }));
}

/// Runs one parsed command line.
///
/// # Errors
/// Whatever the command reports: bad input files or failed writes.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    if let Some(n) = cli.global.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.get())
            .build_global()
            .map_err(|e| anyhow::anyhow!("--threads {n}: {e}"))?;
    }
    let ctx = commands::Context {
        progress: progress::Progress::new(cli.global.quiet),
        quiet: cli.global.quiet,
        json: cli.global.json,
    };
    match cli.command {
        Command::Eval(args) => commands::eval::run(args, &ctx),
        Command::AlphaShape(args) => commands::alpha_shape::run(args, &ctx),
        Command::Tsdf(args) => commands::tsdf::run(args, &ctx),
        Command::OpacityMesh(args) => commands::opacity_mesh::run(args, &ctx),
        Command::Convert(args) => commands::convert::run(args, &ctx),
        Command::Sample(args) => commands::sample::run(args, &ctx),
        Command::Smooth(args) => commands::smooth::run(args, &ctx),
        Command::Bind(args) => commands::bind::run(args, &ctx),
        Command::Deform(args) => commands::deform::run(args, &ctx),
        Command::Densify(args) => commands::densify::run(args, &ctx),
        Command::Prune(args) => commands::prune::run(args, &ctx),
        Command::Init(args) => commands::init::run(args, &ctx),
        Command::Refine(args) => commands::refine::run(*args, &ctx),
        Command::Fit(args) => commands::fit::run(*args, &ctx),
        Command::Render(args) => commands::render::run(args, &ctx),
        Command::Cameras(args) => commands::cameras::run(args, &ctx),
        Command::Extract(args) => commands::extract::run(*args, &ctx),
        Command::Demo(args) => commands::demo::run(args, &ctx),
        Command::Merge(args) => commands::merge::run(args, &ctx),
        Command::Completions(args) => commands::completions::run(&args, &ctx),
        Command::Man(args) => commands::man::run(&args, &ctx),
    }
}
