//! `trisplat deform --template T --animation A --gaussians G -o DIR [--mode binding|jacobian|lbs]
//! [--frames A..B] [--clip NAME|INDEX] [--fps F] [--targets DIR] [--adaptive-scale]`.

use std::collections::HashSet;
use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{
    AnimatedTemplate, BlendshapeAnimation, BlendshapeSet, Clip, GltfMorphAnimation, GltfTemplate,
    MeshSequence, WeightsTrack,
};
use trisplat_geometry::io::read_mesh;
use trisplat_splat::GaussianSet;
use trisplat_splat::deform::{DeformMode, Deformer};
use trisplat_splat::lbs::LbsDeformer;
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};

use super::{Context, parse_clip};

/// Largest difference between the template's positions and the animation's rest pose that
/// `lbs` accepts, relative to the template's bounding-box diagonal (f32 storage of both).
const LBS_REST_TOLERANCE: f64 = 1e-5;

/// Deformation modes (SPEC §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// GaussianAvatars: rigid frame of the posed triangle plus its scale.
    Binding,
    /// SurFhead/TGA: per-triangle deformation gradient J (anisotropic stretch).
    Jacobian,
    /// Linear blend skinning with the glTF skin's weights (bodies).
    Lbs,
}

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
    Each file is written atomically; if a frame fails, the files this run created are removed."
)]
pub struct DeformArgs {
    /// Template mesh T (.ply, .obj, .gltf, .glb): the triangles the Gaussians are bound to, in
    /// its rest shape.
    #[arg(long, value_name = "T")]
    pub template: PathBuf,
    /// Animation: a glTF/GLB, a folder or pattern of OBJ/PLY frames, or a weights JSON.
    #[arg(long, value_name = "A")]
    pub animation: String,
    /// Bound Gaussians (GaussianAvatars-style PLY with `binding_0` or `binding`).
    #[arg(long, value_name = "G")]
    pub gaussians: PathBuf,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Deformation mode.
    #[arg(long, value_enum, default_value_t = ModeArg::Binding)]
    pub mode: ModeArg,
    /// Frames to write: `A..B` (B excluded), `A..=B`, `A..`, `..B` or one frame `A`.
    #[arg(long, value_name = "A..B")]
    pub frames: Option<String>,
    /// glTF animation clip by name or index (default: the first).
    #[arg(long, value_name = "NAME|INDEX")]
    pub clip: Option<String>,
    /// Sampling rate of a glTF clip, frames per second.
    #[arg(long, value_name = "F", default_value_t = trisplat_geometry::animation::DEFAULT_FPS)]
    pub fps: f64,
    /// Folder of blendshape target meshes (with a weights JSON and a non-glTF template).
    #[arg(long, value_name = "DIR")]
    pub targets: Option<PathBuf>,
    /// Scale Gaussians by √(area ratio) of their triangle (binding and lbs modes).
    #[arg(long)]
    pub adaptive_scale: bool,
}

/// The animation source; glTF kept concrete for `lbs`.
enum Animation {
    Gltf(Box<GltfTemplate>),
    Other(Box<dyn AnimatedTemplate>),
}

impl Animation {
    fn get(&self) -> &dyn AnimatedTemplate {
        match self {
            Self::Gltf(g) => g.as_ref(),
            Self::Other(o) => o.as_ref(),
        }
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn is_gltf(path: &Path) -> bool {
    matches!(extension(path).as_str(), "gltf" | "glb")
}

/// Opens the animation `args.animation` (see the command's help).
fn open_animation(args: &DeformArgs) -> anyhow::Result<Animation> {
    let a = Path::new(&args.animation);
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps {}: must be a positive number", args.fps);
    }
    if is_gltf(a) {
        let clip = parse_clip(args.clip.as_deref());
        let clip = match GltfTemplate::open(a, &Clip::None) {
            // A file without animations plays its stored scene unless a clip was asked for.
            Ok(g) if g.clip_names().is_empty() && args.clip.is_none() => Clip::None,
            Ok(_) => clip,
            Err(e) => return Err(e.into()),
        };
        let g = GltfTemplate::open(a, &clip)?.with_fps(args.fps);
        return Ok(Animation::Gltf(Box::new(g)));
    }
    if args.clip.is_some() {
        bail!("{}: --clip needs a glTF animation", args.animation);
    }
    if extension(a) == "json" {
        let track = WeightsTrack::read(a)?;
        if is_gltf(&args.template) {
            if args.targets.is_some() {
                bail!(
                    "{}: --targets is for an OBJ/PLY neutral template; a glTF template brings \
                     its own morph targets",
                    args.template.display()
                );
            }
            let g = GltfTemplate::open(&args.template, &Clip::None)?;
            return Ok(Animation::Other(Box::new(GltfMorphAnimation::new(
                g, track,
            )?)));
        }
        let Some(dir) = &args.targets else {
            bail!(
                "{}: a weights file drives blendshapes: give --targets DIR (one .obj/.ply per \
                 target) or a glTF template with morph targets",
                args.animation
            );
        };
        // The neutral may sit among the targets (ICT FaceKit): it is not a target.
        let template_file = args.template.canonicalize().ok();
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .with_context(|| format!("{}: cannot list the targets folder", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| matches!(extension(p).as_str(), "obj" | "ply"))
            .filter(|p| p.canonicalize().ok() != template_file)
            .collect();
        files.sort();
        if files.is_empty() {
            bail!("{}: no .obj/.ply target meshes", dir.display());
        }
        let set = BlendshapeSet::from_files(&args.template, &files)?;
        return Ok(Animation::Other(Box::new(BlendshapeAnimation::new(
            set, track,
        )?)));
    }
    let sequence = MeshSequence::from_pattern(&args.animation)?.with_fps(args.fps);
    Ok(Animation::Other(Box::new(sequence)))
}

/// Parses `A..B`, `A..=B`, `A..`, `..B`, `A` against `count` frames.
fn parse_frames(spec: Option<&str>, count: usize) -> anyhow::Result<Range<usize>> {
    let Some(spec) = spec else {
        return Ok(0..count);
    };
    let num = |s: &str, default: usize| -> anyhow::Result<usize> {
        let s = s.trim();
        if s.is_empty() {
            Ok(default)
        } else {
            s.parse::<usize>()
                .with_context(|| format!("--frames {spec}: `{s}` is not a frame number"))
        }
    };
    let range = if let Some((a, b)) = spec.split_once("..=") {
        let end = num(b, usize::MAX)?;
        num(a, 0)?..end.saturating_add(1)
    } else if let Some((a, b)) = spec.split_once("..") {
        num(a, 0)?..num(b, count)?
    } else {
        let f = num(spec, 0)?;
        f..f.saturating_add(1)
    };
    if range.start >= range.end {
        bail!("--frames {spec}: the range is empty");
    }
    if range.end > count {
        bail!("--frames {spec}: the animation has {count} frame(s) (0..{count})",);
    }
    Ok(range)
}

/// Frame file name.
fn frame_name(frame: usize) -> String {
    format!("frame_{frame:06}.ply")
}

/// Checks that the animation's frames have the template's vertices and triangles.
fn check_topology(
    template: &TriMesh,
    t_path: &Path,
    anim: &dyn AnimatedTemplate,
    a: &str,
) -> anyhow::Result<()> {
    let rest = anim.rest();
    if rest.vertex_count() != template.vertex_count() {
        bail!(
            "{a}: the animation has {} vertices, the template {} has {}",
            rest.vertex_count(),
            t_path.display(),
            template.vertex_count()
        );
    }
    if rest.triangles() != template.triangles() {
        let first = rest
            .triangles()
            .iter()
            .zip(template.triangles())
            .position(|(x, y)| x != y)
            .unwrap_or(rest.triangle_count().min(template.triangle_count()));
        bail!(
            "{a}: the animation's triangles differ from those of the template {} (triangle {first}; \
             {} vs {} triangles)",
            t_path.display(),
            rest.triangle_count(),
            template.triangle_count()
        );
    }
    Ok(())
}

/// How frames are deformed.
enum Engine {
    Frames(Deformer),
    Lbs(LbsDeformer),
}

/// Runs `trisplat deform`.
///
/// # Errors
/// Unreadable or mismatched inputs (named), a failed write (files of this run removed).
pub fn run(args: DeformArgs, ctx: &Context) -> anyhow::Result<()> {
    let template = read_mesh(&args.template)?;
    let set = read_gaussians(&args.gaussians)?;
    let g_name = args.gaussians.display().to_string();
    if set.binding().is_none() {
        bail!(
            "{g_name}: the Gaussians are not bound to triangles (no `binding_0`/`binding` property); use `trisplat bind` first"
        );
    }
    if let Some(issue) = set
        .report(Some(template.triangle_count()))
        .issues
        .into_iter()
        .next()
    {
        bail!("{g_name}: {issue} (template {})", args.template.display());
    }
    if args.adaptive_scale && args.mode == ModeArg::Jacobian {
        bail!(
            "--adaptive-scale: jacobian mode already carries the area change in J; use it with binding or lbs"
        );
    }
    let animation = open_animation(&args)?;
    let anim = animation.get();
    check_topology(&template, &args.template, anim, &args.animation)?;
    let frames = parse_frames(args.frames.as_deref(), anim.frame_count())?;
    let engine = match args.mode {
        ModeArg::Binding | ModeArg::Jacobian => {
            let mode = if args.mode == ModeArg::Binding {
                DeformMode::Binding
            } else {
                DeformMode::Jacobian
            };
            let mut d = Deformer::new(&template, mode);
            if args.adaptive_scale {
                d = d.with_adaptive_scale(&template);
            }
            d.check(&set).with_context(|| g_name.clone())?;
            Engine::Frames(d)
        }
        ModeArg::Lbs => {
            let Animation::Gltf(g) = &animation else {
                bail!(
                    "{}: lbs mode needs a skinned glTF animation",
                    args.animation
                );
            };
            if !g.is_skinned() {
                bail!(
                    "{}: lbs mode needs a skinned glTF (this file has no skin with joint weights)",
                    args.animation
                );
            }
            let diag = f64::from(template.bounds().map_or(0.0, |b| b.diagonal()));
            let worst = template
                .positions()
                .iter()
                .zip(g.rest().positions())
                .map(|(a, b)| f64::from((*a - *b).length()))
                .fold(0.0, f64::max);
            if worst > LBS_REST_TOLERANCE * diag.max(f64::MIN_POSITIVE) {
                bail!(
                    "{}: the template's positions differ from the rest pose of {} by up to {worst:.3e}; lbs needs T to be the animation's rest shape (e.g. T = A)",
                    args.template.display(),
                    args.animation
                );
            }
            let rig = LbsDeformer::new(&set, &template, &g.skinning(), &g.palette_at(None)?)
                .with_context(|| g_name.clone())?;
            Engine::Lbs(if args.adaptive_scale {
                rig.with_adaptive_scale(&template)
            } else {
                rig
            })
        }
    };
    // Never write over an input.
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("{}: cannot create the output folder", args.output.display()))?;
    let mut inputs = vec![
        args.template.clone(),
        args.gaussians.clone(),
        PathBuf::from(&args.animation),
    ];
    if let Some(t) = &args.targets {
        inputs.push(t.clone());
    }
    let inputs: HashSet<PathBuf> = inputs
        .iter()
        .filter_map(|p| p.canonicalize().ok())
        .collect();
    for f in frames.clone() {
        let out = args.output.join(frame_name(f));
        if out.canonicalize().is_ok_and(|c| inputs.contains(&c)) {
            bail!(
                "{}: refusing to overwrite an input file; choose another output folder",
                out.display()
            );
        }
    }
    let bar = ctx.progress.bar(frames.len() as u64, "deforming");
    let mut created: Vec<PathBuf> = Vec::new();
    let result = (|| -> anyhow::Result<()> {
        for f in frames.clone() {
            let out = args.output.join(frame_name(f));
            let existed = out.exists();
            let world = deform_frame(&engine, &animation, &set, f, &g_name, &args.animation)?;
            write_gaussians(&out, &world, &PlyWriteOptions::default())?;
            if !existed {
                created.push(out);
            }
            bar.inc(1);
        }
        Ok(())
    })();
    bar.finish_and_clear();
    if result.is_err() {
        for p in &created {
            let _ = std::fs::remove_file(p);
        }
    }
    result
}

/// One deformed frame.
fn deform_frame(
    engine: &Engine,
    animation: &Animation,
    set: &GaussianSet,
    frame: usize,
    g_name: &str,
    a_name: &str,
) -> anyhow::Result<GaussianSet> {
    let anim = animation.get();
    match engine {
        Engine::Frames(d) => {
            let positions = anim.frame(frame)?;
            d.deform(set, &positions)
                .with_context(|| format!("{g_name}: frame {frame} of {a_name}"))
        }
        Engine::Lbs(rig) => {
            let Animation::Gltf(g) = animation else {
                bail!("{a_name}: lbs mode needs a skinned glTF animation");
            };
            let palette = g.frame_palette(frame)?;
            let positions = if rig.adaptive_scale() {
                Some(anim.frame(frame)?)
            } else {
                None
            };
            rig.deform(set, &palette, positions.as_deref())
                .with_context(|| format!("{g_name}: frame {frame} of {a_name}"))
        }
    }
}
