//! `trisplat extract` through the real binary on a tiny case (the bundled RiggedFigure, two
//! frames, small depth images): every promised output exists and reads back; bad inputs give
//! exit 1 or 2 with one line naming the culprit; --explain prints the plan and writes nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use trisplat_geometry::io::{read_mesh, write_mesh};

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_trisplat"))
        .args(args)
        .output()
        .expect("run trisplat")
}

fn fresh_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cli_extract_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test folder");
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn figure() -> PathBuf {
    trisplat_fixtures::path("anim/RiggedFigure.glb")
}

/// The fast settings of the tiny case.
const TINY: [&str; 8] = [
    "--fps",
    "2",
    "--views",
    "6",
    "--resolution",
    "48",
    "--samples",
    "2000",
];

fn stderr_line(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    err
}

#[test]
fn tiny_case_writes_every_promised_output() {
    let dir = fresh_dir("tiny");
    let out = dir.join("out");
    let t = figure();
    let mut args = vec![
        "extract",
        "--template",
        s(&t),
        "--method",
        "tsdf,delaunay,alpha",
        "--frames",
        "0..2",
        "--gt",
        "template",
        "-o",
        s(&out),
    ];
    args.extend(TINY);
    let res = run(&args);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let stdout = String::from_utf8_lossy(&res.stdout);
    for m in ["tsdf", "delaunay", "alpha"] {
        assert!(stdout.contains(m), "{stdout}");
        for f in 0..2 {
            let ply = out.join(m).join(format!("frame_{f:06}.ply"));
            let mesh = read_mesh(&ply).unwrap_or_else(|e| panic!("{}: {e}", ply.display()));
            assert!(mesh.triangle_count() > 0, "{}", ply.display());
        }
        let glb = out.join(format!("{m}.glb"));
        let bytes = std::fs::read(&glb).expect("glb written");
        assert_eq!(&bytes[..4], b"glTF", "{}", glb.display());
    }
    let png = std::fs::read(out.join("error_vs_time.png")).expect("png written");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(md.contains("| delaunay |"), "{md}");
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    assert!(!text.contains("NaN"));
    let r: serde_json::Value = serde_json::from_str(&text).expect("json");
    assert_eq!(r["frames"], serde_json::json!([0, 1]));
    assert_eq!(r["ground_truth"], "template");
    for m in ["tsdf", "delaunay", "alpha"] {
        let method = &r["methods"][m];
        let frames = method["frames"].as_array().expect("frames");
        assert_eq!(frames.len(), 2);
        for f in frames {
            for key in ["ms", "vertices", "faces", "watertight"] {
                assert!(!f[key].is_null(), "{m}: {key}");
            }
            let c = f["metrics"]["chamfer_l1"].as_f64().expect("chamfer");
            assert!(c.is_finite() && c >= 0.0);
            assert!(f["metrics"]["fscore"].as_f64().is_some());
        }
        let mean = method["mean"]["chamfer_l1"].as_f64().expect("mean");
        let direct = frames
            .iter()
            .map(|f| f["metrics"]["chamfer_l1"].as_f64().unwrap_or(f64::NAN))
            .sum::<f64>()
            / 2.0;
        assert!((mean - direct).abs() <= 1e-12 * direct.max(1.0), "{m}");
    }
    // Delaunay vertices are the template's plus one per Gaussian (4 per triangle).
    let v = r["methods"]["delaunay"]["frames"][0]["vertices"]
        .as_u64()
        .expect("v");
    let g = r["gaussian_count"].as_u64().expect("g");
    assert!(v > g);
}

#[test]
fn without_gt_no_metrics_and_rebuild_every_one() {
    let dir = fresh_dir("nogt");
    let out = dir.join("out");
    let t = figure();
    let mut args = vec![
        "extract",
        "--template",
        s(&t),
        "--method",
        "delaunay",
        "--frames",
        "0..=1",
        "--rebuild-every",
        "1",
        "-o",
        s(&out),
    ];
    args.extend(TINY);
    let res = run(&args);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("json"))
            .expect("parse");
    assert!(r["ground_truth"].is_null());
    assert!(r["methods"]["delaunay"]["frames"][0]["metrics"].is_null());
    assert!(r["methods"]["tsdf"].is_null(), "only the asked method");
    assert!(!out.join("tsdf").exists());
    assert!(out.join("error_vs_time.png").is_file());
}

#[test]
fn explain_prints_the_plan_and_writes_nothing() {
    let dir = fresh_dir("explain");
    let out = dir.join("out");
    let t = figure();
    let res = run(&[
        "extract",
        "--template",
        s(&t),
        "--method",
        "alpha",
        "-o",
        s(&out),
        "--explain",
    ]);
    assert!(res.status.success());
    let plan = String::from_utf8_lossy(&res.stdout);
    assert!(plan.contains("skip  render"), "{plan}");
    assert!(plan.contains("run   bind"), "{plan}");
    assert!(plan.contains("skip  metrics"), "{plan}");
    assert!(plan.contains("run   mesh:alpha"), "{plan}");
    assert!(!out.exists());
}

#[test]
fn bad_inputs_exit_with_one_line() {
    let dir = fresh_dir("bad");
    let out = dir.join("out");
    let t = figure();
    // Missing template: exit 1, names the file.
    let missing = dir.join("missing.glb");
    let res = run(&[
        "extract",
        "--template",
        s(&missing),
        "--method",
        "alpha",
        "-o",
        s(&out),
    ]);
    assert_eq!(res.status.code(), Some(1));
    assert!(stderr_line(&res).contains("missing.glb"));
    // Unknown method: usage error, exit 2.
    let res = run(&[
        "extract",
        "--template",
        s(&t),
        "--method",
        "poisson",
        "-o",
        s(&out),
    ]);
    assert_eq!(res.status.code(), Some(2));
    // Frames out of range: exit 1, names --frames.
    let res = run(&[
        "extract",
        "--template",
        s(&t),
        "--method",
        "alpha",
        "--frames",
        "0..100000",
        "-o",
        s(&out),
    ]);
    assert_eq!(res.status.code(), Some(1));
    assert!(stderr_line(&res).contains("--frames 0..100000"));
    // Gaussians bound to another (larger) template: refused, naming the file.
    let other = dir.join("cesium_bound.ply");
    let cesium = trisplat_fixtures::path("anim/CesiumMan.glb");
    let res = run(&["bind", s(&cesium), "-o", s(&other)]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let res = run(&[
        "extract",
        "--template",
        s(&t),
        "--gaussians",
        s(&other),
        "--method",
        "alpha",
        "-o",
        s(&out),
    ]);
    assert_eq!(res.status.code(), Some(1));
    assert!(stderr_line(&res).contains("cesium_bound.ply"));
    // A Gaussian file that is not bound at all: refused by name.
    let unbound = dir.join("points.ply");
    let mesh = read_mesh(&t).expect("figure");
    write_mesh(
        &unbound,
        &mesh,
        trisplat_geometry::io::WriteOptions::default(),
    )
    .expect("write");
    let res = run(&[
        "extract",
        "--template",
        s(&t),
        "--gaussians",
        s(&unbound),
        "--method",
        "alpha",
        "-o",
        s(&out),
    ]);
    assert_eq!(res.status.code(), Some(1));
    assert!(stderr_line(&res).contains("points.ply"));
    // A static ground truth that is the output folder's report: refused, nothing over inputs.
    let gt_out = dir.join("gt_out");
    std::fs::create_dir_all(gt_out.join("alpha")).expect("dir");
    let gt = gt_out.join("alpha").join("frame_000000.ply");
    write_mesh(&gt, &mesh, trisplat_geometry::io::WriteOptions::default()).expect("write");
    let res = run(&[
        "extract",
        "--template",
        s(&t),
        "--method",
        "alpha",
        "--frames",
        "0",
        "--gt",
        s(&gt),
        "-o",
        s(&gt_out),
    ]);
    assert_eq!(res.status.code(), Some(1));
    assert!(stderr_line(&res).contains("refusing to overwrite"));
    assert_eq!(
        read_mesh(&gt).expect("intact").triangle_count(),
        mesh.triangle_count()
    );
}
