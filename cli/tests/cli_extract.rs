//! `trisplat extract` through the real binary on tiny cases (the bundled RiggedFigure and
//! CesiumMan, two frames, small depth images): every promised output exists and reads back;
//! the jacobian and lbs modes run end to end with plausible errors; bad inputs give exit 1 or
//! 2 with one line naming the culprit; --explain prints the plan and writes nothing.

mod common;

use std::path::{Path, PathBuf};

use common::{fixture, fresh_dir, one_error_line, report, run, run_ok, s};
use trisplat_geometry::io::{read_mesh, write_mesh};

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

/// `extract --template TEMPLATE --method M --frames F -o OUT`, then `extra` and the tiny settings.
fn tiny_run<'a>(
    template: &'a Path,
    (method, frames): (&'a str, &'a str),
    out: &'a Path,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![
        "extract",
        "--template",
        s(template),
        "--method",
        method,
        "--frames",
        frames,
        "-o",
        s(out),
    ];
    args.extend(extra);
    args.extend(TINY);
    args
}

#[test]
fn tiny_case_writes_every_promised_output() {
    let dir = fresh_dir("tiny");
    let out = dir.join("out");
    let t = figure();
    let args = tiny_run(
        &t,
        ("tsdf,delaunay,alpha", "0..2"),
        &out,
        &["--gt", "template"],
    );
    let res = run_ok(&args);
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
    assert!(
        stdout.contains("report.html (open it in a browser)"),
        "{stdout}"
    );
    let svg = std::fs::read_to_string(out.join("error_vs_time.svg")).expect("svg written");
    assert!(svg.starts_with("<svg") && svg.contains(">\ndelaunay *\n</text>"));
    let html = std::fs::read_to_string(out.join("report.html")).expect("report.html");
    for m in ["tsdf", "delaunay", "alpha"] {
        let thumbnail = format!("thumbnails/{m}_frame_000000.png");
        assert!(
            html.contains(&format!("src=\"{thumbnail}\"")),
            "{thumbnail}"
        );
        assert!(out.join(&thumbnail).is_file(), "{thumbnail}");
    }
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(md.contains("| delaunay |"), "{md}");
    let r = report(&out);
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

/// With `--gt template` (default thresholds), delaunay's meshes hold the deformed template's
/// vertices, so its scores are self-consistency; tsdf's and alpha's are accuracy. Each
/// frame's tau is 0.005 of its ground truth's diagonal; the structure is there.
#[test]
fn delaunay_against_its_own_template_is_self_consistency_tsdf_is_not() {
    let dir = fresh_dir("relation");
    let out = dir.join("out");
    let t = figure();
    let extra = ["--gt", "template", "--targets", "report"];
    run_ok(&tiny_run(&t, ("tsdf,delaunay,alpha", "0..2"), &out, &extra));
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    let r = report(&out);
    assert_eq!(r["tau_fraction"], 0.005);
    assert!(r["tau"].is_null());
    for (m, relation) in [
        ("tsdf", "accuracy"),
        ("delaunay", "self-consistency"),
        ("alpha", "accuracy"),
    ] {
        let method = &r["methods"][m];
        assert_eq!(method["relation"], relation, "{m}");
        for f in method["frames"].as_array().expect("frames") {
            let x = &f["metrics"];
            assert_eq!(x["relation"], relation, "{m}");
            let shared = x["shared_vertex_fraction"].as_f64().expect("shared");
            assert_eq!(
                shared >= 0.5,
                relation == "self-consistency",
                "{m}: {shared}"
            );
            let diagonal = x["gt_diagonal"].as_f64().expect("diagonal");
            assert_eq!(x["tau"].as_f64(), Some(0.005 * diagonal), "{m}");
            assert_eq!(x["tau_fraction"], 0.005);
            for key in ["normal_angle_deg", "recall", "area_ratio"] {
                assert!(x[key].as_f64().is_some_and(f64::is_finite), "{m}: {key}");
            }
            let st = &x["structure"];
            assert!(st["components"].as_u64().is_some_and(|c| c >= 1), "{m}");
            assert!(st["boundary_edges"].as_u64().is_some(), "{m}");
            assert!(st["area"].as_f64().is_some_and(|a| a > 0.0), "{m}");
        }
        assert!(method["mean"]["recall"].as_f64().is_some(), "{m}");
        assert!(method["mean"]["normal_angle_deg"].as_f64().is_some(), "{m}");
    }
    assert_eq!(
        r["methods"]["delaunay"]["mean"]["self_consistency_frames"],
        2
    );
    assert!(md.contains("| delaunay | **self-consistency** |"), "{md}");
    assert!(md.contains("| tsdf | accuracy |"), "{md}");
    assert!(
        md.contains("**delaunay: self-consistency, not accuracy.**"),
        "{md}"
    );
    assert!(!md.contains("**tsdf: self-consistency"), "{md}");
    assert!(
        md.contains("0.005 x each frame's ground-truth bounding-box diagonal"),
        "{md}"
    );
}

#[test]
fn without_gt_no_metrics_and_rebuild_every_one() {
    let dir = fresh_dir("nogt");
    let out = dir.join("out");
    let t = figure();
    let extra = ["--rebuild-every", "1"];
    run_ok(&tiny_run(&t, ("delaunay", "0..=1"), &out, &extra));
    let r = report(&out);
    assert!(r["ground_truth"].is_null());
    assert!(r["methods"]["delaunay"]["frames"][0]["metrics"].is_null());
    assert!(r["methods"]["tsdf"].is_null(), "only the asked method");
    assert!(!out.join("tsdf").exists());
    assert!(out.join("error_vs_time.png").is_file());
    assert!(out.join("error_vs_time.svg").is_file());
    assert!(out.join("report.html").is_file());
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
    assert!(one_error_line(&res).contains("missing.glb"));
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
    // Error colours without a ground truth to measure, or beside the TSDF's own colours:
    // usage errors, exit 2, nothing written.
    for extra in [
        &["--error-colors"][..],
        &["--error-colors", "--gt", "template", "--tsdf-colors"],
    ] {
        let mut args = vec![
            "extract",
            "--template",
            s(&t),
            "--method",
            "delaunay",
            "-o",
            s(&out),
        ];
        args.extend(extra);
        let res = run(&args);
        assert_eq!(res.status.code(), Some(2), "{extra:?}");
        let stderr = String::from_utf8_lossy(&res.stderr);
        assert!(stderr.contains("--error-colors"), "{extra:?}: {stderr}");
        assert!(!out.join("report.json").exists());
    }
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
    assert!(one_error_line(&res).contains("--frames 0..100000"));
    // Gaussians bound to another (larger) template: refused, naming the file.
    let other = dir.join("cesium_bound.ply");
    let cesium = trisplat_fixtures::path("anim/CesiumMan.glb");
    run_ok(&["bind", s(&cesium), "-o", s(&other)]);
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
    assert!(one_error_line(&res).contains("cesium_bound.ply"));
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
    assert!(one_error_line(&res).contains("points.ply"));
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
    assert!(one_error_line(&res).contains("refusing to overwrite"));
    assert_eq!(
        read_mesh(&gt).expect("intact").triangle_count(),
        mesh.triangle_count()
    );
}

/// Runs CesiumMan's first two frames (3 per second) in `mode` with every method, one Gaussian
/// per triangle and small settings, and checks the report: finite metrics against the
/// deformed template, a delaunay mesh on the surface and watertight (the template's glTF
/// seams are welded), alpha and tsdf near it, finite output meshes.
fn cesium_in_mode(mode: &str, delaunay_max_rel: f64) -> serde_json::Value {
    let dir = fresh_dir(&format!("cesium_{mode}"));
    let out = dir.join("out");
    let t = fixture("anim/CesiumMan.glb");
    run_ok(&[
        "extract",
        "--template",
        &t,
        "--method",
        "tsdf,delaunay,alpha",
        "--mode",
        mode,
        "--frames",
        "0..2",
        "--fps",
        "3",
        "--per-triangle",
        "1",
        "--views",
        "6",
        "--resolution",
        "48",
        "--voxel",
        "0.02",
        "--samples",
        "2000",
        "--gt",
        "template",
        "-o",
        s(&out),
    ]);
    let r = report(&out);
    assert_eq!(r["mode"], mode);
    assert_eq!(r["frames"], serde_json::json!([0, 1]));
    assert_eq!(r["template_vertices"], 3273);
    assert_eq!(r["welded_vertices"], 2338);
    assert_eq!(r["gaussian_count"], 4672);
    let radius = r["resolved"]["template_radius"].as_f64().expect("radius");
    assert!((0.5..1.0).contains(&radius), "{radius}");
    // Chamfer L1 bounds relative to the template radius: delaunay interpolates the
    // Gaussians, which lie on the surface (jacobian/binding) or within skinning's blend of
    // it (lbs); alpha and tsdf (48-pixel views, 0.02 voxels) are coarser.
    for (method, max_rel) in [
        ("delaunay", delaunay_max_rel),
        ("alpha", 0.03),
        ("tsdf", 0.1),
    ] {
        let m = &r["methods"][method];
        for f in m["frames"].as_array().expect("frames") {
            let c = f["metrics"]["chamfer_l1"].as_f64().expect("chamfer");
            assert!(
                c.is_finite() && c >= 0.0 && c < max_rel * radius,
                "{method}: {c}"
            );
            let nc = f["metrics"]["normal_consistency"].as_f64().expect("nc");
            assert!(nc > 0.5 && nc <= 1.0 + 1e-9, "{method}: {nc}");
            assert!(f["ms"].as_f64().expect("ms").is_finite());
            let frame = f["frame"].as_u64().expect("frame");
            let ply = out.join(method).join(format!("frame_{frame:06}.ply"));
            let mesh = read_mesh(&ply).unwrap_or_else(|e| panic!("{}: {e}", ply.display()));
            assert!(mesh.triangle_count() > 0, "{}", ply.display());
            assert!(
                mesh.positions().iter().all(|p| p.is_finite()),
                "{}",
                ply.display()
            );
        }
    }
    let delaunay = &r["methods"]["delaunay"];
    assert_eq!(delaunay["mean"]["watertight_frames"], 2, "{mode}");
    // Welded template vertices plus one per Gaussian.
    assert_eq!(delaunay["frames"][0]["vertices"], 2338 + 4672);
    r
}

#[test]
fn jacobian_mode_on_cesium_man() {
    cesium_in_mode("jacobian", 1e-4);
}

#[test]
fn lbs_mode_on_cesium_man() {
    cesium_in_mode("lbs", 1e-3);
    // lbs needs a skinned glTF animation: a still OBJ template is refused by name.
    let dir = fresh_dir("lbs_still");
    let spot = fixture("spot_triangulated.obj");
    let res = run(&[
        "extract",
        "--template",
        &spot,
        "--method",
        "delaunay",
        "--mode",
        "lbs",
        "-o",
        s(&dir.join("out")),
    ]);
    let line = one_error_line(&res);
    assert!(
        line.contains("spot_triangulated.obj") && line.contains("skinned glTF"),
        "{line}"
    );
}

#[test]
fn hop_threshold_is_recorded_with_the_delaunay_statistics() {
    let dir = fresh_dir("hop");
    let out = dir.join("out");
    let t = figure();
    // The incremental Delaunay's statistics are per meshed frame.
    let extra = ["--hop-threshold", "0.1", "--topology", "per-frame"];
    run_ok(&tiny_run(&t, ("delaunay", "0..3"), &out, &extra));
    let r = report(&out);
    let d = &r["methods"]["delaunay"];
    assert_eq!(d["parameters"]["hop_threshold"], 0.1);
    assert_eq!(d["parameters"]["rebuild_every"], 0.0);
    let stats = &d["delaunay"];
    assert_eq!(stats["gaussians"], r["gaussian_count"]);
    let frames = stats["frames"].as_array().expect("per-frame statistics");
    assert_eq!(frames.len(), 3);
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(f["frame"], i);
        // The first update triangulates every chart; the others only what changed.
        assert_eq!(f["rebuilt"], i == 0, "{f}");
        let redone = f["charts_redone"].as_u64().expect("charts");
        let charts = stats["charts"].as_u64().expect("charts");
        assert!(redone <= charts);
        if i == 0 {
            assert_eq!(redone, charts);
        }
        assert!(f["hopped"].as_u64().is_some());
    }
    assert_eq!(stats["rebuilt_frames"], 1);
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(md.contains("hopped | charts redone | rebuilt |"), "{md}");
    assert!(md.contains("hop_threshold 0.1"), "{md}");
    // Not a finite number >= 0: exit 1 naming the option.
    for bad in ["inf", "-1", "nan"] {
        let flag = format!("--hop-threshold={bad}");
        let res = run(&[
            "extract",
            "--template",
            s(&t),
            "--method",
            "delaunay",
            &flag,
            "-o",
            s(&dir.join("bad")),
        ]);
        let line = one_error_line(&res);
        assert!(line.contains("--hop-threshold"), "{line}");
    }
}

/// `--tau` is absolute (and replaces the default fraction); a bad `--tau-fraction` is exit 1
/// naming it; both together are a usage error (exit 2).
#[test]
fn absolute_tau_replaces_the_relative_default() {
    let dir = fresh_dir("tau");
    let t = figure();
    let out = dir.join("abs");
    let base = |out: &Path| {
        let extra = ["--gt", "template", "--targets", "report"];
        let args = tiny_run(&t, ("delaunay", "0"), out, &extra);
        args.into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    let mut args = base(&out);
    args.extend(["--tau".to_owned(), "0.02".to_owned()]);
    run_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let r = report(&out);
    assert_eq!(r["tau"], 0.02);
    assert!(r["tau_fraction"].is_null());
    let m = &r["methods"]["delaunay"]["frames"][0]["metrics"];
    assert_eq!(m["tau"], 0.02);
    assert!(m["tau_fraction"].is_null());
    let md = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(md.contains("at tau 0.02 (absolute)"), "{md}");
    for bad in ["0", "-1", "nan"] {
        let mut args = base(&dir.join("bad"));
        args.push(format!("--tau-fraction={bad}"));
        let res = run(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let line = one_error_line(&res);
        assert!(line.contains("--tau-fraction"), "{line}");
    }
    let mut args = base(&dir.join("both"));
    args.extend(["--tau", "0.02", "--tau-fraction", "0.01"].map(str::to_owned));
    let res = run(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(res.status.code(), Some(2));
}

/// A weights track whose channels match no morph target (ARKit's `tongueOut` on LAM's head):
/// listed once on stderr and in the report, refused with `--strict` (exit 1, one line,
/// nothing written).
#[test]
fn weights_channels_that_drive_nothing_are_listed_or_refused() {
    let dir = fresh_dir("unused_channels");
    let weights = dir.join("weights.json");
    // SyntheticFeatures: mesh 0 has targets "widen", "dents"; mesh 1 "a", "b".
    std::fs::write(
        &weights,
        r#"{"names": ["dents", "tongueOut", "b"], "frames": [
            {"weights": [0.0, 0.3, 0.5]}, {"weights": [1.0, 0.3, 0.5]}]}"#,
    )
    .expect("write weights");
    let template = fixture("anim/SyntheticFeatures.gltf");
    let out = dir.join("out");
    let args = [
        "extract",
        "--template",
        &template,
        "--animation",
        s(&weights),
        "--method",
        "delaunay",
        "-q",
        "-o",
        s(&out),
    ];
    let ran = run_ok(&args);
    let stderr = String::from_utf8_lossy(&ran.stderr);
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("tongueOut")).collect();
    assert_eq!(warnings.len(), 1, "{stderr}");
    assert!(warnings[0].starts_with("warning: ") && warnings[0].contains("--strict"));
    let r = report(&out);
    assert_eq!(r["unused_channels"], serde_json::json!(["tongueOut"]));
    let md = std::fs::read_to_string(out.join("report.md")).expect("md");
    assert!(
        md.contains("drive no morph target (ignored): tongueOut"),
        "{md}"
    );

    let strict_out = dir.join("strict");
    let mut strict = args[..args.len() - 1].to_vec();
    strict.extend([s(&strict_out), "--strict"]);
    let line = one_error_line(&run(&strict));
    assert!(
        line.contains("tongueOut") && line.contains("--strict"),
        "{line}"
    );
    assert!(!strict_out.exists(), "nothing written");
}

#[test]
fn resource_limits_are_checked_before_anything_runs() {
    let dir = fresh_dir("limits");
    let (avatar, track) = (fixture("lam_mini"), fixture("lam_mini/expression.json"));
    let base = |out: &std::path::Path| {
        vec![
            "extract".to_owned(),
            "--avatar".to_owned(),
            avatar.clone(),
            "--animation".to_owned(),
            track.clone(),
            "--frames".to_owned(),
            "0..1".to_owned(),
            "--method".to_owned(),
            "tsdf".to_owned(),
            "-q".to_owned(),
            "-o".to_owned(),
            s(out).to_owned(),
        ]
    };
    for (extra, needle) in [
        (
            &["--views", "100000000"][..],
            "--views 100000000: over the limit of 4096 views per frame (raise it with \
             --max-views)",
        ),
        (
            &["--voxel", "1e-9"],
            "over the limit of 65536 voxels across the template's bounding sphere (a coarser \
             --voxel gives fewer) (raise it with --max-voxels)",
        ),
        (
            &["--samples", "1000000000", "--gt", "template"],
            "over the limit of 100000000 samples per mesh (raise it with --max-samples)",
        ),
        (
            &["--views", "30", "--max-views", "20"],
            "--views 30: over the limit of 20 views per frame",
        ),
    ] {
        let out = dir.join(format!(
            "{}_{}",
            extra[0].trim_start_matches('-'),
            extra.len()
        ));
        let mut args = base(&out);
        args.extend(extra.iter().map(|a| (*a).to_owned()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let line = one_error_line(&run(&args));
        assert!(line.contains(needle), "{line}");
        assert!(!out.exists(), "{extra:?}: nothing written");
    }
    // Raised, the same request runs.
    let out = dir.join("raised");
    let mut args = base(&out);
    args.extend(["--views", "30", "--max-views", "40", "--resolution", "16"].map(str::to_owned));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    run_ok(&args);
    assert!(out.join("report.json").exists());
}
