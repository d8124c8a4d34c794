//! `RenderOptions::contribution`: each Gaussian's largest blending weight `α·T` over the image,
//! against the same weight assembled from two independent renders per Gaussian (its own alpha,
//! times the transmittance left by the Gaussians sorted before it); hidden, culled and lone
//! Gaussians.

mod common;
use common::{camera, world_set};

use glam::{Quat, Vec3};
use trisplat_splat::GaussianSet;
use trisplat_splat::render::{Outputs, RenderMode, RenderOptions, render};

const SIZE: u32 = 64;

fn options(mode: RenderMode, contribution: bool) -> RenderOptions {
    RenderOptions {
        mode,
        outputs: Outputs {
            rgb: false,
            alpha: true,
            depth: false,
            median_depth: false,
            normal: false,
        },
        contribution,
        ..RenderOptions::default()
    }
}

/// A deterministic value in [0, 1).
fn unit(state: &mut u64) -> f32 {
    *state = state
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    (*state >> 40) as f32 / (1u64 << 24) as f32
}

/// 40 Gaussians of opacity ≤ 0.5 in front of the camera at distinct depths (so the depth order
/// has no ties and the transmittance never reaches the stopping threshold).
fn random_scene(seed: u64) -> GaussianSet {
    let mut state = seed;
    let n = 40;
    let mut means = Vec::new();
    let mut rotations = Vec::new();
    let mut scales = Vec::new();
    let mut opacities = Vec::new();
    for i in 0..n {
        let z = 2.0 + 0.02 * i as f32 + 0.001 * unit(&mut state);
        means.push(Vec3::new(
            0.6 * (unit(&mut state) - 0.5),
            0.6 * (unit(&mut state) - 0.5),
            z,
        ));
        let axis = Vec3::new(
            unit(&mut state) - 0.5,
            unit(&mut state) - 0.5,
            unit(&mut state) - 0.5,
        )
        .normalize_or(Vec3::X);
        rotations.push(Quat::from_axis_angle(axis, 6.0 * unit(&mut state)));
        scales.push(Vec3::new(
            (0.02 + 0.1 * unit(&mut state)).ln(),
            (0.02 + 0.1 * unit(&mut state)).ln(),
            (0.01 + 0.05 * unit(&mut state)).ln(),
        ));
        opacities.push(0.05 + 0.45 * unit(&mut state));
    }
    world_set(&means, &rotations, &scales, &opacities)
}

fn alpha_of(set: &GaussianSet, mode: RenderMode) -> Vec<f32> {
    render(set, &camera(SIZE), &options(mode, false))
        .expect("renders")
        .images
        .alpha
        .expect("alpha")
}

#[test]
fn largest_weight_equals_own_alpha_times_the_transmittance_in_front() {
    for mode in [RenderMode::Gaussian3d, RenderMode::Perspective] {
        for seed in [1, 2, 3] {
            let scene = random_scene(seed);
            let out = render(&scene, &camera(SIZE), &options(mode, true)).expect("renders");
            let got = out.contribution.expect("contribution asked for");
            assert_eq!(got.len(), scene.len());
            // Means are at increasing depth by index: the ones before i are in front of it.
            let mut positive = 0;
            for (i, &w) in got.iter().enumerate() {
                let own = alpha_of(&scene.select(&[i]), mode);
                let front: Vec<usize> = (0..i).collect();
                let in_front = if front.is_empty() {
                    vec![0.0; own.len()]
                } else {
                    alpha_of(&scene.select(&front), mode)
                };
                let expected = own
                    .iter()
                    .zip(&in_front)
                    .map(|(a, f)| a * (1.0 - f))
                    .fold(0.0f32, f32::max);
                assert!(
                    (w - expected).abs() <= 1e-5,
                    "{mode:?} seed {seed}: Gaussian {i} largest weight {w}, expected {expected}"
                );
                positive += usize::from(w > 0.0);
            }
            assert!(
                positive > 30,
                "{mode:?} seed {seed}: only {positive} visible"
            );
        }
    }
}

#[test]
fn hidden_culled_and_lone_gaussians() {
    let flat = Vec3::new(0.5f32.ln(), 0.5f32.ln(), 1e-3f32.ln());
    let small = Vec3::splat(0.05f32.ln());
    let scene = world_set(
        &[
            // An opaque wall filling the view.
            Vec3::new(0.0, 0.0, 2.0),
            // Behind it.
            Vec3::new(0.0, 0.0, 3.0),
            // Behind the camera.
            Vec3::new(0.0, 0.0, -1.0),
        ],
        &[Quat::IDENTITY; 3],
        &[flat, small, small],
        &[0.999, 0.9, 0.9],
    );
    let out = render(
        &scene,
        &camera(SIZE),
        &options(RenderMode::Gaussian3d, true),
    )
    .expect("renders");
    let w = out.contribution.expect("contribution");
    // The wall's alpha is clamped at gsplat's 0.999.
    assert!(w[0] > 0.99 && w[0] <= 0.999, "the wall's weight {}", w[0]);
    // Without the wall it would reach 0.9; the wall lets through a few thousandths.
    assert!(w[1] < 1e-2 && w[1] > 0.0, "behind the wall: {}", w[1]);
    assert_eq!(w[2], 0.0, "culled");

    let lone = world_set(
        &[Vec3::new(0.0, 0.0, 2.0)],
        &[Quat::IDENTITY],
        &[small],
        &[0.3],
    );
    let out =
        render(&lone, &camera(SIZE), &options(RenderMode::Gaussian3d, true)).expect("renders");
    let peak = out
        .images
        .alpha
        .expect("alpha")
        .iter()
        .copied()
        .fold(0.0f32, f32::max);
    assert_eq!(out.contribution.expect("contribution"), vec![peak]);

    let none = render(
        &lone,
        &camera(SIZE),
        &options(RenderMode::Gaussian3d, false),
    )
    .expect("renders");
    assert!(none.contribution.is_none(), "only computed when asked for");
}
