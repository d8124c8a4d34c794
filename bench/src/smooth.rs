//! `smooth`: Laplacian and Taubin smoothing (10 iterations) and surface sampling (1M uniform,
//! 100k Poisson disk) on a 1.5M-face mesh, against Open3D 0.20 on the same PLY file.
//!
//! The mesh is Spot (5,856 faces) split four times by midpoint subdivision: 1,499,136 faces.
//! Loading is excluded on both sides. Smoothed vertices are compared with Open3D's (max
//! absolute difference, and relative to the bounding-box diagonal).

use std::path::Path;

use anyhow::{Context, bail};
use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};
use trisplat_geometry::sampling::{sample_poisson_disk, sample_uniform};
use trisplat_geometry::smoothing::{SmoothMethod, SmoothOptions, smooth};
use trisplat_geometry::subdivide;

use crate::harness::{python_script, report, run_python, time_best};

/// Midpoint subdivisions of Spot: 5,856 x 4^4 = 1,499,136 faces.
const SUBDIVISIONS: usize = 4;
/// Smoothing iterations (the target: Laplacian x10 >= 3x faster than Open3D).
const ITERATIONS: usize = 10;
/// Repeats of our side (best time reported).
const REPEATS: usize = 3;
/// Uniform sample count.
const UNIFORM_POINTS: usize = 1_000_000;
/// Poisson-disk sample count.
const POISSON_POINTS: usize = 100_000;

/// Runs the benchmark; `python` is the interpreter for the Open3D side (None: ours only).
///
/// # Errors
/// When the fixture cannot be read, the temporary files cannot be written, or the Python side
/// fails.
pub fn run(python: Option<&str>) -> anyhow::Result<()> {
    let spot = read_mesh(&trisplat_fixtures::path("reference/smoothing/spot.ply"))?;
    let big = subdivide::midpoint(&spot, SUBDIVISIONS)?;
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("spot_x4.ply");
    write_mesh(&path, &big, WriteOptions::default())?;
    let mesh = read_mesh(&path)?;
    println!(
        "mesh: Spot subdivided x{SUBDIVISIONS}: {} vertices, {} faces ({} rayon threads)",
        mesh.vertex_count(),
        mesh.triangle_count(),
        rayon::current_num_threads()
    );
    let diag = mesh.bounds().map_or(1.0, |b| b.diagonal());

    let script = python_script("smooth_open3d.py");
    let path_str = path.to_str().context("temporary path is not UTF-8")?;

    for (name, method, extra) in [
        ("laplacian", SmoothMethod::Laplacian, vec![]),
        ("taubin", SmoothMethod::Taubin, vec!["-0.53"]),
    ] {
        let options = SmoothOptions {
            method,
            iterations: ITERATIONS,
            lambda: 0.5,
            mu: -0.53,
        };
        let (ours, smoothed) = time_best(REPEATS, || smooth(&mesh, &options));
        let smoothed = smoothed?;
        let label = format!("{name} x{ITERATIONS} (1.5M faces)");
        match python {
            Some(py) => {
                let out = dir.path().join(format!("{name}.npy"));
                let out_str = out.to_str().context("temporary path is not UTF-8")?;
                let iterations = ITERATIONS.to_string();
                let mut args = vec![path_str, name, iterations.as_str(), "0.5"];
                args.extend(extra.iter().copied());
                args.push(out_str);
                let result = run_python(py, &script, &args)?;
                let theirs = seconds(&result)?;
                report(&label, ours, Some(("Open3D", theirs)));
                let reference = read_npy_f64(&out)?;
                let max_abs = max_abs_diff(&smoothed, &reference)?;
                println!(
                    "{:<40} max |ours - Open3D| = {max_abs:.3e} ({:.3e} of the bbox diagonal)",
                    "",
                    max_abs / diag
                );
            }
            None => report(&label, ours, None),
        }
    }

    let (ours, cloud) = time_best(REPEATS, || sample_uniform(&mesh, UNIFORM_POINTS, 1));
    if cloud.len() != UNIFORM_POINTS {
        bail!("uniform sampling returned {} points", cloud.len());
    }
    let label = format!("sample uniform {UNIFORM_POINTS}");
    let theirs = match python {
        Some(py) => Some(seconds(&run_python(
            py,
            &script,
            &[path_str, "uniform", &UNIFORM_POINTS.to_string()],
        )?)?),
        None => None,
    };
    report(&label, ours, theirs.map(|t| ("Open3D", t)));

    let (ours, poisson) = time_best(1, || sample_poisson_disk(&mesh, POISSON_POINTS, 1));
    let poisson = poisson?;
    if poisson.len() != POISSON_POINTS {
        bail!("Poisson sampling returned {} points", poisson.len());
    }
    let label = format!("sample poisson {POISSON_POINTS}");
    let theirs = match python {
        Some(py) => Some(seconds(&run_python(
            py,
            &script,
            &[path_str, "poisson", &POISSON_POINTS.to_string()],
        )?)?),
        None => None,
    };
    report(&label, ours, theirs.map(|t| ("Open3D", t)));
    Ok(())
}

fn seconds(result: &serde_json::Value) -> anyhow::Result<f64> {
    result["seconds"]
        .as_f64()
        .context("the Python side reported no `seconds`")
}

fn max_abs_diff(ours: &TriMesh, reference: &[DVec3]) -> anyhow::Result<f64> {
    if ours.vertex_count() != reference.len() {
        bail!(
            "vertex counts differ: ours {}, Open3D {}",
            ours.vertex_count(),
            reference.len()
        );
    }
    Ok(ours
        .positions()
        .iter()
        .zip(reference)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0, f64::max))
}

/// Reads a C-order `<f8` `.npy` array of shape [V, 3].
fn read_npy_f64(path: &Path) -> anyhow::Result<Vec<DVec3>> {
    let bytes = std::fs::read(path).with_context(|| path.display().to_string())?;
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        bail!("{}: not a .npy file", path.display());
    }
    let (header_len, start) = if bytes[6] == 1 {
        (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10)
    } else {
        let b = bytes.get(8..12).context("truncated .npy header")?;
        (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize, 12)
    };
    let header = bytes
        .get(start..start + header_len)
        .context("truncated .npy header")?;
    let header = String::from_utf8_lossy(header);
    if !header.contains("'<f8'") || header.contains("'fortran_order': True") {
        bail!("{}: expected C-order float64, got {header}", path.display());
    }
    let data = &bytes[start + header_len..];
    Ok(data
        .chunks_exact(24)
        .map(|c| {
            let f = |k: usize| {
                let mut b = [0u8; 8];
                b.copy_from_slice(&c[k * 8..k * 8 + 8]);
                f64::from_le_bytes(b)
            };
            DVec3::new(f(0), f(1), f(2))
        })
        .collect())
}
