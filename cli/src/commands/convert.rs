//! `trisplat convert`: PLY, OBJ, glTF and GLB meshes from one format to another.

use std::path::PathBuf;

use anyhow::bail;
use trisplat_geometry::io::{self, Format, ObjVertices, PlyEncoding, ReadOptions, WriteOptions};

use super::{Context, refuse_to_overwrite};

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
    /// Animation clip to evaluate (name or index): not supported yet.
    #[arg(long, value_name = "NAME|INDEX")]
    pub clip: Option<String>,
    /// Time in seconds at which to evaluate the animation: not supported yet.
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
}

/// Runs `trisplat convert`.
///
/// # Errors
/// Unknown formats, unreadable or malformed input, an output equal to the input, a failed
/// write, or animation options (not supported yet).
pub fn run(args: ConvertArgs, ctx: &Context) -> anyhow::Result<()> {
    if args.clip.is_some() || args.time.is_some() {
        bail!(
            "{}: --clip/--time need animation support, which trisplat convert does not have \
             yet; without them it writes the rest state",
            args.input.display()
        );
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
