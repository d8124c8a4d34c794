//! Relit shading and its backward pass against torch (`tests/reference/ref_relight_torch.py`,
//! torch 2.15.0 on the CPU in float64, autograd; fixture `relight/split_sum_torch.json` on the
//! CC0 map `relight/esplanade_64x32.hdr`): per Gaussian the colour through its shortest-axis
//! normal, and the gradient of `Σ g · colour` with respect to albedo, roughness, F0, the raw
//! quaternion and the mean; and (fixture `relight/split_sum_env_torch.json`) the gradient of the
//! same loss with respect to every texel of the map, through its preparation.

mod reference_json;

use reference_json::floats;
use serde_json::Value;
use trisplat_geometry::envmap::EnvMap;
use trisplat_geometry::glam::DVec3;
use trisplat_splat::material::{
    EnvGrad, EnvOptions, Environment, Material, relit_backward, relit_env_backward, shade_params,
};
use trisplat_splat::render::{GaussianGrads, GaussianParams};

/// The forward: colours within 1e-4 of torch's float64, relative to `max(1, |c|)` (the Rust side
/// keeps the maps and the table in f32; observed 7e-8).
const FORWARD_TOL: f64 = 1e-4;

/// The backward: every gradient within 1e-4 of torch's, relative to `max(1, |g|)` (f32 lookups
/// and interpolation weights; observed 1.4e-6).
const BACKWARD_TOL: f64 = 1e-4;

fn f32s<const N: usize>(v: &Value) -> [f32; N] {
    let a = floats(v);
    std::array::from_fn(|k| a[k] as f32)
}

fn check(got: f64, want: f64, tol: f64, what: &str) -> f64 {
    let err = (got - want).abs() / want.abs().max(1.0);
    assert!(
        err <= tol,
        "{what}: {got} vs torch {want} (error {err:.2e})"
    );
    err
}

/// The fixture's environment, eye, Gaussians, materials and colour gradients.
struct Case {
    doc: Value,
    map: EnvMap,
    options: EnvOptions,
    env: Environment,
    eye: DVec3,
    params: GaussianParams,
    material: Material,
    g: Vec<[f32; 3]>,
}

fn case() -> Case {
    let doc: Value = serde_json::from_str(
        &std::fs::read_to_string(trisplat_fixtures::path("relight/split_sum_torch.json"))
            .expect("fixture"),
    )
    .expect("json");
    let map = EnvMap::read(&trisplat_fixtures::path("relight/esplanade_64x32.hdr")).expect("map");
    let options = EnvOptions {
        rotation_deg: doc["rotation_deg"].as_f64().unwrap(),
        intensity: doc["intensity"].as_f64().unwrap() as f32,
    };
    let env = Environment::new(&map, options).unwrap();
    let eye = {
        let e = floats(&doc["eye"]);
        DVec3::new(e[0], e[1], e[2])
    };
    let records = doc["records"].as_array().unwrap();
    let n = records.len();
    let mut params = GaussianParams {
        sh_degree: 0,
        sh: vec![0.0; 3 * n],
        opacity_logits: vec![0.0; n],
        ..GaussianParams::default()
    };
    let mut material = Material::default();
    let mut g = Vec::new();
    for r in records {
        let f = floats(&r["rotation"]);
        params.rotations.push([f[0], f[1], f[2], f[3]]);
        let f = floats(&r["log_scales"]);
        params.log_scales.push([f[0], f[1], f[2]]);
        let f = floats(&r["mean"]);
        params.means.push([f[0], f[1], f[2]]);
        material.albedo.push(f32s::<3>(&r["albedo"]));
        material
            .roughness
            .push(r["roughness"].as_f64().unwrap() as f32);
        material.f0.push(r["f0"].as_f64().unwrap() as f32);
        g.push(f32s::<3>(&r["g"]));
    }
    Case {
        doc,
        map,
        options,
        env,
        eye,
        params,
        material,
        g,
    }
}

#[test]
fn relit_forward_and_backward_match_torch() {
    let Case {
        doc,
        env,
        eye,
        params,
        material,
        g,
        ..
    } = case();
    let records = doc["records"].as_array().unwrap();
    let n = records.len();
    let relit = shade_params(&params, &material, eye, &env);
    let mut geometry = GaussianGrads::zeros(n, 0);
    let grads = relit_backward(&params, &material, eye, &env, &g, &mut geometry);
    let (mut fwd, mut bwd) = (0.0f64, 0.0f64);
    for (i, r) in records.iter().enumerate() {
        for (c, want) in floats(&r["color"]).into_iter().enumerate() {
            let e = check(
                f64::from(relit.colors[i][c]),
                want,
                FORWARD_TOL,
                &format!("record {i} colour {c}"),
            );
            fwd = fwd.max(e);
        }
        let mut pairs: Vec<(f64, f64, String)> = Vec::new();
        for (c, want) in floats(&r["d_albedo"]).into_iter().enumerate() {
            pairs.push((f64::from(grads.albedo[i][c]), want, format!("albedo {c}")));
        }
        pairs.push((
            f64::from(grads.roughness[i]),
            r["d_roughness"].as_f64().unwrap(),
            "roughness".into(),
        ));
        pairs.push((
            f64::from(grads.f0[i]),
            r["d_f0"].as_f64().unwrap(),
            "F0".into(),
        ));
        for (k, want) in floats(&r["d_rotation"]).into_iter().enumerate() {
            pairs.push((geometry.rotations[i][k], want, format!("quaternion {k}")));
        }
        for (k, want) in floats(&r["d_mean"]).into_iter().enumerate() {
            pairs.push((geometry.means[i][k], want, format!("mean {k}")));
        }
        for (got, want, what) in pairs {
            bwd = bwd.max(check(
                got,
                want,
                BACKWARD_TOL,
                &format!("record {i} {what}"),
            ));
        }
    }
    println!("largest relative error: forward {fwd:.2e}, backward {bwd:.2e}");
}

/// The gradient with respect to the map's 64 × 32 × 3 texels within 1e-4 of torch's, relative
/// to the largest (f32 maps and lookup weights on the Rust side).
#[test]
fn the_environment_gradient_matches_torch() {
    let c = case();
    let want: Value = serde_json::from_str(
        &std::fs::read_to_string(trisplat_fixtures::path("relight/split_sum_env_torch.json"))
            .expect("fixture"),
    )
    .expect("json");
    let want = floats(&want["d_texels"]);
    let mut acc = EnvGrad::zeros(&c.env);
    relit_env_backward(&c.params, &c.material, c.eye, &c.env, &c.g, &mut acc);
    let got = acc.to_texels(&c.map, c.options);
    assert_eq!(got.len() * 3, want.len());
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.01, "a degenerate fixture");
    let worst = got
        .iter()
        .flatten()
        .zip(&want)
        .map(|(g, w)| (g - w).abs())
        .fold(0.0f64, f64::max);
    assert!(worst <= 1e-4 * scale, "worst {worst:.3e} of {scale}");
    println!("environment gradient: worst {worst:.2e} of {scale:.3}");
}
