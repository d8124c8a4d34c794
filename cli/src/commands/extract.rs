//! `trisplat extract --template T [--animation A] [--gaussians G] --method tsdf|delaunay|alpha|opacity[,...]
//! -o DIR [--frames A..B] [--gt GT] [--explain] [--rebuild-every N] [--hop-threshold T]`: the
//! main job.

use std::path::{Path, PathBuf};

use trisplat_pipeline::{
    ExtractConfig, ExtractOptions, GroundTruth, Method, OutputTarget, Plan, Report, RunControl,
};

use trisplat_geometry::metrics::Relation;
use trisplat_pipeline::avatar::AvatarFolder;
use trisplat_pipeline::config::GaussianLayout;

use super::Context;
use crate::progress::RunProgress;

/// Arguments of `trisplat extract`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
The main job: an animated template and Gaussians bound to its triangles in; one mesh per frame \
and method, an animated glTF per method, a report and a plot out. Only the stages the arguments \
need run (--explain lists them with the reason each runs or is skipped).

Stages: read T and its animation A (a glTF clip sampled at --fps; a folder or pattern of OBJ/PLY \
frames; a weights JSON driving a glTF template's morph targets by name (LAM's head_pose, an \
axis-angle vector in radians per frame, turns the skin's joint named head); without A a glTF template plays \
its own first clip and any other template is one frame; vertices the file splits at UV/normal \
seams are welded by position, each taking its first copy's position in every frame) -> bind Gaussians (only without \
--gaussians: --per-triangle N per triangle, opaque discs flat along the normal) -> deform them \
to every frame (--mode, as `trisplat deform`) -> render depth maps (only for tsdf) -> mesh \
(tsdf | delaunay | alpha) -> metrics (only with --gt) -> write.

Methods and their defaults (derived from the template in world space, as its animation poses \
it, so any scale works; a glTF template is posed with its node transforms and skins, and \
frames whose bounding radius differs from the template's by more than 10x are refused as a \
scale mismatch):
  tsdf      render median depth (3DGS, gsplat rules; --tsdf-depth; each splat at its ray depth, \
--tsdf-splat-depth; alpha < 0.5 = no depth) from --views \
cameras on a sphere around each frame (--resolution px square, 40 deg field of view) and fuse \
(TSDF, marching cubes, largest piece kept); --voxel defaults to the template's bounding radius / \
128, truncation 5 voxels.
  delaunay  incremental Delaunay of the bound Gaussians: per-triangle charts triangulated in the \
rest pose, lifted to the deformed means each frame; only charts that Gaussians hop into or out \
of are redone. --rebuild-every N rebuilds from scratch every N frames (1: every frame). \
--hop-threshold T (multiples of the mean template edge, default 0) trades exactness for time: \
at 0 a Gaussian moves to whichever triangle is nearest, so every frame equals a from-scratch \
triangulation; at T > 0 it moves only when another triangle is nearer by more than T edges, \
so fewer charts are redone per frame (CesiumMan at 0.1: 4.1% -> 0.3% of the charts, a quarter \
to a third less time) but a frame may differ from a from-scratch triangulation until the next \
rebuild. report.json/report.md record per frame the Gaussians that hopped, the charts redone \
and whether the frame was rebuilt.
  alpha     the boundary of the solid enclosed by the alpha complex of the deformed Gaussian \
means (CGAL's GENERAL rule: the faces of exactly one tetrahedron of circumradius <= alpha, plus \
the triangles whose own smallest circumsphere is empty and of radius <= alpha; the solid is what \
the outside cannot reach without crossing them, so folds and inner sheets are dropped), per \
frame at the smallest alpha from 1.5 to 12 x the mean nearest-neighbour spacing of the \
rest-pose means whose mesh has at most --alpha-pieces (default 10) pieces; --alpha A fixes it; \
--alpha-rule complex outputs the whole complex (not manifold); --alpha-rule open3d is Open3D's \
alpha shape (default 6 spacings, hundreds of pieces on surface samples).

--gt GT: a mesh file (a static ground truth for every frame), the word `template`: each \
frame's deformed template, or the word `gaussians`: each frame's surface of the Gaussians' \
centres, the template as stored with vertex i at the deformed centre of Gaussian i (avatars \
with one Gaussian per vertex, LAM's layout, whose centres sit up to centimetres off the skin); \
--gt-sequence DIR|PATTERN: one mesh per frame (a folder or pattern of \
OBJ/PLY files in natural order, file i for animation frame i; scans may differ in topology). Metrics as `trisplat eval --surface` (docs/conventions.md §8): --samples points per \
mesh, exact point-to-triangle distances, Chamfer L1/L2, normal consistency and angle, \
precision, recall and F-score at tau = --tau-fraction (default 0.005) x each frame's \
ground-truth bounding-box diagonal, or at an absolute --tau; the structure of each mesh \
(area and area ratio to the ground truth, connected components and the largest one's share \
of the area, boundary and non-manifold edges, watertight, winding). Self-consistency: when a \
mesh contains at least half of the ground truth's vertices (bit for bit) it is scored \
against its own input, and its scores are labelled self-consistency, not accuracy, in \
report.json (relation), report.md and the plot: the delaunay method's meshes contain the \
deformed template's vertices, so with --gt template its scores are self-consistency; score \
it against a ground truth it did not consume (--gt MESH, --gt-sequence).

Outputs in DIR: <method>/frame_NNNNNN.ply (NNNNNN = the animation's frame index), <method>.glb \
(the animated sequence), journal.jsonl (the run journal), report.json (per method and frame: ms, vertices, faces, watertight, \
metrics with each frame's absolute tau, structure and relation; per-method means and relation; \
tau_fraction or the absolute tau), report.md (the same as tables), error_vs_time.svg and \
error_vs_time.png (Chamfer L1 against ms/frame per method, log axes, self-consistency starred; \
without --gt: ms per frame), report.html (the plot, the tables and a thumbnail of each \
method's mesh and the ground truth at the middle frame, coloured by the distance to the ground \
truth; the pictures in thumbnails/). --error-colors colours the frame meshes' vertices the same \
way. Times cover each method's \
own work (rendering included for tsdf); deformation is reported separately.

--faces N or --simplify-error E decimate every mesh (with --topology fixed|adaptive each key \
mesh, before it is bound, so the carried frames are the decimated key deformed) through \
meshoptimizer's simplifier; report.json gives per decimated mesh the faces before and after, \
meshoptimizer's error estimate and the measured one-sided Hausdorff and mean distance from the \
undecimated mesh. Vertices are coloured from the Gaussians near them (SH degree-0 colours \
weighted by opacity times density; the opacity method composites its own) unless \
--vertex-colors off (docs/conventions.md §6).

--explain prints the plan and exits without reading or writing anything.

Long runs: every file is written atomically, never over an input, and each frame's files as \
soon as they exist; journal.jsonl records the run's configuration and every frame done, so a run \
killed at any point (Ctrl-C, kill, crash) continues with --resume (refused if the inputs or \
options changed; frames listed as done are kept, with the incremental Delaunay rebuilt at the \
first frame run). A folder holding a previous run is refused without --resume or --force (which \
removes its outputs first). A frame that fails is recorded (journal, report, a warning) and the \
run goes on; the exit code is then 1 and --resume retries it; --fail-fast stops at the first \
failure instead. The animated glTF is assembled from the frame files; past glTF's 4 GiB limit it \
is split into <method>_part001.glb, ... (listed in the report). --targets chooses the outputs \
(meshes, glb, report; default all) so a run that only needs the numbers writes no meshes.")]
pub struct ExtractArgs {
    /// Template mesh T (.ply, .obj, .gltf, .glb) in its rest shape, or a LAM avatar folder
    /// (as --avatar).
    #[arg(long, value_name = "T", required_unless_present = "avatar")]
    pub template: Option<PathBuf>,
    /// A LAM avatar folder: --template DIR/skin.glb --gaussians DIR/offset.ply --layout lam.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["template", "gaussians"])]
    pub avatar: Option<PathBuf>,
    /// Animation: a glTF/GLB, a folder or pattern of OBJ/PLY frames, or a weights JSON.
    #[arg(long, value_name = "A")]
    pub animation: Option<String>,
    /// Bound Gaussians (GaussianAvatars-style PLY with `binding_0`); default: bind new ones.
    #[arg(long, value_name = "G")]
    pub gaussians: Option<PathBuf>,
    /// Extraction methods, comma-separated.
    #[arg(
        long = "method",
        value_enum,
        value_delimiter = ',',
        required = true,
        value_name = "LIST"
    )]
    pub methods: Vec<Method>,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Frames: `A..B` (B excluded), `A..=B`, `A..`, `..B` or one frame `A` [default: all].
    #[arg(long, value_name = "A..B")]
    pub frames: Option<String>,
    /// Ground truth: a mesh file, `template` for each frame's deformed template, or
    /// `gaussians` for each frame's surface of the Gaussians' centres (LAM avatars).
    #[arg(long, value_name = "GT")]
    pub gt: Option<String>,
    /// Ground truth per frame: a folder or pattern of OBJ/PLY meshes (e.g. scans), the i-th
    /// file for animation frame i.
    #[arg(long, value_name = "DIR|PATTERN", conflicts_with = "gt")]
    pub gt_sequence: Option<String>,
    /// Print the stages (run or skipped, and why) and exit without running.
    #[arg(long)]
    pub explain: bool,
    /// Method and metric settings.
    #[command(flatten)]
    pub options: ExtractOptions,
    /// Resuming, starting over, failing frames.
    #[command(flatten)]
    pub control: RunControl,
}

impl ExtractArgs {
    /// The run's configuration; an avatar folder (`--avatar DIR`, or `--template DIR` when it
    /// holds one) stands for its template and per-vertex Gaussians.
    fn config(self) -> anyhow::Result<ExtractConfig> {
        if self.options.outputs.error_colors && self.gt.is_none() && self.gt_sequence.is_none() {
            return Err(super::UsageError(
                "--error-colors colours the meshes by their distance to the ground truth: give \
                 --gt or --gt-sequence"
                    .to_owned(),
            )
            .into());
        }
        let mut options = self.options;
        // `--shard auto` resolved now, so that the journal records the shard itself and a
        // resumed task with other variables is refused.
        let shard = options
            .shard
            .resolve(&|name| std::env::var(name).ok())
            .map_err(super::UsageError)?;
        options.shard = trisplat_pipeline::ShardOptions {
            shard: shard.map(trisplat_pipeline::ShardSpec::Given),
            shard_count: None,
        };
        let (template, gaussians) = match (self.avatar, self.template) {
            (Some(dir), _) => avatar_files(&dir, self.gaussians.as_deref(), &mut options)?,
            (None, Some(t)) if t.is_dir() => {
                avatar_files(&t, self.gaussians.as_deref(), &mut options)?
            }
            (None, Some(t)) => (t, self.gaussians),
            (None, None) => anyhow::bail!("--template or --avatar is needed"),
        };
        Ok(ExtractConfig {
            template,
            animation: self.animation,
            gaussians,
            methods: self.methods,
            output: self.output,
            frames: self.frames,
            gt: self
                .gt
                .as_deref()
                .map(GroundTruth::parse)
                .or(self.gt_sequence.map(GroundTruth::Sequence)),
            options,
        })
    }
}

/// The template and Gaussians of the LAM avatar folder `dir`, with `options` set to read it
/// (`extract` and `deform`).
///
/// # Errors
/// Not an avatar folder, or `--gaussians` given beside one.
pub(crate) fn avatar_files(
    dir: &Path,
    gaussians: Option<&Path>,
    options: &mut ExtractOptions,
) -> anyhow::Result<(PathBuf, Option<PathBuf>)> {
    let avatar = AvatarFolder::open(dir)?;
    if let Some(g) = gaussians {
        anyhow::bail!(
            "--gaussians {}: the avatar folder {} brings its own ({})",
            g.display(),
            dir.display(),
            avatar.gaussians.display()
        );
    }
    options.bind.layout = GaussianLayout::Lam;
    Ok((avatar.template, Some(avatar.gaussians)))
}

/// Runs `trisplat extract`.
///
/// # Errors
/// Whatever the pipeline reports (bad inputs, named; failed writes).
pub fn run(args: ExtractArgs, ctx: &Context) -> anyhow::Result<()> {
    let explain = args.explain;
    let control = args.control;
    let config = args.config()?;
    if explain {
        let plan = Plan::new(&config);
        if !ctx.json {
            print!("{plan}");
        }
        let stages: Vec<serde_json::Value> = plan
            .stages
            .iter()
            .map(
                |s| serde_json::json!({"stage": s.stage.to_string(), "runs": s.runs, "why": s.why}),
            )
            .collect();
        return ctx.emit("extract", serde_json::json!({ "plan": stages }));
    }
    run_and_summarise(&config, control, ("extract", ctx))
}

/// Runs the pipeline with a progress bar, prints the summary of `command` ([`print_summary`])
/// and fails when frames failed ([`fail_on_failed_frames`]).
///
/// # Errors
/// As [`trisplat_pipeline::run`], and failed frames.
pub fn run_and_summarise(
    config: &ExtractConfig,
    control: RunControl,
    (command, ctx): (&str, &Context),
) -> anyhow::Result<()> {
    let report = run_with_progress(config, control, ctx)?;
    print_summary(
        &report,
        &config.output,
        &config.options.outputs.targets,
        true,
        (command, ctx),
    )?;
    fail_on_failed_frames(&report)
}

/// An error when frames failed (they are listed in the report; the others were written).
///
/// # Errors
/// When `report.failed_frames` is not empty.
pub fn fail_on_failed_frames(report: &Report) -> anyhow::Result<()> {
    match report.failed_frames.as_slice() {
        [] => Ok(()),
        [first, ..] => anyhow::bail!(
            "{} frame(s) failed (listed in report.md; the other frames were written, rerun \
             with --resume to retry them); first: frame {}: {}",
            report.failed_frames.len(),
            first.frame,
            first.error
        ),
    }
}

/// Runs the pipeline with a progress bar on stderr ([`RunProgress`] reading its events).
///
/// # Errors
/// As [`trisplat_pipeline::run`].
fn run_with_progress(
    config: &ExtractConfig,
    control: RunControl,
    ctx: &Context,
) -> anyhow::Result<Report> {
    let mut progress = RunProgress::new(ctx.progress, "extract");
    let result = trisplat_pipeline::run(config, control, &mut |event| progress.show(event));
    progress.finish();
    Ok(result?)
}

/// Prints one line per method (ms/frame, Chamfer L1 and what it measures, faces, watertight
/// frames) and the outputs. `targets`: the outputs written; `journal`: whether a run journal
/// was written too.
///
/// With `--json`, one object instead: `output`, `frames`, `gaussians`, `deform_ms`, `failed_frames`,
/// `methods` (per method its mean summary as in report.json, and `relation`) and `files`.
///
/// # Errors
/// None in practice (a summary that does not serialise is a bug).
pub fn print_summary(
    report: &Report,
    out: &Path,
    targets: &[OutputTarget],
    journal: bool,
    (command, ctx): (&str, &Context),
) -> anyhow::Result<()> {
    let written = written_files(targets, journal);
    if ctx.json {
        let mut methods = serde_json::Map::new();
        for m in report.ordered() {
            let mut summary = serde_json::to_value(&m.mean)?;
            summary["relation"] = serde_json::to_value(m.relation)?;
            methods.insert(m.method.name().to_owned(), summary);
        }
        return ctx.emit(
            command,
            serde_json::json!({
                "output": out,
                "frames": report.frames.len(),
                "gaussians": report.gaussian_count,
                "deform_ms": report.deform_ms.iter().sum::<f64>()
                    / report.deform_ms.len().max(1) as f64,
                "failed_frames": report.failed_frames.len(),
                "methods": methods,
                "files": written,
            }),
        );
    }
    println!(
        "{} frame(s), {} Gaussians, deformation {:.2} ms/frame",
        report.frames.len(),
        report.gaussian_count,
        report.deform_ms.iter().sum::<f64>() / report.deform_ms.len().max(1) as f64
    );
    println!(
        "{:<10} {:>10} {:>12} {:<17} {:>10} {:>11}",
        "method", "ms/frame", "Chamfer L1", " scored as", "faces", "watertight"
    );
    for m in report.ordered() {
        let a = &m.mean;
        let chamfer = a
            .chamfer_l1
            .map_or_else(|| "-".to_owned(), |c| format!("{c:.4e}"));
        println!(
            "{:<10} {:>10.2} {:>12} {:<17} {:>10.0} {:>11}",
            m.method.name(),
            a.ms,
            chamfer,
            format!(" {}", m.relation.map_or("-", |r| r.name())),
            a.faces,
            format!("{}/{}", a.watertight_frames, a.frames)
        );
    }
    for m in report.ordered() {
        if m.relation == Some(Relation::SelfConsistency) {
            println!(
                "{}: its meshes contain the ground truth's vertices: the scores are \
                 self-consistency, not accuracy (score it against a ground truth it did not \
                 consume)",
                m.method.name()
            );
        }
    }
    println!("outputs: {}/{{{}}}", out.display(), written.join(", "));
    if targets.contains(&OutputTarget::Report) {
        println!(
            "report: {} (open it in a browser)",
            out.join("report.html").display()
        );
    }
    Ok(())
}

/// The files a run writes in its folder, as patterns.
fn written_files(targets: &[OutputTarget], journal: bool) -> Vec<&'static str> {
    let mut written = Vec::new();
    if targets.contains(&OutputTarget::Meshes) {
        written.push("<method>/frame_*.ply");
    }
    if targets.contains(&OutputTarget::Glb) {
        written.push("<method>.glb");
    }
    if targets.contains(&OutputTarget::Usd) {
        written.push("<method>.usda");
    }
    if targets.contains(&OutputTarget::Rig) {
        written.push("<method>_rig.glb");
    }
    if targets.contains(&OutputTarget::Report) {
        written.extend([
            "report.json",
            "report.md",
            "report.html",
            "thumbnails/*.png",
            "error_vs_time.svg",
            "error_vs_time.png",
        ]);
    }
    if journal {
        written.push("journal.jsonl");
    }
    written
}
