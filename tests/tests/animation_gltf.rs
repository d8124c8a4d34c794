//! glTF animation evaluation against the independent pygltflib + numpy reference
//! (`tests/reference/ref_animation.py`), plus clip selection, frame sampling and bad input.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use trisplat_geometry::animation::{AnimatedTemplate, AnimationError, Clip, GltfTemplate};
use trisplat_geometry::io::read_mesh;

/// Largest allowed difference between a position and the float64 reference, relative to
/// `max(|reference|, 1)` (metre-sized models: 10 µm). trisplat stores f32, so ~1e-7 is expected.
const POSITION_TOLERANCE: f64 = 1e-5;

/// Largest allowed mean difference per vertex, from the sums over every vertex.
const MEAN_TOLERANCE: f64 = 1e-6;

fn reference(name: &str) -> Value {
    trisplat_tests::reference_json(&trisplat_fixtures::path(&format!(
        "reference/animation/{name}.json"
    )))
}

fn clip_of(v: &Value) -> Clip {
    match v {
        Value::Number(n) => Clip::Index(n.as_u64().expect("clip index") as usize),
        Value::String(s) => Clip::Name(s.clone()),
        _ => Clip::None,
    }
}

fn as_f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// Compares every case of a reference file; returns the largest relative error.
fn check_model(name: &str) -> f64 {
    let r = reference(name);
    let path = trisplat_fixtures::path(r["file"].as_str().expect("file"));
    let indices: Vec<usize> = r["vertex_indices"]
        .as_array()
        .expect("indices")
        .iter()
        .map(|v| v.as_u64().expect("index") as usize)
        .collect();
    let mut worst = 0.0f64;
    for case in r["cases"].as_array().expect("cases") {
        let clip = clip_of(&case["clip"]);
        let template = GltfTemplate::open(&path, &clip).expect("template opens");
        assert_eq!(
            template.rest().vertex_count() as u64,
            r["vertex_count"].as_u64().expect("count"),
            "{name}: vertex count"
        );
        assert_eq!(
            template.topology().len() as u64,
            r["triangle_count"].as_u64().expect("count"),
            "{name}: triangle count"
        );
        let positions = match case["time"].as_f64() {
            Some(t) => template.evaluate_at(t).expect("evaluates"),
            None => template.rest().positions().to_vec(),
        };
        let mut case_worst = 0.0f64;
        for (k, &v) in indices.iter().enumerate() {
            let want = as_f64s(&case["positions"][k]);
            for c in 0..3 {
                let got = positions[v][c];
                let err = trisplat_tests::relative_error(got, want[c], 1.0);
                case_worst = case_worst.max(err);
            }
        }
        let sum = as_f64s(&case["sum"]);
        let n = positions.len() as f64;
        for c in 0..3 {
            let got: f64 = positions.iter().map(|p| p[c]).sum();
            let mean_err = (got - sum[c]).abs() / n;
            assert!(
                mean_err < MEAN_TOLERANCE,
                "{name} clip {:?} t {:?}: mean error {mean_err:e} on axis {c}",
                case["clip"],
                case["time"]
            );
        }
        eprintln!(
            "{name:>20} clip {:<14} t {:<8} max rel error {case_worst:.3e}",
            case["clip"].to_string(),
            case["time"].to_string()
        );
        assert!(
            case_worst < POSITION_TOLERANCE,
            "{name} clip {:?} t {:?}: error {case_worst:e}",
            case["clip"],
            case["time"]
        );
        worst = worst.max(case_worst);
    }
    eprintln!("{name}: worst {worst:.3e}");
    worst
}

#[test]
fn simple_skin_matches_reference() {
    check_model("SimpleSkin");
}

#[test]
fn rigged_simple_matches_reference() {
    check_model("RiggedSimple");
}

#[test]
fn rigged_figure_matches_reference() {
    check_model("RiggedFigure");
}

#[test]
fn cesium_man_matches_reference() {
    check_model("CesiumMan");
}

#[test]
fn morph_stress_test_matches_reference() {
    check_model("MorphStressTest");
}

#[test]
fn animated_morph_sphere_matches_reference() {
    check_model("AnimatedMorphSphere");
}

#[test]
fn simple_morph_matches_reference() {
    // External .bin buffers.
    check_model("SimpleMorph");
}

#[test]
fn animated_morph_cube_matches_reference() {
    check_model("AnimatedMorphCube");
}

#[test]
fn synthetic_features_match_reference() {
    // STEP and CUBICSPLINE on every path, sparse morph targets, normalised integer weights and
    // rotations, 8 influences per vertex, a zero-weight vertex, strip and fan primitives.
    check_model("SyntheticFeatures");
    let r = reference("SyntheticFeatures");
    let path = trisplat_fixtures::path(r["file"].as_str().expect("file"));
    let t = GltfTemplate::open(&path, &Clip::None).expect("opens");
    let want: Vec<[u32; 3]> = r["triangles"]
        .as_array()
        .expect("triangles")
        .iter()
        .map(|t| {
            let v = as_f64s(t);
            [v[0] as u32, v[1] as u32, v[2] as u32]
        })
        .collect();
    assert_eq!(t.topology(), want.as_slice());
}

#[test]
fn topology_matches_the_static_reader() {
    for name in [
        "CesiumMan",
        "MorphStressTest",
        "SyntheticFeatures",
        "RiggedFigure",
    ] {
        let r = reference(name);
        let path = trisplat_fixtures::path(r["file"].as_str().expect("file"));
        let t = GltfTemplate::open(&path, &Clip::None).expect("opens");
        let stat = read_mesh(&path).expect("static read");
        assert_eq!(t.topology(), stat.triangles(), "{name}");
        assert_eq!(t.rest().vertex_count(), stat.vertex_count(), "{name}");
    }
    // Without skins the rest state is the static mesh itself.
    let path = trisplat_fixtures::path(reference("MorphStressTest")["file"].as_str().expect("f"));
    let t = GltfTemplate::open(&path, &Clip::None).expect("opens");
    let stat = read_mesh(&path).expect("static read");
    for (a, b) in t.rest().positions().iter().zip(stat.positions()) {
        assert!((*a - *b).length() < 1e-6);
    }
}

#[test]
fn frames_sample_the_clip_at_the_frame_rate() {
    let path = trisplat_fixtures::path(reference("RiggedSimple")["file"].as_str().expect("f"));
    let t = GltfTemplate::open(&path, &Clip::Index(0))
        .expect("opens")
        .with_fps(24.0);
    let d = t.duration();
    assert!(d > 0.0);
    assert_eq!(t.frame_count(), (d * 24.0 + 1e-9).floor() as usize + 1);
    assert_eq!(t.frame_time(3), Some(3.0 / 24.0));
    assert_eq!(t.frame_time(t.frame_count()), None);
    assert_eq!(
        t.frame(5).expect("frame"),
        t.evaluate_at(5.0 / 24.0).expect("eval")
    );
    let m = t.frame_mesh(2).expect("mesh");
    assert_eq!(m.triangles(), t.topology());
    assert!(matches!(
        t.frame(t.frame_count()),
        Err(AnimationError::FrameOutOfRange { .. })
    ));
    assert!(matches!(
        t.evaluate_at(f64::NAN),
        Err(AnimationError::BadTime { .. })
    ));
    // Past the end and before the start clamp.
    assert_eq!(
        t.evaluate_at(d + 10.0).expect("eval"),
        t.evaluate_at(d).expect("eval")
    );
    assert_eq!(
        t.evaluate_at(-3.0).expect("eval"),
        t.evaluate_at(0.0).expect("eval")
    );
    // A template without a clip has one frame: the rest pose.
    let s = GltfTemplate::open(&path, &Clip::None).expect("opens");
    assert_eq!(s.frame_count(), 1);
    assert_eq!(s.frame(0).expect("frame"), s.rest().positions());
}

#[test]
fn clips_by_name_and_index_agree() {
    let path = trisplat_fixtures::path(reference("MorphStressTest")["file"].as_str().expect("f"));
    let by_name = GltfTemplate::open(&path, &Clip::Name("Pulse".into())).expect("opens");
    let (index, name) = by_name.clip().expect("clip");
    assert_eq!(name, Some("Pulse"));
    let by_index = GltfTemplate::open(&path, &Clip::Index(index)).expect("opens");
    assert_eq!(
        by_name.evaluate_at(0.7).expect("eval"),
        by_index.evaluate_at(0.7).expect("eval")
    );
    let err = GltfTemplate::open(&path, &Clip::Name("Walk".into())).expect_err("no such clip");
    let text = err.to_string();
    assert!(matches!(err, AnimationError::ClipNotFound { .. }));
    assert!(text.contains("Walk") && text.contains("TheWave"), "{text}");
    assert!(matches!(
        GltfTemplate::open(&path, &Clip::Index(3)),
        Err(AnimationError::ClipNotFound { .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Bad input

fn synthetic_json() -> Value {
    let path = trisplat_fixtures::path("anim/SyntheticFeatures.gltf");
    serde_json::from_str(&std::fs::read_to_string(path).expect("read")).expect("json")
}

fn write_json(dir: &Path, name: &str, doc: &Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_string(doc).expect("json")).expect("write");
    p
}

/// Standard base64 (for a hand-made data URI).
fn base64(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(A[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[test]
fn missing_bin_names_the_file() {
    let dir = tempfile::tempdir().expect("tmp");
    let src = trisplat_fixtures::path("anim/AnimatedMorphSphere/AnimatedMorphSphere.gltf");
    let dst = dir.path().join("AnimatedMorphSphere.gltf");
    std::fs::copy(&src, &dst).expect("copy");
    let err = GltfTemplate::open(&dst, &Clip::Index(0)).expect_err("no .bin");
    let text = err.to_string();
    assert!(
        matches!(err, AnimationError::MissingBuffer { .. }),
        "{text}"
    );
    assert!(text.contains("AnimatedMorphSphere.bin"), "{text}");
}

/// Appends a data-URI buffer of f32 `values`, its view and a `kind` accessor; returns the
/// accessor index.
fn push_floats(doc: &mut Value, values: &[f32], kind: &str) -> usize {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let buffers = doc["buffers"].as_array_mut().expect("buffers");
    buffers.push(json!({
        "byteLength": bytes.len(),
        "uri": format!("data:application/octet-stream;base64,{}", base64(&bytes)),
    }));
    let buffer = buffers.len() - 1;
    let views = doc["bufferViews"].as_array_mut().expect("views");
    views.push(json!({"buffer": buffer, "byteLength": bytes.len()}));
    let view = views.len() - 1;
    let dims = if kind == "VEC4" { 4 } else { 1 };
    let accessors = doc["accessors"].as_array_mut().expect("accessors");
    accessors.push(json!({
        "bufferView": view, "componentType": 5126, "count": values.len() / dims, "type": kind,
    }));
    accessors.len() - 1
}

#[test]
fn zero_and_nan_quaternions_are_refused() {
    let dir = tempfile::tempdir().expect("tmp");
    // A rotation channel with a zero quaternion at key 1.
    let mut doc = synthetic_json();
    let times = push_floats(&mut doc, &[0.0, 1.0], "SCALAR");
    let zero = push_floats(&mut doc, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], "VEC4");
    doc["animations"][0]["samplers"][2]["input"] = json!(times);
    doc["animations"][0]["samplers"][2]["output"] = json!(zero);
    let p = write_json(dir.path(), "zero.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::Index(0)).expect_err("zero quaternion");
    assert!(
        matches!(
            err,
            AnimationError::Animation {
                animation: 0,
                channel: 2,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("key 1 holds a zero"), "{err}");
    // Not refused while that clip is not selected.
    assert!(GltfTemplate::open(&p, &Clip::Index(1)).is_ok());

    // A NaN component in a float rotation output.
    let mut doc = synthetic_json();
    let times = push_floats(&mut doc, &[0.0, 1.0], "SCALAR");
    let nan = push_floats(
        &mut doc,
        &[0.0, 0.0, 0.0, 1.0, f32::NAN, 0.0, 0.0, 1.0],
        "VEC4",
    );
    doc["animations"][0]["samplers"][2]["input"] = json!(times);
    doc["animations"][0]["samplers"][2]["output"] = json!(nan);
    let p = write_json(dir.path(), "nan.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::Index(0)).expect_err("NaN quaternion");
    assert!(
        matches!(err, AnimationError::Accessor { accessor, .. } if accessor == nan),
        "{err}"
    );
    assert!(err.to_string().contains("not finite"), "{err}");

    // Key times that do not increase.
    let mut doc = synthetic_json();
    let times = push_floats(&mut doc, &[1.0, 0.5], "SCALAR");
    doc["animations"][0]["samplers"][2]["input"] = json!(times);
    let unit = push_floats(&mut doc, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], "VEC4");
    doc["animations"][0]["samplers"][2]["output"] = json!(unit);
    let p = write_json(dir.path(), "times.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::Index(0)).expect_err("decreasing times");
    assert!(err.to_string().contains("increase"), "{err}");

    // A zero node rotation.
    let mut doc = synthetic_json();
    doc["nodes"][3]["rotation"] = json!([0.0, 0.0, 0.0, 0.0]);
    let p = write_json(dir.path(), "node.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::None).expect_err("zero rotation");
    assert!(matches!(err, AnimationError::Node { node: 3, .. }), "{err}");
}

#[test]
fn broken_references_give_errors_not_panics() {
    let dir = tempfile::tempdir().expect("tmp");
    // Missing accessor for a sampler: the gltf crate's validation refuses it.
    let mut doc = synthetic_json();
    doc["animations"][0]["samplers"][0]["output"] = json!(999);
    let p = write_json(dir.path(), "missing.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::Index(0)).expect_err("missing accessor");
    assert!(matches!(err, AnimationError::Gltf { .. }), "{err}");

    // Output count that does not fit the keys.
    let mut doc = synthetic_json();
    doc["animations"][0]["samplers"][1]["output"] =
        doc["animations"][0]["samplers"][0]["output"].clone();
    let p = write_json(dir.path(), "count.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::Index(0)).expect_err("bad count");
    assert!(
        matches!(err, AnimationError::Animation { channel: 1, .. }),
        "{err}"
    );

    // A joint index past the skin's joints.
    let mut doc = synthetic_json();
    doc["skins"][0]["joints"] = json!([1, 2]);
    doc["skins"][0]
        .as_object_mut()
        .expect("skin")
        .remove("inverseBindMatrices");
    let p = write_json(dir.path(), "joints.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::None).expect_err("joint out of range");
    assert!(
        matches!(err, AnimationError::Primitive { mesh: 0, .. }),
        "{err}"
    );

    // An accessor that runs past its buffer view.
    let mut doc = synthetic_json();
    doc["accessors"][0]["count"] = json!(10_000);
    let p = write_json(dir.path(), "short.gltf", &doc);
    let err = GltfTemplate::open(&p, &Clip::None).expect_err("short view");
    assert!(
        matches!(err, AnimationError::Accessor { accessor: 0, .. }),
        "{err}"
    );

    // Garbage.
    let p = dir.path().join("garbage.glb");
    std::fs::write(&p, b"glTF\x02\x00\x00\x00garbage").expect("write");
    assert!(GltfTemplate::open(&p, &Clip::None).is_err());
    assert!(matches!(
        GltfTemplate::open(&dir.path().join("absent.gltf"), &Clip::None),
        Err(AnimationError::Os { .. })
    ));
}

#[test]
fn mutated_accessors_and_nodes_never_panic() {
    // Every accessor's count and offset, every node's children and every sampler's
    // interpolation pushed to odd values: each open must return (Ok or a clear Err), not panic.
    let dir = tempfile::tempdir().expect("tmp");
    let base = synthetic_json();
    let accessors = base["accessors"].as_array().expect("a").len();
    let mut cases: Vec<Value> = Vec::new();
    for a in 0..accessors {
        for count in [0u64, 1, 2, 7, 1 << 20, u64::from(u32::MAX)] {
            let mut doc = base.clone();
            doc["accessors"][a]["count"] = json!(count);
            cases.push(doc);
        }
        for offset in [1u64, 3, 4096, u64::from(u32::MAX)] {
            let mut doc = base.clone();
            doc["accessors"][a]["byteOffset"] = json!(offset);
            cases.push(doc);
        }
        let mut doc = base.clone();
        doc["accessors"][a]["normalized"] = json!(true);
        doc["accessors"][a]["componentType"] = json!(5121);
        cases.push(doc);
    }
    for n in 0..6 {
        let mut doc = base.clone();
        doc["nodes"][n]["children"] = json!([0]);
        cases.push(doc);
        let mut doc = base.clone();
        doc["nodes"][n]["weights"] = json!([1.0]);
        cases.push(doc);
    }
    for s in 0..7 {
        for interp in ["STEP", "CUBICSPLINE", "LINEAR"] {
            let mut doc = base.clone();
            doc["animations"][0]["samplers"][s]["interpolation"] = json!(interp);
            cases.push(doc);
        }
    }
    let mut errors = 0;
    for (k, doc) in cases.iter().enumerate() {
        let p = write_json(dir.path(), &format!("m{k}.gltf"), doc);
        for clip in [Clip::None, Clip::Index(0), Clip::Index(1)] {
            match GltfTemplate::open(&p, &clip) {
                Ok(t) => {
                    for i in 0..t.frame_count().min(3) {
                        let _ = t.frame(i);
                    }
                    let _ = t.evaluate_at(0.7);
                }
                Err(e) => {
                    assert!(!e.to_string().is_empty());
                    errors += 1;
                }
            }
        }
    }
    assert!(
        errors > cases.len(),
        "most mutations must be refused: {errors}"
    );
}
