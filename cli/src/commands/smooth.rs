//! `trisplat smooth MESH -o OUT [--method laplacian|taubin|uniform|cotangent] [--iterations N]
//! [--lambda L] [--mu M]`.

use std::path::PathBuf;

use anyhow::Context as _;
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};
use trisplat_geometry::smoothing::{SmoothOptions, smooth};

use super::{Context, refuse_to_overwrite};

/// Arguments of `trisplat smooth`.
#[derive(Debug, clap::Args)]
pub struct SmoothArgs {
    /// Input mesh (.ply, .obj, .gltf, .glb).
    pub mesh: PathBuf,
    /// Output mesh; format from the extension (.ply, .obj, .gltf, .glb).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Method, iterations and step sizes (Open3D semantics; `uniform` is trimesh's
    /// volume-preserving filter).
    #[command(flatten)]
    pub options: SmoothOptions,
}

/// Runs `trisplat smooth`.
///
/// # Errors
/// Unreadable input, non-finite λ/μ, a diverging iteration, an output that is the input, a
/// failed write.
pub fn run(args: SmoothArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.mesh, &args.output)?;
    let mesh = read_mesh(&args.mesh)?;
    let spinner = ctx.progress.spinner("smoothing");
    let smoothed = smooth(&mesh, &args.options)
        .with_context(|| format!("{}: smoothing failed", args.mesh.display()))?;
    spinner.finish_and_clear();
    write_mesh(&args.output, &smoothed, WriteOptions::default())?;
    ctx.emit(
        "smooth",
        serde_json::json!({
            "output": args.output,
            "vertices": smoothed.vertex_count(),
            "triangles": smoothed.triangle_count(),
        }),
    )
}
