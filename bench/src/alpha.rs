//! `alpha`: 3D Delaunay + alpha shape of N surface samples against Open3D 0.20's
//! `TriangleMesh.create_from_point_cloud_alpha_shape` (Qhull) on the same PLY file.
//!
//! Input: N area-uniform samples (seed 1) of the FLAME registered head scan in
//! `../shared/data/faces/flame/` (read only, not redistributed), or of Spot when the scan is
//! missing, or of any mesh given with `--mesh`. The points are written as binary PLY and read
//! back, so both tools see the same float32 values. α defaults to `--alpha-spacings` times the
//! mean sample spacing `sqrt(area / N)`. Timed on both sides: tetrahedralisation + filtering +
//! boundary extraction (file loading excluded). The boundary triangles are compared as sets of
//! sorted input-index triples, leaving out faces of tetrahedra whose circumradius is within
//! [`ALPHA_TIE_REL`] of α.

use std::collections::HashSet;
use std::path::PathBuf;

use anyhow::{Context, bail};
use trisplat_extract::alpha_shape::{alpha_shape_from_delaunay, circumradius};
use trisplat_extract::delaunay3d::{Delaunay3d, FACE_VERTICES};
use trisplat_geometry::io::{WriteOptions, read_mesh, read_points, write_points};
use trisplat_geometry::metrics::point_metrics;
use trisplat_geometry::sampling::sample_uniform;

use crate::harness::{python_script, report, run_python, time_best};

/// Repeats of our side (best time reported).
const REPEATS: usize = 3;
/// Relative band around α inside which a tetrahedron counts as a tie (not compared).
const ALPHA_TIE_REL: f64 = 1e-9;
/// The default mesh: the FLAME registered head scan beside the repository checkout.
const FLAME_SCAN: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/faces/flame/flame_registered_scan.ply"
);

/// Options of the `alpha` benchmark.
#[derive(Debug, clap::Args)]
pub struct AlphaBenchArgs {
    /// Number of surface samples.
    #[arg(long, default_value_t = 100_000)]
    points: usize,
    /// Sample this mesh instead of the FLAME head scan.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// α as a multiple of the mean sample spacing sqrt(area / N).
    #[arg(long, default_value_t = 2.0)]
    alpha_spacings: f64,
    /// α in absolute units (overrides --alpha-spacings).
    #[arg(long)]
    alpha: Option<f64>,
    /// Also print the error-vs-time table: for several α (multiples of the spacing), the
    /// milliseconds of the alpha step on a reused tetrahedralisation and the Chamfer-L1 /
    /// F-score of the alpha mesh against the scan (ours only).
    #[arg(long)]
    sweep: bool,
}

/// α values of the sweep, in units of the mean sample spacing.
const SWEEP_SPACINGS: [f64; 7] = [1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 30.0];
/// Points sampled on each side for the sweep's Chamfer distance.
const SWEEP_SAMPLES: usize = 200_000;

/// Runs the benchmark; `python` is the interpreter for the Open3D side (None: ours only).
///
/// # Errors
/// When the mesh cannot be read, the temporary files cannot be written, the Python side fails,
/// or the two tools disagree.
pub fn run(args: &AlphaBenchArgs, python: Option<&str>) -> anyhow::Result<()> {
    let (mesh, label) = match &args.mesh {
        Some(path) => (read_mesh(path)?, path.display().to_string()),
        None => match read_mesh(FLAME_SCAN.as_ref()) {
            Ok(scan) => (scan, "FLAME registered scan".to_owned()),
            Err(e) => {
                let fallback = trisplat_fixtures::path("spot_triangulated.obj");
                println!("{e}; using {}", fallback.display());
                (read_mesh(&fallback)?, "Spot".to_owned())
            }
        },
    };
    let n = args.points;
    let samples = sample_uniform(&mesh, n, 1);
    if samples.is_empty() {
        bail!("the mesh has zero area or no samples were asked for");
    }
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("samples.ply");
    write_points(&path, &samples, WriteOptions::default())?;
    let points = read_points(&path)?.positions().to_vec();
    let spacing = (mesh.area() / n as f64).sqrt();
    let alpha = args.alpha.unwrap_or(args.alpha_spacings * spacing);
    println!(
        "{label}: {} samples, alpha {alpha:.6} (mean spacing {spacing:.6}; {} rayon threads)",
        points.len(),
        rayon::current_num_threads()
    );

    let (t_delaunay, delaunay) = time_best(REPEATS, || Delaunay3d::new(&points));
    let delaunay = delaunay?;
    let (t_total, shape) = time_best(REPEATS, || {
        Delaunay3d::new(&points)
            .map_err(anyhow::Error::from)
            .and_then(|d| Ok(alpha_shape_from_delaunay(&d, alpha)?))
    });
    let shape = shape?;
    println!(
        "ours: {} tetrahedra ({} duplicates skipped), {} kept, {} boundary triangles, signed volume {:.6e}",
        delaunay.tetrahedra().len(),
        delaunay.duplicates().len(),
        shape.kept_tetrahedra,
        shape.mesh.triangle_count(),
        shape.mesh.signed_volume()
    );
    report("delaunay 3d (ours only)", t_delaunay, None);
    if args.sweep {
        sweep(&mesh, &delaunay, spacing)?;
    }
    let name = format!("delaunay + alpha shape ({n} points)");
    let Some(py) = python else {
        report(&name, t_total, None);
        return Ok(());
    };
    let out = dir.path().join("open3d_triangles.bin");
    let path_str = path.to_str().context("temporary path is not UTF-8")?;
    let out_str = out.to_str().context("temporary path is not UTF-8")?;
    let alpha_str = format!("{alpha:.17e}");
    let result = run_python(
        py,
        &python_script("alpha_open3d.py"),
        &[path_str, &alpha_str, out_str],
    )?;
    let theirs = result
        .get("seconds")
        .and_then(serde_json::Value::as_f64)
        .context("the Open3D script printed no seconds")?;
    report(&name, t_total, Some(("Open3D", theirs)));

    // Agreement: the boundary triangles as sets, tie faces left out.
    let bytes = std::fs::read(&out)?;
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let mut ties = HashSet::new();
    let pts = delaunay.points();
    for t in delaunay.tetrahedra() {
        let r = circumradius(t.map(|v| pts[v as usize]));
        if (r - alpha).abs() <= ALPHA_TIE_REL * alpha {
            for f in FACE_VERTICES {
                ties.insert(sorted(f.map(|k| t[k])));
            }
        }
    }
    let theirs: HashSet<[u32; 3]> = words
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .filter(|t| !ties.contains(t))
        .collect();
    let ours: HashSet<[u32; 3]> = shape
        .mesh
        .triangles()
        .iter()
        .map(|t| sorted(t.map(|v| shape.vertex_ids[v as usize])))
        .filter(|t| !ties.contains(t))
        .collect();
    let only_ours = ours.difference(&theirs).count();
    let only_theirs = theirs.difference(&ours).count();
    println!(
        "agreement: {} triangles here, {} in Open3D, {} only here, {} only in Open3D ({} tie faces left out)",
        ours.len(),
        theirs.len(),
        only_ours,
        only_theirs,
        ties.len()
    );
    if only_ours + only_theirs > 0 {
        bail!("the boundary triangles differ from Open3D's");
    }
    Ok(())
}

/// Error against run time over α: a Markdown table on stdout.
fn sweep(
    scan: &trisplat_geometry::TriMesh,
    delaunay: &Delaunay3d,
    spacing: f64,
) -> anyhow::Result<()> {
    let gt = sample_uniform(scan, SWEEP_SAMPLES, 2);
    let tau = 2.0 * spacing;
    println!();
    println!(
        "| alpha / spacing | alpha | alpha step ms | kept tetrahedra | triangles | signed volume | Chamfer-L1 | F-score @ {tau:.2e} |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for k in SWEEP_SPACINGS {
        let alpha = k * spacing;
        let (seconds, shape) = time_best(REPEATS, || alpha_shape_from_delaunay(delaunay, alpha));
        let shape = shape?;
        let samples = sample_uniform(&shape.mesh, SWEEP_SAMPLES, 3);
        let (chamfer, fscore) = if samples.is_empty() {
            (f64::NAN, 0.0)
        } else {
            let m = point_metrics(&samples, &gt, &[tau])?;
            (m.chamfer_l1, m.thresholds.first().map_or(0.0, |t| t.fscore))
        };
        println!(
            "| {k} | {alpha:.3e} | {:.1} | {} | {} | {:.3e} | {chamfer:.3e} | {fscore:.4} |",
            seconds * 1e3,
            shape.kept_tetrahedra,
            shape.mesh.triangle_count(),
            shape.mesh.signed_volume()
        );
    }
    println!();
    Ok(())
}

fn sorted(mut t: [u32; 3]) -> [u32; 3] {
    t.sort_unstable();
    t
}
