//! `--faces` / `--simplify-error` (docs/conventions.md §6, §10): `convert` decimates one mesh
//! and says what it cost; bad values are usage errors (exit 2) that write nothing, on
//! `convert` and `extract` alike; a mesh with nothing to decimate is exit 1.

mod common;
use common::{fixture, fresh_dir, listing, one_error_line, run, run_ok, s};

use std::collections::HashMap;

use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{ObjVertices, ReadOptions, read_mesh, read_mesh_with};
use trisplat_geometry::topology::boundary_edges;

/// `mesh`'s triangles with vertices at one position merged.
fn welded(mesh: &TriMesh) -> Vec<[u32; 3]> {
    let mut first: HashMap<[u64; 3], u32> = HashMap::new();
    let ids: Vec<u32> = mesh
        .positions()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            *first
                .entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
                .or_insert(i as u32)
        })
        .collect();
    mesh.triangles()
        .iter()
        .map(|t| t.map(|v| ids[v as usize]))
        .collect()
}

#[test]
fn convert_decimates_a_closed_mesh_and_reports_the_cost() {
    let dir = fresh_dir("decimate_spot");
    let out = dir.join("spot_small.ply");
    let spot = fixture("spot_triangulated.obj");
    let read = ReadOptions {
        obj_vertices: ObjVertices::Auto,
    };
    let original = read_mesh_with(std::path::Path::new(&spot), read).expect("spot");
    let stdout = run_ok(&["convert", &spot, s(&out), "--faces", "1000", "--json"]).stdout;
    let json: serde_json::Value = serde_json::from_slice(&stdout).expect("json");
    let cost = &json["simplify"];
    assert_eq!(cost["faces_before"], original.triangle_count());
    let after = cost["faces_after"].as_u64().expect("faces_after");
    // meshoptimizer stops at or a little below the target on a closed mesh.
    assert!((900..=1000).contains(&after), "{json}");
    let small = read_mesh(&out).expect("written");
    assert_eq!(small.triangle_count() as u64, after);
    // Closed once its seams (vertices split at uv seams, one position) are welded, before and
    // after: the seams stayed paired and no hole opened.
    assert!(boundary_edges(&welded(&original)).is_empty());
    assert!(
        boundary_edges(&welded(&small)).is_empty(),
        "a seam or hole opened"
    );
    let (estimate, hausdorff, mean) = (
        cost["meshopt_error"].as_f64().expect("estimate"),
        cost["hausdorff"].as_f64().expect("hausdorff"),
        cost["mean_distance"].as_f64().expect("mean"),
    );
    assert!(estimate > 0.0 && mean > 0.0 && mean <= hausdorff, "{json}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_decimation_options_are_usage_errors_that_write_nothing() {
    let dir = fresh_dir("decimate_bad");
    let spot = fixture("spot_triangulated.obj");
    let out = dir.join("x.ply");
    for bad in [
        &["--faces", "0"][..],
        &["--simplify-error=-0.1"],
        &["--simplify-error", "NaN"],
        &["--simplify-error", "inf"],
        &["--faces", "10", "--simplify-error", "0.01"],
    ] {
        let mut args = vec!["convert", &spot, s(&out)];
        args.extend(bad);
        let o = run(&args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {stderr}");
        assert!(
            stderr.contains("--faces") || stderr.contains("--simplify-error"),
            "{bad:?} names the option: {stderr}"
        );
        let lam = fixture("lam_mini");
        let mut args = vec!["extract", "--avatar", &lam, "--method", "alpha", "-o"];
        let run_dir = dir.join("run");
        args.push(s(&run_dir));
        args.extend(bad);
        let o = run(&args);
        assert_eq!(o.status.code(), Some(2), "extract {bad:?}");
    }
    assert!(
        listing(&dir).is_empty(),
        "nothing written: {:?}",
        listing(&dir)
    );
    // Frames and Gaussians are not decimated by convert.
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).expect("dir");
    let o = run(&[
        "convert",
        s(&frames),
        s(&dir.join("seq.glb")),
        "--faces",
        "10",
    ]);
    assert_eq!(o.status.code(), Some(2));
    // A mesh with no triangle to decimate: exit 1, naming the file, nothing written.
    let flat = dir.join("flat.ply");
    std::fs::write(
        &flat,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n0 1 0\n3 0 0 1\n",
    )
    .expect("write");
    let line = one_error_line(&run(&["convert", s(&flat), s(&out), "--faces", "1"]));
    assert!(
        line.contains("flat.ply") && line.contains("no triangle"),
        "{line}"
    );
    assert!(!out.exists());
    let _ = std::fs::remove_dir_all(&dir);
}
