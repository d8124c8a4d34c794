//! Blendshape sets driven by LAM/ARKit weight files, glTF morph targets by name, and the
//! weights-file parser's errors. The real ICT FaceKit and LAM files are too large to commit:
//! `real_face_assets` measures them when `TRISPLAT_SHARED_DATA` names the shared data folder.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{
    AnimatedTemplate, AnimationError, BlendshapeAnimation, BlendshapeSet, Clip, GltfMorphAnimation,
    GltfTemplate, WeightsTrack,
};
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};
use trisplat_geometry::rng::Rng;

/// Allowed difference from the float64 sum `neutral + Σ wᵢ·Δᵢ`, relative to
/// `max(|expected|, 1)`: f32 storage of the result.
const BLEND_TOLERANCE: f64 = 1e-6;

/// A quad grid (triangulated by the OBJ reader) and three targets with random offsets.
fn write_set(dir: &Path) -> (PathBuf, Vec<PathBuf>) {
    let n = 5;
    let mut obj = String::new();
    for j in 0..n {
        for i in 0..n {
            obj += &format!("v {} {} 0\n", i as f32 * 0.1, j as f32 * 0.1);
        }
    }
    let faces: String = (0..n - 1)
        .flat_map(|j| (0..n - 1).map(move |i| (i, j)))
        .map(|(i, j)| {
            let a = j * n + i + 1;
            format!("f {} {} {} {}\n", a, a + 1, a + n + 1, a + n)
        })
        .collect();
    let neutral = dir.join("generic_neutral_mesh.obj");
    std::fs::write(&neutral, format!("{obj}{faces}")).expect("write neutral");
    let base = read_mesh(&neutral).expect("neutral reads");
    let mut rng = Rng::new(11);
    let mut targets = Vec::new();
    for name in ["jawOpen", "eyeBlink_L", "mouthSmile_L"] {
        let moved: Vec<DVec3> = base
            .positions()
            .iter()
            .map(|p| {
                *p + DVec3::new(
                    rng.uniform_f64() - 0.5,
                    rng.uniform_f64() - 0.5,
                    rng.uniform_f64(),
                ) * 0.05
            })
            .collect();
        let path = dir.join(format!("{name}.obj"));
        let mesh = TriMesh::new(moved, base.triangles().to_vec());
        write_mesh(&path, &mesh, WriteOptions::default()).expect("write target");
        targets.push(path);
    }
    (neutral, targets)
}

const TRACK: &str = r#"{
  "names": ["browDownLeft", "eyeBlinkLeft", "jawOpen", "mouthSmileLeft", "tongueOut"],
  "frames": [
    {"weights": [0.1, 0.0, 0.0, 0.0, 0.3], "time": 0.0, "rotation": []},
    {"weights": [0.0, 0.5, 0.25, 1.0, 0.0], "time": 0.0333, "rotation": []},
    {"weights": [0.0, -0.2, 1.3, 0.7, 0.0], "time": 0.0667, "rotation": []}
  ],
  "head_pose": [[0, 0, 0], [0, 0, 0], [0, 0, 0]]
}"#;

fn track(text: &str) -> Result<WeightsTrack, AnimationError> {
    WeightsTrack::parse(text, Path::new("weights.json"))
}

/// `neutral + Σ wᵢ (targetᵢ − neutral)` in f64 straight from the files.
fn expected(neutral: &Path, targets: &[(PathBuf, f64)]) -> Vec<DVec3> {
    let n = read_mesh(neutral).expect("neutral");
    let mut out: Vec<DVec3> = n.positions().to_vec();
    for (path, w) in targets {
        let t = read_mesh(path).expect("target");
        for (o, (tp, np)) in out.iter_mut().zip(t.positions().iter().zip(n.positions())) {
            *o += *w * (tp - np);
        }
    }
    out
}

fn max_error(got: &[DVec3], want: &[DVec3]) -> f64 {
    assert_eq!(got.len(), want.len());
    got.iter()
        .zip(want)
        .flat_map(|(g, w)| (0..3).map(move |c| trisplat_tests::relative_error(g[c], w[c], 1.0)))
        .fold(0.0, f64::max)
}

#[test]
fn frames_equal_neutral_plus_weighted_deltas() {
    let dir = tempfile::tempdir().expect("tmp");
    let (neutral, targets) = write_set(dir.path());
    let set = BlendshapeSet::from_files(&neutral, &targets).expect("set");
    assert_eq!(set.names(), ["jawOpen", "eyeBlink_L", "mouthSmile_L"]);
    let anim = BlendshapeAnimation::new(set, track(TRACK).expect("track")).expect("anim");
    // OBJ blendshapes have no head joint: the head pose drives nothing either.
    assert_eq!(
        anim.unused_channels(),
        ["browDownLeft", "tongueOut", "head_pose"]
    );
    assert!(anim.unmatched_targets().is_empty());
    assert_eq!(anim.frame_count(), 3);
    assert_eq!(anim.frame_time(1), Some(0.0333));
    assert_eq!(anim.topology(), anim.rest().triangles());
    assert_eq!(anim.rest().triangle_count(), 32);
    // Frame 0: no target weight is set: the neutral itself.
    assert_eq!(anim.frame(0).expect("frame"), anim.rest().positions());
    // jawOpen = channel 2, eyeBlink_L = eyeBlinkLeft (1), mouthSmile_L = mouthSmileLeft (3).
    for (frame, w) in [(1, [0.25, 0.5, 1.0]), (2, [1.3, -0.2, 0.7])] {
        let want = expected(
            &neutral,
            &[
                (targets[0].clone(), w[0]),
                (targets[1].clone(), w[1]),
                (targets[2].clone(), w[2]),
            ],
        );
        let got = anim.frame(frame).expect("frame");
        let err = max_error(&got, &want);
        assert!(err < BLEND_TOLERANCE, "frame {frame}: {err:e}");
        // And a weight that moves nothing is really applied: frame 2 differs from frame 1.
        assert_ne!(got, anim.frame(1 + frame % 2).expect("frame"));
    }
    assert!(matches!(
        anim.frame(3),
        Err(AnimationError::FrameOutOfRange { frame: 3, count: 3 })
    ));
    assert_eq!(anim.frame_mesh(1).expect("mesh").triangle_count(), 32);
}

#[test]
fn sets_check_topology_and_weight_counts() {
    let dir = tempfile::tempdir().expect("tmp");
    let (neutral, mut targets) = write_set(dir.path());
    let set = BlendshapeSet::from_files(&neutral, &targets).expect("set");
    assert!(matches!(
        set.evaluate(&[1.0]),
        Err(AnimationError::WeightCount {
            expected: 3,
            found: 1
        })
    ));
    assert_eq!(
        set.evaluate(&[0.0, 0.0, 0.0]).expect("zero"),
        set.neutral().positions()
    );
    // A target with other faces.
    let bad = dir.path().join("cheekPuff.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").expect("write");
    targets.push(bad.clone());
    let err = BlendshapeSet::from_files(&neutral, &targets).expect_err("mismatch");
    assert!(
        matches!(&err, AnimationError::TopologyMismatch { path, .. } if *path == bad),
        "{err}"
    );
    assert!(err.to_string().contains("cheekPuff.obj"), "{err}");
    // In memory.
    let base = read_mesh(&neutral).expect("neutral");
    let n = base.vertex_count();
    let err =
        BlendshapeSet::from_meshes(base.clone(), vec![("x".into(), vec![DVec3::ZERO; n - 1])])
            .expect_err("short");
    assert!(
        matches!(err, AnimationError::TopologyMismatch { .. }),
        "{err}"
    );
    let mut nan = vec![DVec3::ZERO; n];
    nan[3].x = f64::NAN;
    assert!(BlendshapeSet::from_meshes(base.clone(), vec![("x".into(), nan)]).is_err());
    let ok = BlendshapeSet::from_meshes(base.clone(), vec![("x".into(), vec![DVec3::ONE; n])])
        .expect("set");
    let half = ok.evaluate(&[0.5]).expect("eval");
    for (h, p) in half.iter().zip(base.positions()) {
        assert!((*h - (*p + (DVec3::ONE - *p) * 0.5)).length() < 1e-6);
    }
    // A track whose names match nothing.
    let t = track(r#"{"names": ["tongueOut"], "frames": [{"weights": [1]}]}"#).expect("track");
    let err = BlendshapeAnimation::new(ok, t).expect_err("no match");
    assert!(
        matches!(err, AnimationError::NoMatchingTargets { .. }),
        "{err}"
    );
}

#[test]
fn weights_file_errors_are_clear() {
    let cases: [(&str, &str); 10] = [
        (r#"{"frames": [{"weights": [1]}]}"#, "names: missing"),
        (
            r#"{"names": [], "frames": [{"weights": []}]}"#,
            "names: is empty",
        ),
        (
            r#"{"names": ["a", 3], "frames": []}"#,
            "names[1]: is not a string",
        ),
        (
            r#"{"names": ["a", "a"], "frames": [{"weights": [1, 2]}]}"#,
            "repeats names[0]",
        ),
        (r#"{"names": ["a"]}"#, "frames: missing"),
        (r#"{"names": ["a"], "frames": []}"#, "frames: is empty"),
        (
            r#"{"names": ["a", "b"], "frames": [{"weights": [1, 2]}, {"weights": [1]}]}"#,
            "frames[1].weights: has 1 values for 2 names",
        ),
        (
            r#"{"names": ["a", "jawOpen"], "frames": [{"weights": [0.5, NaN]}]}"#,
            "frames[0].weights[1] (jawOpen): null is not a finite number",
        ),
        (
            r#"{"names": ["a"], "frames": [{"weights": [null]}]}"#,
            "frames[0].weights[0] (a)",
        ),
        ("[1, 2, 3]", "expected a JSON object"),
    ];
    for (text, want) in cases {
        let err = track(text).expect_err(text);
        let msg = err.to_string();
        assert!(matches!(err, AnimationError::Weights { .. }), "{msg}");
        assert!(msg.contains(want), "{text}: {msg}");
        assert!(msg.contains("weights.json"), "{msg}");
    }
    for text in [
        r#"{"names": ["a"], "frames": [{"weights": [-Infinity]}]}"#,
        r#"{"names": ["a"], "frames": [{"weights": ["0.5"]}]}"#,
        r#"{"names": ["a"], "frames": [{"weights": [1], "time": 1}, {"weights": [1], "time": 0.5}]}"#,
        r#"{"names": ["a"], "fps": 0, "frames": [{"weights": [1]}]}"#,
        "not json",
    ] {
        assert!(track(text).is_err(), "{text}");
    }
    // Without times: i / fps, from the file or 30.
    let t = track(r#"{"names": ["a"], "fps": 25, "frames": [{"weights": [1]}, {"weights": [0]}]}"#)
        .expect("fps");
    assert_eq!(t.time(1), Some(1.0 / 25.0));
    let t = track(r#"{"names": ["a"], "frames": [{"weights": [1]}, {"weights": [0]}]}"#)
        .expect("default fps");
    assert_eq!(t.time(1), Some(1.0 / 30.0));
    assert_eq!(t.weights(1), Some(&[0.0][..]));
    assert_eq!(t.weights(2), None);
    // "NaN" inside a string is a name, not a number.
    let t = track(r#"{"names": ["NaN"], "frames": [{"weights": [1]}]}"#).expect("string");
    assert_eq!(t.names(), ["NaN"]);
    assert!(matches!(
        WeightsTrack::read(Path::new("/nonexistent/weights.json")),
        Err(AnimationError::Os { .. })
    ));
}

#[test]
fn gltf_morph_targets_by_name() {
    // SyntheticFeatures: mesh 0 (skinned) has targets "widen", "dents"; mesh 1 "a", "b".
    let path = trisplat_fixtures::path("anim/SyntheticFeatures.gltf");
    let template = GltfTemplate::open(&path, &Clip::None).expect("opens");
    let text = r#"{"names": ["dents", "b", "unused"], "frames": [
        {"weights": [0.0, 0.75, 9.0]},
        {"weights": [1.0, 0.75, 9.0]},
        {"weights": [0.0, 2.0, 9.0]},
        {"weights": [1.0, 2.0, 9.0]}]}"#;
    let anim = GltfMorphAnimation::new(template.clone(), track(text).expect("track"))
        .expect("morph animation");
    assert_eq!(anim.unused_channels(), ["unused"]);
    assert_eq!(anim.frame_count(), 4);
    // Frame 0 sets the node defaults (widen 0.5 from mesh.weights stays; b = 0.75 as the
    // node's own weights): the stored scene.
    let rest = template.rest().positions();
    let f0 = anim.frame(0).expect("frame");
    assert!(max_error(&f0, rest) < BLEND_TOLERANCE);
    // Positions are affine in the weights (skinning and node transforms are linear in p):
    // f(1, 2) - f(0, 0.75) = (f(1, 0.75) - f(0, 0.75)) + (f(0, 2) - f(0, 0.75)).
    let f1 = anim.frame(1).expect("frame");
    let f2 = anim.frame(2).expect("frame");
    let f3 = anim.frame(3).expect("frame");
    let want: Vec<DVec3> = (0..f0.len()).map(|v| f1[v] + f2[v] - f0[v]).collect();
    assert!(max_error(&f3, &want) < 1e-5);
    // Both meshes moved.
    assert!(
        (f1[3] - f0[3]).length() > 1e-3,
        "sparse target vertex 3 of mesh 0"
    );
    assert!((f2[20] - f0[20]).length() > 1e-3, "mesh 1");
}

/// The real ICT FaceKit blendshapes and LAM head (too large to commit). Run with
/// `TRISPLAT_SHARED_DATA=$PWD/../shared/data cargo test --release -p trisplat-tests --test
/// animation_blendshape -- --ignored --nocapture`.
#[test]
#[ignore = "needs TRISPLAT_SHARED_DATA (ICT FaceKit OBJs, LAM skin.glb)"]
fn real_face_assets() {
    let Some(root) = std::env::var_os("TRISPLAT_SHARED_DATA").map(PathBuf::from) else {
        eprintln!("TRISPLAT_SHARED_DATA not set: nothing to measure");
        return;
    };
    let lam = root.join("avatars/lam_p2-1");
    let weights = lam.join("test_expression_1s.json");
    let started = Instant::now();
    let track_data = WeightsTrack::read(&weights).expect("LAM weights");
    eprintln!(
        "weights: {} frames x {} channels, read in {:.3} s",
        track_data.frame_count(),
        track_data.names().len(),
        started.elapsed().as_secs_f64()
    );

    // ICT FaceKit.
    let ict = root.join("faces/ict_facekit");
    let targets: Vec<PathBuf> = ["jawOpen", "eyeBlink_L", "mouthSmile_L"]
        .iter()
        .map(|n| ict.join(format!("{n}.obj")))
        .collect();
    let neutral = ict.join("generic_neutral_mesh.obj");
    let started = Instant::now();
    let set = BlendshapeSet::from_files(&neutral, &targets).expect("ICT set");
    eprintln!(
        "ICT: {} vertices, {} triangles, {} targets, read in {:.3} s",
        set.neutral().vertex_count(),
        set.neutral().triangle_count(),
        set.names().len(),
        started.elapsed().as_secs_f64()
    );
    let anim = BlendshapeAnimation::new(set, track_data.clone()).expect("ICT animation");
    assert!(
        anim.unmatched_targets().is_empty(),
        "{:?}",
        anim.unmatched_targets()
    );
    let mut worst = 0.0f64;
    let frames = [0, 100, 400, anim.frame_count() - 1];
    let started = Instant::now();
    for &f in &frames {
        let w = track_data.weights(f).expect("weights");
        let idx = |n: &str| {
            track_data
                .names()
                .iter()
                .position(|x| x == n)
                .expect("name")
        };
        let want = expected(
            &neutral,
            &[
                (targets[0].clone(), w[idx("jawOpen")]),
                (targets[1].clone(), w[idx("eyeBlinkLeft")]),
                (targets[2].clone(), w[idx("mouthSmileLeft")]),
            ],
        );
        worst = worst.max(max_error(&anim.frame(f).expect("frame"), &want));
    }
    eprintln!(
        "ICT: frames {frames:?}: max rel error vs neutral + sum w*delta {worst:.3e} ({:.3} s incl. reference)",
        started.elapsed().as_secs_f64()
    );
    assert!(worst < BLEND_TOLERANCE);
    let started = Instant::now();
    for f in 0..100 {
        anim.frame(f).expect("frame");
    }
    eprintln!(
        "ICT: {:.3} ms per frame",
        started.elapsed().as_secs_f64() * 10.0
    );

    // LAM skin.glb: 51 ARKit morph targets under a 262-joint skin.
    let started = Instant::now();
    let template = GltfTemplate::open(&lam.join("skin.glb"), &Clip::None).expect("skin.glb");
    eprintln!(
        "LAM: {} vertices, {} triangles, {} morph targets, opened in {:.3} s",
        template.rest().vertex_count(),
        template.rest().triangle_count(),
        template.morph_target_names().concat().len(),
        started.elapsed().as_secs_f64()
    );
    let anim = GltfMorphAnimation::new(template.clone(), track_data.clone()).expect("LAM anim");
    eprintln!("LAM: unused channels {:?}", anim.unused_channels());
    let names = template.morph_target_names()[0].to_vec();
    let rest = template.rest().positions().to_vec();
    // Δᵢ in world space: the template with target i at weight 1, minus the rest.
    let deltas: Vec<Vec<DVec3>> = (0..names.len())
        .map(|i| {
            let one = template
                .evaluate_with_weights(None, &|_, t| Some(if t == i { 1.0 } else { 0.0 }))
                .expect("eval");
            one.iter().zip(&rest).map(|(a, r)| a - *r).collect()
        })
        .collect();
    let mut worst = 0.0f64;
    for &f in &frames {
        let w = track_data.weights(f).expect("weights");
        let mut want = rest.clone();
        for (i, name) in names.iter().enumerate() {
            let c = track_data
                .names()
                .iter()
                .position(|n| n == name)
                .expect("channel");
            for (o, d) in want.iter_mut().zip(&deltas[i]) {
                *o += w[c] * *d;
            }
        }
        worst = worst.max(max_error(&anim.frame(f).expect("frame"), &want));
    }
    eprintln!("LAM: frames {frames:?}: max rel error vs rest + sum w*delta {worst:.3e}");
    assert!(worst < 1e-5);
    let started = Instant::now();
    for f in 0..100 {
        anim.frame(f).expect("frame");
    }
    eprintln!(
        "LAM: {:.3} ms per frame",
        started.elapsed().as_secs_f64() * 10.0
    );
}
