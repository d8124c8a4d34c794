//! `trisplat convert FRAMES OUT.glb`: a folder or pattern of same-topology OBJ/PLY frames
//! becomes one animated glTF that plays them at `--fps`; usage errors exit 2, a bad frame
//! exits 1 naming its file, and nothing is written on failure.

mod common;
use common::{fresh_dir, listing, one_error_line, run, run_ok, s};

use std::path::{Path, PathBuf};

use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{Clip, GltfTemplate};
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};

/// Largest allowed difference between an evaluated and a frame coordinate (f32 storage).
const POSITION_TOLERANCE: f64 = 1e-6;

/// Frame `k`: Spot scaled by `1 + 0.02 k` (same topology for every `k`).
fn frame(k: usize) -> TriMesh {
    let spot = trisplat_fixtures::spot().expect("spot");
    let scale = 1.0 + 0.02 * k as f64;
    let positions = spot.positions().iter().map(|p| *p * scale).collect();
    TriMesh::new(positions, spot.triangles().to_vec())
}

/// Writes frames `0..n` into `dir` as `name(k)`; returns the paths.
fn write_frames(dir: &Path, n: usize, name: impl Fn(usize) -> String) -> Vec<PathBuf> {
    std::fs::create_dir_all(dir).expect("frame folder");
    (0..n)
        .map(|k| {
            let path = dir.join(name(k));
            write_mesh(&path, &frame(k), WriteOptions::default()).expect("write frame");
            path
        })
        .collect()
}

/// The animated output shows frame file `files[k]` at `k / fps` seconds and between frames.
fn check_plays(output: &Path, files: &[PathBuf], fps: f64) {
    let template = GltfTemplate::open(output, &Clip::Index(0)).expect("output opens");
    for (k, file) in files.iter().enumerate() {
        let want = read_mesh(file).expect("frame");
        for t in [k as f64 / fps, (k as f64 + 0.5) / fps] {
            let got = template.evaluate_at(t).expect("evaluates");
            assert_eq!(got.len(), want.vertex_count());
            let d = got
                .iter()
                .zip(want.positions())
                .map(|(a, b)| (*a - *b).abs().max_element())
                .fold(0.0f64, f64::max);
            assert!(d <= POSITION_TOLERANCE, "frame {k} at {t} s: off by {d}");
        }
    }
}

#[test]
fn folder_of_frames_to_glb_in_natural_order() {
    let dir = fresh_dir("seq_folder");
    let frames_dir = dir.join("frames");
    // f2 before f10: natural order, not byte order.
    let files = write_frames(&frames_dir, 12, |k| format!("f{k}.ply"));
    std::fs::write(frames_dir.join("notes.txt"), "not a frame").expect("write");
    let output = dir.join("anim.glb");
    // Plain f32 storage: `GltfTemplate` (the gltf crate) reads it (quantised and compressed
    // files: tests/tests/io_gltf_quantized.rs and the three.js check).
    run_ok(&[
        "convert",
        s(&frames_dir),
        s(&output),
        "--fps",
        "12.5",
        "--gltf-compression",
        "none",
    ]);
    check_plays(&output, &files, 12.5);
    // The default: quantised and meshopt-compressed, much smaller.
    let packed = dir.join("packed.glb");
    run_ok(&["convert", s(&frames_dir), s(&packed), "--fps", "12.5"]);
    let bytes = std::fs::read(&packed).expect("glb");
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes")) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).expect("json");
    assert_eq!(
        doc["extensionsRequired"],
        serde_json::json!(["EXT_meshopt_compression", "KHR_mesh_quantization"])
    );
    let plain = std::fs::metadata(&output).expect("size").len();
    assert!(
        (bytes.len() as u64) * 2 < plain,
        "{} bytes compressed, {plain} plain",
        bytes.len()
    );
}

#[test]
fn patterns_of_frames_to_gltf_at_the_default_rate() {
    let dir = fresh_dir("seq_pattern");
    let frames_dir = dir.join("frames");
    let files = write_frames(&frames_dir, 5, |k| format!("frame_{k:04}.obj"));
    // Not matched by either pattern.
    write_frames(&frames_dir, 1, |_| "other.obj".to_string());
    for (pattern, name) in [
        ("frame_%04d.obj", "printf.gltf"),
        ("frame_*.obj", "glob.glb"),
    ] {
        let output = dir.join(name);
        run_ok(&[
            "convert",
            s(&frames_dir.join(pattern)),
            s(&output),
            "--gltf-compression",
            "none",
        ]);
        check_plays(&output, &files, 30.0);
    }
}

#[test]
fn sequence_usage_errors_exit_2_and_write_nothing() {
    let dir = fresh_dir("seq_usage");
    let frames_dir = dir.join("frames");
    let files = write_frames(&frames_dir, 3, |k| format!("f{k}.obj"));
    let frames = s(&frames_dir);
    let cases: Vec<Vec<String>> = vec![
        // A folder of frames writes an animated glTF, not one PLY/OBJ mesh.
        vec![frames.into(), s(&dir.join("out.ply")).into()],
        vec![frames.into(), s(&dir.join("out.obj")).into()],
        // --clip/--time evaluate a glTF animation.
        vec![
            frames.into(),
            s(&dir.join("out.glb")).into(),
            "--time".into(),
            "1".into(),
        ],
        // --fps needs frames, and a positive rate.
        vec![
            s(&files[0]).into(),
            s(&dir.join("out.glb")).into(),
            "--fps".into(),
            "10".into(),
        ],
        vec![
            frames.into(),
            s(&dir.join("out.glb")).into(),
            "--fps".into(),
            "0".into(),
        ],
        vec![
            frames.into(),
            s(&dir.join("out.glb")).into(),
            "--fps".into(),
            "nan".into(),
        ],
    ];
    for case in cases {
        let mut args = vec!["convert"];
        args.extend(case.iter().map(String::as_str));
        let out = run(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.starts_with("error: "), "{stderr}");
        assert_eq!(listing(&dir), ["frames"], "{args:?} wrote something");
    }
    let out = run(&["convert", frames, s(&dir.join("out.ply"))]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(".glb or .gltf"), "{stderr}");
}

#[test]
fn a_frame_of_another_topology_fails_naming_its_file() {
    let dir = fresh_dir("seq_bad");
    let frames_dir = dir.join("frames");
    write_frames(&frames_dir, 4, |k| format!("f{k}.obj"));
    let spot = trisplat_fixtures::spot().expect("spot");
    let fewer = TriMesh::new(spot.positions().to_vec(), spot.triangles()[..100].to_vec());
    let bad = frames_dir.join("f2.obj");
    write_mesh(&bad, &fewer, WriteOptions::default()).expect("write bad frame");
    let output = dir.join("anim.glb");
    let line = one_error_line(&run(&["convert", s(&frames_dir), s(&output)]));
    assert!(line.contains(s(&bad)), "names the bad frame: {line}");
    assert!(line.contains("triangles"), "{line}");
    assert_eq!(listing(&dir), ["frames"]);
    assert_eq!(listing(&frames_dir).len(), 4);
    // A pattern that matches nothing.
    let line = one_error_line(&run(&[
        "convert",
        s(&frames_dir.join("g_*.ply")),
        s(&output),
    ]));
    assert!(line.contains("no frame files"), "{line}");
    assert_eq!(listing(&dir), ["frames"]);
}

#[test]
fn frames_of_any_topology_with_the_flag_become_one_node_per_run() {
    let dir = fresh_dir("seq_any");
    let frames_dir = dir.join("frames");
    let files = write_frames(&frames_dir, 4, |k| format!("f{k}.ply"));
    // Frame 2 keeps only its first 100 triangles (and all vertices).
    let spot = trisplat_fixtures::spot().expect("spot");
    let fewer = TriMesh::new(
        frame(2).positions().to_vec(),
        spot.triangles()[..100].to_vec(),
    );
    write_mesh(&files[2], &fewer, WriteOptions::default()).expect("write");
    let output = dir.join("anim.glb");
    // Refused without the flag (the morph-target contract), written with it.
    let line = one_error_line(&run(&["convert", s(&frames_dir), s(&output)]));
    assert!(line.contains("triangles"), "{line}");
    run_ok(&["convert", s(&frames_dir), s(&output), "--any-topology"]);
    let bytes = std::fs::read(&output).expect("glb");
    assert_eq!(&bytes[..4], b"glTF");
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes")) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).expect("json");
    // One mesh per run of frames with one topology: frames 0-1 (frame 1 a morph target of
    // frame 0), frame 2, frame 3.
    let meshes = doc["meshes"].as_array().expect("meshes");
    assert_eq!(meshes.len(), 3, "one mesh per run of one topology");
    for (mesh, k, targets) in [(0, 0, 1), (1, 2, 0), (2, 3, 0)] {
        let want = read_mesh(&files[k]).expect("frame");
        let primitive = &meshes[mesh]["primitives"][0];
        let indices = primitive["indices"].as_u64().expect("indices");
        let count = doc["accessors"][indices as usize]["count"]
            .as_u64()
            .expect("count");
        assert_eq!(count as usize, 3 * want.triangle_count(), "frame {k}");
        assert_eq!(
            primitive["targets"].as_array().map_or(0, Vec::len),
            targets,
            "frame {k}"
        );
    }
    // Frames that share the first's topology still become morph targets.
    let same_dir = dir.join("same");
    let same = write_frames(&same_dir, 3, |k| format!("f{k}.obj"));
    let same_out = dir.join("same.glb");
    run_ok(&[
        "convert",
        s(&same_dir),
        s(&same_out),
        "--any-topology",
        "--gltf-compression",
        "none",
    ]);
    check_plays(&same_out, &same, 30.0);
}
