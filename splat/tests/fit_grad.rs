//! The fitter's pieces against central finite differences in `f64` (docs/conventions.md §5
//! "Fitting"): each image loss's gradient (L1, masked L1, SSIM, depth–normal consistency with
//! respect to both images), the chain rule from world-space gradients to bound (local)
//! parameters through the GaussianAvatars frame (end to end through the `f64` renderer), and
//! Adam's update and state remapping.

use glam::DVec3;
use trisplat_geometry::rng::Rng;
use trisplat_geometry::{Camera, TriMesh};
use trisplat_splat::fit::adam::{Adam, LearningRates};
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, grads_to_local, to_world};
use trisplat_splat::fit::loss::{DepthNormal, Ssim, l1, masked_l1};
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, ImageGrads, RenderOptions, backward, render_with_grad,
};

/// Central-difference step.
const STEP: f64 = 1e-6;
/// Bound on `max |analytic − fd| / max |fd|` over an image or parameter group.
const MAX_REL_ERR: f64 = 1e-5;

fn draw(rng: &mut Rng, n: usize, lo: f64, hi: f64) -> Vec<f64> {
    (0..n).map(|_| lo + (hi - lo) * rng.uniform_f64()).collect()
}

/// `max |analytic − fd| / max |fd|` of the gradient of `f` at `x` over the indices `which`.
fn fd_error(x: &[f64], analytic: &[f64], which: &[usize], f: &dyn Fn(&[f64]) -> f64) -> f64 {
    let (mut worst, mut scale) = (0.0f64, 0.0f64);
    let mut y = x.to_vec();
    for &i in which {
        y[i] = x[i] + STEP;
        let up = f(&y);
        y[i] = x[i] - STEP;
        let down = f(&y);
        y[i] = x[i];
        let fd = (up - down) / (2.0 * STEP);
        worst = worst.max((analytic[i] - fd).abs());
        scale = scale.max(fd.abs());
    }
    assert!(scale > 1e-9, "the gradient is ~0 everywhere checked");
    worst / scale
}

#[test]
fn l1_and_masked_l1_gradients() {
    let mut rng = Rng::new(1);
    let n = 60;
    let x = draw(&mut rng, n, 0.0, 1.0);
    let t = draw(&mut rng, n, 0.0, 1.0);
    let m = draw(&mut rng, n, 0.0, 1.0);
    let mut g = vec![0.0; n];
    l1(&x, &t, 0.7, &mut g);
    let all: Vec<usize> = (0..n).collect();
    let e = fd_error(&x, &g, &all, &|y| 0.7 * l1(y, &t, 0.0, &mut vec![0.0; n]));
    println!("l1: {e:.2e}");
    assert!(e < MAX_REL_ERR, "l1 {e}");
    let mut g = vec![0.0; n];
    masked_l1(&x, &t, &m, 1.3, &mut g);
    let e = fd_error(&x, &g, &all, &|y| {
        1.3 * masked_l1(y, &t, &m, 0.0, &mut vec![0.0; n])
    });
    println!("masked l1: {e:.2e}");
    assert!(e < MAX_REL_ERR, "masked l1 {e}");
}

#[test]
fn ssim_gradient() {
    let mut rng = Rng::new(2);
    let (w, h, c) = (17, 13, 3);
    let n = w * h * c;
    let t = draw(&mut rng, n, 0.0, 1.0);
    // A prediction near the target, as in a fit (and a random one).
    for spread in [0.1, 1.0] {
        let x: Vec<f64> = t
            .iter()
            .map(|&v| (v + spread * (rng.uniform_f64() - 0.5)).clamp(0.0, 1.0))
            .collect();
        let mut ssim = Ssim::new(w, h);
        let mut g = vec![0.0; n];
        let s = ssim.ssim(&x, &t, c, -1.0, Some(&mut g));
        assert!(s > -1.0 && s < 1.0);
        // Corners, borders and the interior of every channel.
        let which: Vec<usize> = (0..n).step_by(7).collect();
        let e = fd_error(&x, &g, &which, &|y| {
            -Ssim::new(w, h).ssim(y, &t, c, 0.0, None)
        });
        println!("ssim (spread {spread}): {e:.2e}");
        assert!(e < MAX_REL_ERR, "ssim {e}");
    }
}

fn depth_camera() -> Camera {
    Camera::look_at(
        "dn",
        DVec3::new(0.0, 0.0, -3.0),
        DVec3::ZERO,
        DVec3::NEG_Y,
        (14, 11),
        40.0,
    )
    .unwrap()
}

#[test]
fn depth_normal_gradients() {
    let camera = depth_camera();
    let (w, h) = (camera.width as usize, camera.height as usize);
    let px = w * h;
    let mut rng = Rng::new(3);
    // A smooth bumpy surface in front of the camera, a hole and random normals.
    let mut depth: Vec<f64> = (0..px)
        .map(|p| {
            let (i, j) = ((p / w) as f64, (p % w) as f64);
            2.5 + 0.1 * (0.5 * j).sin() + 0.05 * (0.7 * i).cos() + 0.01 * rng.uniform_f64()
        })
        .collect();
    depth[5 * w + 6] = 0.0;
    let normal: Vec<f64> = (0..px)
        .flat_map(|_| {
            let n = [
                rng.uniform_f64() - 0.5,
                rng.uniform_f64() - 0.5,
                -1.0 - rng.uniform_f64(),
            ];
            let l = 0.8 / (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            n.map(|v| v * l)
        })
        .collect();
    let weight = draw(&mut rng, px, 0.2, 1.0);
    let mut dn = DepthNormal::default();
    let mut gd = vec![0.0; px];
    let mut gn = vec![0.0; 3 * px];
    let v = dn.loss(
        &camera,
        &depth,
        &normal,
        &weight,
        2.0,
        Some(&mut gd),
        Some(&mut gn),
    );
    assert!(v > 0.0);
    let which_d: Vec<usize> = (0..px).filter(|&p| depth[p] > 0.0).collect();
    let e = fd_error(&depth, &gd, &which_d, &|d| {
        2.0 * DepthNormal::default().loss(&camera, d, &normal, &weight, 0.0, None, None)
    });
    println!("depth-normal d/d depth: {e:.2e}");
    assert!(e < MAX_REL_ERR, "depth {e}");
    let which_n: Vec<usize> = (0..3 * px).collect();
    let e = fd_error(&normal, &gn, &which_n, &|n| {
        2.0 * DepthNormal::default().loss(&camera, &depth, n, &weight, 0.0, None, None)
    });
    println!("depth-normal d/d normal: {e:.2e}");
    assert!(e < MAX_REL_ERR, "normal {e}");
    // A plane at constant depth has the normal (0, 0, -1): zero loss for that normal.
    let flat = vec![2.0; px];
    let facing: Vec<f64> = (0..px).flat_map(|_| [0.0, 0.0, -1.0]).collect();
    let ones = vec![1.0; px];
    let z = dn.loss(&camera, &flat, &facing, &ones, 1.0, None, None);
    assert!(z.abs() < 1e-12, "flat plane: {z}");
}

/// Two triangles, a few Gaussians bound to them with random local parameters.
fn bound_scene() -> (TriMesh, Vec<DVec3>, BoundParams) {
    let positions = vec![
        DVec3::new(-0.6, -0.5, 0.1),
        DVec3::new(0.7, -0.4, 0.0),
        DVec3::new(0.0, 0.6, -0.2),
        DVec3::new(0.8, 0.5, 0.3),
    ];
    let mesh = TriMesh::try_new(positions.clone(), vec![[0, 1, 2], [1, 3, 2]]).unwrap();
    // A posed frame: the template moved and bent.
    let posed: Vec<DVec3> = positions
        .iter()
        .enumerate()
        .map(|(i, p)| *p * 1.1 + DVec3::new(0.05 * i as f64, -0.02, 0.1 * (i % 2) as f64))
        .collect();
    let mut rng = Rng::new(4);
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform_f64();
    let n = 6;
    let degree = 1u8;
    let k = 3 * (usize::from(degree) + 1).pow(2);
    let mut local = GaussianParams {
        sh_degree: degree,
        ..GaussianParams::default()
    };
    for _ in 0..n {
        local.means.push([u(-0.3, 0.3), u(-0.1, 0.1), u(-0.3, 0.3)]);
        local
            .log_scales
            .push([u(-1.6, -0.8), u(-2.5, -1.8), u(-1.6, -0.8)]);
        local
            .rotations
            .push([u(0.5, 1.0), u(-0.5, 0.5), u(-0.5, 0.5), u(-0.5, 0.5)]);
        local.opacity_logits.push(u(-0.5, 1.5));
        for j in 0..k {
            local
                .sh
                .push(if j < 3 { u(-1.0, 1.0) } else { u(-0.3, 0.3) });
        }
    }
    let bound = BoundParams {
        local,
        triangles: (0..n as u32).map(|i| i % 2).collect(),
    };
    (mesh, posed, bound)
}

#[test]
fn bound_parameter_gradients_through_the_renderer() {
    let (mesh, posed, bound) = bound_scene();
    let frames = TriangleFrames::binding(&mesh, &posed);
    let camera = Camera::look_at(
        "bound",
        DVec3::new(0.2, -0.1, -3.0),
        DVec3::new(0.1, 0.0, 0.1),
        DVec3::NEG_Y,
        (36, 30),
        40.0,
    )
    .unwrap();
    let options = RenderOptions::default();
    let px = 36 * 30;
    let mut rng = Rng::new(5);
    let w_rgb = draw(&mut rng, 3 * px, -0.5, 0.5);
    let w_alpha = draw(&mut rng, px, -0.5, 0.5);
    let value = |b: &BoundParams| {
        let mut world = GaussianParams::default();
        to_world(b, &frames, &mut world);
        let out = render_with_grad::<f64, _>(&world, &camera, &options).unwrap();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        dot(&out.rgb, &w_rgb) + dot(&out.alpha, &w_alpha)
    };
    let mut world = GaussianParams::default();
    to_world(&bound, &frames, &mut world);
    let fwd = render_with_grad::<f64, _>(&world, &camera, &options).unwrap();
    let g_world = backward(
        &world,
        &camera,
        &options,
        &fwd,
        &ImageGrads {
            rgb: Some(&w_rgb),
            alpha: Some(&w_alpha),
            ..ImageGrads::default()
        },
    )
    .unwrap();
    let mut g = GaussianGrads::default();
    grads_to_local(&bound, &frames, &g_world, &mut g);
    type Pick = fn(&mut GaussianParams) -> &mut [f64];
    type PickG = fn(&GaussianGrads) -> &[f64];
    let groups: [(&str, Pick, PickG); 5] = [
        (
            "means",
            |p| p.means.as_flattened_mut(),
            |g| g.means.as_flattened(),
        ),
        (
            "log_scales",
            |p| p.log_scales.as_flattened_mut(),
            |g| g.log_scales.as_flattened(),
        ),
        (
            "rotations",
            |p| p.rotations.as_flattened_mut(),
            |g| g.rotations.as_flattened(),
        ),
        (
            "opacities",
            |p| &mut p.opacity_logits,
            |g| &g.opacity_logits,
        ),
        ("sh", |p| &mut p.sh, |g| &g.sh),
    ];
    for (name, pick, pick_g) in groups {
        let mut b = bound.clone();
        let x = pick(&mut b.local).to_vec();
        let which: Vec<usize> = (0..x.len()).collect();
        let e = fd_error(&x, pick_g(&g), &which, &|y| {
            let mut b = bound.clone();
            pick(&mut b.local).copy_from_slice(y);
            value(&b)
        });
        println!("bound {name}: {e:.2e}");
        assert!(e < 1e-4, "bound {name}: {e}");
    }
}

#[test]
fn world_parameters_match_the_deformer() {
    let (mesh, posed, bound) = bound_scene();
    let set = trisplat_splat::fit::bound::to_set(&bound);
    let deformer = trisplat_splat::Deformer::new(&mesh, Default::default());
    let baked = deformer.deform(&set, &posed).unwrap();
    let frames = TriangleFrames::binding(&mesh, &posed);
    let b32 = BoundParams::from_set(&set, 2).unwrap();
    let mut world = GaussianParams::default();
    to_world(&b32, &frames, &mut world);
    for i in 0..bound.len() {
        let m = baked.means()[i].as_dvec3();
        assert!((m - DVec3::from_array(world.means[i])).length() < 1e-5);
        let s = baked.log_scales()[i].as_dvec3();
        assert!((s - DVec3::from_array(world.log_scales[i])).length() < 1e-5);
        let q = world.rotations[i];
        let l = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
        for (c, &qc) in q.iter().enumerate() {
            let d = f64::from(baked.rotations()[i][c]) - sign * qc / l;
            assert!(d.abs() < 1e-5, "rotation {i}: {d}");
        }
    }
}

#[test]
fn adam_step_and_remap() {
    let mut p = GaussianParams {
        means: vec![[1.0, 2.0, 3.0], [0.0; 3]],
        log_scales: vec![[0.0; 3]; 2],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        opacity_logits: vec![0.0; 2],
        sh_degree: 0,
        sh: vec![0.0; 6],
    };
    let mut g = GaussianGrads::zeros(2, 0);
    g.means[0] = [0.5, -2.0, 0.0];
    g.sh[3] = 1.0;
    let mut adam = Adam::new(LearningRates::BOUND, 2, 3);
    adam.step(&mut p, &g);
    // First step: m̂ = g, v̂ = g², update = lr sign(g).
    let lr = LearningRates::BOUND.means;
    assert!((p.means[0][0] - (1.0 - lr)).abs() < 1e-12);
    assert!((p.means[0][1] - (2.0 + lr)).abs() < 1e-12);
    assert_eq!(p.means[0][2], 3.0);
    assert!((p.sh[3] + LearningRates::BOUND.sh_dc).abs() < 1e-12);
    // Gaussian 1 cloned from 0 keeps its state; a new one starts fresh at step 1.
    adam.remap(&[Some(0), Some(0), None]);
    assert_eq!(adam.len(), 3);
    let mut p3 = GaussianParams {
        means: vec![[0.0; 3]; 3],
        log_scales: vec![[0.0; 3]; 3],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; 3],
        opacity_logits: vec![0.0; 3],
        sh_degree: 0,
        sh: vec![0.0; 9],
    };
    let mut g3 = GaussianGrads::zeros(3, 0);
    g3.means[1] = [-0.5, 0.0, 0.0];
    g3.means[2] = [0.5, 0.0, 0.0];
    adam.step(&mut p3, &g3);
    // The fresh Gaussian moves by exactly lr; the clone, whose history pulls the other way
    // (m̂ = −0.026, v̂ = 0.25), by far less.
    assert!((p3.means[2][0] + lr).abs() < 1e-12);
    assert!(
        p3.means[1][0] > 0.0 && p3.means[1][0] < 0.1 * lr,
        "{}",
        p3.means[1][0]
    );
    // The clone with a zero gradient still moves with its momentum.
    assert!(p3.means[0][1] != 0.0);
}
