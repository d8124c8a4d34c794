//! `trisplat convert`: PLY, OBJ, glTF and GLB meshes from one format to another, Gaussians
//! between INRIA PLY, SPZ and glTF/GLB with `KHR_gaussian_splatting`, and a folder or pattern
//! of same-topology OBJ/PLY frames to one animated glTF/GLB.

use std::path::{Path, PathBuf};

use anyhow::bail;
use rayon::prelude::*;
use trisplat_geometry::animation::{
    AnimatedTemplate, DEFAULT_FPS, GltfTemplate, MeshSequence, check_topology,
};
use trisplat_geometry::io::{
    self, Format, ObjVertices, PlyEncoding, ReadOptions, SequenceLayout, WriteOptions,
};

use trisplat_geometry::TriMesh;
use trisplat_geometry::simplify::{SimplifyOptions, SimplifyTarget, simplify};
use trisplat_pipeline::config::SimplifyBorder;

use super::gaussian_io::{GaussianFormatArgs, read_gaussian_file, write_gaussian_file};
use super::{Context, UsageError, parse_clip, refuse_to_overwrite};

/// Arguments of `trisplat convert`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Convert a mesh between PLY, OBJ, glTF and GLB; formats come from the \
    extensions.\n\nOBJ input keeps its vertex order unless its texture coordinates or normals are \
    indexed differently from its positions; then vertices are split at the seams (as trimesh \
    does) so nothing is lost. PLY to PLY keeps unknown properties and elements. glTF input is \
    read in its rest state (skinned meshes in bind pose, morph targets at zero) with node \
    transforms applied. The output is written atomically and never over the input.\n\n\
    A folder of OBJ/PLY frames (natural order of the file names: f2 before f10) or a pattern \
    (frames/f_%04d.ply, frames/f_*.obj) as INPUT and a .glb/.gltf OUTPUT write one animated \
    glTF: every frame must have the vertex count and triangles of the first; frame 0 is the \
    base mesh, each later frame a morph target, and a STEP weights track shows frame k at \
    k / FPS seconds (--fps, default 30). With --any-topology the frames may differ (one node \
    per run of frames with one topology, morph-animated within it, each shown by a STEP scale \
    track at its times).\n\n\
    Gaussians: an .spz input or output, a .glb/.gltf input with KHR_gaussian_splatting \
    primitives, or a 3DGS PLY (vertex properties x, opacity, f_dc_0, scale_0, rot_0) converted \
    to .spz/.glb/.gltf converts Gaussians between INRIA PLY (lossless), Niantic SPZ (quantised: \
    positions to 1/4096, log-scales to 1/16, opacity and colour to 8 bits, SH to 5/4 bits, \
    rotations to 8 or 10 bits) and glTF with KHR_gaussian_splatting (float: means, rotations \
    and SH exact; scales and opacities through exp/sigmoid rounded once). SPZ stores RUB axes: \
    --axes names the axes of the other side (default rdf, the INRIA training frame). Only \
    world-space Gaussians go to SPZ and glTF (bound ones: `trisplat deform` first).\n\n\
    --faces N or --simplify-error E decimate one mesh (also a posed --time frame) through \
    meshoptimizer's simplifier before it is written (docs/conventions.md §10): kept vertices \
    stay in place with their attributes, an open mesh's border stays put unless \
    --simplify-border free; --json gives the faces before and after, meshoptimizer's error \
    estimate and the measured one-sided Hausdorff and mean distance from the input's vertices \
    and triangle centroids to the result. Frame sequences and Gaussians are not decimated."
)]
pub struct ConvertArgs {
    /// Input mesh (.ply, .obj, .gltf, .glb), or a folder or pattern of OBJ/PLY frames.
    pub input: PathBuf,
    /// Output mesh (.ply, .obj, .gltf, .glb); .glb or .gltf for frames, or .usda (a USD mesh
    /// cache: points at every frame, topology where it changes).
    pub output: PathBuf,
    /// Write PLY as ascii instead of binary little-endian.
    #[arg(long)]
    pub ascii: bool,
    /// Animation clip of a glTF/GLB input to evaluate (name or index; default the first).
    #[arg(long, value_name = "NAME|INDEX")]
    pub clip: Option<String>,
    /// Time in seconds at which to evaluate the clip (clamped to the clip; default 0).
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
    /// Frame rate of a folder or pattern of frames: frame k is shown at k / F seconds
    /// [default: 30].
    #[arg(long, value_name = "F", value_parser = parse_fps)]
    pub fps: Option<f64>,
    /// Frames may differ in vertices and triangles (TSDF or alpha-shape meshes of a sequence):
    /// one node per run of frames with one topology (morph targets within a run) shown by
    /// STEP scale tracks, as extract's sequences; frames that all share the first's topology
    /// become one morph-target mesh.
    #[arg(long)]
    pub any_topology: bool,
    /// How a frame sequence's glTF stores its data: meshopt (default; 16-bit positions and
    /// morph deltas within 5.3e-5 of the sequence's bounding-box diagonal, byte normals,
    /// KHR_mesh_quantization + EXT_meshopt_compression), quantize (the integers,
    /// uncompressed), none (plain f32 glTF 2.0, every reader; largest).
    #[arg(long, value_enum, value_name = "KIND", default_value_t = io::GltfCompression::Meshopt)]
    pub gltf_compression: io::GltfCompression,
    /// A frame sequence's morph basis (meshopt and quantize; frames without normals): the
    /// frames as a few basis shapes and a weight per shape and frame, the fewest (up to 128,
    /// fewer than the frames) that put every vertex of every frame within E of the frame's
    /// bounding-box diagonal of its place; else one morph target per frame. 0 (the default,
    /// as extract's): one morph target per frame; the basis is made for 8e-5.
    #[arg(long, value_name = "E", default_value_t = 0.0, value_parser = parse_share)]
    pub gltf_morph_tolerance: f64,
    /// Gaussian formats.
    #[command(flatten)]
    pub gaussian: GaussianFormatArgs,
    /// Decimate the mesh to at most N triangles (meshoptimizer; a mesh with no more is
    /// written as it is).
    #[arg(long, value_name = "N", conflicts_with = "simplify_error", value_parser = parse_faces)]
    pub faces: Option<usize>,
    /// Decimate the mesh while meshoptimizer's error stays within E times its extent (the
    /// largest side of its bounding box; 0.001 = 0.1%).
    #[arg(long, value_name = "E", value_parser = parse_share)]
    pub simplify_error: Option<f64>,
    /// Decimation: whether an open mesh's border vertices stay in place.
    #[arg(long, value_enum, value_name = "RULE", default_value_t = SimplifyBorder::Locked)]
    pub simplify_border: SimplifyBorder,
}

/// A `--faces` value: a positive integer.
fn parse_faces(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("expected a face count of at least 1, got {s:?}")),
    }
}

/// A `--simplify-error` or `--gltf-morph-tolerance` value: finite and 0 or more.
pub(crate) fn parse_share(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        _ => Err(format!(
            "expected a finite share of the mesh's extent, 0 or more, got {s:?}"
        )),
    }
}

impl ConvertArgs {
    /// The decimation asked for, if any.
    fn simplify(&self) -> Option<SimplifyOptions> {
        let target = match (self.faces, self.simplify_error) {
            (Some(n), _) => SimplifyTarget::Faces(n),
            (None, Some(e)) => SimplifyTarget::Error(e),
            (None, None) => return None,
        };
        Some(SimplifyOptions {
            target,
            lock_border: self.simplify_border == SimplifyBorder::Locked,
        })
    }
}

/// `mesh` (read from `input`) decimated as `options` asks, with the JSON of what it cost.
fn decimate(
    mesh: TriMesh,
    input: &Path,
    options: Option<&SimplifyOptions>,
) -> anyhow::Result<(TriMesh, Option<serde_json::Value>)> {
    let Some(options) = options else {
        return Ok((mesh, None));
    };
    let s = simplify(&mesh, options)
        .map_err(|e| anyhow::anyhow!("{}: cannot decimate: {e}", input.display()))?;
    let json = serde_json::json!({
        "faces_before": s.faces_before,
        "faces_after": s.faces_after,
        "meshopt_error": s.error,
        "hausdorff": s.hausdorff,
        "mean_distance": s.mean_distance,
    });
    Ok((s.mesh, Some(json)))
}

/// A `--fps` value: finite and > 0.
fn parse_fps(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(f) if f.is_finite() && f > 0.0 => Ok(f),
        _ => Err(format!(
            "expected a positive number of frames per second, got {s:?}"
        )),
    }
}

/// Whether `input` names a sequence of frames: a folder, or a file-name pattern (`%d`, `*`,
/// `?`) that is not itself an existing file.
fn is_sequence_input(input: &Path) -> bool {
    input.is_dir()
        || (!input.is_file()
            && input
                .file_name()
                .is_some_and(|n| n.to_string_lossy().contains(['%', '*', '?'])))
}

/// Runs `trisplat convert`.
///
/// # Errors
/// Unknown formats, unreadable or malformed input, an output equal to the input, a failed
/// write, animation options on a non-glTF input or a glTF without that clip.
pub fn run(args: ConvertArgs, ctx: &Context) -> anyhow::Result<()> {
    let simplified = convert_any(&args, ctx)?;
    let bytes = std::fs::metadata(&args.output).map(|m| m.len()).ok();
    let mut json =
        serde_json::json!({ "input": args.input, "output": args.output, "bytes": bytes });
    if let Some(s) = simplified {
        json["simplify"] = s;
    }
    ctx.emit("convert", json)
}

/// The conversion `args` asks for: a frame sequence to an animated glTF, Gaussians between
/// their formats, a posed glTF frame, or a mesh between formats; what decimation cost, if
/// asked.
fn convert_any(args: &ConvertArgs, ctx: &Context) -> anyhow::Result<Option<serde_json::Value>> {
    let simplify = args.simplify();
    let sequence = is_sequence_input(&args.input);
    if simplify.is_some() && (sequence || is_gaussian_conversion(&args.input, &args.output)) {
        return Err(UsageError(format!(
            "--faces/--simplify-error decimate one mesh; {} is {}",
            args.input.display(),
            if sequence {
                "a frame sequence (trisplat extract decimates each frame or key)"
            } else {
                "Gaussians"
            }
        ))
        .into());
    }
    if sequence {
        return convert_sequence(args, ctx).map(|()| None);
    }
    if args.fps.is_some() {
        return Err(UsageError(format!(
            "--fps is the frame rate of a folder or pattern of frames; {} is one mesh",
            args.input.display()
        ))
        .into());
    }
    if is_gaussian_conversion(&args.input, &args.output) {
        return convert_gaussians(args, ctx).map(|()| None);
    }
    if args.clip.is_some() || args.time.is_some() {
        return convert_animated(args, ctx, simplify.as_ref());
    }
    let in_format = Format::from_path(&args.input)?;
    let out_format = Format::from_path(&args.output)?;
    refuse_to_overwrite(&args.input, &args.output)?;
    let options = WriteOptions { ascii: args.ascii };
    let spinner = ctx
        .progress
        .spinner(&format!("converting {}", args.input.display()));
    let result = if let Some(options) = &simplify {
        // Decimated: per-vertex and per-face extras would no longer fit, so only the mesh.
        let read = ReadOptions {
            obj_vertices: ObjVertices::Auto,
        };
        let mesh = io::read_mesh_with(&args.input, read)?;
        let (mesh, json) = decimate(mesh, &args.input, Some(options))?;
        spinner.finish_and_clear();
        io::write_mesh(&args.output, &mesh, options_for(args))?;
        return Ok(json);
    } else if in_format == Format::Ply && out_format == Format::Ply {
        // Keep unknown properties and elements.
        let (mesh, extras) = io::ply::read_ply_mesh(&args.input)?;
        let encoding = if args.ascii {
            PlyEncoding::Ascii
        } else {
            PlyEncoding::BinaryLittleEndian
        };
        io::ply::write_ply_mesh(&args.output, &mesh, &extras, encoding)
    } else {
        let read = ReadOptions {
            obj_vertices: ObjVertices::Auto,
        };
        let mesh = io::read_mesh_with(&args.input, read)?;
        io::write_mesh(&args.output, &mesh, options)
    };
    spinner.finish_and_clear();
    result?;
    Ok(None)
}

/// The write options of `args`.
fn options_for(args: &ConvertArgs) -> WriteOptions {
    WriteOptions { ascii: args.ascii }
}

/// Whether `convert` moves Gaussians: SPZ on either side, a glTF/GLB input with
/// `KHR_gaussian_splatting`, or a 3DGS PLY to glTF/GLB (PLY to PLY keeps the mesh path, which
/// keeps every property and element).
fn is_gaussian_conversion(input: &Path, output: &Path) -> bool {
    use super::gaussian_io::GaussianFormat as F;
    let (i, o) = (F::from_path(input), F::from_path(output));
    matches!(i, Some(F::Spz))
        || matches!(o, Some(F::Spz))
        || (matches!(i, Some(F::Glb | F::Gltf))
            && trisplat_splat::gltf_splat::has_gaussian_splats(input))
        || (matches!(i, Some(F::Ply))
            && matches!(o, Some(F::Glb | F::Gltf))
            && trisplat_splat::ply::is_gaussian_ply(input))
}

/// `convert` of Gaussians between PLY, SPZ and glTF/GLB.
fn convert_gaussians(args: &ConvertArgs, ctx: &Context) -> anyhow::Result<()> {
    if args.clip.is_some() || args.time.is_some() {
        return Err(UsageError(format!(
            "--clip/--time evaluate a mesh animation; {} holds Gaussians",
            args.input.display()
        ))
        .into());
    }
    refuse_to_overwrite(&args.input, &args.output)?;
    let spinner = ctx
        .progress
        .spinner(&format!("converting {}", args.input.display()));
    let result = read_gaussian_file(&args.input, &args.gaussian).and_then(|read| {
        write_gaussian_file(
            &args.output,
            &read.set,
            &args.gaussian,
            read.antialiased,
            args.ascii,
        )
    });
    spinner.finish_and_clear();
    result
}

/// `convert` of a glTF/GLB clip evaluated at `--time`: skins, morph targets and node
/// animations applied, written as a static mesh.
fn convert_animated(
    args: &ConvertArgs,
    ctx: &Context,
    simplify: Option<&SimplifyOptions>,
) -> anyhow::Result<Option<serde_json::Value>> {
    if !matches!(Format::from_path(&args.input)?, Format::Gltf | Format::Glb) {
        bail!(
            "{}: --clip/--time evaluate an animation, which only glTF/GLB input has",
            args.input.display()
        );
    }
    Format::from_path(&args.output)?;
    refuse_to_overwrite(&args.input, &args.output)?;
    let time = args.time.unwrap_or(0.0);
    let spinner = ctx
        .progress
        .spinner(&format!("evaluating {} at {time} s", args.input.display()));
    let template = GltfTemplate::open(&args.input, &parse_clip(args.clip.as_deref()))?;
    let positions = template.evaluate_at(time)?;
    let mut mesh = template.rest().clone();
    mesh.clear_normals();
    mesh.set_positions(positions)
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.input.display()))?;
    spinner.finish_and_clear();
    let (mesh, json) = decimate(mesh, &args.input, simplify)?;
    io::write_mesh(&args.output, &mesh, options_for(args))?;
    Ok(json)
}

/// `convert` of a folder or pattern of frames to one animated glTF/GLB, frame k at k / fps
/// seconds: morph targets (the frames share the first's topology), or with `--any-topology`
/// one node per run of one topology where they do not.
fn convert_sequence(args: &ConvertArgs, ctx: &Context) -> anyhow::Result<()> {
    let input = args.input.display();
    if args.clip.is_some() || args.time.is_some() {
        return Err(UsageError(format!(
            "--clip/--time evaluate a glTF animation; {input} is a folder or pattern of frames"
        ))
        .into());
    }
    let usda = args
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("usda"));
    if !usda
        && !matches!(
            Format::from_path(&args.output),
            Ok(Format::Glb | Format::Gltf)
        )
    {
        return Err(UsageError(format!(
            "{input} is a folder or pattern of frames, which converts to one animated .glb or \
             .gltf, or a .usda mesh cache, not {}; to convert one frame, name its file",
            args.output.display()
        ))
        .into());
    }
    let sequence = if args.input.is_dir() {
        MeshSequence::from_dir(&args.input)?
    } else {
        let Some(pattern) = args.input.to_str() else {
            bail!("{input}: the pattern is not valid UTF-8");
        };
        MeshSequence::from_pattern(pattern)?
    };
    for file in sequence.files() {
        refuse_to_overwrite(file, &args.output)?;
    }
    let files = sequence.files();
    if !args.any_topology && sequence.rest().triangle_count() == 0 {
        bail!(
            "{}: has no triangles; the first frame is the base mesh of the animated glTF",
            files[0].display()
        );
    }
    let bar = ctx.progress.bar(
        files.len().saturating_sub(1) as u64,
        &format!("checking frames of {input}"),
    );
    // Check in parallel (the first bad frame in file order is reported, naming its file); the
    // writer then reads the frames one at a time, so memory does not grow with their number.
    let first = sequence.rest();
    let checked: Vec<anyhow::Result<()>> = files[1..]
        .par_iter()
        .map(|file| {
            let mesh = io::read_mesh(file)?;
            if !args.any_topology {
                check_topology(&mesh, first, file, &files[0])?;
            }
            bar.inc(1);
            Ok(())
        })
        .collect();
    bar.finish_and_clear();
    checked.into_iter().collect::<anyhow::Result<Vec<()>>>()?;
    let fps = args.fps.unwrap_or(DEFAULT_FPS);
    let times: Vec<f64> = (0..files.len()).map(|k| k as f64 / fps).collect();
    let spinner = ctx
        .progress
        .spinner(&format!("writing {}", args.output.display()));
    let result = if usda {
        io::write_usd_sequence(&args.output, &io::FrameFiles(files), &times).map(|_| ())
    } else {
        let options = io::SequenceOptions {
            layout: if args.any_topology {
                SequenceLayout::Auto
            } else {
                SequenceLayout::MorphTargets
            },
            compression: args.gltf_compression,
            morph_basis: io::MorphBasis {
                tolerance: args.gltf_morph_tolerance,
                ..io::MorphBasis::default()
            },
        };
        io::write_sequence_with(&args.output, &io::FrameFiles(files), &times, &options)
    };
    spinner.finish_and_clear();
    result?;
    Ok(())
}
