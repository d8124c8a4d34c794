//! `trisplat convert`: PLY, OBJ, glTF and GLB meshes from one format to another.

use std::path::PathBuf;

use anyhow::bail;
use trisplat_geometry::animation::{AnimatedTemplate, GltfTemplate};
use trisplat_geometry::io::{self, Format, ObjVertices, PlyEncoding, ReadOptions, WriteOptions};

use super::{Context, parse_clip, refuse_to_overwrite};

/// Arguments of `trisplat convert`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Convert a mesh between PLY, OBJ, glTF and GLB; formats come from the \
    extensions.\n\nOBJ input keeps its vertex order unless its texture coordinates or normals are \
    indexed differently from its positions; then vertices are split at the seams (as trimesh \
    does) so nothing is lost. PLY to PLY keeps unknown properties and elements. glTF input is \
    read in its rest state (skinned meshes in bind pose, morph targets at zero) with node \
    transforms applied. The output is written atomically and never over the input."
)]
pub struct ConvertArgs {
    /// Input mesh (.ply, .obj, .gltf, .glb).
    pub input: PathBuf,
    /// Output mesh (.ply, .obj, .gltf, .glb).
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
}

/// Runs `trisplat convert`.
///
/// # Errors
/// Unknown formats, unreadable or malformed input, an output equal to the input, a failed
/// write, animation options on a non-glTF input or a glTF without that clip.
pub fn run(args: ConvertArgs, ctx: &Context) -> anyhow::Result<()> {
    if args.clip.is_some() || args.time.is_some() {
        return convert_animated(&args, ctx);
    }
    if args.input.is_dir() {
        bail!(
            "{}: converting a folder of frames (an animated sequence) is not supported yet",
            args.input.display()
        );
    }
    let in_format = Format::from_path(&args.input)?;
    let out_format = Format::from_path(&args.output)?;
    refuse_to_overwrite(&args.input, &args.output)?;
    let options = WriteOptions { ascii: args.ascii };
    let spinner = ctx
        .progress
        .spinner(&format!("converting {}", args.input.display()));
    let result = if in_format == Format::Ply && out_format == Format::Ply {
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
    Ok(())
}

/// `convert` of a glTF/GLB clip evaluated at `--time`: skins, morph targets and node
/// animations applied, written as a static mesh.
fn convert_animated(args: &ConvertArgs, ctx: &Context) -> anyhow::Result<()> {
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
    io::write_mesh(&args.output, &mesh, WriteOptions { ascii: args.ascii })?;
    Ok(())
}
