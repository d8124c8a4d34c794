//! `trisplat sample`, `smooth` and common contract checks through the real binary: success
//! paths produce readable files, usage errors exit 2, refused outputs leave inputs untouched.

mod common;
use common::{fresh_dir, one_error_line, run};

use std::path::Path;

use trisplat_geometry::io::{read_mesh, read_points};

fn spot() -> String {
    trisplat_fixtures::path("spot_triangulated.obj")
        .to_string_lossy()
        .into_owned()
}

#[test]
fn smooth_keeps_topology_and_moves_vertices() {
    let dir = fresh_dir("smooth");
    let out_path = dir.join("spot_smooth.ply");
    let out = run(&[
        "smooth",
        &spot(),
        "-o",
        out_path.to_str().expect("utf-8"),
        "--method",
        "taubin",
        "--iterations",
        "3",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let original = read_mesh(Path::new(&spot())).expect("read spot");
    let smoothed = read_mesh(&out_path).expect("read output");
    assert_eq!(smoothed.triangles(), original.triangles());
    let moved = original
        .positions()
        .iter()
        .zip(smoothed.positions())
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        moved > original.vertex_count() / 2,
        "only {moved} vertices moved"
    );
}

#[test]
fn sample_writes_n_points_reproducibly() {
    let dir = fresh_dir("sample");
    let a = dir.join("a.ply");
    let b = dir.join("b.ply");
    for path in [&a, &b] {
        let out = run(&[
            "sample",
            &spot(),
            "-n",
            "1000",
            "--seed",
            "7",
            "-o",
            path.to_str().expect("utf-8"),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let points = read_points(&a).expect("read samples");
    assert_eq!(points.len(), 1000);
    assert!(points.normals().is_some(), "samples carry face normals");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

#[test]
fn output_equal_to_input_is_refused_and_input_kept() {
    let dir = fresh_dir("overwrite");
    let input = dir.join("mesh.obj");
    std::fs::copy(spot(), &input).expect("copy fixture");
    let before = std::fs::read(&input).unwrap();
    let input = input.to_str().expect("utf-8");
    for args in [
        vec!["smooth", input, "-o", input],
        vec!["sample", input, "-n", "10", "-o", input],
        vec!["convert", input, input],
    ] {
        let stderr = one_error_line(&run(&args));
        assert!(stderr.contains("overwrite"), "{stderr}");
    }
    assert_eq!(std::fs::read(input).unwrap(), before);
}

#[test]
fn missing_input_names_the_file() {
    let dir = fresh_dir("missing");
    let missing = dir.join("nope.ply");
    let missing = missing.to_str().expect("utf-8");
    let target = dir.join("out.ply");
    for args in [
        vec!["smooth", missing, "-o", target.to_str().unwrap()],
        vec!["sample", missing, "-n", "5", "-o", target.to_str().unwrap()],
        vec!["eval", missing, missing],
    ] {
        let stderr = one_error_line(&run(&args));
        assert!(stderr.contains("nope.ply"), "{stderr}");
        assert!(!target.exists());
    }
}

#[test]
fn bad_usage_exits_2() {
    for args in [
        vec!["smooth"],
        vec!["sample", "x.ply", "-o", "y.ply", "-n", "many"],
        vec!["no-such-command"],
    ] {
        assert_eq!(run(&args).status.code(), Some(2), "{args:?}");
    }
}

#[test]
fn convert_evaluates_a_gltf_clip_at_a_time() {
    use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate};
    let dir = fresh_dir("convert_time");
    let input = trisplat_fixtures::path("anim/CesiumMan.glb");
    let out_path = dir.join("posed.ply");
    let out = run(&[
        "convert",
        input.to_str().expect("utf-8"),
        out_path.to_str().expect("utf-8"),
        "--time",
        "1.25",
        "--clip",
        "0",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let posed = read_mesh(&out_path).expect("read output");
    let template = GltfTemplate::open(&input, &Clip::Index(0)).expect("open clip");
    let want = template.evaluate_at(1.25).expect("evaluate");
    assert_eq!(posed.triangles(), template.rest().triangles());
    assert_eq!(posed.positions(), want.as_slice());
    let moved = want
        .iter()
        .zip(template.rest().positions())
        .filter(|(a, b)| a != b)
        .count();
    assert!(moved > 100, "the clip moves the mesh ({moved} vertices)");
    // A clip that does not exist is one clear error.
    let bad = run(&[
        "convert",
        input.to_str().expect("utf-8"),
        dir.join("x.ply").to_str().expect("utf-8"),
        "--clip",
        "no-such-clip",
    ]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(!dir.join("x.ply").exists());
}

/// A reader that closes stdout before the output is written (`trisplat ... | head`): the run
/// ends quietly with SIGPIPE's exit code, no panic message.
#[test]
fn closed_stdout_ends_quietly() {
    use std::process::{Command, Stdio};
    let mut child = Command::new(common::BIN)
        .args([
            "extract",
            "--template",
            &common::fixture("anim/RiggedFigure.glb"),
        ])
        .args([
            "--method",
            "tsdf,delaunay,alpha",
            "-o",
            "unused",
            "--explain",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("wait");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        out.status.success() || out.status.code() == Some(141),
        "{:?}: {stderr}",
        out.status
    );
}

/// `sample -n` beyond `--max-points` (a capacity-overflow panic for 2^64 - 1 before) is
/// refused before anything is allocated, naming the option; `-n 0` is a usage error instead of
/// an empty file.
#[test]
fn sample_counts_are_limited_before_allocation() {
    let dir = fresh_dir("sample_limits");
    let out = dir.join("points.ply");
    let spot = common::fixture("spot_triangulated.obj");
    let line = one_error_line(&run(&[
        "sample",
        &spot,
        "-n",
        "18446744073709551615",
        "-o",
        out.to_str().expect("utf-8"),
    ]));
    assert!(line.contains("--max-points"), "{line}");
    let line = one_error_line(&run(&[
        "sample",
        &spot,
        "-n",
        "1000",
        "--max-points",
        "999",
        "-o",
        out.to_str().expect("utf-8"),
    ]));
    assert!(line.contains("more than --max-points 999"), "{line}");
    let zero = run(&[
        "sample",
        &spot,
        "-n",
        "0",
        "-o",
        out.to_str().expect("utf-8"),
    ]);
    assert_eq!(zero.status.code(), Some(2));
    assert!(!out.exists());
}

/// `eval --samples` beyond `--max-samples` is refused before sampling (an allocation abort
/// before); the limit can be raised.
#[test]
fn eval_samples_are_limited_before_allocation() {
    let mesh = spot();
    let res = run(&["eval", &mesh, &mesh, "--samples", "100000000000"]);
    let line = one_error_line(&res);
    assert!(
        line.contains("--samples 100000000000: over the limit of 100000000 samples per mesh")
            && line.contains("--max-samples"),
        "{line}"
    );
    let res = run(&[
        "eval",
        &mesh,
        &mesh,
        "--samples",
        "2000",
        "--max-samples",
        "1000",
    ]);
    assert!(one_error_line(&res).contains("over the limit of 1000"));
    let res = run(&[
        "eval",
        &mesh,
        &mesh,
        "--samples",
        "2000",
        "--max-samples",
        "2000",
        "--json",
    ]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
}
