//! `trisplat alpha-shape POINTS.ply --alpha A -o MESH.ply`.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_extract::alpha_shape::alpha_shape;
use trisplat_geometry::cleanup::keep_largest_clusters;
use trisplat_geometry::io::{WriteOptions, read_points_local, write_mesh};
use trisplat_geometry::topology::TriangleClusters;

use super::{Context, refuse_to_overwrite};

/// Arguments of `trisplat alpha-shape`.
#[derive(Debug, clap::Args)]
pub struct AlphaShapeArgs {
    /// Input points: a PLY point cloud, or the vertices of any mesh (.ply, .obj, .gltf, .glb).
    pub points: PathBuf,
    /// Keep the Delaunay tetrahedra with circumradius <= ALPHA (Open3D's definition; same units
    /// as the points).
    #[arg(long)]
    pub alpha: f64,
    /// Output mesh (.ply, .obj, .gltf, .glb): the boundary triangles, oriented outward.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Keep only the edge-connected pieces at least as large (in triangles) as the K-th
    /// largest (0: every piece, as Open3D).
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub keep_clusters: usize,
}

/// Runs `trisplat alpha-shape`.
///
/// # Errors
/// Unreadable input, a NaN α, non-finite or huge coordinates, an output that is the input, a
/// failed write.
pub fn run(args: AlphaShapeArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.points, &args.output)?;
    if args.alpha.is_nan() || args.alpha < 0.0 {
        bail!("--alpha {}: expected a non-negative radius", args.alpha);
    }
    // Points far from the world origin are tetrahedralised at their local origin (f64 before
    // f32) and the mesh moved back in f64.
    let (cloud, origin) = read_points_local(&args.points)?;
    let spinner = ctx.progress.spinner("tetrahedralising");
    let shape = alpha_shape(cloud.positions(), args.alpha)
        .with_context(|| format!("{}: alpha shape failed", args.points.display()))?;
    spinner.finish_and_clear();
    if shape.kept_tetrahedra == 0 {
        eprintln!(
            "warning: {}: the alpha shape is empty: no tetrahedron of the {} points has a \
             circumradius <= {} (points that are all coincident, collinear or coplanar have no \
             tetrahedra at all)",
            args.points.display(),
            cloud.len(),
            args.alpha
        );
    }
    let mut mesh = shape.mesh.clone();
    if let Some(colors) = cloud.colors() {
        let picked = shape
            .vertex_ids
            .iter()
            .map(|&i| colors[i as usize])
            .collect();
        mesh = mesh
            .with_colors(picked)
            .context("carrying the point colours")?;
    }
    let pieces = TriangleClusters::of(&mesh).count();
    let mut mesh = keep_largest_clusters(&mesh, args.keep_clusters);
    mesh.translate(origin);
    if !ctx.quiet && pieces > 1 {
        eprintln!(
            "{}: the alpha shape has {pieces} edge-connected pieces{}",
            args.points.display(),
            if mesh.triangle_count() < shape.mesh.triangle_count() {
                format!(
                    "; kept {} (--keep-clusters {})",
                    TriangleClusters::of(&mesh).count(),
                    args.keep_clusters
                )
            } else {
                " (--keep-clusters K keeps the K largest)".to_owned()
            }
        );
    }
    write_mesh(&args.output, &mesh, WriteOptions::default())?;
    ctx.emit(
        "alpha-shape",
        serde_json::json!({
            "output": args.output,
            "alpha": args.alpha,
            "vertices": mesh.vertex_count(),
            "triangles": mesh.triangle_count(),
            "pieces": pieces,
            "kept_pieces": TriangleClusters::of(&mesh).count(),
        }),
    )
}
