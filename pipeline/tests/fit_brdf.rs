//! `pipeline::fit::fit_brdf` (`trisplat fit --appearance brdf`) on a synthetic avatar with known
//! materials: a sphere of flat bound Gaussians with spatially varying albedo, roughness and F0,
//! rendered under the CC0 fixture map (`relight/esplanade_64x32.hdr`) from a ring of cameras,
//! then fitted back from default materials and rotations turned by 17° to 57° about random axes: the albedo maps'
//! LMSE and the normal maps' cosine similarity on held-out views (HRAvatar's Table 3 scores,
//! `pipeline::fit::material_scores`). The `#[ignore]`d variant is the benchmark of
//! docs/benchmarks.md.

use std::time::Instant;

use glam::{DQuat, DVec3};
use trisplat_geometry::envmap::EnvMap;
use trisplat_geometry::rng::Rng;
use trisplat_geometry::{Camera, TriMesh};
use trisplat_pipeline::fit::{
    BrdfFitOptions, CommonOptions, EnvFit, FitFrame, MaterialScores, Target, fit_brdf,
    material_scores,
};
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, to_world};
use trisplat_splat::material::{EnvOptions, Environment, Material, normal_of, shade_params};
use trisplat_splat::render::{GaussianParams, RenderOptions, render_with_grad};
use trisplat_splat::{BindOptions, GaussianSet, init_bound, rgb_to_dc};

/// A UV sphere of radius 1 (`rings` × `segments`).
fn sphere(rings: u32, segments: u32) -> TriMesh {
    let mut p = vec![DVec3::Y];
    for r in 1..rings {
        let t = std::f64::consts::PI * f64::from(r) / f64::from(rings);
        for s in 0..segments {
            let f = 2.0 * std::f64::consts::PI * f64::from(s) / f64::from(segments);
            p.push(DVec3::new(t.sin() * f.cos(), t.cos(), t.sin() * f.sin()));
        }
    }
    p.push(DVec3::NEG_Y);
    let bottom = p.len() as u32 - 1;
    let at = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
    let mut tris = Vec::new();
    for s in 0..segments {
        tris.push([0, at(1, s + 1), at(1, s)]);
        tris.push([bottom, at(rings - 1, s), at(rings - 1, s + 1)]);
        for r in 1..rings - 1 {
            tris.push([at(r, s), at(r, s + 1), at(r + 1, s)]);
            tris.push([at(r, s + 1), at(r + 1, s + 1), at(r + 1, s)]);
        }
    }
    TriMesh::try_new(p, tris).unwrap()
}

/// The avatar: flat Gaussians (thin along their triangle's normal) with known materials, and
/// the initial set to fit: the same Gaussians turned by random rotations, without materials.
fn avatar(mesh: &TriMesh, per_triangle: usize, seed: u64) -> (GaussianSet, GaussianSet) {
    let set = init_bound(
        mesh,
        &BindOptions {
            per_triangle,
            opacity: 0.9,
            ..BindOptions::default()
        },
    )
    .unwrap();
    let frames = TriangleFrames::binding(mesh, mesh.positions());
    let tri = |i: usize| set.binding().unwrap().triangles[i].index();
    let mut parts = set.clone().into_parts();
    let mut rng = Rng::new(seed);
    let mut material = Material::default();
    for i in 0..parts.means.len() {
        let t = tri(i);
        let [a, b, c] = mesh.triangles()[t].map(|v| mesh.positions()[v as usize]);
        let normal = (b - a).cross(c - a).normalize();
        let local = frames.rotation[t].transpose() * normal;
        let axis = (0..3)
            .max_by(|&x, &y| local[x].abs().total_cmp(&local[y].abs()))
            .unwrap();
        let s = &mut parts.log_scales[i];
        s[axis] -= 2.5;
        let p = (frames.rotation[t] * parts.means[i].as_dvec3() * frames.scale[t]
            + frames.origin[t])
            .as_vec3();
        material.albedo.push([
            0.5 + 0.35 * (3.0 * p.x).sin(),
            0.5 + 0.35 * (2.5 * p.y).cos(),
            0.45 + 0.3 * (2.0 * p.z + 1.0).sin(),
        ]);
        material
            .roughness
            .push(0.45 + 0.3 * (4.0 * p.y + p.x).sin());
        material.f0.push(0.2 + 0.15 * (3.0 * p.x).cos());
    }
    let mut init = parts.clone();
    parts.material = Some(material);
    for q in &mut init.rotations {
        let axis = DVec3::new(
            rng.uniform_f64() - 0.5,
            rng.uniform_f64() - 0.5,
            rng.uniform_f64() - 0.5,
        )
        .normalize();
        let turn = DQuat::from_axis_angle(axis, 0.3 + 0.7 * rng.uniform_f64());
        let local = DQuat::from_xyzw(
            f64::from(q[1]),
            f64::from(q[2]),
            f64::from(q[3]),
            f64::from(q[0]),
        );
        let r = local * turn;
        *q = [r.w as f32, r.x as f32, r.y as f32, r.z as f32];
    }
    // No materials: grey albedo from the SH colour, roughness 0.9, F0 0.04.
    for c in &mut init.sh {
        *c = rgb_to_dc(0.5);
    }
    (
        GaussianSet::try_new(parts).unwrap(),
        GaussianSet::try_new(init).unwrap(),
    )
}

fn cameras(count: usize, size: u32, offset: f64, prefix: &str) -> Vec<Camera> {
    (0..count)
        .map(|k| {
            let a = 2.0 * std::f64::consts::PI * (k as f64 + offset) / count as f64;
            let eye = DVec3::new(3.2 * a.cos(), 1.2 * (2.0 * a).sin(), 3.2 * a.sin());
            Camera::look_at(
                format!("{prefix}{k}"),
                eye,
                DVec3::ZERO,
                DVec3::NEG_Y,
                (size, size),
                45.0,
            )
            .unwrap()
        })
        .collect()
}

/// The true light's placement (the fitted map is placed the same way).
const ENV_OPTIONS: EnvOptions = EnvOptions {
    rotation_deg: 20.0,
    intensity: 0.8,
};

fn environment_map() -> EnvMap {
    EnvMap::read(&trisplat_fixtures::path("relight/esplanade_64x32.hdr")).unwrap()
}

fn environment() -> Environment {
    Environment::new(&environment_map(), ENV_OPTIONS).unwrap()
}

/// The fitted map against the true one downsampled to its width: the relative RMS error of
/// `s F` against `T` (solid-angle weighted, all channels), `s = ⟨F, T⟩ / ⟨F, F⟩` the one factor
/// that albedo and light share (the split sum cannot tell them apart), and `s`.
fn env_error(fitted: &EnvMap, truth: &EnvMap) -> (f64, f64) {
    let truth = truth.downsampled(fitted.width());
    let (mut ft, mut ff, mut tt) = (0.0f64, 0.0f64, 0.0f64);
    for j in 0..fitted.height() {
        let omega = fitted.row_solid_angle(j);
        for i in 0..fitted.width() {
            let k = (j * fitted.width() + i) as usize;
            for c in 0..3 {
                let (f, t) = (
                    f64::from(fitted.texels()[k][c]),
                    f64::from(truth.texels()[k][c]),
                );
                ft += f * t * omega;
                ff += f * f * omega;
                tt += t * t * omega;
            }
        }
    }
    let s = ft / ff;
    (((tt - 2.0 * s * ft + s * s * ff).max(0.0) / tt).sqrt(), s)
}

/// The relative RMS error, after the factor `s` of [`env_error`], of the fitted map's
/// prefiltered level `k` (roughness `k / 4`) against the true map's (both 32 wide at most):
/// the light as the shading sees it.
fn level_error(fitted: &EnvMap, truth: &EnvMap, s: f64, k: usize) -> f64 {
    let a = Environment::new(fitted, ENV_OPTIONS).unwrap();
    let b = Environment::new(&truth.downsampled(fitted.width()), ENV_OPTIONS).unwrap();
    let (la, lb) = (
        &a.specular_chain().levels()[k],
        &b.specular_chain().levels()[k],
    );
    let (mut e, mut t) = (0.0f64, 0.0f64);
    for j in 0..la.height() {
        let omega = la.row_solid_angle(j);
        for i in 0..la.width() {
            let q = (j * la.width() + i) as usize;
            for c in 0..3 {
                let (x, y) = (f64::from(la.texels()[q][c]), f64::from(lb.texels()[q][c]));
                e += (s * x - y).powi(2) * omega;
                t += y * y * omega;
            }
        }
    }
    (e / t).sqrt()
}

/// World parameters of a bound set at the mesh's rest pose, and its material.
fn world(set: &GaussianSet, mesh: &TriMesh) -> (GaussianParams, Material) {
    let bound = BoundParams::from_set(set, mesh.triangle_count()).unwrap();
    let mut out = GaussianParams::default();
    to_world(
        &bound,
        &TriangleFrames::binding(mesh, mesh.positions()),
        &mut out,
    );
    (out, set.material().cloned().unwrap())
}

fn targets(truth: &(GaussianParams, Material), cams: &[Camera], env: &Environment) -> Vec<Target> {
    cams.iter()
        .map(|camera| {
            let relit = shade_params(&truth.0, &truth.1, camera.position(), env);
            let params = GaussianParams {
                sh_degree: 0,
                sh: relit
                    .colors
                    .iter()
                    .flat_map(|c| c.map(|v| f64::from(rgb_to_dc(v))))
                    .collect(),
                ..truth.0.clone()
            };
            let out =
                render_with_grad::<f32, _>(&params, camera, &RenderOptions::default()).unwrap();
            Target {
                camera: camera.clone(),
                rgb: out.rgb,
                alpha: Some(out.alpha),
                depth: None,
                normal: None,
            }
        })
        .collect()
}

/// Mean over the Gaussians of `|cos|` between the two sets' shortest axes.
fn axis_cosine(a: &GaussianParams, b: &GaussianParams) -> f64 {
    let eye = DVec3::new(0.0, 0.0, 10.0);
    let n = a.means.len();
    (0..n)
        .map(|i| {
            normal_of(a, i, eye)
                .normal
                .dot(normal_of(b, i, eye).normal)
                .abs()
        })
        .sum::<f64>()
        / n as f64
}

struct Run {
    /// Per-Gaussian normal cosine before and after.
    axes: (f64, f64),
    before: MaterialScores,
    after: MaterialScores,
    first_psnr: f64,
    last_psnr: f64,
    seconds: f64,
    gaussians: usize,
    /// With a fitted environment: its error and scale ([`env_error`]) before and after.
    env: Option<((f64, f64), (f64, f64))>,
    /// With a fitted environment: [`level_error`] at roughness 0.5 and 1, before and after.
    levels: ([f64; 2], [f64; 2]),
}

fn run(
    rings: u32,
    per_triangle: usize,
    size: u32,
    views: usize,
    iterations: usize,
    env_fit: Option<u32>,
) -> Run {
    let mesh = sphere(rings, 2 * rings);
    let (truth_set, init) = avatar(&mesh, per_triangle, 7);
    let env = environment();
    let truth = world(&truth_set, &mesh);
    let train = cameras(views, size, 0.0, "train");
    let eval = cameras(4, size, 0.37, "eval");
    let frame = |cams: &[Camera]| FitFrame {
        frame: 0,
        positions: mesh.positions().to_vec(),
        targets: targets(&truth, cams, &env),
    };
    let (frames, held_out) = (vec![frame(&train)], vec![frame(&eval)]);
    let options = CommonOptions {
        iterations,
        lambda_dssim: 0.2,
        alpha_weight: 0.0,
        render: RenderOptions::default(),
        seed: 3,
        eval_every: iterations,
        time_budget: None,
    };
    // Fitted from a uniform grey map (0.5) at `env_fit` texels wide.
    let grey = env_fit.map(|w| EnvMap::uniform(w / 2, [0.5; 3]).unwrap());
    let brdf = BrdfFitOptions {
        normals: true,
        env_fit: grey.clone().map(|initial| EnvFit {
            initial,
            options: ENV_OPTIONS,
            lr: 0.02,
        }),
        ..BrdfFitOptions::default()
    };
    let start = Instant::now();
    let fitted = fit_brdf(
        &init,
        &mesh,
        &frames,
        &held_out,
        &env,
        &options,
        &brdf,
        |_| {},
    )
    .unwrap();
    let seconds = start.elapsed().as_secs_f64();
    let bound = BoundParams::from_set(&init, mesh.triangle_count()).unwrap();
    let mut init_world = GaussianParams::default();
    to_world(
        &bound,
        &TriangleFrames::binding(&mesh, mesh.positions()),
        &mut init_world,
    );
    let init_material = Material::uniform(init.len(), [0.5; 3], 0.9, 0.04);
    let opts = RenderOptions::default();
    let before = material_scores(
        (&truth.0, &truth.1),
        (&init_world, &init_material),
        &eval,
        &opts,
    )
    .unwrap();
    let fit = world(&fitted.set, &mesh);
    let after = material_scores((&truth.0, &truth.1), (&fit.0, &fit.1), &eval, &opts).unwrap();
    Run {
        axes: (
            axis_cosine(&truth.0, &init_world),
            axis_cosine(&truth.0, &fit.0),
        ),
        before,
        after,
        first_psnr: fitted.checkpoints[0].eval_psnr.unwrap(),
        last_psnr: fitted.checkpoints.last().unwrap().eval_psnr.unwrap(),
        seconds,
        gaussians: init.len(),
        levels: grey.as_ref().map_or(([0.0; 2], [0.0; 2]), |s| {
            let truth = environment_map();
            let f = fitted.env.as_ref().unwrap();
            let (s0, s1) = (env_error(s, &truth).1, env_error(f, &truth).1);
            (
                [2, 4].map(|k| level_error(s, &truth, s0, k)),
                [2, 4].map(|k| level_error(f, &truth, s1, k)),
            )
        }),
        env: grey.map(|s| {
            let truth = environment_map();
            (
                env_error(&s, &truth),
                env_error(fitted.env.as_ref().unwrap(), &truth),
            )
        }),
    }
}

fn report(r: &Run) {
    println!(
        "{} Gaussians, {:.2} s: albedo LMSE {:.4} -> {:.4}, normal cosine {:.4} -> {:.4}, \
         held-out PSNR {:.2} -> {:.2} dB; per-Gaussian normal |cos| {:.4} -> {:.4}",
        r.gaussians,
        r.seconds,
        r.before.albedo_lmse,
        r.after.albedo_lmse,
        r.before.normal_cosine,
        r.after.normal_cosine,
        r.first_psnr,
        r.last_psnr,
        r.axes.0,
        r.axes.1
    );
    if let Some((before, after)) = r.env {
        println!(
            "prefiltered level error (roughness 0.5, 1): {:.4}, {:.4} -> {:.4}, {:.4}",
            r.levels.0[0], r.levels.0[1], r.levels.1[0], r.levels.1[1]
        );
        println!(
            "environment relative RMS error (after the shared scale): {:.4} -> {:.4} (scale \
             {:.3} -> {:.3})",
            before.0, after.0, before.1, after.1
        );
    }
}

#[test]
fn a_synthetic_avatar_is_fitted_back() {
    let r = run(12, 1, 40, 10, 250, None);
    report(&r);
    assert!(r.after.normal_cosine >= 0.95, "{:?}", r.after);
    assert!(r.after.normal_cosine > r.before.normal_cosine);
    assert!(
        r.axes.1 >= 0.95 && r.axes.1 > r.axes.0 + 0.05,
        "{:?}",
        r.axes
    );
    assert!(
        r.after.albedo_lmse < 0.5 * r.before.albedo_lmse,
        "{:?}",
        r.after
    );
    assert!(r.last_psnr > r.first_psnr + 3.0);
}

/// The benchmark of docs/benchmarks.md ("Relightable fit"):
/// `cargo test --release -p trisplat-pipeline --test fit_brdf -- --ignored --nocapture`.
#[test]
#[ignore = "benchmark: a larger avatar, about a minute of CPU"]
fn benchmark_synthetic_avatar() {
    report(&run(24, 2, 96, 16, 1000, None));
}

/// Materials, normals and the environment from scratch (grey map 16 × 8, grey albedo): the fit
/// lowers the map's error (after the shared scale), most where the shading reads it (the rough
/// prefiltered level), and reaches the held-out views.
#[test]
fn materials_and_the_environment_are_fitted_together() {
    let r = run(12, 1, 40, 10, 300, Some(16));
    report(&r);
    let (before, after) = r.env.unwrap();
    // The texels are only partly seen (a ring of views on a sphere), the light as the rough
    // lobe sees it well (measured 0.4485 -> 0.4045 and 0.182 -> 0.111).
    assert!(after.0 < 0.95 * before.0, "{before:?} -> {after:?}");
    assert!(r.levels.1[1] < 0.75 * r.levels.0[1], "{:?}", r.levels);
    assert!(r.after.normal_cosine >= 0.95, "{:?}", r.after);
    assert!(r.after.albedo_lmse < 0.5 * r.before.albedo_lmse);
    assert!(r.last_psnr > r.first_psnr + 3.0);
}

/// The benchmark of docs/benchmarks.md ("Relightable fit", the jointly estimated environment).
#[test]
#[ignore = "benchmark: a larger avatar, a few minutes of CPU"]
fn benchmark_synthetic_avatar_with_environment() {
    report(&run(24, 2, 96, 16, 1000, Some(32)));
}
