//! `eval`: point-set metrics (docs/conventions.md §8) between two N-point sets against scipy's cKDTree, and
//! exact point-to-surface distances against trimesh.
//!
//! Inputs: two independent N-point area-uniform samplings (seeds 1 and 2, with face normals) of
//! the FLAME registered head scan in `../shared/data/faces/flame/` (not redistributed; the
//! benchmark only reads it), or of any mesh given with `--mesh`. Both sets are written as binary PLY and read back, so both tools see the
//! same float32 values. Timed on our side: both k-d tree builds, both query sweeps and the
//! sums (file loading excluded, as on the Python side).

use std::path::PathBuf;

use anyhow::{Context, bail};
use trisplat_geometry::io::{WriteOptions, read_mesh, read_points, write_mesh, write_points};
use trisplat_geometry::metrics::{DEFAULT_TAUS, point_metrics};
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::spatial::{PointIndex, TriangleBvh};

use crate::harness::{python_script, report, run_python, time_best};

/// Repeats of our side (best time reported).
const REPEATS: usize = 3;
/// Largest relative difference of the two tools' chamfer_l1 accepted as "agree".
const AGREE_REL: f64 = 1e-9;
/// The default mesh: the FLAME registered head scan beside the repository checkout.
const FLAME_SCAN: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/faces/flame/flame_registered_scan.ply"
);

/// Options of the `eval` benchmark.
#[derive(Debug, clap::Args)]
pub struct EvalBenchArgs {
    /// Points per set.
    #[arg(long, default_value_t = 1_000_000)]
    points: usize,
    /// Sample this mesh instead of the FLAME head scan (e.g. the Spot fixture).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Points for the surface-distance row (trimesh is slow; keep it moderate).
    #[arg(long, default_value_t = 100_000)]
    surface_points: usize,
}

/// Runs the benchmark; `python` is the interpreter for the scipy/trimesh side (None: ours only).
///
/// # Errors
/// When the meshes cannot be read, the temporary files cannot be written, the Python side
/// fails, or the two tools disagree.
pub fn run(args: &EvalBenchArgs, python: Option<&str>) -> anyhow::Result<()> {
    let (gt_mesh, label) = match &args.mesh {
        Some(path) => (read_mesh(path)?, path.display().to_string()),
        None => match read_mesh(FLAME_SCAN.as_ref()) {
            Ok(scan) => (scan, "FLAME registered scan, two samplings".to_owned()),
            Err(e) => {
                let fallback = trisplat_fixtures::path("spot_triangulated.obj");
                println!("{e}; using {}", fallback.display());
                (read_mesh(&fallback)?, "Spot, two samplings".to_owned())
            }
        },
    };
    let n = args.points;
    let pred = sample_uniform(&gt_mesh, n, 1);
    let gt = sample_uniform(&gt_mesh, n, 2);
    if pred.is_empty() || gt.is_empty() {
        bail!("a mesh has zero area");
    }
    let dir = tempfile::tempdir()?;
    let pred_path = dir.path().join("pred.ply");
    let gt_path = dir.path().join("gt.ply");
    let mesh_path = dir.path().join("gt_mesh.ply");
    write_points(&pred_path, &pred, WriteOptions::default())?;
    write_points(&gt_path, &gt, WriteOptions::default())?;
    write_mesh(&mesh_path, &gt_mesh, WriteOptions::default())?;
    let pred = read_points(&pred_path)?;
    let gt = read_points(&gt_path)?;
    println!(
        "{label}: {} + {} points with normals ({} rayon threads)",
        pred.len(),
        gt.len(),
        rayon::current_num_threads()
    );

    // Point mode, both ways.
    let (ours, metrics) = time_best(REPEATS, || point_metrics(&pred, &gt, &DEFAULT_TAUS));
    let metrics = metrics?;
    // Where our time goes (one run each).
    let (build, index) = time_best(1, || PointIndex::new(gt.positions()));
    let index = index?;
    let (query, _) = time_best(1, || index.nearest_batch(pred.positions()));
    println!("  breakdown: one k-d tree build {build:.3} s, one 1M-query sweep {query:.3} s");
    let pred_index = PointIndex::new(pred.positions())?;
    let (sweep, _) = time_best(1, || index.nearest_to_points_of(&pred_index));
    println!("  the same sweep in the queries' own tree order (as `eval` runs it) {sweep:.3} s");
    let row = format!("point metrics {}k <-> {}k", n / 1000, n / 1000);
    let path_str = |p: &std::path::Path| -> anyhow::Result<String> {
        Ok(p.to_str()
            .context("temporary path is not UTF-8")?
            .to_owned())
    };
    match python {
        Some(py) => {
            let (p, g) = (path_str(&pred_path)?, path_str(&gt_path)?);
            let taus: Vec<String> = DEFAULT_TAUS.iter().map(f64::to_string).collect();
            let mut script_args = vec!["points", p.as_str(), g.as_str()];
            script_args.extend(taus.iter().map(String::as_str));
            let result = run_python(py, &python_script("eval_scipy.py"), &script_args)?;
            let theirs = number(&result, "seconds")?;
            report(&row, ours, Some(("scipy cKDTree", theirs)));
            let their_chamfer = number(&result, "chamfer_l1")?;
            let rel = ((metrics.chamfer_l1 - their_chamfer) / their_chamfer).abs();
            println!(
                "  chamfer_l1 trisplat {:.12e}  scipy {their_chamfer:.12e}  rel diff {rel:.2e}",
                metrics.chamfer_l1
            );
            if let Some(nc) = result.get("normal_consistency").and_then(|v| v.as_f64()) {
                println!(
                    "  normal_consistency trisplat {:.12}  scipy {nc:.12}",
                    metrics.normal_consistency.unwrap_or(f64::NAN)
                );
            }
            if rel > AGREE_REL {
                bail!("chamfer_l1 differs from scipy's by {rel:.2e} (relative)");
            }
        }
        None => report(&row, ours, None),
    }

    // Surface distances: exact closest point on the ground-truth mesh for M points.
    let m = args.surface_points.min(pred.len());
    let queries = &pred.positions()[..m];
    let (ours, found) = time_best(REPEATS, || {
        TriangleBvh::new(&gt_mesh).and_then(|bvh| bvh.closest_points(queries))
    });
    let found = found?;
    let mean = found.iter().map(|c| c.distance).sum::<f64>() / m as f64;
    let row = format!(
        "surface distance {}k pts, {}k tris",
        m / 1000,
        gt_mesh.triangle_count() / 1000
    );
    match python {
        Some(py) => {
            let (p, g) = (path_str(&pred_path)?, path_str(&mesh_path)?);
            let count = m.to_string();
            let result = run_python(
                py,
                &python_script("eval_scipy.py"),
                &["surface", p.as_str(), g.as_str(), count.as_str()],
            )?;
            let theirs = number(&result, "seconds")?;
            report(&row, ours, Some(("trimesh", theirs)));
            let their_mean = number(&result, "mean_distance")?;
            println!(
                "  mean distance trisplat {mean:.12e}  trimesh {their_mean:.12e}  diff {:.2e}",
                (mean - their_mean).abs()
            );
        }
        None => report(&row, ours, None),
    }
    Ok(())
}

fn number(v: &serde_json::Value, key: &str) -> anyhow::Result<f64> {
    v.get(key)
        .and_then(serde_json::Value::as_f64)
        .with_context(|| format!("Python result has no {key}"))
}
