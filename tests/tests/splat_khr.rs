//! glTF Gaussians with `KHR_gaussian_splatting` (docs/conventions.md §3, "glTF"; the Khronos
//! Release Candidate of 2026-04-15): the file's structure as the extension specifies it, round
//! trips (means, rotations and SH bit for bit; scales and opacities through one f32 rounding
//! of exp/ln and sigmoid/logit), files written by hand with quantised accessors and node
//! transforms, refusals and bad inputs.

use std::path::Path;

use base64::Engine as _;
use glam::{DMat3, DQuat, DVec3, Vec3};
use serde_json::{Value, json};
use trisplat_geometry::TriId;
use trisplat_splat::eval_rgb;
use trisplat_splat::gltf_splat::{
    EXTENSION, GltfSplatError, OPAQUE_LOGIT, TRANSPARENT_LOGIT, ZERO_LOG_SCALE, glb_gaussians,
    gltf_text_gaussians, has_gaussian_splats, read_gltf_gaussians, write_gltf_gaussians,
};
use trisplat_splat::{
    Binding, GaussianParts, GaussianSet, ParameterSpace, ScaleDims, normalize_wxyz, sigmoid,
};

fn random_set(n: usize, degree: u8, seed: u64) -> GaussianSet {
    let mut rng = trisplat_geometry::rng::Rng::new(seed);
    let mut u = |a: f32, b: f32| a + (b - a) * rng.uniform_f32();
    let k = (usize::from(degree) + 1).pow(2);
    let mut parts = GaussianParts {
        sh_degree: degree,
        ..GaussianParts::default()
    };
    for _ in 0..n {
        parts
            .means
            .push(Vec3::new(u(-2.0, 2.0), u(-2.0, 2.0), u(-2.0, 2.0)));
        parts
            .log_scales
            .push(Vec3::new(u(-12.0, 2.0), u(-12.0, 2.0), u(-12.0, 2.0)));
        parts
            .rotations
            .push([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
        parts.opacity_logits.push(u(-9.0, 9.0));
        for _ in 0..3 * k {
            parts.sh.push(u(-2.0, 2.0));
        }
    }
    GaussianSet::try_new(parts).expect("valid")
}

fn glb_json(bytes: &[u8]) -> Value {
    let len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
    serde_json::from_slice(&bytes[20..20 + len]).expect("json chunk")
}

/// Half an f32 ulp of `x` (at least of the smallest normal).
fn half_ulp(x: f32) -> f64 {
    let x = x.abs().max(f32::MIN_POSITIVE);
    f64::from(f32::from_bits(x.to_bits() + 1) - x) / 2.0
}

#[test]
fn written_files_follow_the_extension() {
    let set = random_set(5, 2, 1);
    let bytes = glb_gaussians(&set, Path::new("s.glb")).expect("glb");
    let doc = glb_json(&bytes);
    assert_eq!(doc["extensionsUsed"], json!([EXTENSION]));
    assert!(
        doc.get("extensionsRequired").is_none(),
        "viewers fall back to points"
    );
    let prim = &doc["meshes"][0]["primitives"][0];
    assert_eq!(prim["mode"], 0, "POINTS");
    assert!(prim.get("indices").is_none());
    let ext = &prim["extensions"][EXTENSION];
    assert_eq!(ext["kernel"], "ellipse");
    assert_eq!(ext["colorSpace"], "srgb_rec709_display");
    assert_eq!(ext["projection"], "perspective");
    assert_eq!(ext["sortingMethod"], "cameraDistance");
    let mut names: Vec<&str> = prim["attributes"]
        .as_object()
        .expect("attributes")
        .keys()
        .map(String::as_str)
        .collect();
    names.sort_unstable();
    let mut expect = vec![
        "COLOR_0",
        "POSITION",
        "KHR_gaussian_splatting:ROTATION",
        "KHR_gaussian_splatting:SCALE",
        "KHR_gaussian_splatting:OPACITY",
        "KHR_gaussian_splatting:SH_DEGREE_0_COEF_0",
    ];
    for l in 1..=2 {
        for n in 0..=2 * l {
            expect.push(Box::leak(
                format!("KHR_gaussian_splatting:SH_DEGREE_{l}_COEF_{n}").into_boxed_str(),
            ));
        }
    }
    expect.sort_unstable();
    assert_eq!(names, expect);
    // Accessor types and the values of Gaussian 0, decoded from the binary chunk by hand.
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().expect("4")) as usize;
    let bin = &bytes[20 + json_len + 8..];
    let value = |attr: &str, component: usize| -> f32 {
        let a = &doc["accessors"][prim["attributes"][attr].as_u64().expect("index") as usize];
        assert_eq!(a["componentType"], 5126, "{attr} is float");
        assert_eq!(a["count"], 5);
        let view = &doc["bufferViews"][a["bufferView"].as_u64().expect("view") as usize];
        let at = view["byteOffset"].as_u64().expect("offset") as usize + 4 * component;
        f32::from_le_bytes(bin[at..at + 4].try_into().expect("4"))
    };
    let check_type = |attr: &str, ty: &str| {
        let a = &doc["accessors"][prim["attributes"][attr].as_u64().expect("index") as usize];
        assert_eq!(a["type"], ty, "{attr}");
    };
    check_type("POSITION", "VEC3");
    check_type("KHR_gaussian_splatting:ROTATION", "VEC4");
    check_type("KHR_gaussian_splatting:SCALE", "VEC3");
    check_type("KHR_gaussian_splatting:OPACITY", "SCALAR");
    check_type("KHR_gaussian_splatting:SH_DEGREE_2_COEF_4", "VEC3");
    check_type("COLOR_0", "VEC4");
    let q = normalize_wxyz(set.rotations()[0]).expect("q");
    // glTF order x y z w.
    assert_eq!(value("KHR_gaussian_splatting:ROTATION", 0), q.x as f32);
    assert_eq!(value("KHR_gaussian_splatting:ROTATION", 3), q.w as f32);
    // Linear scales.
    let l = set.log_scales()[0];
    assert_eq!(
        value("KHR_gaussian_splatting:SCALE", 1),
        f64::from(l.y).exp() as f32
    );
    assert_eq!(value("KHR_gaussian_splatting:OPACITY", 0), set.opacity(0));
    // SH: degree l coefficient n is basis l² + n (m = -l..l); channels r g b.
    let c = set.sh_coeffs(0);
    let rest = 8;
    assert_eq!(value("KHR_gaussian_splatting:SH_DEGREE_0_COEF_0", 2), c[2]);
    assert_eq!(value("KHR_gaussian_splatting:SH_DEGREE_1_COEF_0", 0), c[3]);
    assert_eq!(
        value("KHR_gaussian_splatting:SH_DEGREE_2_COEF_3", 1),
        c[3 + rest + 6]
    );
    assert_eq!(
        value("KHR_gaussian_splatting:SH_DEGREE_2_COEF_4", 2),
        c[3 + 2 * rest + 7]
    );
    // POSITION has min/max.
    let pos = &doc["accessors"][prim["attributes"]["POSITION"].as_u64().expect("i") as usize];
    assert!(pos["min"].is_array() && pos["max"].is_array());
}

#[test]
fn round_trips_keep_means_rotations_and_sh_bit_for_bit() {
    let set = random_set(1000, 3, 11);
    let dir = tempfile::tempdir().expect("tmp");
    let mut report = String::new();
    for name in ["s.glb", "s.gltf"] {
        let path = dir.path().join(name);
        write_gltf_gaussians(&path, &set).expect("write");
        assert!(has_gaussian_splats(&path));
        let read = read_gltf_gaussians(&path).expect("read");
        assert_eq!(read.primitives, 1);
        assert_eq!(read.color_space, "srgb_rec709_display");
        let back = read.gaussians;
        assert_eq!(back.means(), set.means());
        assert_eq!(back.sh(), set.sh());
        assert_eq!(back.sh_degree(), 3);
        assert_eq!(back.scale_dims(), ScaleDims::Three);
        let (mut worst_scale, mut worst_opacity) = (0.0f64, 0.0f64);
        for i in 0..set.len() {
            let q = normalize_wxyz(set.rotations()[i]).expect("q");
            assert_eq!(
                back.rotations()[i],
                [q.w as f32, q.x as f32, q.y as f32, q.z as f32],
                "rotation {i}"
            );
            // log-scale: exp rounded to f32 (relative 2^-24), ln rounded to f32.
            for (a, b) in set.log_scales()[i]
                .to_array()
                .into_iter()
                .zip(back.log_scales()[i].to_array())
            {
                let d = f64::from((a - b).abs());
                assert!(d <= 2f64.powi(-24) * 1.000_001 + half_ulp(a), "{a} -> {b}");
                worst_scale = worst_scale.max(d);
            }
            // Opacity: stored as f32 sigmoid; read back it gives that same f32 within an ulp.
            let d = f64::from((set.opacity(i) - back.opacity(i)).abs());
            assert!(d <= 1.2e-7, "opacity {i}: {d}");
            worst_opacity = worst_opacity.max(d);
        }
        report.push_str(&format!(
            "{name}: log-scale max error {worst_scale:.3e}, opacity max error {worst_opacity:.3e}\n"
        ));
        // Writing what was read gives the same positions, rotations and SH bytes again.
        let again = glb_gaussians(&back, Path::new("again.glb")).expect("glb");
        let first = glb_gaussians(&set, Path::new("first.glb")).expect("glb");
        assert_eq!(glb_json(&again), glb_json(&first), "same structure");
    }
    println!("{report}");
}

#[test]
fn saturated_values_and_surfels() {
    let mut parts = random_set(3, 0, 2).into_parts();
    parts.opacity_logits = vec![40.0, -200.0, 0.0];
    parts.scale_dims = ScaleDims::Two;
    parts.log_scales[1].x = -120.0; // exp underflows to 0 in f32
    let set = GaussianSet::try_new(parts).expect("set");
    let bytes = glb_gaussians(&set, Path::new("s.glb")).expect("glb");
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("s.glb");
    std::fs::write(&path, bytes).expect("write");
    let back = read_gltf_gaussians(&path).expect("read").gaussians;
    assert_eq!(back.opacity_logits()[0], OPAQUE_LOGIT);
    assert_eq!(back.opacity_logits()[1], TRANSPARENT_LOGIT);
    assert_eq!(back.opacity(0), 1.0);
    assert_eq!(back.opacity(1), 0.0);
    assert_eq!(back.opacity_logits()[2], 0.0);
    assert_eq!(back.log_scales()[1].x, ZERO_LOG_SCALE);
    // Every third scale was written as 0: read back as surfels.
    assert_eq!(back.scale_dims(), ScaleDims::Two);
}

/// A `.gltf` with the given accessors (`(componentType, normalized, type, bytes)`), attributes
/// and node.
fn hand_gltf(
    accessors: &[(u32, bool, &str, usize, Vec<u8>)],
    attributes: Value,
    node: Value,
    mode: u32,
) -> String {
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut accs = Vec::new();
    for (i, (ty, normalized, kind, count, data)) in accessors.iter().enumerate() {
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": data.len()}));
        bin.extend_from_slice(data);
        let mut a = json!({"bufferView": i, "componentType": ty, "count": count, "type": kind});
        if i == 0 {
            // POSITION's bounds (required by glTF).
            let v: Vec<f32> = data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            let lo: Vec<f32> = (0..3)
                .map(|c| {
                    v.iter()
                        .skip(c)
                        .step_by(3)
                        .copied()
                        .fold(f32::INFINITY, f32::min)
                })
                .collect();
            let hi: Vec<f32> = (0..3)
                .map(|c| {
                    v.iter()
                        .skip(c)
                        .step_by(3)
                        .copied()
                        .fold(f32::NEG_INFINITY, f32::max)
                })
                .collect();
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        if *normalized {
            a["normalized"] = json!(true);
        }
        accs.push(a);
    }
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    );
    json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": [EXTENSION],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [node],
        "meshes": [{"primitives": [{
            "attributes": attributes,
            "mode": mode,
            "extensions": {EXTENSION: {"kernel": "ellipse", "colorSpace": "lin_rec709_display"}},
        }]}],
        "accessors": accs,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len(), "uri": uri}],
    })
    .to_string()
}

fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn standard_attributes(sh1: bool) -> Value {
    let mut a = json!({
        "POSITION": 0,
        "KHR_gaussian_splatting:ROTATION": 1,
        "KHR_gaussian_splatting:SCALE": 2,
        "KHR_gaussian_splatting:OPACITY": 3,
        "KHR_gaussian_splatting:SH_DEGREE_0_COEF_0": 4,
    });
    if sh1 {
        for n in 0..3 {
            a[format!("KHR_gaussian_splatting:SH_DEGREE_1_COEF_{n}")] = json!(5 + n);
        }
    }
    a
}

/// Two Gaussians with quantised rotation (normalised i16), scale (u8 integers) and opacity
/// (normalised u8) accessors, SH degree 1.
fn quantised_accessors() -> Vec<(u32, bool, &'static str, usize, Vec<u8>)> {
    let rot: Vec<u8> = [0i16, 0, 0, 32767, 0, 32767, 0, 0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let mut acc = vec![
        (
            5126,
            false,
            "VEC3",
            2,
            f32s(&[1.0, 2.0, 3.0, -1.0, 0.5, 0.25]),
        ),
        (5122, true, "VEC4", 2, rot),
        (5121, false, "VEC3", 2, vec![1, 2, 4, 8, 16, 0, 0, 0]),
        (5121, true, "SCALAR", 2, vec![255, 51]),
        (
            5126,
            false,
            "VEC3",
            2,
            f32s(&[0.1, 0.2, 0.3, -0.1, -0.2, -0.3]),
        ),
    ];
    for n in 0..3 {
        let base = n as f32;
        acc.push((
            5126,
            false,
            "VEC3",
            2,
            f32s(&[base + 0.1, base + 0.2, base + 0.3, -base, 0.5, -0.5]),
        ));
    }
    acc
}

#[test]
fn quantised_accessors_read_per_the_gltf_rules() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("q.gltf");
    std::fs::write(
        &path,
        hand_gltf(
            &quantised_accessors(),
            standard_attributes(true),
            json!({"mesh": 0}),
            0,
        ),
    )
    .expect("write");
    let read = read_gltf_gaussians(&path).expect("read");
    assert_eq!(read.color_space, "lin_rec709_display");
    let s = read.gaussians;
    assert_eq!(s.len(), 2);
    assert_eq!(s.means()[1], Vec3::new(-1.0, 0.5, 0.25));
    // Normalised i16 32767 -> 1; xyzw (0,0,0,1) is the identity, (0,1,0,0) a half turn about y.
    assert_eq!(s.rotations()[0], [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(s.rotations()[1], [0.0, 0.0, 1.0, 0.0]);
    // u8 integer scales 1, 2, 4 read as linear scales.
    assert_eq!(s.log_scales()[0], Vec3::new(0.0, 2f32.ln(), 4f32.ln()));
    assert_eq!(s.log_scales()[1].z, ZERO_LOG_SCALE);
    // Normalised u8 255 -> 1 (opaque), 51 -> 0.2.
    assert_eq!(s.opacity_logits()[0], OPAQUE_LOGIT);
    assert!((s.opacity(1) - 0.2).abs() < 1e-7);
    // SH degree 1, coefficient n of channel c at 3 + c·3 + n.
    assert_eq!(s.sh_degree(), 1);
    let c = s.sh_coeffs(0);
    assert_eq!(&c[..3], &[0.1, 0.2, 0.3]);
    assert_eq!([c[3], c[4], c[5]], [0.1, 1.1, 2.1]); // red of COEF_0, 1, 2
    assert_eq!([c[6], c[9]], [0.2, 0.3]); // green and blue of COEF_0
}

#[test]
fn node_transforms_move_means_covariances_and_sh() {
    let dir = tempfile::tempdir().expect("tmp");
    let turn = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.8);
    let node = json!({
        "mesh": 0,
        "translation": [0.5, -1.0, 2.0],
        "rotation": [turn.x, turn.y, turn.z, turn.w],
        "scale": [2.0, 2.0, 2.0],
    });
    let plain = dir.path().join("plain.gltf");
    let moved = dir.path().join("moved.gltf");
    std::fs::write(
        &plain,
        hand_gltf(
            &quantised_accessors(),
            standard_attributes(true),
            json!({"mesh": 0}),
            0,
        ),
    )
    .expect("w");
    std::fs::write(
        &moved,
        hand_gltf(&quantised_accessors(), standard_attributes(true), node, 0),
    )
    .expect("w");
    let a = read_gltf_gaussians(&plain).expect("plain").gaussians;
    let b = read_gltf_gaussians(&moved).expect("moved").gaussians;
    let r = DMat3::from_quat(turn);
    let m = r * 2.0;
    let t = DVec3::new(0.5, -1.0, 2.0);
    for i in 0..2 {
        let expect = m * a.means()[i].as_dvec3() + t;
        assert!(
            (b.means()[i].as_dvec3() - expect).length() < 1e-5,
            "mean {i}"
        );
        let cov = m * a.covariance(i) * m.transpose();
        let got = b.covariance(i);
        let scale = cov
            .to_cols_array()
            .iter()
            .fold(0.0f64, |x, v| x.max(v.abs()));
        for (x, y) in cov.to_cols_array().iter().zip(got.to_cols_array()) {
            assert!(
                (x - y).abs() <= 1e-5 * scale,
                "covariance {i}: {cov} vs {got}"
            );
        }
        // The colour seen along the rotated direction is the colour seen before.
        for d in [DVec3::X, DVec3::new(0.3, -0.8, 0.5)] {
            let before = eval_rgb(1, a.sh_coeffs(i), d);
            let after = eval_rgb(1, b.sh_coeffs(i), r * d);
            for c in 0..3 {
                assert!((before[c] - after[c]).abs() < 1e-5, "colour {i}");
            }
        }
    }
    // A mirroring node is refused.
    let mirrored = dir.path().join("mirror.gltf");
    std::fs::write(
        &mirrored,
        hand_gltf(
            &quantised_accessors(),
            standard_attributes(true),
            json!({"mesh": 0, "scale": [-1.0, 1.0, 1.0]}),
            0,
        ),
    )
    .expect("w");
    let err = read_gltf_gaussians(&mirrored).expect_err("mirror");
    assert!(err.to_string().contains("node transform"), "{err}");
}

#[test]
fn bad_files_are_refused_naming_the_problem() {
    let dir = tempfile::tempdir().expect("tmp");
    let write = |name: &str, text: String| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).expect("write");
        p
    };
    let acc = quantised_accessors();
    let expect_err = |p: &Path, what: &str| {
        let err = read_gltf_gaussians(p).expect_err(what);
        assert!(err.to_string().contains(what), "{err} lacks {what:?}");
    };
    // Mode TRIANGLES.
    expect_err(
        &write(
            "m.gltf",
            hand_gltf(&acc, standard_attributes(true), json!({"mesh": 0}), 4),
        ),
        "mode POINTS",
    );
    // A missing attribute.
    let mut attrs = standard_attributes(true);
    attrs
        .as_object_mut()
        .expect("o")
        .remove("KHR_gaussian_splatting:OPACITY");
    expect_err(
        &write("o.gltf", hand_gltf(&acc, attrs, json!({"mesh": 0}), 0)),
        "missing attribute KHR_gaussian_splatting:OPACITY",
    );
    // SH degree 1 in part.
    let mut attrs = standard_attributes(true);
    attrs
        .as_object_mut()
        .expect("o")
        .remove("KHR_gaussian_splatting:SH_DEGREE_1_COEF_2");
    expect_err(
        &write("p.gltf", hand_gltf(&acc, attrs, json!({"mesh": 0}), 0)),
        "given in part",
    );
    // Degree 2 without degree 1.
    let mut attrs = standard_attributes(false);
    attrs["KHR_gaussian_splatting:SH_DEGREE_2_COEF_0"] = json!(5);
    expect_err(
        &write("d.gltf", hand_gltf(&acc, attrs, json!({"mesh": 0}), 0)),
        "without degree 1",
    );
    // A component type the extension does not allow (float opacity is; u8 not normalised not).
    let mut bad = acc.clone();
    bad[3].1 = false;
    expect_err(
        &write(
            "t.gltf",
            hand_gltf(&bad, standard_attributes(true), json!({"mesh": 0}), 0),
        ),
        "not one the extension allows",
    );
    // Opacity above 1, negative scale.
    let mut bad = acc.clone();
    bad[3] = (5126, false, "SCALAR", 2, f32s(&[0.5, 1.5]));
    expect_err(
        &write(
            "a.gltf",
            hand_gltf(&bad, standard_attributes(true), json!({"mesh": 0}), 0),
        ),
        "outside 0..1",
    );
    let mut bad = acc.clone();
    bad[2] = (
        5126,
        false,
        "VEC3",
        2,
        f32s(&[1.0, -1.0, 1.0, 1.0, 1.0, 1.0]),
    );
    expect_err(
        &write(
            "s.gltf",
            hand_gltf(&bad, standard_attributes(true), json!({"mesh": 0}), 0),
        ),
        "negative scale",
    );
    // Count mismatch.
    let mut bad = acc.clone();
    bad[1] = (5126, false, "VEC4", 1, f32s(&[0.0, 0.0, 0.0, 1.0]));
    expect_err(
        &write(
            "c.gltf",
            hand_gltf(&bad, standard_attributes(true), json!({"mesh": 0}), 0),
        ),
        "POSITION has 2",
    );
    // A zero quaternion: refused naming the Gaussian.
    let mut bad = acc.clone();
    bad[1] = (5126, false, "VEC4", 2, f32s(&[0.0; 8]));
    expect_err(
        &write(
            "z.gltf",
            hand_gltf(&bad, standard_attributes(true), json!({"mesh": 0}), 0),
        ),
        "Gaussian 0",
    );
    // Another kernel.
    let text = hand_gltf(&acc, standard_attributes(true), json!({"mesh": 0}), 0)
        .replace("\"ellipse\"", "\"customShape\"");
    let err = read_gltf_gaussians(&write("k.gltf", text)).expect_err("kernel");
    assert!(
        matches!(err, GltfSplatError::Io(_)) && err.to_string().contains("customShape"),
        "{err}"
    );
    // A mesh glTF has no splats.
    let mesh = trisplat_fixtures::path("gltf/RiggedSimple.glb");
    assert!(!has_gaussian_splats(&mesh));
    expect_err(
        &mesh,
        "no primitive of the scene has the KHR_gaussian_splatting extension",
    );
    // Truncated and corrupted GLBs: errors, not panics.
    let bytes = glb_gaussians(&random_set(4, 1, 5), Path::new("x.glb")).expect("glb");
    let p = dir.path().join("cut.glb");
    for cut in (0..bytes.len()).step_by(7) {
        std::fs::write(&p, &bytes[..cut]).expect("w");
        assert!(read_gltf_gaussians(&p).is_err(), "cut at {cut}");
    }
}

#[test]
fn bound_and_empty_sets_are_not_written() {
    let set = random_set(2, 0, 3);
    let mut parts = set.clone().into_parts();
    parts.binding = Some(Binding {
        triangles: vec![TriId(0); 2],
        ..Binding::default()
    });
    parts.space = ParameterSpace::Local;
    let bound = GaussianSet::try_new(parts).expect("bound");
    let err = glb_gaussians(&bound, Path::new("b.glb")).expect_err("bound");
    assert!(err.to_string().contains("bound Gaussians"), "{err}");
    assert!(gltf_text_gaussians(&set.select(&[]), Path::new("e.gltf")).is_err());
    // The colour fallback: COLOR_0 is the sRGB-decoded DC colour and the opacity.
    let doc: Value =
        serde_json::from_str(&gltf_text_gaussians(&set, Path::new("c.gltf")).expect("text"))
            .expect("json");
    assert!(doc["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"].is_u64());
    let _ = sigmoid(0.0);
}
