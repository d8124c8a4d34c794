//! The 3DGS backward pass against central finite differences of the `f64` forward
//! (docs/conventions.md §5 "Gradients"): random small scenes (gsplat rules, antialiased, the
//! original 3DGS rules) and the degree-3 fixture scene `render/random_deg3.ply`. Run in release
//! mode (`cargo test --release -p trisplat-splat --test render_grad`).
//!
//! The loss (seeded random weights on rgb, alpha and depth) and each parameter group's relative
//! error are `grad_check`'s.

mod grad_check;

use glam::DVec3;
use grad_check::{
    GROUPS, Group, Loss, assert_within_bound, by_screen_gradient, f32_against_f64, fixture_scene,
    group_errors, max_abs_diff,
};
use trisplat_geometry::Camera;
use trisplat_geometry::rng::Rng;
use trisplat_splat::render::{
    GaussianParams, ImageGrads, RenderOptions, Rules, backward, render, render_with_grad,
};

/// Relative error per group over Gaussians `which`, with the loss of `seed`.
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
    group_errors(
        params,
        camera,
        options,
        (which, &GROUPS),
        (&loss, &g),
        label,
    )
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
        assert_within_bound(&check(&p, &camera, &options, &all, seed, &label), &label);
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
    assert_within_bound(
        &check(&p, &camera, &aa, &all, 11, "antialiased"),
        "antialiased",
    );
    let original = RenderOptions {
        rules: Rules::Original3dgs,
        ..RenderOptions::original_3dgs()
    };
    assert_within_bound(
        &check(&p, &camera, &original, &all, 12, "original 3dgs"),
        "original 3dgs",
    );
}

#[test]
fn degree3_fixture_scene() {
    let (set, cams) = fixture_scene();
    let p = GaussianParams::from_set(&set);
    let camera = &cams[0];
    let options = RenderOptions::default();
    // The 24 visible Gaussians with the largest screen-space gradient.
    let loss = Loss::new(camera.width as usize * camera.height as usize, 5);
    let g = loss.grads(&p, camera, &options);
    let mut order = by_screen_gradient(&g);
    order.truncate(24);
    assert_within_bound(
        &check(&p, camera, &options, &order, 5, "random_deg3.ply"),
        "random_deg3.ply",
    );
}

#[test]
fn f32_forward_matches_the_renderer_and_f64_backward() {
    let (set, cams) = fixture_scene();
    for camera in &cams {
        let options = RenderOptions::default();
        let plain = render(&set, camera, &options).unwrap().images;
        let fwd = render_with_grad::<f32, _>(&set, camera, &options).unwrap();
        let rgb = max_abs_diff(&fwd.rgb, plain.rgb.as_ref().unwrap());
        let alpha = max_abs_diff(&fwd.alpha, plain.alpha.as_ref().unwrap());
        println!(
            "{}: f32 grad forward vs render: rgb {rgb:.2e}, alpha {alpha:.2e}",
            camera.name
        );
        assert!(rgb < 1e-4 && alpha < 1e-4);

        let pixels = camera.width as usize * camera.height as usize;
        let loss = Loss::new(pixels, 9);
        let p = trisplat_splat::render::GaussianParams::from_set(&set);
        let g64 = loss.grads(&p, camera, &options);
        let [r, a, d, _] = loss.weights_f32();
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
        let errs = f32_against_f64(&g32, &g64);
        println!("{}: f32 vs f64 backward, per group {errs:?}", camera.name);
        assert!(errs.iter().all(|&e| e < 1e-3));
    }
}

#[test]
fn gradients_do_not_depend_on_the_thread_count() {
    let (p, camera) = random_scene(40, 3, 77);
    let options = RenderOptions::default();
    let loss = Loss::new(camera.width as usize * camera.height as usize, 3);
    let run = |threads: usize| loss.grads_on(threads, &p, &camera, &options);
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
