//! SPZ files (docs/conventions.md §3, "SPZ"): the reference library's files read back to the
//! values it printed, our encoder's bytes equal to the reference's, round trips within the
//! format's quantisation (bounds derived from the layout below), axes, refusals and
//! robustness.
//!
//! `fixtures/data/reference/spz/` holds `reference_v{2,3,4}.spz`, written by nianticlabs/spz
//! (commit 21715c3) from the inputs in `reference_values.json`, and the values its `loadSpz`
//! returned (`to = RDF`); see that folder's README.

use std::path::Path;

use glam::{DQuat, Vec3};
use serde_json::Value;
use trisplat_geometry::TriId;
use trisplat_splat::Axes;
use trisplat_splat::spz::{
    OPAQUE_LOGIT, SpzError, SpzReadOptions, SpzWriteOptions, TRANSPARENT_LOGIT, decode_spz,
    encode_spz, read_spz,
};
use trisplat_splat::{Binding, GaussianParts, GaussianSet, ParameterSpace, ScaleDims};

fn fixture(name: &str) -> std::path::PathBuf {
    trisplat_fixtures::path(&format!("reference/spz/{name}"))
}

fn values() -> Value {
    let text = std::fs::read_to_string(fixture("reference_values.json")).expect("values");
    serde_json::from_str(&text).expect("json")
}

fn floats(v: &Value) -> Vec<Option<f32>> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().map(|f| f as f32))
        .collect()
}

/// The reference's `GaussianCloud` arrays (xyzw rotations, coefficient-major SH).
struct Cloud {
    n: usize,
    degree: u8,
    positions: Vec<Option<f32>>,
    scales: Vec<Option<f32>>,
    rotations: Vec<Option<f32>>,
    alphas: Vec<Option<f32>>,
    colors: Vec<Option<f32>>,
    sh: Vec<Option<f32>>,
}

fn cloud(v: &Value) -> Cloud {
    Cloud {
        n: v["numPoints"].as_u64().expect("n") as usize,
        degree: v["shDegree"].as_u64().expect("degree") as u8,
        positions: floats(&v["positions"]),
        scales: floats(&v["scales"]),
        rotations: floats(&v["rotations"]),
        alphas: floats(&v["alphas"]),
        colors: floats(&v["colors"]),
        sh: floats(&v["sh"]),
    }
}

/// The reference's input cloud as our set (its SH re-laid channel-major).
fn input_set(c: &Cloud) -> GaussianSet {
    let f = |v: &[Option<f32>], i: usize| v[i].expect("finite input");
    let k = (usize::from(c.degree) + 1).pow(2);
    let mut sh = Vec::new();
    for i in 0..c.n {
        sh.extend((0..3).map(|ch| f(&c.colors, 3 * i + ch)));
        for ch in 0..3 {
            for j in 0..k - 1 {
                sh.push(f(&c.sh, (i * (k - 1) + j) * 3 + ch));
            }
        }
    }
    GaussianSet::try_new(GaussianParts {
        means: (0..c.n)
            .map(|i| {
                Vec3::new(
                    f(&c.positions, 3 * i),
                    f(&c.positions, 3 * i + 1),
                    f(&c.positions, 3 * i + 2),
                )
            })
            .collect(),
        log_scales: (0..c.n)
            .map(|i| {
                Vec3::new(
                    f(&c.scales, 3 * i),
                    f(&c.scales, 3 * i + 1),
                    f(&c.scales, 3 * i + 2),
                )
            })
            .collect(),
        rotations: (0..c.n)
            .map(|i| {
                let q = |a| f(&c.rotations, 4 * i + a);
                [q(3), q(0), q(1), q(2)]
            })
            .collect(),
        opacity_logits: (0..c.n).map(|i| f(&c.alphas, i)).collect(),
        sh_degree: c.degree,
        sh,
        ..GaussianParts::default()
    })
    .expect("valid input")
}

/// Asserts that `set` equals the reference's decoded cloud value for value (`==` on f32, so
/// -0 equals 0), for the Gaussians `keep`; an alpha the reference decoded as ±infinity (stored
/// 0 or 255) must be our clamped logit of that sign.
fn assert_same(set: &GaussianSet, c: &Cloud, keep: &[usize], what: &str) {
    let k = (usize::from(c.degree) + 1).pow(2);
    assert_eq!(set.sh_degree(), c.degree);
    for (mine, &i) in keep.iter().enumerate() {
        let eq = |ours: f32, theirs: Option<f32>, field: &str| {
            assert_eq!(Some(ours), theirs, "{what}: Gaussian {i} {field}");
        };
        let m = set.means()[mine].to_array();
        let s = set.log_scales()[mine].to_array();
        let [w, x, y, z] = set.rotations()[mine];
        for a in 0..3 {
            eq(m[a], c.positions[3 * i + a], "position");
            eq(s[a], c.scales[3 * i + a], "log-scale");
        }
        for (a, v) in [x, y, z, w].into_iter().enumerate() {
            eq(v, c.rotations[4 * i + a], "rotation");
        }
        let logit = set.opacity_logits()[mine];
        match c.alphas[i] {
            Some(a) => eq(logit, Some(a), "opacity"),
            None => assert!(
                logit == OPAQUE_LOGIT || logit == TRANSPARENT_LOGIT,
                "{what}: Gaussian {i} saturated alpha read as {logit}"
            ),
        }
        let coeffs = set.sh_coeffs(mine);
        for ch in 0..3 {
            eq(coeffs[ch], c.colors[3 * i + ch], "colour");
            for j in 0..k - 1 {
                eq(
                    coeffs[3 + ch * (k - 1) + j],
                    c.sh[(i * (k - 1) + j) * 3 + ch],
                    "SH",
                );
            }
        }
    }
}

#[test]
fn reference_files_read_to_the_values_the_reference_decoded() {
    let v = values();
    for version in [2u32, 3, 4] {
        let file = read_spz(
            &fixture(&format!("reference_v{version}.spz")),
            &SpzReadOptions::default(),
        )
        .expect("reference file reads");
        assert_eq!(file.version, version);
        assert_eq!(file.fractional_bits, 12);
        assert!(file.antialiased);
        assert_eq!(file.stored_axes, Axes::Rub);
        let c = cloud(&v["decoded"][format!("v{version}")]);
        assert_eq!(file.gaussians.len(), c.n);
        let all: Vec<usize> = (0..c.n).collect();
        assert_same(&file.gaussians, &c, &all, &format!("v{version}"));
        // The two saturated alphas of the inputs (logit +20 and -20).
        assert_eq!(file.gaussians.opacity_logits()[0], OPAQUE_LOGIT);
        assert_eq!(file.gaussians.opacity_logits()[1], TRANSPARENT_LOGIT);
        assert_eq!(file.gaussians.opacity(0), 1.0);
        assert_eq!(file.gaussians.opacity(1), 0.0);
    }
}

#[test]
fn our_encoding_equals_the_references() {
    let v = values();
    let input = cloud(&v["input"]);
    // Gaussian 1 has y = -2048: in RUB +2048 = 2^23 / 2^12, one step past 24-bit fixed point.
    // The reference wraps it to -2048 (its decoded y is +2048 in RDF); we refuse, or use 11
    // fractional bits when free to choose. Every other Gaussian must come out identical.
    let set = input_set(&input);
    let keep: Vec<usize> = (0..input.n).filter(|&i| i != 1).collect();
    let subset = set.select(&keep);
    for version in [2u32, 3, 4] {
        let options = SpzWriteOptions {
            version,
            antialiased: true,
            ..SpzWriteOptions::default()
        };
        let bytes = encode_spz(&subset, Path::new("ours.spz"), &options).expect("encode");
        let back =
            decode_spz(&bytes, Path::new("ours.spz"), &SpzReadOptions::default()).expect("decode");
        assert_eq!(back.fractional_bits, 12);
        let c = cloud(&v["decoded"][format!("v{version}")]);
        assert_same(&back.gaussians, &c, &keep, &format!("ours v{version}"));
    }
    let fixed12 = SpzWriteOptions {
        fractional_bits: Some(12),
        ..SpzWriteOptions::default()
    };
    let err = encode_spz(&set, Path::new("x.spz"), &fixed12).expect_err("2048 does not fit");
    assert!(
        err.to_string().contains("Gaussian 1: coordinate 2048"),
        "{err}"
    );
    let bytes = encode_spz(&set, Path::new("x.spz"), &SpzWriteOptions::default()).expect("auto");
    let back = decode_spz(&bytes, Path::new("x.spz"), &SpzReadOptions::default()).expect("read");
    assert_eq!(back.fractional_bits, 11);
    assert_eq!(back.gaussians.means()[1].y, -2048.0);
}

/// A seeded set in the ranges SPZ stores without clamping.
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
            .push(Vec3::new(u(-9.5, 5.5), u(-9.5, 5.5), u(-9.5, 5.5)));
        parts
            .rotations
            .push([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
        parts.opacity_logits.push(u(-5.0, 5.0));
        for _ in 0..3 {
            parts.sh.push(u(-3.0, 3.0));
        }
        for _ in 0..3 * (k - 1) {
            parts.sh.push(u(-0.95, 0.95));
        }
    }
    GaussianSet::try_new(parts).expect("valid")
}

/// Rotation angle between two raw quaternions, radians.
fn angle(a: [f32; 4], b: [f32; 4]) -> f64 {
    let qa = trisplat_splat::normalize_wxyz(a).expect("a");
    let qb = trisplat_splat::normalize_wxyz(b).expect("b");
    2.0 * qa.dot(qb).abs().min(1.0).acos()
}

/// The largest error of the components a version stores: x, y, z with w >= 0 (version 2),
/// or the three other than the largest, with the largest made positive (versions 3-4).
fn stored_component_error(a: [f32; 4], b: [f32; 4], version: u32) -> f64 {
    let unit = |q: [f32; 4]| {
        let u = trisplat_splat::normalize_wxyz(q).expect("q");
        [u.x, u.y, u.z, u.w]
    };
    let (mut qa, mut qb) = (unit(a), unit(b));
    let pivot = if version == 2 {
        3
    } else {
        (0..4)
            .max_by(|&i, &j| qa[i].abs().total_cmp(&qa[j].abs()))
            .expect("4")
    };
    for q in [&mut qa, &mut qb] {
        if q[pivot] < 0.0 {
            q.iter_mut().for_each(|v| *v = -*v);
        }
    }
    (0..4)
        .filter(|&i| i != pivot)
        .map(|i| (qa[i] - qb[i]).abs())
        .fold(0.0, f64::max)
}

#[test]
fn round_trips_stay_within_the_quantisation() {
    // Bounds from the layout (fractionalBits 12, default SH bits 5 and 4):
    let position = 0.5 / 4096.0; // half a fixed-point step
    let log_scale = 0.5 / 16.0 + 1e-6; // half of 1/16 (+ f32 rounding of (s + 10) * 16)
    let opacity = 0.5 / 255.0 + 1e-6; // half an alpha step
    let dc = 0.5 / (0.15 * 255.0) + 1e-6; // half a colour step
    let sh1 = 4.5 / 128.0 + 1e-6; // 8-bit rounding (1/2) then buckets of 8 (4)
    let sh_rest = 8.5 / 128.0 + 1e-6; // 8-bit rounding then buckets of 16
    // Rotations: the stored components of the normalised quaternion within half a step:
    // version 2 stores x, y, z of the quaternion with w >= 0 in steps of 1/127.5 (w follows
    // from unit length, so its error grows as w -> 0); versions 3-4 store the three smallest
    // components (each at most 1/√2) in steps of (1/√2)/511 and the largest (at least 1/2)
    // follows, so the rotation angle 2 acos|q·q'| stays within 2 · 2 · √3 · step / 2.
    let component_v2 = 0.5 / 127.5 + 1e-6;
    let component_v3 = 0.5 * std::f64::consts::FRAC_1_SQRT_2 / 511.0 + 1e-6;
    let angle_v3 = 2.0 * 3f64.sqrt() * component_v3 * 2.0;
    let set = random_set(2000, 3, 7);
    let mut report = String::new();
    for version in [2u32, 3, 4] {
        let bytes = encode_spz(
            &set,
            Path::new("r.spz"),
            &SpzWriteOptions {
                version,
                ..SpzWriteOptions::default()
            },
        )
        .expect("encode");
        let back = decode_spz(&bytes, Path::new("r.spz"), &SpzReadOptions::default())
            .expect("decode")
            .gaussians;
        let mut worst = [0.0f64; 8];
        for i in 0..set.len() {
            let d = (set.means()[i] - back.means()[i]).abs().max_element();
            worst[0] = worst[0].max(f64::from(d));
            let d = (set.log_scales()[i] - back.log_scales()[i])
                .abs()
                .max_element();
            worst[1] = worst[1].max(f64::from(d));
            worst[2] = worst[2].max(f64::from((set.opacity(i) - back.opacity(i)).abs()));
            let (a, b) = (set.sh_coeffs(i), back.sh_coeffs(i));
            for j in 0..a.len() {
                let d = f64::from((a[j] - b[j]).abs());
                let slot = if j < 3 {
                    3
                } else {
                    let coef = (j - 3) % 15;
                    if coef < 3 { 4 } else { 5 }
                };
                worst[slot] = worst[slot].max(d);
            }
            worst[6] = worst[6].max(angle(set.rotations()[i], back.rotations()[i]));
            worst[7] = worst[7].max(stored_component_error(
                set.rotations()[i],
                back.rotations()[i],
                version,
            ));
        }
        let (component, rot) = if version == 2 {
            (component_v2, f64::INFINITY)
        } else {
            (component_v3, angle_v3)
        };
        let bounds = [
            position, log_scale, opacity, dc, sh1, sh_rest, rot, component,
        ];
        let names = [
            "position",
            "log-scale",
            "opacity",
            "dc",
            "sh1",
            "sh2-3",
            "rotation angle (rad)",
            "stored quaternion component",
        ];
        for ((w, b), name) in worst.iter().zip(bounds).zip(names) {
            assert!(w <= &b, "v{version} {name}: {w} > {b}");
            report.push_str(&format!("v{version} {name}: max {w:.3e} (bound {b:.3e})\n"));
        }
    }
    println!("{report}");
    // 8 bits for the SH: half a 1/128 step.
    let bytes = encode_spz(
        &set,
        Path::new("r.spz"),
        &SpzWriteOptions {
            sh1_bits: 8,
            sh_rest_bits: 8,
            ..SpzWriteOptions::default()
        },
    )
    .expect("encode");
    let back = decode_spz(&bytes, Path::new("r.spz"), &SpzReadOptions::default())
        .expect("decode")
        .gaussians;
    let worst = set
        .sh()
        .iter()
        .zip(back.sh())
        .enumerate()
        .filter(|(j, _)| j % 48 >= 3)
        .map(|(_, (a, b))| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst <= 0.5 / 128.0 + 1e-6, "8-bit SH: {worst}");
}

#[test]
fn written_files_store_rub_and_read_back_in_the_axes_asked() {
    let set = random_set(50, 1, 3);
    let bytes = encode_spz(&set, Path::new("a.spz"), &SpzWriteOptions::default()).expect("encode");
    let stored = decode_spz(&bytes, Path::new("a.spz"), &SpzReadOptions { axes: None })
        .expect("decode")
        .gaussians;
    let back = decode_spz(&bytes, Path::new("a.spz"), &SpzReadOptions::default())
        .expect("decode")
        .gaussians;
    for i in 0..set.len() {
        // RDF -> RUB negates y and z; the reader undoes it exactly.
        let (s, b) = (stored.means()[i], back.means()[i]);
        assert_eq!(s, Vec3::new(b.x, -b.y, -b.z));
        let [w, x, y, z] = back.rotations()[i];
        assert_eq!(stored.rotations()[i], [w, x, -y, -z]);
        // Degree 1: Y = (-C1 y, C1 z, -C1 x) -> the first two flip.
        let (cs, cb) = (stored.sh_coeffs(i), back.sh_coeffs(i));
        for ch in 0..3 {
            assert_eq!(cs[ch], cb[ch]);
            assert_eq!(cs[3 + ch * 3], -cb[3 + ch * 3]);
            assert_eq!(cs[3 + ch * 3 + 1], -cb[3 + ch * 3 + 1]);
            assert_eq!(cs[3 + ch * 3 + 2], cb[3 + ch * 3 + 2]);
        }
    }
    // Written with no axes: stored as given.
    let raw = encode_spz(
        &set,
        Path::new("a.spz"),
        &SpzWriteOptions {
            axes: None,
            ..SpzWriteOptions::default()
        },
    )
    .expect("encode");
    let same = decode_spz(&raw, Path::new("a.spz"), &SpzReadOptions { axes: None })
        .expect("decode")
        .gaussians;
    for (a, b) in set.means().iter().zip(same.means()) {
        assert!((*a - *b).abs().max_element() <= 0.5 / 4096.0, "{a} {b}");
    }
    // A version-4 file that names its axes (SPZ_ADOBE_coordinate_system = RDF): its stored
    // values are RDF already, so reading as RDF changes nothing.
    let v4 = encode_spz(
        &set,
        Path::new("a.spz"),
        &SpzWriteOptions {
            axes: None,
            version: 4,
            ..SpzWriteOptions::default()
        },
    )
    .expect("encode");
    let mut tagged = v4[..32].to_vec();
    tagged[14] |= 0x2;
    tagged[16..20].copy_from_slice(&(32u32 + 12).to_le_bytes());
    tagged.extend_from_slice(&0xADBE_0003u32.to_le_bytes());
    tagged.extend_from_slice(&4u32.to_le_bytes());
    tagged.extend_from_slice(&Axes::Rdf.id().to_le_bytes());
    tagged.extend_from_slice(&v4[32..]);
    let file = decode_spz(&tagged, Path::new("t.spz"), &SpzReadOptions::default()).expect("tagged");
    assert_eq!(file.stored_axes, Axes::Rdf);
    assert_eq!(file.gaussians, same);
    // ... and reading it into RUB flips it.
    let rub = decode_spz(
        &tagged,
        Path::new("t.spz"),
        &SpzReadOptions {
            axes: Some(Axes::Rub),
        },
    )
    .expect("tagged")
    .gaussians;
    assert_eq!(rub.means()[0].y, -same.means()[0].y);
    // Unknown extension records are skipped and listed; an unknown axes id is an error.
    let mut other = tagged.clone();
    other[32..36].copy_from_slice(&0x1234_0001u32.to_le_bytes());
    let file = decode_spz(&other, Path::new("o.spz"), &SpzReadOptions::default()).expect("other");
    assert_eq!(file.skipped_extensions, vec![0x1234_0001]);
    let mut bad = tagged.clone();
    bad[40..44].copy_from_slice(&17u32.to_le_bytes());
    let err = decode_spz(&bad, Path::new("b.spz"), &SpzReadOptions::default()).expect_err("17");
    assert!(
        err.to_string().contains("unknown coordinate system 17"),
        "{err}"
    );
}

#[test]
fn hand_made_version_3_bytes_decode_as_the_layout_says() {
    // One Gaussian, degree 0, 12 fractional bits, stored axes read as they are.
    let mut raw = Vec::new();
    raw.extend_from_slice(&0x5053_474eu32.to_le_bytes());
    raw.extend_from_slice(&3u32.to_le_bytes());
    raw.extend_from_slice(&1u32.to_le_bytes());
    raw.extend_from_slice(&[0, 12, 0, 0]);
    // x = 1.5 (6144 = 0x001800), y = -1/4096 (0xFFFFFF), z = 0.
    raw.extend_from_slice(&[0x00, 0x18, 0x00, 0xFF, 0xFF, 0xFF, 0, 0, 0]);
    raw.push(51); // alpha: 51/255 = 0.2
    raw.extend_from_slice(&[128, 0, 255]); // colours
    raw.extend_from_slice(&[160, 0, 255]); // scales: 160/16 - 10 = 0, -10, 5.9375
    // Smallest three: largest w (index 3); x = -(1/√2)(511/511), y = z = 0.
    let comp: u32 = (3 << 30) | (((1 << 9) | 511) << 20);
    raw.extend_from_slice(&comp.to_le_bytes());
    let set = decode_spz(
        &gzip(&raw),
        Path::new("h.spz"),
        &SpzReadOptions { axes: None },
    )
    .expect("decode")
    .gaussians;
    assert_eq!(set.means()[0], Vec3::new(1.5, -1.0 / 4096.0, 0.0));
    assert!((set.opacity(0) - 0.2).abs() < 1e-6);
    assert_eq!(set.sh_coeffs(0)[0], (128.0f32 / 255.0 - 0.5) / 0.15);
    assert_eq!(set.sh_coeffs(0)[1], -0.5 / 0.15);
    assert_eq!(set.log_scales()[0], Vec3::new(0.0, -10.0, 5.9375));
    let q = set.rotation(0);
    let expect = DQuat::from_xyzw(
        -std::f64::consts::FRAC_1_SQRT_2,
        0.0,
        0.0,
        std::f64::consts::FRAC_1_SQRT_2,
    );
    assert!(q.dot(expect).abs() > 1.0 - 1e-6, "{q}");
}

/// A gzip stream of `raw`.
fn gzip(raw: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(raw).expect("gzip");
    e.finish().expect("gzip")
}

#[test]
fn refusals_name_the_problem() {
    let set = random_set(3, 0, 1);
    let p = Path::new("w.spz");
    // Bound sets.
    let mut parts = set.clone().into_parts();
    parts.binding = Some(Binding {
        triangles: vec![TriId(0); 3],
        ..Binding::default()
    });
    parts.space = ParameterSpace::Local;
    let bound = GaussianSet::try_new(parts).expect("bound");
    let err = encode_spz(&bound, p, &SpzWriteOptions::default()).expect_err("bound");
    assert!(matches!(err, SpzError::Unrepresentable { .. }));
    assert!(err.to_string().contains("bound Gaussians"), "{err}");
    // Empty sets, bad versions and SH bits.
    let empty = set.select(&[]);
    assert!(encode_spz(&empty, p, &SpzWriteOptions::default()).is_err());
    for version in [1, 5] {
        let o = SpzWriteOptions {
            version,
            ..SpzWriteOptions::default()
        };
        assert!(encode_spz(&set, p, &o).is_err(), "version {version}");
    }
    let o = SpzWriteOptions {
        sh1_bits: 0,
        ..SpzWriteOptions::default()
    };
    assert!(encode_spz(&set, p, &o).is_err());
    // Beyond the fixed point's range whatever the bits.
    let mut parts = set.clone().into_parts();
    parts.means[2].z = 9.0e6;
    let far = GaussianSet::try_new(parts).expect("far");
    let err = encode_spz(&far, p, &SpzWriteOptions::default()).expect_err("far");
    assert!(err.to_string().contains("Gaussian 2"), "{err}");
    // Surfels: the flat axis stored as the smallest scale.
    let mut parts = set.clone().into_parts();
    parts.scale_dims = ScaleDims::Two;
    let surfels = GaussianSet::try_new(parts).expect("surfels");
    let bytes = encode_spz(&surfels, p, &SpzWriteOptions::default()).expect("surfels");
    let back = decode_spz(&bytes, p, &SpzReadOptions::default()).expect("read");
    assert!(back.gaussians.log_scales().iter().all(|l| l.z == -10.0));
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let p = Path::new("bad.spz");
    let o = SpzReadOptions::default();
    for version in [2, 3, 4] {
        let bytes = std::fs::read(fixture(&format!("reference_v{version}.spz"))).expect("fixture");
        for cut in 0..bytes.len() {
            assert!(
                decode_spz(&bytes[..cut], p, &o).is_err(),
                "v{version} cut at {cut}"
            );
        }
        for at in 0..bytes.len() {
            for flip in [0x01u8, 0x80, 0xFF] {
                let mut m = bytes.clone();
                m[at] ^= flip;
                let _ = decode_spz(&m, p, &o);
            }
        }
    }
    // Uncompressed payloads: truncated arrays, huge counts, bad fields.
    let set = random_set(4, 2, 9);
    let ours = encode_spz(&set, p, &SpzWriteOptions::default()).expect("encode");
    assert!(decode_spz(&ours, p, &o).is_ok());
    let mut payload = Vec::new();
    payload.extend_from_slice(&0x5053_474eu32.to_le_bytes());
    payload.extend_from_slice(&3u32.to_le_bytes());
    payload.extend_from_slice(&4u32.to_le_bytes());
    payload.extend_from_slice(&[2, 12, 0, 0]);
    payload.extend(std::iter::repeat_n(7u8, 4 * (9 + 1 + 3 + 3 + 4 + 24)));
    let wrap = gzip;
    assert!(decode_spz(&wrap(&payload), p, &o).is_ok());
    for cut in 0..payload.len() {
        let err = decode_spz(&wrap(&payload[..cut]), p, &o).expect_err("truncated payload");
        let text = err.to_string();
        assert!(text.starts_with("bad.spz: "), "{text}");
    }
    let cases: [(usize, &[u8], &str); 6] = [
        (8, &u32::MAX.to_le_bytes(), "numPoints"),
        (8, &1_000_000u32.to_le_bytes(), "numPoints"),
        (4, &9u32.to_le_bytes(), "version 9"),
        (12, &[4], "SH degree 4"),
        (12, &[7], "shDegree 7"),
        (13, &[40], "fractionalBits 40"),
    ];
    for (at, value, expect) in cases {
        let mut m = payload.clone();
        m[at..at + value.len()].copy_from_slice(value);
        let err = decode_spz(&wrap(&m), p, &o).expect_err(expect);
        assert!(err.to_string().contains(expect), "{err} lacks {expect}");
    }
    // Version-4 table of contents lying about sizes.
    let v4 = encode_spz(
        &set,
        p,
        &SpzWriteOptions {
            version: 4,
            ..SpzWriteOptions::default()
        },
    )
    .expect("v4");
    for (at, value) in [
        (15usize, 9u8),
        (16, 200),
        (32, 0xFF),
        (40, 0x01),
        (40, 0xFF),
    ] {
        let mut m = v4.clone();
        m[at] = value;
        assert!(decode_spz(&m, p, &o).is_err(), "byte {at} = {value}");
    }
    assert!(decode_spz(b"not spz at all", p, &o).is_err());
    assert!(decode_spz(&[], p, &o).is_err());
}
