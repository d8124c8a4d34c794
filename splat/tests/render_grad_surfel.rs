//! The 2DGS surfel backward pass against central finite differences of the `f64` forward
//! (docs/conventions.md §5 "Gradients"): random small scenes with a grazing surfel and one with a
//! near-zero scale (camera- and world-frame normals), and the degree-3 fixture scene
//! `render/random_deg3.ply` seen as surfels. Run in release mode (`cargo test --release -p
//! trisplat-splat --test render_grad_surfel`).
//!
//! The loss is linear in the rgb, alpha, depth and normal images with seeded random weights per
//! pixel, plus `λ` times the summed depth distortion. The error of a parameter group is
//! `max |analytic − fd| / max |fd|` over the group.

mod grad_check;

use glam::DVec3;
use grad_check::{
    GROUPS, Group, Loss, assert_within_bound, by_screen_gradient, f32_against_f64, fixture_scene,
    group_errors, max_abs_diff,
};
use trisplat_geometry::Camera;
use trisplat_geometry::mesh_render::NormalFrame;
use trisplat_geometry::rng::Rng;
use trisplat_splat::render::{
    GaussianParams, GradError, ImageGrads, RenderMode, RenderOptions, backward, render,
    render_with_grad,
};

/// Weight of the distortion term in the test loss (the distortion is small: `m` lies in [0, 1)
/// and varies little across a scene of depth ~1 at distance 3).
const LAMBDA: f64 = 50.0;

fn surfel_options(frame: NormalFrame) -> RenderOptions {
    RenderOptions {
        mode: RenderMode::Surfel2d,
        normal_frame: frame,
        near: 0.2,
        background: [0.2, 0.5, 0.9],
        ..RenderOptions::default()
    }
}

/// Relative error per group over Gaussians `which` (each group's gradient must not be all
/// zero); also checks that the third log-scale, unused by surfels, gets exactly 0.
fn check(
    params: &GaussianParams,
    camera: &Camera,
    options: &RenderOptions,
    (which, groups): (&[usize], &[Group]),
    loss: &Loss,
    label: &str,
) -> f64 {
    let g = loss.grads(params, camera, options);
    assert!(
        g.log_scales.iter().all(|s| s[2] == 0.0),
        "{label}: third log-scale"
    );
    let errors = group_errors(params, camera, options, (which, groups), (loss, &g), label);
    assert_within_bound(&errors, label)
}

fn camera() -> Camera {
    Camera::look_at(
        "grad",
        DVec3::new(0.3, -0.2, -3.0),
        DVec3::ZERO,
        DVec3::NEG_Y,
        (40, 34),
        40.0,
    )
    .unwrap()
}

/// `n` random surfels, then a grazing one (its normal almost perpendicular to the view ray)
/// and one with a near-zero second scale (a needle).
fn random_scene(n: usize, degree: u8, seed: u64) -> GaussianParams {
    let mut rng = Rng::new(seed);
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform_f64();
    let k = 3 * (usize::from(degree) + 1).pow(2);
    let mut p = GaussianParams {
        sh_degree: degree,
        ..GaussianParams::default()
    };
    for _ in 0..n + 2 {
        p.means.push([u(-0.6, 0.6), u(-0.45, 0.45), u(-0.5, 0.5)]);
        p.log_scales
            .push([u(-2.3, -1.3), u(-2.3, -1.3), u(-3.0, -1.0)]);
        p.rotations
            .push([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
        p.opacity_logits.push(u(-1.0, 1.5));
        for j in 0..k {
            p.sh.push(if j < 3 { u(-1.0, 1.0) } else { u(-0.3, 0.3) });
        }
    }
    // Grazing: the camera looks along ~+z; a surfel whose normal is ~x, tilted 3° towards z
    // (rotation about y by 87°: the third axis becomes (sin, 0, cos) of 87°).
    let half = 87f64.to_radians() / 2.0;
    p.rotations[n] = [half.cos(), 0.0, half.sin(), 0.0];
    p.means[n] = [0.1, 0.05, 0.0];
    p.log_scales[n] = [-1.4, -1.6, -5.0];
    p.opacity_logits[n] = 2.0;
    // Needle: second scale e^-9 (far below a pixel).
    p.means[n + 1] = [-0.2, 0.1, -0.2];
    p.log_scales[n + 1] = [-1.5, -9.0, -5.0];
    p.opacity_logits[n + 1] = 1.5;
    p
}

#[test]
fn random_scenes_camera_frame() {
    let camera = camera();
    let pixels = (camera.width * camera.height) as usize;
    for seed in 0..3 {
        let p = random_scene(10, 3, 200 + seed);
        let all: Vec<usize> = (0..p.means.len()).collect();
        let loss = Loss::surfel(pixels, seed, LAMBDA);
        let label = format!("surfel random {seed} (camera normals)");
        let options = surfel_options(NormalFrame::Camera);
        check(&p, &camera, &options, (&all, &GROUPS), &loss, &label);
        // The grazing surfel and the needle alone (relative to their own gradients' scale).
        let label = format!("surfel random {seed}: grazing and needle surfels");
        check(&p, &camera, &options, (&[10, 11], &GROUPS), &loss, &label);
    }
}

#[test]
fn random_scene_world_frame_and_separate_terms() {
    let camera = camera();
    let pixels = (camera.width * camera.height) as usize;
    let p = random_scene(10, 2, 300);
    let all: Vec<usize> = (0..p.means.len()).collect();
    let options = surfel_options(NormalFrame::World);
    let full = Loss::surfel(pixels, 31, LAMBDA);
    check(
        &p,
        &camera,
        &options,
        (&all, &GROUPS),
        &full,
        "surfel world normals",
    );
    // Each new term alone, so that one cannot hide behind the others.
    let zero = vec![0.0; 3 * pixels];
    let normal_only = Loss {
        rgb: zero.clone(),
        alpha: zero[..pixels].to_vec(),
        depth: zero[..pixels].to_vec(),
        normal: full.normal.clone(),
        lambda: 0.0,
    };
    // (The normal does not depend on SH: that group's gradient is zero.)
    let no_sh = &GROUPS[..4];
    check(
        &p,
        &camera,
        &options,
        (&all, no_sh),
        &normal_only,
        "normal only",
    );
    let distortion_only = Loss {
        normal: zero,
        lambda: 1.0,
        ..normal_only
    };
    check(
        &p,
        &camera,
        &options,
        (&all, no_sh),
        &distortion_only,
        "distortion only",
    );
    let fwd = render_with_grad::<f64, _>(&p, &camera, &options).unwrap();
    assert!(fwd.distortion_total() > 0.0);
    assert!(fwd.distortion.iter().all(|&d| d >= -1e-12));
    let g = distortion_only.grads(&p, &camera, &options);
    assert!(g.means.iter().flatten().any(|&v| v != 0.0));
    assert!(g.sh.iter().all(|&v| v == 0.0));
}

#[test]
fn degree3_fixture_scene_as_surfels() {
    let (set, cams) = fixture_scene();
    let camera = &cams[0];
    let options = surfel_options(NormalFrame::Camera);
    let loss = Loss::surfel((camera.width * camera.height) as usize, 5, LAMBDA);
    // The scene: the 64 Gaussians (file rows, in file order) with the largest screen-space
    // gradient of the whole file's render, so that each finite difference renders 64, not 1000.
    let by_gradient = |p: &GaussianParams| by_screen_gradient(&loss.grads(p, camera, &options));
    let mut rows = by_gradient(&GaussianParams::from_set(&set));
    rows.truncate(64);
    rows.sort_unstable();
    let p = GaussianParams::from_set(&set.select(&rows));
    assert_eq!(p.sh_degree, 3);
    // Every group over the 12 with the largest screen-space gradient; SH (48 per Gaussian,
    // linear in the colour) over the first 4 of them.
    let mut order = by_gradient(&p);
    order.truncate(12);
    check(
        &p,
        camera,
        &options,
        (&order, &GROUPS[..4]),
        &loss,
        "random_deg3.ply surfels",
    );
    check(
        &p,
        camera,
        &options,
        (&order[..4], &GROUPS[4..]),
        &loss,
        "random_deg3.ply surfels",
    );
}

#[test]
fn f32_forward_matches_the_renderer_and_f64_backward() {
    let (set, cams) = fixture_scene();
    for frame in [NormalFrame::Camera, NormalFrame::World] {
        let camera = &cams[0];
        let options = RenderOptions {
            outputs: trisplat_splat::render::Outputs::ALL,
            ..surfel_options(frame)
        };
        let plain = render(&set, camera, &options).unwrap().images;
        let fwd = render_with_grad::<f32, _>(&set, camera, &options).unwrap();
        let rgb = max_abs_diff(&fwd.rgb, plain.rgb.as_ref().unwrap());
        let alpha = max_abs_diff(&fwd.alpha, plain.alpha.as_ref().unwrap());
        let depth = max_abs_diff(&fwd.depth, plain.depth.as_ref().unwrap());
        let normal = max_abs_diff(&fwd.normal, plain.normal.as_ref().unwrap());
        println!(
            "{frame:?}: f32 grad forward vs render: rgb {rgb:.2e}, alpha {alpha:.2e}, depth \
             {depth:.2e}, normal {normal:.2e}"
        );
        assert!(rgb < 1e-4 && alpha < 1e-4 && normal < 1e-4 && depth < 1e-3);

        let pixels = (camera.width * camera.height) as usize;
        let loss = Loss::surfel(pixels, 9, LAMBDA);
        let p = GaussianParams::from_set(&set);
        let g64 = loss.grads(&p, camera, &options);
        let [r, a, d, n] = loss.weights_f32();
        let g32 = backward(
            &set,
            camera,
            &options,
            &fwd,
            &ImageGrads {
                rgb: Some(&r),
                alpha: Some(&a),
                depth: Some(&d),
                normal: Some(&n),
                distortion: LAMBDA as f32,
            },
        )
        .unwrap();
        let errs = f32_against_f64(&g32, &g64);
        println!("{frame:?}: f32 vs f64 backward, per group {errs:?}");
        assert!(errs.iter().all(|&e| e < 1e-3));
    }
}

#[test]
fn surfel_gradients_do_not_depend_on_the_thread_count() {
    let camera = camera();
    let p = random_scene(40, 3, 77);
    let options = surfel_options(NormalFrame::Camera);
    let loss = Loss::surfel((camera.width * camera.height) as usize, 3, LAMBDA);
    let run = |threads: usize| loss.grads_on(threads, &p, &camera, &options);
    assert_eq!(run(1), run(3));
}

/// Degenerate surfels: zero and huge scales, edge-on (exactly), a zero quaternion, a centre on
/// the near plane, a surfel through the camera: no panic, finite gradients.
#[test]
fn degenerate_surfels_get_finite_gradients() {
    let camera = camera();
    let pixels = (camera.width * camera.height) as usize;
    let mut p = random_scene(4, 1, 9);
    let c = camera.position();
    let to_camera = camera.world_to_camera_rotation().transpose();
    // Exactly edge-on to the camera's axis: third axis = the camera's x axis.
    let x_axis = to_camera.x_axis;
    let q = glam::DQuat::from_rotation_arc(DVec3::Z, x_axis);
    let edge_on = [q.w, q.x, q.y, q.z];
    let add = |p: &mut GaussianParams, mean: DVec3, ls: [f64; 3], rot: [f64; 4]| {
        p.means.push(mean.to_array());
        p.log_scales.push(ls);
        p.rotations.push(rot);
        p.opacity_logits.push(3.0);
        let k = p.sh_per_gaussian();
        p.sh.extend(std::iter::repeat_n(0.3, k));
    };
    add(&mut p, DVec3::ZERO, [-1.5, -1.5, -1.5], edge_on);
    add(
        &mut p,
        DVec3::new(0.1, 0.0, 0.0),
        [f64::NEG_INFINITY, -1.5, 0.0],
        [1.0, 0.0, 0.0, 0.0],
    );
    add(
        &mut p,
        DVec3::new(0.0, 0.1, 0.0),
        [-40.0, -40.0, -40.0],
        [1.0, 0.2, 0.0, 0.0],
    );
    add(
        &mut p,
        DVec3::new(0.0, 0.0, 0.3),
        [3.0, 3.0, 3.0],
        [0.0, 0.0, 0.0, 0.0],
    );
    add(
        &mut p,
        c + DVec3::new(0.0, 0.0, 0.2),
        [-1.0, -1.0, -1.0],
        [1.0, 0.0, 0.0, 0.0],
    );
    add(&mut p, c, [0.0, 0.0, 0.0], [1.0, 0.3, 0.0, 0.0]);
    add(
        &mut p,
        DVec3::new(0.2, -0.1, 0.1),
        [-1.0, -1.2, 0.0],
        [1e-30, 0.0, 0.0, 0.0],
    );
    for frame in [NormalFrame::Camera, NormalFrame::World] {
        let options = surfel_options(frame);
        let loss = Loss::surfel(pixels, 4, LAMBDA);
        for g in [loss.grads(&p, &camera, &options), {
            let set_f32 = render_with_grad::<f32, _>(&p, &camera, &options).unwrap();
            assert!(set_f32.rgb.iter().all(|v| v.is_finite()));
            let [r, a, d, n] = loss.weights_f32();
            backward(
                &p,
                &camera,
                &options,
                &set_f32,
                &ImageGrads {
                    rgb: Some(&r),
                    alpha: Some(&a),
                    depth: Some(&d),
                    normal: Some(&n),
                    distortion: 1.0,
                },
            )
            .unwrap()
        }] {
            let finite = g.means.iter().flatten().all(|v| v.is_finite())
                && g.log_scales.iter().flatten().all(|v| v.is_finite())
                && g.rotations.iter().flatten().all(|v| v.is_finite())
                && g.opacity_logits.iter().all(|v| v.is_finite())
                && g.sh.iter().all(|v| v.is_finite())
                && g.means2d.iter().flatten().all(|v| v.is_finite());
            assert!(finite, "{frame:?}: non-finite gradient");
        }
    }
}

#[test]
fn normal_and_distortion_are_refused_in_3dgs_mode() {
    let camera = camera();
    let pixels = (camera.width * camera.height) as usize;
    let p = random_scene(3, 0, 1);
    let options = RenderOptions::default();
    let fwd = render_with_grad::<f64, _>(&p, &camera, &options).unwrap();
    assert!(fwd.normal.is_empty() && fwd.distortion_total() == 0.0);
    let normal = vec![0.0; 3 * pixels];
    for grads in [
        ImageGrads {
            normal: Some(&normal),
            ..ImageGrads::default()
        },
        ImageGrads {
            distortion: 0.5,
            ..ImageGrads::default()
        },
    ] {
        assert!(matches!(
            backward(&p, &camera, &options, &fwd, &grads),
            Err(GradError::NotInMode { .. })
        ));
    }
    // A forward in one mode, a backward in the other.
    let surfels = surfel_options(NormalFrame::Camera);
    assert!(matches!(
        backward(&p, &camera, &surfels, &fwd, &ImageGrads::default()),
        Err(GradError::ModeMismatch { .. })
    ));
    let sfwd = render_with_grad::<f64, _>(&p, &camera, &surfels).unwrap();
    let bad = ImageGrads {
        distortion: f64::NAN,
        ..ImageGrads::default()
    };
    assert!(matches!(
        backward(&p, &camera, &surfels, &sfwd, &bad),
        Err(GradError::BadDistortionWeight(_))
    ));
    let short = vec![0.0; 5];
    let bad = ImageGrads {
        normal: Some(&short),
        ..ImageGrads::default()
    };
    assert!(matches!(
        backward(&p, &camera, &surfels, &sfwd, &bad),
        Err(GradError::Size { .. })
    ));
    let perspective = RenderOptions {
        mode: RenderMode::Perspective,
        ..RenderOptions::default()
    };
    assert!(matches!(
        render_with_grad::<f64, _>(&p, &camera, &perspective),
        Err(GradError::UnsupportedMode(RenderMode::Perspective))
    ));
}
