//! `trisplat deform (--template T --gaussians G | --avatar DIR) --animation A -o DIR
//! [--mode binding|jacobian|lbs] [--frames A..B] [--clip NAME|INDEX] [--clip-from A.glb] [--fps F]
//! [--targets DIR] [--adaptive-scale] [--format ply|spz|glb|gltf]`.

use std::path::PathBuf;
use trisplat_pipeline::config::AnimationOptions;

use super::Context;
use super::extract::avatar_files;
use super::gaussian_io::{GaussianFormat, GaussianFormatArgs, write_gaussian_file};
use anyhow::Context as _;
use trisplat_pipeline::output::{Created, Inputs, frame_file};
use trisplat_pipeline::{ExtractConfig, ExtractOptions, Mode, Session, SessionOptions};

/// Arguments of `trisplat deform`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Deform bound Gaussians with an animated template and write one \
    world-space, viewer-ready 3DGS PLY per frame: DIR/frame_000000.ply, ... (the number is the \
    animation's frame index), with normalised rotations (w >= 0) and no binding.\n\n\
    The animation A is one of:\n  \
    - a .gltf/.glb file: its clip (--clip, default the first) sampled at --fps (default 30) \
    from t = 0 to the clip end; a file without animations gives one frame;\n  \
    - a folder of .obj/.ply frames (natural order of the names), or a pattern \
    (frames/f_%04d.obj, frames/*.ply): one frame per file;\n  \
    - a .json weights file in the LAM/ARKit layout (names, frames[].weights): blendshapes. If \
    T is a .gltf/.glb, its morph targets are driven by name (extras.targetNames); otherwise T \
    is the neutral mesh and --targets DIR holds one .obj/.ply per target, named by the file \
    stem (jawOpen.obj drives the channel jawOpen; names match ignoring case, `_`/`.` and `_L`/`_R` vs `Left`/`Right`).\n\n\
    --avatar DIR reads a LAM avatar folder (skin.glb, offset.ply, vertex_order.json) as \
    `extract --avatar` does; --clip-from A.glb plays a clip of another glTF (LAM's \
    animation.glb) on T's joints by name, together with a weights JSON animation.\n\n\
    Every frame must have the vertices and triangles of T, in T's order; the Gaussians' \
    bindings must name triangles of T.\n\n\
    Modes: binding (GaussianAvatars: local parameters in the frame of the posed triangle, as \
    `bind --convention gaussianavatars` writes them); jacobian (SurFhead/TGA: local parameters \
    in T's canonical frame, `bind --convention surfhead`; Σ' = J Σ Jᵀ written as the \
    rotation/scales of its SVD); lbs (A must be a skinned glTF and T its rest shape: each \
    Gaussian moves with the barycentric blend of its triangle's vertex skin weights; its \
    rotation by the polar part of the blended transform; local parameters as for binding).\n\n\
    --adaptive-scale (binding and lbs): Gaussian scales follow the square root of their \
    triangle's area ratio to T (3DFilmPCA). Off by default.\n\n\
    --format spz|glb|gltf writes each frame as Niantic SPZ (quantised; --axes names the \
    frame of the Gaussians, stored as SPZ's RUB: use --axes rub for a Y-up glTF template) or \
    glTF with KHR_gaussian_splatting instead of PLY: DIR/frame_000000.spz, ...\n\n\
    Each file is written atomically; if a frame fails, the files this run created are removed."
)]
pub struct DeformArgs {
    /// Template mesh T (.ply, .obj, .gltf, .glb): the triangles the Gaussians are bound to, in
    /// its rest shape; or a LAM avatar folder (as --avatar).
    #[arg(long, value_name = "T", required_unless_present = "avatar")]
    pub template: Option<PathBuf>,
    /// A LAM avatar folder: --template DIR/skin.glb with DIR/offset.ply's per-vertex Gaussians.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["template", "gaussians"])]
    pub avatar: Option<PathBuf>,
    /// Animation: a glTF/GLB, a folder or pattern of OBJ/PLY frames, or a weights JSON.
    #[arg(long, value_name = "A")]
    pub animation: String,
    /// Bound Gaussians (GaussianAvatars-style PLY with `binding_0` or `binding`); not with an
    /// avatar folder, which brings its own.
    #[arg(long, value_name = "G")]
    pub gaussians: Option<PathBuf>,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Deformation mode.
    #[arg(long, value_enum, default_value_t = Mode::Binding)]
    pub mode: Mode,
    /// Frames to write: `A..B` (B excluded), `A..=B`, `A..`, `..B` or one frame `A`.
    #[arg(long, value_name = "A..B")]
    pub frames: Option<String>,
    /// glTF animation clip by name or index (default: the first).
    #[arg(long, value_name = "NAME|INDEX")]
    pub clip: Option<String>,
    /// Play --clip of this glTF (e.g. LAM's animation.glb) on the template's joints, matched
    /// by name; with a weights JSON animation both play together (the clip looped).
    #[arg(long, value_name = "A.glb")]
    pub clip_from: Option<PathBuf>,
    /// Sampling rate of a glTF clip, frames per second.
    #[arg(long, value_name = "F", default_value_t = trisplat_geometry::animation::DEFAULT_FPS)]
    pub fps: f64,
    /// Folder of blendshape target meshes (with a weights JSON and a non-glTF template).
    #[arg(long, value_name = "DIR")]
    pub targets: Option<PathBuf>,
    /// Scale Gaussians by √(area ratio) of their triangle (binding and lbs modes).
    #[arg(long)]
    pub adaptive_scale: bool,
    /// Refuse a weights JSON with channels that drive no morph target (without it they are
    /// listed once on stderr and ignored).
    #[arg(long)]
    pub strict: bool,
    /// Format of the frame files: ply (INRIA 3DGS, lossless), spz (Niantic SPZ), glb or gltf
    /// (KHR_gaussian_splatting).
    #[arg(long, value_enum, default_value_t = GaussianFormat::Ply)]
    pub format: GaussianFormat,
    /// Gaussian format options.
    #[command(flatten)]
    pub gaussian: GaussianFormatArgs,
}

/// Runs `trisplat deform`.
///
/// A [`Session`] opens the inputs (the template as stored, not welded) and deforms each frame
/// with the same engine as the main job: one rule for every input format, frame range and
/// mode.
///
/// # Errors
/// Unreadable or mismatched inputs (named), a failed write (files of this run removed).
pub fn run(args: DeformArgs, ctx: &Context) -> anyhow::Result<()> {
    let mut options = ExtractOptions {
        animation: AnimationOptions {
            mode: args.mode,
            clip: args.clip.clone(),
            clip_from: args.clip_from.clone(),
            fps: args.fps,
            strict: args.strict,
        },
        ..ExtractOptions::default()
    };
    let (template, gaussians) = match (&args.avatar, &args.template) {
        (Some(dir), _) => avatar_files(dir, args.gaussians.as_deref(), &mut options)?,
        (None, Some(t)) if t.is_dir() => avatar_files(t, args.gaussians.as_deref(), &mut options)?,
        (None, Some(t)) => (t.clone(), args.gaussians.clone()),
        (None, None) => anyhow::bail!("--template or --avatar is needed"),
    };
    let Some(gaussians) = gaussians else {
        anyhow::bail!("--gaussians is needed (deform moves bound Gaussians; `bind` makes them)");
    };
    let config = ExtractConfig {
        template,
        animation: Some(args.animation.clone()),
        gaussians: Some(gaussians),
        methods: Vec::new(),
        output: args.output.clone(),
        frames: args.frames.clone(),
        gt: None,
        options,
    };
    let mut session = Session::open_with(
        &config,
        &SessionOptions {
            weld: false,
            targets: args.targets.clone(),
            adaptive_scale: args.adaptive_scale,
        },
    )?;
    if !session.unused_channels().is_empty() {
        eprintln!(
            "warning: {}: {} channel(s) drive no morph target and are ignored: {} (--strict \
             refuses)",
            args.animation,
            session.unused_channels().len(),
            session.unused_channels().join(", ")
        );
    }
    let frames = session.frames();
    // Never write over an input.
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("{}: cannot create the output folder", args.output.display()))?;
    let inputs = Inputs::new(session.input_files());
    let frame_path = |f: usize| {
        args.output
            .join(frame_file(f))
            .with_extension(args.format.extension())
    };
    for f in frames.clone() {
        inputs.check(&frame_path(f))?;
    }
    let bar = ctx.progress.bar(frames.len() as u64, "deforming");
    let mut created = Created::default();
    // Frames with collapsed template triangles (each kept its last valid frame), and how many.
    let mut collapsed: Vec<(usize, usize)> = Vec::new();
    let result = (|| -> anyhow::Result<()> {
        for f in frames.clone() {
            let out = frame_path(f);
            let existed = out.exists();
            let (world, c) = session.world_counted(f)?;
            if c.total() > 0 {
                collapsed.push((f, c.total()));
            }
            write_gaussian_file(&out, &world, &args.gaussian, false, false)?;
            created.note(&out, existed);
            bar.inc(1);
        }
        Ok(())
    })();
    bar.finish_and_clear();
    if result.is_err() {
        created.remove();
    }
    result?;
    if !collapsed.is_empty() && !ctx.quiet && !ctx.json {
        let listed: Vec<String> = collapsed
            .iter()
            .take(10)
            .map(|(f, n)| format!("{f} ({n})"))
            .collect();
        eprintln!(
            "warning: {} frame(s) have template triangles of zero area, whose Gaussians kept \
             their last valid frame: {}{}",
            collapsed.len(),
            listed.join(", "),
            if collapsed.len() > 10 { ", ..." } else { "" }
        );
    }
    ctx.emit(
        "deform",
        serde_json::json!({
            "output": args.output,
            "frames": frames.len(),
            "gaussians": session.gaussians().len(),
            "format": args.format.extension(),
            "collapsed_frames": collapsed
                .iter()
                .map(|(f, n)| serde_json::json!({"frame": f, "triangles": n}))
                .collect::<Vec<_>>(),
        }),
    )
}
