//! `trisplat opacity-mesh` through the real binary: a small blob of Gaussians gives a closed,
//! outward mesh; bad Gaussians give one error line naming the file and no output.

mod common;
use common::{fresh_dir, one_error_line, run, s};

use std::path::Path;

use glam::Vec3;
use trisplat_geometry::io::read_mesh;
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};
use trisplat_splat::{GaussianParts, GaussianSet};

/// 27 isotropic Gaussians on a 3x3x3 grid, overlapping, `log_scale` and `logit` for all.
fn write_blob(path: &Path, log_scale: f32, logit: f32) {
    let means: Vec<Vec3> = (0..27)
        .map(|i| Vec3::new((i % 3) as f32, (i / 3 % 3) as f32, (i / 9) as f32) * 0.05)
        .collect();
    let n = means.len();
    let mut parts = GaussianParts {
        means,
        log_scales: vec![Vec3::splat(log_scale); n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacity_logits: vec![logit; n],
        sh: vec![0.5; 3 * n],
        ..GaussianParts::default()
    };
    parts.sh_degree = 0;
    let set = GaussianSet::new_unchecked(parts);
    write_gaussians(path, &set, &PlyWriteOptions::default()).expect("write");
}

#[test]
fn a_blob_gives_one_closed_piece() {
    let dir = fresh_dir("opacity_ok");
    let g = dir.join("blob.ply");
    write_blob(&g, 0.04f32.ln(), 4.0);
    let out_path = dir.join("mesh.ply");
    let out = run(&[
        "--json",
        "opacity-mesh",
        s(&g),
        "--views",
        "12",
        "--resolution",
        "64",
        "-o",
        s(&out_path),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(json["command"], "opacity-mesh");
    assert_eq!(json["gaussians"], 27);
    assert_eq!(json["views"], 12);
    let mesh = read_mesh(&out_path).expect("read output");
    assert_eq!(json["triangles"], mesh.triangle_count());
    assert!(mesh.triangle_count() > 100);
    assert!(trisplat_geometry::topology::boundary_edges(mesh.triangles()).is_empty());
    assert!(mesh.signed_volume() > 0.0);
    assert!(mesh.colors().is_some());
}

#[test]
fn bad_gaussians_give_one_line_naming_the_file() {
    let dir = fresh_dir("opacity_bad");
    for (name, log_scale, logit) in [
        ("zero_scale.ply", f32::NEG_INFINITY, 4.0),
        ("nan_scale.ply", f32::NAN, 4.0),
        ("transparent.ply", 0.04f32.ln(), -9.0),
    ] {
        let g = dir.join(name);
        write_blob(&g, log_scale, logit);
        let out_path = dir.join("mesh.ply");
        let out = run(&["opacity-mesh", s(&g), "--views", "4", "-o", s(&out_path)]);
        assert_eq!(out.status.code(), Some(1), "{name}");
        let line = one_error_line(&out);
        assert!(line.contains(name), "{line}");
        assert!(!out_path.exists(), "{name}: no output");
    }
}

/// `--field median`: the blob's rendered median-depth maps carve one closed, outward piece with
/// colours; a negative margin is refused by the parser.
#[test]
fn median_field_gives_one_closed_piece() {
    let dir = fresh_dir("opacity_median");
    let g = dir.join("blob.ply");
    write_blob(&g, 0.04f32.ln(), 4.0);
    let out_path = dir.join("mesh.ply");
    let args = |margin: &'static str| {
        vec![
            "--json",
            "opacity-mesh",
            s(&g),
            "--field",
            "median",
            "--margin",
            margin,
            "--views",
            "12",
            "--resolution",
            "64",
        ]
    };
    let mut ok = args("1");
    ok.extend(["-o", s(&out_path)]);
    let out = run(&ok);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(json["pieces"], 1);
    let mesh = read_mesh(&out_path).expect("read output");
    assert!(mesh.triangle_count() > 100);
    assert!(trisplat_geometry::topology::boundary_edges(mesh.triangles()).is_empty());
    assert!(mesh.signed_volume() > 0.0);
    assert!(mesh.colors().is_some());
    std::fs::remove_file(&out_path).expect("remove");
    let mut bad = args("-1");
    bad.extend(["-o", s(&out_path)]);
    let out = run(&bad);
    assert_eq!(
        out.status.code(),
        Some(2),
        "a negative margin is a usage error"
    );
    assert!(!out_path.exists());
}
