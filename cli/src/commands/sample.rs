//! `trisplat sample MESH -n N [--method uniform|poisson|curvature] [--seed S] -o POINTS.ply`.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_geometry::glam::DVec3;
use trisplat_geometry::io::{WriteOptions, read_mesh, write_points_at};
use trisplat_geometry::sampling::{SampleOptions, sample};

use super::{Context, refuse_to_overwrite};

/// Default `--max-points`: 100 million points (2.4 GB of positions and normals).
pub const DEFAULT_MAX_POINTS: u64 = 100_000_000;

/// Arguments of `trisplat sample`.
#[derive(Debug, clap::Args)]
pub struct SampleArgs {
    /// Input mesh (.ply, .obj, .gltf, .glb).
    pub mesh: PathBuf,
    /// Number of points to sample (at least 1, at most --max-points).
    #[arg(short = 'n', long = "number", value_parser = clap::value_parser!(u64).range(1..))]
    pub n: u64,
    /// Largest -n accepted, checked before anything is allocated (each point takes 24 bytes
    /// in memory and in the file).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_POINTS)]
    pub max_points: u64,
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
    let n = match usize::try_from(args.n) {
        Ok(n) if args.n <= args.max_points => n,
        _ => bail!(
            "-n {}: more than --max-points {} (raise --max-points to sample more)",
            args.n,
            args.max_points
        ),
    };
    // A mesh far from the world origin is sampled at its local origin (the f32 samples keep
    // their precision) and the samples written back where it is, in f64.
    let mut mesh = read_mesh(&args.mesh)?;
    let origin = mesh.bounds().map_or(DVec3::ZERO, |b| b.local_origin());
    mesh.translate(-origin);
    let area = mesh.area();
    if n > 0 && (area <= 0.0 || area.is_nan()) {
        bail!(
            "{}: the mesh has no surface to sample ({} triangles, total area 0)",
            args.mesh.display(),
            mesh.triangle_count()
        );
    }
    let spinner = ctx.progress.spinner("sampling");
    let samples = sample(&mesh, n, &args.options)
        .with_context(|| format!("{}: sampling failed", args.mesh.display()))?;
    spinner.finish_and_clear();
    write_points_at(
        &args.output,
        &samples.points,
        origin,
        WriteOptions::default(),
    )?;
    ctx.emit(
        "sample",
        serde_json::json!({
            "output": args.output,
            "points": samples.points.len(),
            "mesh_area": area,
        }),
    )
}
