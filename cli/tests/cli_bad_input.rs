//! `trisplat convert` on bad input: exit code 1, one stderr line naming the file and the
//! problem, and nothing left in the output folder (no output, no temporary file).

mod common;
use common::{BIN, fresh_dir, listing};

use std::path::Path;
use std::process::Command;

/// Runs `trisplat convert input output` (plus `extra`) in a folder holding only `input`;
/// checks the failure contract (the line names the input) and returns the stderr line.
fn convert_fails(name: &str, input_bytes: &[u8], output: &str, extra: &[&str]) -> String {
    convert_fails_naming(name, input_bytes, output, extra, name)
}

/// Like [`convert_fails`], with the file the error line must name.
fn convert_fails_naming(
    name: &str,
    input_bytes: &[u8],
    output: &str,
    extra: &[&str],
    named: &str,
) -> String {
    let dir = fresh_dir(output);
    let input = dir.join(name);
    std::fs::write(&input, input_bytes).expect("write input");
    let before = listing(&dir);
    let out = Command::new(BIN)
        .arg("convert")
        .arg(&input)
        .arg(dir.join(output))
        .args(extra)
        .output()
        .expect("run trisplat");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "one line on stderr: {stderr:?}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    assert!(lines[0].contains(named), "names the file: {stderr}");
    assert_eq!(listing(&dir), before, "no output or temporary file left");
    let _ = std::fs::remove_dir_all(&dir);
    lines[0].to_owned()
}

const HEADER: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
    property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
    end_header\n";

fn binary_spot_ply() -> Vec<u8> {
    let dir = fresh_dir("spot_source");
    let out = dir.join("spot.ply");
    let spot = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/data/spot_triangulated.obj");
    let status = Command::new(BIN)
        .arg("convert")
        .arg(spot)
        .arg(&out)
        .status()
        .expect("run trisplat");
    assert!(status.success());
    let bytes = std::fs::read(&out).expect("read");
    let _ = std::fs::remove_dir_all(&dir);
    bytes
}

#[test]
fn truncated_ply() {
    let bytes = binary_spot_ply();
    let line = convert_fails("cut.ply", &bytes[..bytes.len() / 2], "out.ply", &[]);
    assert!(line.contains("truncated"), "{line}");
}

#[test]
fn counts_larger_than_the_file() {
    let text = HEADER.replace("element vertex 3", "element vertex 3000000000");
    let line = convert_fails(
        "huge.ply",
        format!("{text}0 0 0\n").as_bytes(),
        "out.obj",
        &[],
    );
    assert!(
        line.contains("3000000000") && line.contains("at most"),
        "{line}"
    );
}

#[test]
fn nan_coordinates() {
    let body = format!("{HEADER}0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n");
    let line = convert_fails("nan.ply", body.as_bytes(), "out.glb", &[]);
    assert!(
        line.contains("vertex 1") && line.contains("non-finite"),
        "{line}"
    );
}

#[test]
fn out_of_range_indices() {
    let body = format!("{HEADER}0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
    let line = convert_fails("range.ply", body.as_bytes(), "out.ply", &[]);
    assert!(
        line.contains("face 0") && line.contains("out of range"),
        "{line}"
    );
}

#[test]
fn non_utf8_obj() {
    let line = convert_fails(
        "latin1.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\ng caf\xe9\nf 1 2 3\n",
        "out.ply",
        &[],
    );
    assert!(line.contains("line 4") && line.contains("UTF-8"), "{line}");
}

#[test]
fn missing_external_bin() {
    let text = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
        "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
        "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
          "min":[0,0,0],"max":[1,1,0]}],
        "bufferViews":[{"buffer":0,"byteLength":36}],
        "buffers":[{"byteLength":36,"uri":"geometry.bin"}]}"#;
    let line = convert_fails("scene.gltf", text.as_bytes(), "out.ply", &[]);
    assert!(
        line.contains("geometry.bin"),
        "names the missing file: {line}"
    );
}

#[test]
fn refuses_to_overwrite_the_input() {
    let body = format!("{HEADER}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    let dir = fresh_dir("same");
    let input = dir.join("mesh.ply");
    std::fs::write(&input, &body).expect("write");
    // The same file through a different spelling of its path.
    let same = dir.join(".").join("mesh.ply");
    let out = Command::new(BIN)
        .arg("convert")
        .arg(&input)
        .arg(&same)
        .output()
        .expect("run");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("refusing to overwrite the input"),
        "{stderr}"
    );
    assert_eq!(std::fs::read_to_string(&input).expect("read"), body);
    assert_eq!(listing(&dir), ["mesh.ply"]);
}

#[test]
fn animation_options_are_refused_clearly() {
    let body = format!("{HEADER}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    let line = convert_fails("mesh.ply", body.as_bytes(), "out.glb", &["--time", "0.5"]);
    assert!(line.contains("animation"), "{line}");
}

#[test]
fn unknown_output_format() {
    let body = format!("{HEADER}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    let line = convert_fails_naming("mesh.ply", body.as_bytes(), "out.stl", &[], "out.stl");
    assert!(line.contains("unknown file format"), "{line}");
}

#[test]
fn converts_every_format_pair() {
    let dir = fresh_dir("pairs");
    let spot = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/data/spot_triangulated.obj");
    let mut previous = spot;
    for (k, ext) in ["ply", "glb", "gltf", "obj", "ply"].iter().enumerate() {
        let next = dir.join(format!("step{k}.{ext}"));
        let mut cmd = Command::new(BIN);
        cmd.arg("convert").arg(&previous).arg(&next);
        if k == 4 {
            cmd.arg("--ascii");
        }
        let out = cmd.output().expect("run");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            out.stderr.is_empty(),
            "quiet on success when not a terminal"
        );
        previous = next;
    }
    let text = std::fs::read(&previous).expect("read");
    let head = String::from_utf8_lossy(&text[..200]);
    assert!(head.contains("format ascii 1.0"), "{head}");
    // Spot's uv seams are split on the first step (trimesh's 3225 vertices) and then kept.
    assert!(head.contains("element vertex 3225"), "{head}");
    assert!(head.contains("element face 5856"), "{head}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Hostile suite finds (tests/hostile/hostile.py): errors that did not name the file at fault.
#[test]
fn meshing_and_fusion_errors_name_the_file_at_fault() {
    let dir = fresh_dir("hostile_names");
    // A vertex finite but beyond the spatial indexes' range (1e18): Delaunay refuses it.
    let template = dir.join("far_vertex.obj");
    std::fs::write(
        &template,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1e30\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .expect("write");
    let out = Command::new(BIN)
        .args(["extract", "--template"])
        .arg(&template)
        .args(["--method", "delaunay", "-q", "-o"])
        .arg(dir.join("x"))
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("far_vertex.obj") && err.contains("delaunay"),
        "{err}"
    );
    // Cameras 1e12 away: the depth points are out of the volume's range; the cameras file is
    // named.
    let cameras = dir.join("far_cameras.json");
    std::fs::write(
        &cameras,
        r#"[{"id": 0, "img_name": "wide", "width": 32, "height": 24,
             "position": [1e12, 0, 0], "rotation": [[1,0,0],[0,1,0],[0,0,1]],
             "fx": 30, "fy": 30, "cx": 16, "cy": 12}]"#,
    )
    .expect("write");
    let gaussians = trisplat_fixtures::path("render/random_deg3.ply");
    let out = Command::new(BIN)
        .args(["tsdf", "--gaussians"])
        .arg(&gaussians)
        .arg("--cameras")
        .arg(&cameras)
        .arg("-o")
        .arg(dir.join("t.ply"))
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("far_cameras.json"), "{err}");
    assert!(!dir.join("t.ply").exists());
}
