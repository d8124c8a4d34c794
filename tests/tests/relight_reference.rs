//! Relighting (docs/conventions.md §5 "Relighting") against an independent numpy implementation
//! of the split sum and against OpenCV's Radiance reader (`tests/reference/ref_relight.py`,
//! numpy 2.4.6, opencv-python-headless 4.14.0.94; fixtures `relight/esplanade_64x32.hdr`, a
//! CC0 map downsampled, and `relight/split_sum.json`), the white furnace, and bad input.

use serde_json::Value;
use trisplat_geometry::envmap::EnvMap;
use trisplat_geometry::glam::DVec3;
use trisplat_splat::material::{EnvOptions, Environment};

/// Largest difference from numpy's float64 split sum, relative to `max(1, |reference|)`: the
/// Rust side keeps the prefiltered maps and the table in f32.
const SPLIT_SUM_TOL: f64 = 1e-4;

fn vec3(v: &Value) -> DVec3 {
    let a: Vec<f64> = v
        .as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    DVec3::new(a[0], a[1], a[2])
}

fn close(got: f64, want: f64, what: &str) {
    let err = (got - want).abs() / want.abs().max(1.0);
    assert!(
        err <= SPLIT_SUM_TOL,
        "{what}: {got} vs {want} (error {err:.2e})"
    );
}

#[test]
fn split_sum_matches_numpy_and_the_reader_matches_opencv() {
    let doc: Value = serde_json::from_str(
        &std::fs::read_to_string(trisplat_fixtures::path("relight/split_sum.json"))
            .expect("fixture"),
    )
    .expect("json");
    let map = EnvMap::read(&trisplat_fixtures::path("relight/esplanade_64x32.hdr")).expect("map");
    assert_eq!(u64::from(map.width()), doc["width"].as_u64().unwrap());
    assert_eq!(u64::from(map.height()), doc["height"].as_u64().unwrap());
    let texels = doc["texels_opencv"].as_array().unwrap();
    for (k, (t, r)) in map.texels().iter().zip(texels).enumerate() {
        let r = vec3(r);
        for c in 0..3 {
            // Both decode the same RGBE bytes: exactly equal.
            assert_eq!(f64::from(t[c]), r[c], "texel {k} channel {c}");
        }
    }
    let started = std::time::Instant::now();
    let env = Environment::new(
        &map,
        EnvOptions {
            rotation_deg: doc["rotation_deg"].as_f64().unwrap(),
            intensity: doc["intensity"].as_f64().unwrap() as f32,
        },
    )
    .expect("environment");
    println!(
        "environment prepared in {:.1} ms",
        started.elapsed().as_secs_f64() * 1e3
    );
    let mut worst = 0.0f64;
    for (i, rec) in doc["records"].as_array().unwrap().iter().enumerate() {
        let n = vec3(&rec["normal"]);
        let v = vec3(&rec["view"]);
        let albedo = vec3(&rec["albedo"]).as_vec3().to_array();
        let roughness = rec["roughness"].as_f64().unwrap() as f32;
        let f0 = rec["f0"].as_f64().unwrap() as f32;
        let ab = rec["ab"].as_array().unwrap();
        let n_dot_v = n.dot(v).clamp(0.0, 1.0) as f32;
        let got_ab = env.brdf().lookup(n_dot_v, roughness);
        for k in 0..2 {
            close(
                f64::from(got_ab[k]),
                ab[k].as_f64().unwrap(),
                &format!("record {i} A/B {k}"),
            );
        }
        let s = env.shade(n, v, albedo, roughness, f0);
        let (color, spec) = (vec3(&rec["color"]), vec3(&rec["specular"]));
        for c in 0..3 {
            close(
                f64::from(s.color[c]),
                color[c],
                &format!("record {i} colour {c}"),
            );
            close(
                f64::from(s.specular[c]),
                spec[c],
                &format!("record {i} specular {c}"),
            );
            worst = worst.max((f64::from(s.color[c]) - color[c]).abs() / color[c].abs().max(1.0));
        }
    }
    println!("largest colour difference from numpy: {worst:.2e}");
}

/// Uniform radiance 1: a white albedo with F0 = 0 gives 1 at any roughness and angle (within
/// 1%); a black albedo with F0 = 1 gives the lobe's directional albedo A + B, which the
/// single-scattering split sum keeps below 1 (the energy loss printed here and stated in
/// docs/conventions.md §5).
#[test]
fn white_furnace() {
    let map = EnvMap::uniform(32, [1.0; 3]).unwrap();
    let env = Environment::new(&map, EnvOptions::default()).unwrap();
    let n = DVec3::new(0.3, 0.8, -0.52).normalize();
    let mut min_ab = [f32::INFINITY; 21];
    for (k, min_k) in min_ab.iter_mut().enumerate() {
        let roughness = k as f32 / 20.0;
        for j in 0..=10 {
            let angle = f64::from(j) / 10.0 * 1.5;
            let tangent = n.any_orthonormal_vector();
            let v = (n * angle.cos() + tangent * angle.sin()).normalize();
            let white = env.shade(n, v, [1.0; 3], roughness, 0.0).color;
            assert!(
                white.iter().all(|c| (c - 1.0).abs() < 0.01),
                "r {roughness} angle {angle}: {white:?}"
            );
            let mirror = env.shade(n, v, [0.0; 3], roughness, 1.0).color;
            let [a, b] = env.brdf().lookup(n.dot(v) as f32, roughness);
            assert!((mirror[0] - (a + b)).abs() < 1e-5);
            assert!(mirror[0] <= 1.0 + 1e-3, "never more than 1: {mirror:?}");
            if angle <= 1.05 {
                *min_k = min_k.min(mirror[0]);
            }
            if roughness <= 0.25 && angle <= 1.0 {
                assert!(
                    mirror[0] > 0.9,
                    "smooth lobes lose little: {roughness} {mirror:?}"
                );
            }
        }
    }
    // Up to 60 degrees from the normal, per roughness: what the split sum's single scattering
    // keeps of a white mirror's light (docs/conventions.md §5).
    let table: Vec<String> = [0, 5, 10, 15, 20]
        .iter()
        .map(|&k| format!("r {:.2}: {:.3}", k as f32 / 20.0, min_ab[k]))
        .collect();
    println!(
        "F0 = 1 furnace, smallest A + B up to 60 degrees: {}",
        table.join(", ")
    );
    assert!(min_ab[0] > 0.95 && min_ab[5] > 0.9 && min_ab[20] > 0.3);
}

#[test]
fn bad_maps_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let err = |p: &std::path::Path| EnvMap::read(p).unwrap_err().to_string();
    let p = write("not.hdr", b"P3\n1 1\n255\n0 0 0\n");
    assert!(err(&p).contains("not.hdr") && err(&p).contains("not a Radiance HDR file"));
    let mut wide = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 3\n".to_vec();
    wide.extend([128u8; 24]);
    let p = write("square.hdr", &wide);
    assert!(
        err(&p).contains("square.hdr") && err(&p).contains("2:1"),
        "{}",
        err(&p)
    );
    let p = write(
        "missing_rows.hdr",
        b"#?RADIANCE\n\n-Y 4 +X 8\n\x02\x02\x00\x08",
    );
    assert!(err(&p).contains("missing_rows.hdr"), "{}", err(&p));
    assert!(err(&dir.path().join("absent.hdr")).contains("absent.hdr"));
    // Radiance that is negative or NaN never comes out of RGBE, but maps made otherwise (or
    // scaled) are checked too.
    assert!(EnvMap::try_new(4, 2, vec![[f32::NAN, 0.0, 0.0]; 8]).is_err());
    assert!(EnvMap::uniform(2, [1.0; 3]).unwrap().scaled(-1.0).is_err());
}
