//! `trisplat merge SHARD... -o DIR [--force] [--targets LIST] [--gltf-compression KIND] [--gltf-morph-tolerance E]`: joins `extract` runs over disjoint frame ranges
//! into one run folder.

use std::path::PathBuf;

use trisplat_geometry::io::GltfCompression;
use trisplat_pipeline::{MergeOutputs, OutputTarget};

use super::Context;
use super::extract::{fail_on_failed_frames, print_summary};

/// Arguments of `trisplat merge`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Joins shards of one extract job, each run into its own folder with its own --shard I/N or \
--frames A..B (on one machine or many: each task of a Slurm array or pod of a Kubernetes indexed \
job runs --shard auto, then one merge), into DIR: every shard's frame files (hard links where possible), \
one animated glTF per method assembled from them, and report.json, report.md, report.html and \
error_vs_time.svg/.png over all frames (report.html with the thumbnails of the shard whose \
pictured frame is nearest the middle). The shards must be the same job (same inputs, options and version; only \
--frames or --shard differs), every shard of a --shard split must be there once, and every frame \
of the job must be in exactly one shard; a shard still running is refused, and a refused merge \
writes nothing. Frame files and glTF are then \
byte-identical to one run over all frames (at the default --hop-threshold 0); the report \
differs in the timings, the incremental Delaunay statistics and the thumbnails' frame. See \
docs/shards.md.")]
pub struct MergeArgs {
    /// Shard folders (finished `extract` runs).
    #[arg(required = true, value_name = "SHARD")]
    pub shards: Vec<PathBuf>,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Start over in an output folder that holds a run (its outputs are removed).
    #[arg(long)]
    pub force: bool,
    /// What to write, as extract's --targets: meshes (the frame files), glb, report, usd
    /// (<method>.usda); without meshes the linked frame files are removed once the glb and
    /// USD cache are assembled. The shards' own --targets are not recorded: give the job's.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "LIST", num_args = 1..,
        default_values_t = OutputTarget::ALL)]
    pub targets: Vec<OutputTarget>,
    /// How the glb stores its data, as extract's --gltf-compression (the shards' own choice
    /// is not recorded: give the job's).
    #[arg(long, value_enum, value_name = "KIND", default_value_t = GltfCompression::Meshopt)]
    pub gltf_compression: GltfCompression,
    /// The glb's morph basis, as extract's --gltf-morph-tolerance (not recorded by the shards:
    /// give the job's; default 8e-5 as extract's, 0 is one morph target per frame).
    #[arg(long, value_name = "E",
        default_value_t = trisplat_geometry::io::DEFAULT_MORPH_BASIS_TOLERANCE,
        value_parser = super::convert::parse_share)]
    pub gltf_morph_tolerance: f64,
    /// The glbs given a morph basis, as extract's --gltf-morph-above (megabytes of
    /// one-target-per-frame deltas; default 300 as extract's).
    #[arg(long, value_name = "MB",
        default_value_t = trisplat_pipeline::config::DEFAULT_MORPH_ABOVE_MB,
        value_parser = super::convert::parse_share)]
    pub gltf_morph_above: f64,
}

/// Runs `trisplat merge`.
///
/// # Errors
/// Shards that are not one job, overlap or miss files (named); write errors.
pub fn run(args: MergeArgs, ctx: &Context) -> anyhow::Result<()> {
    let spinner = ctx
        .progress
        .spinner("merge: linking frames, writing sequences and report");
    let outputs = MergeOutputs {
        targets: args.targets.clone(),
        gltf_compression: args.gltf_compression,
        gltf_morph_tolerance: args.gltf_morph_tolerance,
        gltf_morph_above: args.gltf_morph_above,
    };
    let result = trisplat_pipeline::merge_with(&args.shards, &args.output, args.force, &outputs);
    spinner.finish_and_clear();
    let report = result?;
    // No journal: the shards keep theirs.
    print_summary(&report, &args.output, &args.targets, false, ("merge", ctx))?;
    fail_on_failed_frames(&report)
}
