//! `pipeline::fit::fit_neural` (`trisplat fit --appearance mlp`): training lowers the loss and
//! raises the held-out PSNR on a small colour-gradient square; the option checks.

use glam::DVec3;
use trisplat_geometry::{Camera, TriMesh};
use trisplat_pipeline::fit::{
    CommonOptions, FitFrame, NeuralFitOptions, TargetColor, fit_neural, mesh_targets,
};
use trisplat_splat::neural::NeuralConfig;
use trisplat_splat::render::{RenderMode, RenderOptions};
use trisplat_splat::{BindOptions, init_bound};

fn square() -> TriMesh {
    let p = vec![
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(1.0, -1.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
        DVec3::new(-1.0, 1.0, 0.0),
    ];
    TriMesh::try_new(p, vec![[0, 1, 2], [0, 2, 3]])
        .unwrap()
        .with_colors(vec![
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [0.0, 1.0, 0.0, 1.0],
            [1.0, 1.0, 0.0, 1.0],
        ])
        .unwrap()
}

fn camera(name: &str, x: f64) -> Camera {
    Camera::look_at(
        name,
        DVec3::new(x, 0.2, -2.5),
        DVec3::ZERO,
        DVec3::NEG_Y,
        (32, 32),
        40.0,
    )
    .unwrap()
}

/// A small model: the test is about the training loop, not the default's capacity.
fn small() -> NeuralConfig {
    NeuralConfig {
        levels: 3,
        features_per_level: 4,
        log2_table_size: 12,
        base_resolution: 4,
        growth: 2.0,
        hidden: 16,
        feature_width: 8,
    }
}

fn common(iterations: usize) -> CommonOptions {
    CommonOptions {
        iterations,
        lambda_dssim: 0.2,
        alpha_weight: 0.0,
        render: RenderOptions::default(),
        seed: 1,
        eval_every: 50,
        time_budget: None,
    }
}

#[test]
fn training_lowers_the_loss_and_raises_held_out_psnr() {
    let mesh = square();
    let set = init_bound(
        &mesh,
        &BindOptions {
            per_triangle: 200,
            ..BindOptions::default()
        },
    )
    .unwrap();
    let frame = |cams: &[Camera]| FitFrame {
        frame: 0,
        positions: mesh.positions().to_vec(),
        targets: mesh_targets(&mesh, mesh.positions(), cams, TargetColor::Auto, [0.0; 3]).unwrap(),
    };
    let train = [frame(&[
        camera("a", -0.6),
        camera("b", 0.0),
        camera("c", 0.6),
    ])];
    let held = [frame(&[camera("held", 0.3)])];
    let neural = NeuralFitOptions {
        config: small(),
        ..NeuralFitOptions::default()
    };
    let mut seen = Vec::new();
    let fitted = fit_neural(&set, &mesh, &train, &held, &common(150), &neural, |c| {
        seen.push(c.iteration)
    })
    .unwrap();
    assert_eq!(seen, [0, 50, 100, 150]);
    let c = &fitted.checkpoints;
    // The training loss (mean over the 50 iterations before each checkpoint) falls: observed
    // 0.293 -> 0.042.
    let (l50, l150) = (c[1].loss.unwrap(), c[3].loss.unwrap());
    assert!(l150 < 0.5 * l50, "loss {l50:.4} -> {l150:.4}");
    // Held-out views (never trained on) follow: observed 10.4 -> 31.5 dB.
    let (p0, p1) = (c[0].eval_psnr.unwrap(), c[3].eval_psnr.unwrap());
    assert!(p1 > p0 + 10.0, "held-out PSNR {p0:.2} -> {p1:.2} dB");
    assert!(c[3].eval_ssim.unwrap() > c[0].eval_ssim.unwrap() + 0.3);
    assert_eq!(fitted.iterations, 150);
}

#[test]
fn bad_options_are_refused() {
    let mesh = square();
    let set = init_bound(&mesh, &BindOptions::default()).unwrap();
    let train = [FitFrame {
        frame: 0,
        positions: mesh.positions().to_vec(),
        targets: mesh_targets(
            &mesh,
            mesh.positions(),
            &[camera("a", 0.0)],
            TargetColor::Auto,
            [0.0; 3],
        )
        .unwrap(),
    }];
    let neural = NeuralFitOptions {
        config: small(),
        ..NeuralFitOptions::default()
    };
    let mut o = common(2);
    o.render.mode = RenderMode::Perspective;
    let e = fit_neural(&set, &mesh, &train, &[], &o, &neural, |_| {}).unwrap_err();
    assert!(e.to_string().contains("perspective"), "{e}");
    let bad = NeuralFitOptions {
        config: NeuralConfig {
            levels: 0,
            ..small()
        },
        ..NeuralFitOptions::default()
    };
    let e = fit_neural(&set, &mesh, &train, &[], &common(2), &bad, |_| {}).unwrap_err();
    assert!(e.to_string().contains("levels"), "{e}");
    let e = fit_neural(&set, &mesh, &[], &[], &common(2), &neural, |_| {}).unwrap_err();
    assert!(e.to_string().contains("no training views"), "{e}");
}
