//! `--json` on every command (issue #16 item 2): stdout is exactly one JSON object whose
//! `command` is the command's name, with the keys docs/conventions.md §10 lists.

mod common;
use common::{fixture, fresh_dir, run_ok};
use serde_json::Value;

/// Runs `args` with `--json` and returns the one object it printed.
fn json(args: &[&str]) -> Value {
    let mut all = args.to_vec();
    all.push("--json");
    let out = run_ok(&all);
    let text = String::from_utf8(out.stdout).expect("utf-8");
    let mut lines = text.lines();
    let line = lines
        .next()
        .unwrap_or_else(|| panic!("{args:?}: nothing on stdout"));
    assert!(
        lines.next().is_none(),
        "{args:?}: more than one line: {text}"
    );
    let v: Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("{args:?}: {e}: {line}"));
    assert!(v.is_object(), "{args:?}: {v}");
    assert_eq!(v["command"], args[0], "{v}");
    v
}

fn has(v: &Value, keys: &[&str]) {
    for k in keys {
        assert!(v.get(*k).is_some(), "{k} missing: {v}");
    }
}

#[test]
fn every_command_prints_one_json_object() {
    let dir = fresh_dir("json");
    let p = |name: &str| dir.join(name).display().to_string();
    let spot = fixture("spot_triangulated.obj");
    let taubin = fixture("spot_taubin.ply");

    has(
        &json(&["eval", &spot, &spot, "--samples", "500"]),
        &["chamfer_l1", "thresholds"],
    );
    has(
        &json(&["sample", &spot, "-n", "2000", "-o", &p("pts.ply")]),
        &["output", "points"],
    );
    has(
        &json(&["smooth", &spot, "-o", &p("smooth.ply")]),
        &["output", "vertices", "triangles"],
    );
    has(
        &json(&[
            "alpha-shape",
            &p("pts.ply"),
            "--alpha",
            "0.2",
            "-o",
            &p("alpha.ply"),
        ]),
        &["output", "triangles", "pieces"],
    );
    has(
        &json(&[
            "cameras",
            &taubin,
            "-o",
            &p("cams.json"),
            "--views",
            "6",
            "--size",
            "32x32",
        ]),
        &["output", "views"],
    );
    let r = json(&[
        "render",
        "--mesh",
        &taubin,
        "--cameras",
        &p("cams.json"),
        "-o",
        &p("maps"),
        "--outputs",
        "depth",
    ]);
    has(&r, &["output", "views", "files"]);
    // Six views, a depth .npy and its .png preview each.
    assert_eq!(r["files"].as_array().map(Vec::len), Some(12), "{r}");
    has(
        &json(&[
            "tsdf",
            "--cameras",
            &p("cams.json"),
            "--depth",
            &p("maps"),
            "--voxel",
            "0.05",
            "-o",
            &p("fused.ply"),
        ]),
        &["output", "vertices", "triangles"],
    );
    let masks = json(&[
        "render",
        "--mesh",
        &taubin,
        "--cameras",
        &p("cams.json"),
        "-o",
        &p("masks"),
        "--outputs",
        "alpha",
    ]);
    has(&masks, &["files"]);
    has(
        &json(&[
            "init",
            "--cameras",
            &p("cams.json"),
            "--masks",
            &p("masks"),
            "-n",
            "500",
            "--resolution",
            "24",
            "-o",
            &p("init.ply"),
        ]),
        &[
            "output",
            "gaussians",
            "views",
            "voxel",
            "dims",
            "voxels_kept",
            "volume",
            "hull",
        ],
    );
    has(
        &json(&["bind", &spot, "-o", &p("bound.ply")]),
        &["output", "gaussians"],
    );
    has(
        &json(&[
            "densify",
            &p("bound.ply"),
            "-o",
            &p("dense.ply"),
            "--template",
            &spot,
        ]),
        &["before", "after"],
    );
    has(
        &json(&[
            "prune",
            &p("dense.ply"),
            "-o",
            &p("pruned.ply"),
            "--template",
            &spot,
            "--min-opacity",
            "0.5",
        ]),
        &["before", "after", "flagged"],
    );
    let r = json(&[
        "refine",
        &p("bound.ply"),
        "--template",
        &spot,
        "-o",
        &p("refined.ply"),
        "--chamfer-samples",
        "2000",
    ]);
    has(
        &r,
        &[
            "output",
            "template",
            "before",
            "gaussians",
            "triangles",
            "rounds",
            "seconds",
            "surfaces",
        ],
    );
    has(
        &r["rounds"][0],
        &[
            "round",
            "before",
            "after",
            "alpha",
            "samples",
            "refilled",
            "pruned",
            "covered_triangles",
            "chamfer_before",
            "chamfer_after",
            "ms",
            "total_ms",
        ],
    );
    has(
        &r["rounds"][0]["ms"],
        &[
            "bake", "alpha", "smooth", "sample", "inherit", "bind", "prune", "chamfer",
        ],
    );
    let f = json(&[
        "fit",
        &p("bound.ply"),
        "--template",
        &spot,
        "--cameras",
        &p("cams.json"),
        "--eval-cameras",
        &p("cams.json"),
        "-o",
        &p("fitted.ply"),
        "--iterations",
        "4",
        "--eval-every",
        "2",
    ]);
    has(
        &f,
        &[
            "output",
            "template",
            "before",
            "gaussians",
            "iterations",
            "frames",
            "views",
            "eval_views",
            "target",
            "ms_per_iteration",
            "stage_ms",
            "seconds",
            "checkpoints",
            "refines",
        ],
    );
    has(
        &f["checkpoints"][1],
        &[
            "iteration",
            "loss",
            "train_l1",
            "train_psnr",
            "eval_psnr",
            "eval_ssim",
            "gaussians",
            "seconds",
        ],
    );
    has(
        &json(&["convert", &spot, &p("spot.glb")]),
        &["input", "output", "bytes"],
    );
    has(
        &json(&["convert", &world_gaussians(), &p("g.spz")]),
        &["input", "output", "bytes"],
    );
    let d = json(&[
        "deform",
        "--template",
        &spot,
        "--gaussians",
        &p("bound.ply"),
        "--animation",
        &spot,
        "-o",
        &p("frames"),
    ]);
    has(&d, &["output", "frames", "gaussians", "format"]);
    assert_eq!(d["frames"], 1, "{d}");
    has(&json(&["completions", "bash"]), &["shell", "script"]);
    has(&json(&["man", "eval"]), &["page"]);
}

/// A world-space Gaussian file of the fixtures.
fn world_gaussians() -> String {
    fixture("render/random_deg3.ply")
}

#[test]
fn the_main_job_prints_its_summary_and_its_plan() {
    let dir = fresh_dir("json_extract");
    // An animated glTF drives itself.
    let template = fixture("anim/RiggedFigure.glb");
    let shard = |name: &str, range: &str| {
        let out = dir.join(name).display().to_string();
        let v = json(&[
            "extract",
            "--template",
            &template,
            "--animation",
            &template,
            "--method",
            "delaunay,alpha",
            "--gt",
            "template",
            "--samples",
            "1000",
            "--frames",
            range,
            "-q",
            "-o",
            &out,
        ]);
        has(
            &v,
            &[
                "output",
                "frames",
                "gaussians",
                "methods",
                "files",
                "failed_frames",
            ],
        );
        has(&v["methods"]["alpha"], &["ms", "chamfer_l1", "relation"]);
        out
    };
    let (a, b) = (shard("a", "0..2"), shard("b", "2..4"));
    let m = json(&[
        "merge",
        &a,
        &b,
        "-q",
        "-o",
        &dir.join("m").display().to_string(),
    ]);
    assert_eq!(m["frames"], 4, "{m}");
    let plan = json(&[
        "extract",
        "--template",
        &template,
        "--method",
        "tsdf",
        "-o",
        &dir.join("plan").display().to_string(),
        "--explain",
    ]);
    assert!(
        plan["plan"].as_array().is_some_and(|s| !s.is_empty()),
        "{plan}"
    );
}
