//! The 3DGS backward pass against central finite differences of the `f64` forward
//! (docs/conventions.md §5 "Gradients"): random small scenes (gsplat rules, antialiased, the
//! original 3DGS rules) and the degree-3 fixture scene `render/random_deg3.ply`. Run in release
//! mode (`cargo test --release -p trisplat-splat --test render_grad`).
//!
//! The loss is linear in the images with seeded random weights per pixel (rgb, alpha and depth at
//! once), so its image gradients are the weights. The error of a parameter group (means,
//! log-scales, rotations, opacity logits, SH) is `max |analytic − fd| / max |fd|` over the group:
//! relative to the group's scale, so components that are zero up to rounding do not count as
//! relative errors of 1.

use glam::DVec3;
use trisplat_geometry::Camera;
use trisplat_geometry::rng::Rng;
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, ImageGrads, RenderOptions, Rules, backward, render,
    render_with_grad,
};

/// The bound on the relative error of each parameter group.
const MAX_REL_ERR: f64 = 1e-3;
/// Central-difference step (parameters are of order 0.1 to 1; the loss is evaluated in `f64`).
const STEP: f64 = 1e-6;

/// Seeded random per-pixel loss weights.
struct Loss {
    rgb: Vec<f64>,
    alpha: Vec<f64>,
    depth: Vec<f64>,
}

impl Loss {
    fn new(pixels: usize, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let mut draw = |n: usize| (0..n).map(|_| rng.uniform_f64() - 0.5).collect::<Vec<_>>();
        Self {
            rgb: draw(3 * pixels),
            alpha: draw(pixels),
            depth: draw(pixels),
        }
    }

    fn value(&self, params: &GaussianParams, camera: &Camera, options: &RenderOptions) -> f64 {
        let out = render_with_grad::<f64, _>(params, camera, options).unwrap();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        dot(&out.rgb, &self.rgb) + dot(&out.alpha, &self.alpha) + dot(&out.depth, &self.depth)
    }

    fn grads(
        &self,
        params: &GaussianParams,
        camera: &Camera,
        options: &RenderOptions,
    ) -> GaussianGrads {
        let fwd = render_with_grad::<f64, _>(params, camera, options).unwrap();
        let g = ImageGrads {
            rgb: Some(&self.rgb),
            alpha: Some(&self.alpha),
            depth: Some(&self.depth),
            ..ImageGrads::default()
        };
        backward(params, camera, options, &fwd, &g).unwrap()
    }
}

/// The parameter groups.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Group {
    Means,
    LogScales,
    Rotations,
    Opacity,
    Sh,
}

const GROUPS: [Group; 5] = [
    Group::Means,
    Group::LogScales,
    Group::Rotations,
    Group::Opacity,
    Group::Sh,
];

/// Component `c` of Gaussian `i`'s parameters in `group`.
fn slot(p: &mut GaussianParams, group: Group, i: usize, c: usize) -> &mut f64 {
    let k = p.sh_per_gaussian();
    match group {
        Group::Means => &mut p.means[i][c],
        Group::LogScales => &mut p.log_scales[i][c],
        Group::Rotations => &mut p.rotations[i][c],
        Group::Opacity => &mut p.opacity_logits[i],
        Group::Sh => &mut p.sh[i * k + c],
    }
}

fn analytic(g: &GaussianGrads, group: Group, i: usize, c: usize, k: usize) -> f64 {
    match group {
        Group::Means => g.means[i][c],
        Group::LogScales => g.log_scales[i][c],
        Group::Rotations => g.rotations[i][c],
        Group::Opacity => g.opacity_logits[i],
        Group::Sh => g.sh[i * k + c],
    }
}

fn components(group: Group, k: usize) -> usize {
    match group {
        Group::Means | Group::LogScales => 3,
        Group::Rotations => 4,
        Group::Opacity => 1,
        Group::Sh => k,
    }
}

/// Relative error per group over Gaussians `which`; also checks that every group's gradient is
/// not all zero (a test that compares zeros with zeros proves nothing).
fn check(
    params: &GaussianParams,
    camera: &Camera,
    options: &RenderOptions,
    which: &[usize],
    seed: u64,
    label: &str,
) -> Vec<(Group, f64)> {
    let loss = Loss::new(camera.width as usize * camera.height as usize, seed);
    let g = loss.grads(params, camera, options);
    let k = params.sh_per_gaussian();
    let mut out = Vec::new();
    for group in GROUPS {
        let mut worst = 0.0f64;
        let mut scale = 0.0f64;
        for &i in which {
            for c in 0..components(group, k) {
                let mut p = params.clone();
                let x = *slot(&mut p, group, i, c);
                *slot(&mut p, group, i, c) = x + STEP;
                let up = loss.value(&p, camera, options);
                *slot(&mut p, group, i, c) = x - STEP;
                let down = loss.value(&p, camera, options);
                let fd = (up - down) / (2.0 * STEP);
                let a = analytic(&g, group, i, c, k);
                worst = worst.max((a - fd).abs());
                scale = scale.max(fd.abs());
            }
        }
        assert!(scale > 1e-6, "{label}: {group:?} gradients are all ~0");
        let rel = worst / scale;
        println!(
            "{label}: {group:?} max |analytic - fd| / max |fd| = {rel:.2e} (scale {scale:.3e})"
        );
        out.push((group, rel));
    }
    out
}

fn random_scene(n: usize, degree: u8, seed: u64) -> (GaussianParams, Camera) {
    let mut rng = Rng::new(seed);
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform_f64();
    let k = 3 * (usize::from(degree) + 1).pow(2);
    let mut p = GaussianParams {
        sh_degree: degree,
        ..GaussianParams::default()
    };
    for _ in 0..n {
        p.means.push([u(-0.6, 0.6), u(-0.45, 0.45), u(-0.5, 0.5)]);
        p.log_scales
            .push([u(-2.6, -1.4), u(-2.6, -1.4), u(-2.6, -1.4)]);
        p.rotations
            .push([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
        p.opacity_logits.push(u(-1.0, 1.5));
        for j in 0..k {
            p.sh.push(if j < 3 { u(-1.0, 1.0) } else { u(-0.3, 0.3) });
        }
    }
    let camera = Camera::look_at(
        "grad",
        DVec3::new(0.3, -0.2, -3.0),
        DVec3::ZERO,
        DVec3::NEG_Y,
        (40, 34),
        40.0,
    )
    .unwrap();
    (p, camera)
}

fn assert_all(errors: &[(Group, f64)], label: &str) {
    for &(group, rel) in errors {
        assert!(
            rel <= MAX_REL_ERR,
            "{label}: {group:?} relative error {rel:.2e}"
        );
    }
}

#[test]
fn random_scenes_gsplat_rules() {
    for seed in 0..3 {
        let (p, camera) = random_scene(10, 3, 100 + seed);
        let options = RenderOptions {
            background: [0.2, 0.5, 0.9],
            ..RenderOptions::default()
        };
        let all: Vec<usize> = (0..p.means.len()).collect();
        let label = format!("random {seed}");
        assert_all(&check(&p, &camera, &options, &all, seed, &label), &label);
    }
}

#[test]
fn random_scene_antialiased_and_original_rules() {
    let (p, camera) = random_scene(10, 2, 7);
    let all: Vec<usize> = (0..p.means.len()).collect();
    let aa = RenderOptions {
        antialiased: true,
        background: [0.3, 0.1, 0.6],
        ..RenderOptions::default()
    };
    assert_all(
        &check(&p, &camera, &aa, &all, 11, "antialiased"),
        "antialiased",
    );
    let original = RenderOptions {
        rules: Rules::Original3dgs,
        ..RenderOptions::original_3dgs()
    };
    assert_all(
        &check(&p, &camera, &original, &all, 12, "original 3dgs"),
        "original 3dgs",
    );
}

#[test]
fn degree3_fixture_scene() {
    let set =
        trisplat_splat::ply::read_gaussians(&trisplat_fixtures::path("render/random_deg3.ply"))
            .unwrap();
    let cams = trisplat_geometry::read_cameras_json(&trisplat_fixtures::path(
        "render/random_cameras.json",
    ))
    .unwrap();
    let p = GaussianParams::from_set(&set);
    let camera = &cams[0];
    let options = RenderOptions::default();
    // The 24 visible Gaussians with the largest screen-space gradient.
    let loss = Loss::new(camera.width as usize * camera.height as usize, 5);
    let g = loss.grads(&p, camera, &options);
    let mut order: Vec<usize> = (0..p.means.len()).collect();
    let norm = |i: usize| g.means2d[i][0].hypot(g.means2d[i][1]);
    order.sort_by(|&a, &b| norm(b).total_cmp(&norm(a)));
    order.truncate(24);
    assert_all(
        &check(&p, camera, &options, &order, 5, "random_deg3.ply"),
        "random_deg3.ply",
    );
}

#[test]
fn f32_forward_matches_the_renderer_and_f64_backward() {
    let set =
        trisplat_splat::ply::read_gaussians(&trisplat_fixtures::path("render/random_deg3.ply"))
            .unwrap();
    let cams = trisplat_geometry::read_cameras_json(&trisplat_fixtures::path(
        "render/random_cameras.json",
    ))
    .unwrap();
    for camera in &cams {
        let options = RenderOptions::default();
        let plain = render(&set, camera, &options).unwrap().images;
        let fwd = render_with_grad::<f32, _>(&set, camera, &options).unwrap();
        let max_diff = |a: &[f32], b: &[f32]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max)
        };
        let rgb = max_diff(&fwd.rgb, plain.rgb.as_ref().unwrap());
        let alpha = max_diff(&fwd.alpha, plain.alpha.as_ref().unwrap());
        println!(
            "{}: f32 grad forward vs render: rgb {rgb:.2e}, alpha {alpha:.2e}",
            camera.name
        );
        assert!(rgb < 1e-4 && alpha < 1e-4);

        let pixels = camera.width as usize * camera.height as usize;
        let loss = Loss::new(pixels, 9);
        let p = trisplat_splat::render::GaussianParams::from_set(&set);
        let g64 = loss.grads(&p, camera, &options);
        let w32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<_>>();
        let (r, a, d) = (w32(&loss.rgb), w32(&loss.alpha), w32(&loss.depth));
        let g32 = backward(
            &set,
            camera,
            &options,
            &fwd,
            &ImageGrads {
                rgb: Some(&r),
                alpha: Some(&a),
                depth: Some(&d),
                ..ImageGrads::default()
            },
        )
        .unwrap();
        let rel = |a: &[f64], b: &[f64]| {
            let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let err = a
                .iter()
                .zip(b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            err / scale
        };
        let flat3 = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
        let flat4 = |v: &[[f64; 4]]| v.iter().flatten().copied().collect::<Vec<_>>();
        let errs = [
            rel(&flat3(&g32.means), &flat3(&g64.means)),
            rel(&flat3(&g32.log_scales), &flat3(&g64.log_scales)),
            rel(&flat4(&g32.rotations), &flat4(&g64.rotations)),
            rel(&g32.opacity_logits, &g64.opacity_logits),
            rel(&g32.sh, &g64.sh),
        ];
        println!("{}: f32 vs f64 backward, per group {errs:?}", camera.name);
        assert!(errs.iter().all(|&e| e < 1e-3));
    }
}

#[test]
fn gradients_do_not_depend_on_the_thread_count() {
    let (p, camera) = random_scene(40, 3, 77);
    let options = RenderOptions::default();
    let loss = Loss::new(camera.width as usize * camera.height as usize, 3);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| loss.grads(&p, &camera, &options))
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn refuses_what_it_cannot_differentiate() {
    use trisplat_splat::render::{GradError, RenderMode};
    let (p, camera) = random_scene(3, 0, 1);
    let perspective = RenderOptions {
        mode: RenderMode::Perspective,
        ..RenderOptions::default()
    };
    assert!(matches!(
        render_with_grad::<f64, _>(&p, &camera, &perspective),
        Err(GradError::UnsupportedMode(RenderMode::Perspective))
    ));
    let options = RenderOptions::default();
    let fwd = render_with_grad::<f64, _>(&p, &camera, &options).unwrap();
    let short = vec![0.0; 5];
    let grads = ImageGrads {
        alpha: Some(&short),
        ..ImageGrads::default()
    };
    assert!(matches!(
        backward(&p, &camera, &options, &fwd, &grads),
        Err(GradError::Size { .. })
    ));
    // No image gradient at all: zero gradients.
    let g = backward(&p, &camera, &options, &fwd, &ImageGrads::default()).unwrap();
    assert!(g.means.iter().flatten().all(|&v| v == 0.0));
}
