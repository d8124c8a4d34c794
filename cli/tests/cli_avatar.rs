//! LAM avatar folders through the real binary (`fixtures/data/lam_mini`, a cut-down LAM
//! export, MIT): `extract --avatar`, a folder given as `--template`, the separate files with
//! `--layout lam`, `bind --avatar`, and the refusals (`--strict`, a file in the wrong layout,
//! a folder that is not an avatar), each exit 1 with one line naming the culprit.

mod common;

use common::{fixture, fresh_dir, one_error_line, report, run, run_ok, s};

#[test]
fn avatar_folder_extracts_and_reports_its_layout() {
    let dir = fresh_dir("avatar");
    let avatar = fixture("lam_mini");
    let track = fixture("lam_mini/expression.json");
    let common = ["--method", "delaunay", "--frames", "0..3", "-q"];
    let by_flag = dir.join("by_flag");
    let mut args = vec!["extract", "--avatar", &avatar, "--animation", &track];
    args.extend(common);
    args.extend(["-o", s(&by_flag)]);
    let out = run_ok(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("tongueOut"), "{stderr}");
    let r = report(&by_flag);
    assert_eq!(r["gaussian_count"], 952);
    assert!(
        r["gaussians"]
            .as_str()
            .expect("str")
            .contains("LAM per-vertex"),
        "{r}"
    );
    assert_eq!(r["unused_channels"][0], "tongueOut");

    // The folder as --template, and the two files with --layout lam: the same meshes.
    let by_template = dir.join("by_template");
    let mut args = vec!["extract", "--template", &avatar, "--animation", &track];
    args.extend(common);
    args.extend(["-o", s(&by_template)]);
    run_ok(&args);
    let skin = fixture("lam_mini/skin.glb");
    let offsets = fixture("lam_mini/offset.ply");
    let by_files = dir.join("by_files");
    let mut args = vec![
        "extract",
        "--template",
        &skin,
        "--gaussians",
        &offsets,
        "--layout",
        "lam",
        "--animation",
        &track,
    ];
    args.extend(common);
    args.extend(["-o", s(&by_files)]);
    run_ok(&args);
    for other in [&by_template, &by_files] {
        for f in 0..3 {
            let name = format!("delaunay/frame_{f:06}.ply");
            assert_eq!(
                std::fs::read(by_flag.join(&name)).expect("mesh"),
                std::fs::read(other.join(&name)).expect("mesh"),
                "{name}"
            );
        }
    }

    // --explain says the Gaussians are bound here, per vertex.
    let out = run_ok(&[
        "extract",
        "--avatar",
        &avatar,
        "--method",
        "alpha",
        "-o",
        s(&dir.join("explain")),
        "--explain",
    ]);
    let plan = String::from_utf8_lossy(&out.stdout);
    assert!(
        plan.lines()
            .any(|l| l.starts_with("run   bind") && l.contains("LAM's per-vertex layout")),
        "{plan}"
    );
}

#[test]
fn bind_avatar_writes_a_bound_file_and_checks_the_rest_pose() {
    let dir = fresh_dir("bind_avatar");
    let bound = dir.join("bound.ply");
    let out = run_ok(&[
        "bind",
        "--avatar",
        &fixture("lam_mini"),
        "-o",
        s(&bound),
        "--check-views",
        "2",
        "-q",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("silhouette IoU"), "{stdout}");
    // The bound file drives extract like any GaussianAvatars file.
    run_ok(&[
        "extract",
        "--template",
        &fixture("lam_mini/skin.glb"),
        "--gaussians",
        s(&bound),
        "--animation",
        &fixture("lam_mini/expression.json"),
        "--method",
        "alpha",
        "--frames",
        "0..2",
        "-q",
        "-o",
        s(&dir.join("out")),
    ]);
}

#[test]
fn avatar_refusals_name_the_culprit() {
    let dir = fresh_dir("avatar_refusals");
    let avatar = fixture("lam_mini");
    // --strict refuses the track's channel that drives nothing.
    let out = run(&[
        "extract",
        "--avatar",
        &avatar,
        "--animation",
        &fixture("lam_mini/expression.json"),
        "--method",
        "alpha",
        "--strict",
        "-q",
        "-o",
        s(&dir.join("strict")),
    ]);
    let line = one_error_line(&out);
    assert!(
        line.contains("tongueOut") && line.contains("--strict"),
        "{line}"
    );
    // LAM's offsets read as bound Gaussians: refused, pointing at --layout lam.
    let out = run(&[
        "extract",
        "--template",
        &fixture("lam_mini/skin.glb"),
        "--gaussians",
        &fixture("lam_mini/offset.ply"),
        "--method",
        "alpha",
        "-q",
        "-o",
        s(&dir.join("bound")),
    ]);
    let line = one_error_line(&out);
    assert!(
        line.contains("offset.ply") && line.contains("--layout lam"),
        "{line}"
    );
    // An avatar folder as --template brings its own Gaussians: --gaussians beside it is refused.
    let line = one_error_line(&run(&[
        "extract",
        "--template",
        &avatar,
        "--gaussians",
        &fixture("lam_mini/offset.ply"),
        "--method",
        "alpha",
        "-q",
        "-o",
        s(&dir.join("both")),
    ]));
    assert!(line.contains("brings its own"), "{line}");
    // A folder that is not an avatar, as --avatar and as bind's MESH.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).expect("mkdir");
    let out = run(&[
        "extract",
        "--avatar",
        s(&empty),
        "--method",
        "alpha",
        "-q",
        "-o",
        s(&dir.join("x")),
    ]);
    let line = one_error_line(&out);
    assert!(
        line.contains("empty") && line.contains("no skin.glb"),
        "{line}"
    );
    let out = run(&["bind", s(&empty), "-o", s(&dir.join("b.ply")), "-q"]);
    let line = one_error_line(&out);
    assert!(line.contains("no skin.glb"), "{line}");
    // A LAM offset file beside another template: the row count names both.
    let out = run(&[
        "bind",
        &fixture("anim/RiggedFigure.glb"),
        "--gaussians",
        &fixture("lam_mini/offset.ply"),
        "--layout",
        "lam",
        "-o",
        s(&dir.join("c.ply")),
        "-q",
    ]);
    let line = one_error_line(&out);
    assert!(
        line.contains("952 Gaussians") && line.contains("RiggedFigure"),
        "{line}"
    );
}

#[test]
fn clip_from_another_file_plays_by_joint_name_and_lists_the_unmatched() {
    let dir = fresh_dir("clip_from");
    let synthetic = trisplat_fixtures::path("anim/SyntheticFeatures.gltf");
    // The clip's file with one joint renamed: its channels have no namesake.
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&synthetic).expect("read")).expect("json");
    for node in json["nodes"].as_array_mut().expect("nodes") {
        if node["name"] == "joint2" {
            node["name"] = "jointX".into();
        }
    }
    for buffer in json["buffers"].as_array().expect("buffers") {
        if let Some(uri) = buffer["uri"].as_str().filter(|u| !u.starts_with("data:")) {
            std::fs::copy(synthetic.with_file_name(uri), dir.join(uri)).expect("buffer");
        }
    }
    let source = dir.join("motion.gltf");
    std::fs::write(&source, json.to_string()).expect("write");
    let out = dir.join("out");
    let args = [
        "extract",
        "--template",
        s(&synthetic),
        "--clip-from",
        s(&source),
        "--method",
        "alpha",
        "-q",
        "-o",
        s(&out),
    ];
    let ran = run_ok(&args);
    assert!(String::from_utf8_lossy(&ran.stderr).contains("joint:jointX"));
    let r = report(&out);
    assert_eq!(r["unused_channels"], serde_json::json!(["joint:jointX"]));
    assert!(
        r["animation"]
            .as_str()
            .expect("str")
            .contains("by joint name"),
        "{r}"
    );
    // --strict refuses the clip that leaves a joint behind.
    let mut strict = args.to_vec();
    let strict_out = dir.join("strict");
    strict[9] = s(&strict_out);
    strict.push("--strict");
    let line = one_error_line(&run(&strict));
    assert!(line.contains("joint:jointX"), "{line}");
    // --clip-from with a template that has no joints to play it on.
    let line = one_error_line(&run(&[
        "extract",
        "--template",
        &fixture("spot_triangulated.obj"),
        "--clip-from",
        s(&source),
        "--method",
        "alpha",
        "-q",
        "-o",
        s(&dir.join("obj")),
    ]));
    assert!(line.contains("--clip-from needs a glTF template"), "{line}");
}

#[test]
fn deform_reads_an_avatar_folder_and_a_clip_from_another_file() {
    let dir = fresh_dir("deform_avatar");
    let track = fixture("lam_mini/expression.json");
    let out = dir.join("frames");
    run_ok(&[
        "deform",
        "--avatar",
        &fixture("lam_mini"),
        "--animation",
        &track,
        "--frames",
        "0..2",
        "-q",
        "-o",
        s(&out),
    ]);
    for f in 0..2 {
        let set = trisplat_splat::ply::read_gaussians(&out.join(format!("frame_{f:06}.ply")))
            .expect("world-space frame");
        assert_eq!(set.len(), 952, "frame {f}: one Gaussian per LAM vertex");
    }
    // The folder given as --template reads the same; --gaussians beside it is refused.
    let same = dir.join("same");
    run_ok(&[
        "deform",
        "--template",
        &fixture("lam_mini"),
        "--animation",
        &track,
        "--frames",
        "0..2",
        "-q",
        "-o",
        s(&same),
    ]);
    for f in 0..2 {
        let name = format!("frame_{f:06}.ply");
        assert!(
            std::fs::read(out.join(&name)).expect("a")
                == std::fs::read(same.join(&name)).expect("b"),
            "{name}"
        );
    }
    let line = one_error_line(&run(&[
        "deform",
        "--template",
        &fixture("lam_mini"),
        "--gaussians",
        &fixture("lam_mini/offset.ply"),
        "--animation",
        &track,
        "-q",
        "-o",
        s(&dir.join("refused")),
    ]));
    assert!(line.contains("brings its own"), "{line}");
    // --clip-from on a template without joints is refused as in extract.
    let line = one_error_line(&run(&[
        "deform",
        "--template",
        &fixture("spot_triangulated.obj"),
        "--gaussians",
        &fixture("lam_mini/offset.ply"),
        "--animation",
        &track,
        "--clip-from",
        &trisplat_fixtures::path("anim/SyntheticFeatures.gltf")
            .display()
            .to_string(),
        "-q",
        "-o",
        s(&dir.join("no_joints")),
    ]));
    assert!(line.contains("--clip-from"), "{line}");
}

#[test]
fn gt_gaussians_scores_against_the_surface_of_the_centres() {
    let dir = fresh_dir("avatar_gt_gaussians");
    let avatar = fixture("lam_mini");
    let track = fixture("lam_mini/expression.json");
    let out = dir.join("run");
    run_ok(&[
        "extract",
        "--avatar",
        &avatar,
        "--animation",
        &track,
        "--method",
        "tsdf,delaunay",
        "--frames",
        "0..2",
        "--gt",
        "gaussians",
        "--views",
        "8",
        "--resolution",
        "64",
        "-q",
        "-o",
        s(&out),
    ]);
    let r = report(&out);
    assert_eq!(r["ground_truth"], "gaussians", "{r}");
    // The delaunay meshes hold the Gaussians' centres: scored against themselves.
    assert_eq!(r["methods"]["delaunay"]["relation"], "self-consistency");
    assert_eq!(r["methods"]["tsdf"]["relation"], "accuracy");
    // The ground truth's vertices are the deformed centres `deform` writes.
    let deformed = dir.join("deformed");
    run_ok(&[
        "deform",
        "--avatar",
        &avatar,
        "--animation",
        &track,
        "--frames",
        "0..1",
        "-q",
        "-o",
        s(&deformed),
    ]);
    let centres = trisplat_geometry::io::read_points(&deformed.join("frame_000000.ply"))
        .expect("deformed centres");
    let (lo, hi) = centres.positions().iter().fold(
        (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let diagonal = (hi - lo).as_dvec3().length();
    let metrics = &r["methods"]["tsdf"]["frames"][0]["metrics"];
    let gt_diagonal = metrics["gt_diagonal"].as_f64().expect("gt_diagonal");
    assert!(
        (gt_diagonal - diagonal).abs() <= 1e-6 * diagonal,
        "{gt_diagonal} vs {diagonal}"
    );
    assert!(metrics["chamfer_l1"].as_f64().expect("chamfer") > 0.0);

    // Gaussians bound here (several per triangle) have no per-vertex surface: refused.
    let refused = run(&[
        "extract",
        "--template",
        &fixture("lam_mini/skin.glb"),
        "--animation",
        &track,
        "--method",
        "alpha",
        "--gt",
        "gaussians",
        "-q",
        "-o",
        s(&dir.join("refused")),
    ]);
    let line = one_error_line(&refused);
    assert!(
        line.contains("--gt gaussians") && line.contains("per triangle"),
        "{line}"
    );
}

#[test]
fn tsdf_colors_reach_the_frame_files_and_the_gltf() {
    let dir = fresh_dir("avatar_tsdf_colors");
    let out = dir.join("run");
    run_ok(&[
        "extract",
        "--avatar",
        &fixture("lam_mini"),
        "--animation",
        &fixture("lam_mini/expression.json"),
        "--method",
        "tsdf",
        "--tsdf-colors",
        "--frames",
        "0..2",
        "-q",
        "-o",
        s(&out),
    ]);
    let mesh = trisplat_geometry::io::read_mesh(&out.join("tsdf/frame_000000.ply")).expect("frame");
    let colors = mesh.colors().expect("vertex colours");
    assert_eq!(colors.len(), mesh.vertex_count());
    // The head's colours, not the black background: bright on average, and varied.
    let mean = colors.iter().map(|c| c[0] + c[1] + c[2]).sum::<f32>() / (3.0 * colors.len() as f32);
    let spread = colors
        .iter()
        .map(|c| (c[0] - colors[0][0]).abs())
        .fold(0.0f32, f32::max);
    assert!(mean > 0.1 && spread > 0.05, "mean {mean}, spread {spread}");
    let glb = std::fs::read(out.join("tsdf.glb")).expect("glb");
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("4 bytes")) as usize;
    let json = String::from_utf8_lossy(&glb[20..20 + json_len]);
    assert!(json.contains("COLOR_0"), "no COLOR_0 in the glTF");
    let r = report(&out);
    assert_eq!(r["methods"]["tsdf"]["parameters"]["colors"], 1.0);
}
