//! trisplat's smoothing against Open3D 0.20.0 (`filter_smooth_laplacian`, `filter_smooth_taubin`)
//! and trimesh 5.2.0 (`smoothing.filter_laplacian`, uniform weights, volume constraint) on Spot.
//!
//! References: `tests/reference/ref_smoothing.py` → `fixtures/data/reference/smoothing/`. Both
//! tools and this test read the same positions-only `spot.ply`.
//!
//! Error measure: `max_v ‖ours_v − ref_v‖ / diag`, the largest per-vertex Euclidean difference
//! relative to the reference's bounding-box diagonal, computed on the f64 positions; the mesh
//! that `smooth` returns holds exactly these positions (meshes store f64).

use std::path::Path;

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::smoothing::{SmoothMethod, SmoothOptions, smooth, smooth_positions};

/// The f64 iterates differ from Open3D's and trimesh's only by summation order (the issue
/// asked for 1e-5). A regression in the formula shows up orders of magnitude above.
const MAX_RELATIVE_ERROR_F64: f64 = 1e-12;

fn dir() -> std::path::PathBuf {
    trisplat_fixtures::path("reference/smoothing")
}

/// Minimal reader for the `<f8` C-order 2-D `.npy` files the reference script writes.
fn read_npy_f64(path: &Path) -> Vec<DVec3> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..6], b"\x93NUMPY", "{}: not .npy", path.display());
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        _ => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
    };
    let header = std::str::from_utf8(&bytes[start..start + header_len]).expect("ascii header");
    assert!(header.contains("'descr': '<f8'"), "{header}");
    assert!(header.contains("'fortran_order': False"), "{header}");
    let data = &bytes[start + header_len..];
    assert_eq!(data.len() % 24, 0);
    data.chunks_exact(24)
        .map(|c| {
            let f = |k: usize| f64::from_le_bytes(c[k * 8..k * 8 + 8].try_into().unwrap());
            DVec3::new(f(0), f(1), f(2))
        })
        .collect()
}

fn max_relative_error(ours: impl Iterator<Item = DVec3>, reference: &[DVec3]) -> f64 {
    let (lo, hi) = reference.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let diag = (hi - lo).length();
    let mut count = 0;
    let worst = ours
        .zip(reference)
        .map(|(a, b)| {
            count += 1;
            (a - *b).length()
        })
        .fold(0.0f64, f64::max);
    assert_eq!(count, reference.len(), "vertex count");
    worst / diag
}

fn spot() -> TriMesh {
    let mesh = read_mesh(&dir().join("spot.ply")).expect("spot.ply");
    assert_eq!(mesh.vertex_count(), 2930);
    assert_eq!(mesh.triangle_count(), 5856);
    mesh
}

fn options_of(case: &serde_json::Value) -> SmoothOptions {
    let method = match case["method"].as_str().unwrap() {
        "laplacian" => SmoothMethod::Laplacian,
        "taubin" => SmoothMethod::Taubin,
        "uniform" => SmoothMethod::Uniform,
        other => panic!("unknown method {other}"),
    };
    SmoothOptions {
        method,
        iterations: case["iterations"].as_u64().unwrap() as usize,
        lambda: case["lambda"].as_f64().unwrap(),
        mu: case["mu"].as_f64().unwrap_or(SmoothOptions::default().mu),
    }
}

#[test]
fn smoothing_matches_open3d_and_trimesh() {
    let mesh = spot();
    let manifest = trisplat_tests::reference_json(&dir().join("smoothing.json"));
    let cases = manifest["cases"].as_array().unwrap();
    assert!(cases.len() >= 5);
    let mut methods_seen = Vec::new();
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let reference = read_npy_f64(&dir().join(case["file"].as_str().unwrap()));
        let options = options_of(case);
        methods_seen.push(options.method);

        let f64_positions = smooth_positions(&mesh, &options).unwrap();
        let err64 = max_relative_error(f64_positions.iter().copied(), &reference);
        let smoothed = smooth(&mesh, &options).unwrap();
        assert_eq!(smoothed.positions(), f64_positions.as_slice(), "{name}");
        // Also make sure the reference moved the mesh: a no-op would match trivially.
        let moved = max_relative_error(mesh.positions().iter().copied(), &reference);
        println!("{name}: max |Δ|/diag {err64:.3e} (input vs ref {moved:.3e})");
        assert!(moved > 1e-3, "{name}: the reference barely moved");
        assert!(
            err64 < MAX_RELATIVE_ERROR_F64,
            "{name}: f64 error {err64:e}"
        );
    }
    for m in [
        SmoothMethod::Laplacian,
        SmoothMethod::Taubin,
        SmoothMethod::Uniform,
    ] {
        assert!(methods_seen.contains(&m), "no reference for {m:?}");
    }
}

#[test]
fn cotangent_smoothing_reduces_roughness_and_stays_close() {
    // No tool computes our clamped explicit cotangent flow, so check its properties: it moves
    // vertices, keeps the surface close, and (as a discrete mean-curvature flow) lowers the
    // surface area.
    let mesh = spot();
    let input: Vec<DVec3> = mesh.positions().to_vec();
    let out = smooth_positions(
        &mesh,
        &SmoothOptions {
            method: SmoothMethod::Cotangent,
            iterations: 10,
            ..SmoothOptions::default()
        },
    )
    .unwrap();
    let moved = max_relative_error(out.iter().copied(), &input);
    assert!(moved > 1e-4 && moved < 0.05, "{moved}");
    let smoothed = smooth(
        &mesh,
        &SmoothOptions {
            method: SmoothMethod::Cotangent,
            iterations: 10,
            ..SmoothOptions::default()
        },
    )
    .unwrap();
    let (a0, a1) = (mesh.area(), smoothed.area());
    println!("cotangent x10: moved {moved:.3e} of diag, area {a0:.5} -> {a1:.5}");
    assert!(a1 < 0.995 * a0);
}
