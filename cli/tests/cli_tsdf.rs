//! `trisplat tsdf` through the real binary, on the Spot depth maps of
//! `fixtures/data/reference/tsdf/` (written by `tests/reference/ref_tsdf.py`).

mod common;
use common::{fresh_dir, one_error_line, run, s};

use std::path::PathBuf;

use trisplat_geometry::io::{read_mesh, write_npy};
use trisplat_geometry::topology::boundary_edges;

fn fixture_dir() -> PathBuf {
    trisplat_fixtures::path("reference/tsdf")
}

/// A copy of the fixture folder (cameras.json and depth maps) that a test may break.
fn copy_fixture(name: &str) -> PathBuf {
    let dir = fresh_dir(name);
    for entry in std::fs::read_dir(fixture_dir()).expect("fixture folder") {
        let path = entry.expect("entry").path();
        std::fs::copy(&path, dir.join(path.file_name().expect("name"))).expect("copy");
    }
    dir
}

#[test]
fn fuses_spot_into_a_closed_mesh() {
    let dir = fresh_dir("ok");
    let out_path = dir.join("spot_tsdf.ply");
    let cams = fixture_dir().join("cameras.json");
    let out = run(&[
        "tsdf",
        "--cameras",
        s(&cams),
        "--depth",
        s(&fixture_dir()),
        "--voxel",
        "0.02",
        "--trunc",
        "0.1",
        "-o",
        s(&out_path),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mesh = read_mesh(&out_path).expect("read output");
    assert!(mesh.triangle_count() > 10_000);
    assert!(boundary_edges(mesh.triangles()).is_empty());
    assert!(mesh.signed_volume() > 0.0);
    // No temporary file left behind.
    let names: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(names.len(), 1);
}

#[test]
fn bad_inputs_give_one_line_naming_the_file() {
    let dir = copy_fixture("bad");
    let cams = dir.join("cameras.json");
    let out_path = dir.join("out.ply");
    let args = |extra: &[&str]| {
        let mut v = vec![
            "tsdf".to_owned(),
            "--cameras".to_owned(),
            s(&cams).to_owned(),
            "--depth".to_owned(),
            s(&dir).to_owned(),
            "-o".to_owned(),
            s(&out_path).to_owned(),
        ];
        v.extend(extra.iter().map(|x| (*x).to_owned()));
        v
    };
    let run_args = |v: Vec<String>| {
        let refs: Vec<&str> = v.iter().map(String::as_str).collect();
        run(&refs)
    };

    // Bad voxel.
    let err = one_error_line(&run_args(args(&["--voxel", "0"])));
    assert!(err.contains("voxel"), "{err}");
    // Wrong size.
    write_npy(&dir.join("view_004_depth.npy"), &[2, 2], &[1.0; 4]).unwrap();
    let err = one_error_line(&run_args(args(&["--voxel", "0.02"])));
    assert!(err.contains("view_004_depth.npy"), "{err}");
    // Missing file.
    std::fs::remove_file(dir.join("view_004_depth.npy")).unwrap();
    let err = one_error_line(&run_args(args(&["--voxel", "0.02"])));
    assert!(err.contains("view_004_depth.npy"), "{err}");
    assert!(!out_path.exists());
    // The output may not be the cameras file.
    let before = std::fs::read(&cams).unwrap();
    let out = run(&[
        "tsdf",
        "--cameras",
        s(&cams),
        "--depth",
        s(&dir),
        "-o",
        s(&cams),
    ]);
    one_error_line(&out);
    assert_eq!(std::fs::read(&cams).unwrap(), before);
    // Usage error: no depth folder.
    let out = run(&["tsdf", "--cameras", s(&cams), "-o", s(&out_path)]);
    assert_eq!(out.status.code(), Some(2));
}
