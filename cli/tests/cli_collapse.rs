//! `trisplat deform` over a triangle that collapses to zero area: the Gaussians keep their
//! last valid frame (docs/numerics.md), and the run says which frames had collapsed triangles,
//! on stderr and in `--json`.

mod common;
use common::{fresh_dir, run_ok, s};
use serde_json::Value;

/// A two-triangle template whose vertex 0 lies on the edge 1-2 in frames 2 and 3.
fn scene(dir: &std::path::Path) {
    let obj = |v0: &str| format!("v {v0}\nv 1 0 0\nv 0 1 0\nv 1 1 0.25\nf 1 2 3\nf 2 4 3\n");
    std::fs::write(dir.join("template.obj"), obj("0 0 0")).expect("template");
    std::fs::create_dir(dir.join("frames")).expect("frames");
    for (i, v0) in [
        "0 0 0",
        "0.1 0.2 0.1",
        "0.5 0.5 0",
        "0.5 0.5 0",
        "0.3 0.2 0.2",
    ]
    .iter()
    .enumerate()
    {
        std::fs::write(dir.join(format!("frames/f{i:03}.obj")), obj(v0)).expect("frame");
    }
}

#[test]
fn deform_reports_the_frames_with_collapsed_triangles() {
    let dir = fresh_dir("collapse");
    scene(&dir);
    let (t, a) = (dir.join("template.obj"), dir.join("frames"));
    let bound = dir.join("bound.ply");
    run_ok(&["bind", s(&t), "-o", s(&bound), "-q"]);
    let out = run_ok(&[
        "deform",
        "--template",
        s(&t),
        "--gaussians",
        s(&bound),
        "--animation",
        s(&a),
        "-o",
        s(&dir.join("plain")),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("2 frame(s) have template triangles of zero area")
            && stderr.contains("2 (1), 3 (1)"),
        "{stderr}"
    );
    let out = run_ok(&[
        "deform",
        "--template",
        s(&t),
        "--gaussians",
        s(&bound),
        "--animation",
        s(&a),
        "-o",
        s(&dir.join("json")),
        "--json",
    ]);
    let v: Value = serde_json::from_slice(&out.stdout).expect("json");
    let frames: Vec<u64> = v["collapsed_frames"]
        .as_array()
        .expect("array")
        .iter()
        .map(|c| c["frame"].as_u64().expect("frame"))
        .collect();
    assert_eq!(frames, [2, 3], "{v}");
}
