//! `trisplat sample MESH -n N [--method uniform|poisson|curvature] [--seed S] -o POINTS.ply`.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_geometry::io::{WriteOptions, read_mesh, write_points};
use trisplat_geometry::sampling::{SampleOptions, sample};

use super::{Context, refuse_to_overwrite};

/// Arguments of `trisplat sample`.
#[derive(Debug, clap::Args)]
pub struct SampleArgs {
    /// Input mesh (.ply, .obj, .gltf, .glb).
    pub mesh: PathBuf,
    /// Number of points to sample.
    #[arg(short = 'n', long = "number")]
    pub n: usize,
    /// Output point cloud (.ply): positions and the unit normals of the sampled triangles.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Method, seed and curvature strength.
    #[command(flatten)]
    pub options: SampleOptions,
}

/// Runs `trisplat sample`.
///
/// # Errors
/// Unreadable or empty input, zero surface area, bad options, an output that is the input or
/// not a `.ply`, a failed write.
pub fn run(args: SampleArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.mesh, &args.output)?;
    let is_ply = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if !is_ply {
        bail!(
            "{}: point clouds are written as PLY: use a .ply output",
            args.output.display()
        );
    }
    let mesh = read_mesh(&args.mesh)?;
    let area = mesh.area();
    if args.n > 0 && (area <= 0.0 || area.is_nan()) {
        bail!(
            "{}: the mesh has no surface to sample ({} triangles, total area 0)",
            args.mesh.display(),
            mesh.triangle_count()
        );
    }
    let spinner = ctx.progress.spinner("sampling");
    let samples = sample(&mesh, args.n, &args.options)
        .with_context(|| format!("{}: sampling failed", args.mesh.display()))?;
    spinner.finish_and_clear();
    write_points(&args.output, &samples.points, WriteOptions::default())?;
    Ok(())
}
