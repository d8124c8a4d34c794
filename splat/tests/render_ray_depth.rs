//! `SplatDepth::Ray`: the depth of the point of highest density on each pixel's ray (RaDe-GS,
//! GOF), against the exact intersection of the ray with a flat Gaussian's plane; the mean's
//! depth left as it was; finite on degenerate and grazing Gaussians; no backward pass.

mod common;
use common::world_set;

use glam::{DVec3, Quat, Vec3};
use trisplat_geometry::Camera;
use trisplat_splat::GaussianSet;
use trisplat_splat::render::{
    GradError, Outputs, RenderOptions, SplatDepth, render, render_with_grad,
};

const SIZE: u32 = 256;

fn options(splat_depth: SplatDepth) -> RenderOptions {
    RenderOptions {
        outputs: Outputs {
            rgb: false,
            alpha: true,
            depth: true,
            median_depth: true,
            normal: false,
        },
        splat_depth,
        ..RenderOptions::default()
    }
}

/// Gaussians at `means` with rotations `rotations` and log-scales `log_scales`, opacity 0.99.
fn set(means: &[Vec3], rotations: &[Quat], log_scales: &[Vec3]) -> GaussianSet {
    world_set(means, rotations, log_scales, &vec![0.99; means.len()])
}

fn camera() -> Camera {
    common::camera(SIZE)
}

/// The world-space direction of pixel `(col, row)`'s centre whose camera z is 1.
fn ray(camera: &Camera, col: u32, row: u32) -> DVec3 {
    camera.rotation() * camera.unproject(f64::from(col) + 0.5, f64::from(row) + 0.5)
}

/// Largest |rendered − plane| over the pixels whose alpha is at least 1/2, for a flat Gaussian
/// tilted by `tilt_deg` about the world y axis at depth 2 (the exact depth of the ray's
/// intersection with the Gaussian's plane), and the number of those pixels.
fn plane_error(splat_depth: SplatDepth, tilt_deg: f32, median: bool) -> (f64, usize) {
    let mean = Vec3::new(0.0, 0.0, 2.0);
    let rotation = Quat::from_rotation_y(tilt_deg.to_radians());
    let set = set(
        &[mean],
        &[rotation],
        &[Vec3::new(0.05f32.ln(), 0.05f32.ln(), 1e-5f32.ln())],
    );
    let camera = camera();
    let out = render(&set, &camera, &options(splat_depth)).expect("renders");
    let alpha = out.images.alpha.expect("alpha");
    let depth = if median {
        out.images.median_depth.expect("median depth")
    } else {
        out.images.depth.expect("depth")
    };
    let normal = (rotation * Vec3::Z).as_dvec3();
    let along = normal.dot(mean.as_dvec3() - camera.position());
    let (mut worst, mut pixels) = (0.0f64, 0);
    for row in 0..SIZE {
        for col in 0..SIZE {
            let i = (row * SIZE + col) as usize;
            if alpha[i] < 0.5 {
                continue;
            }
            let exact = along / normal.dot(ray(&camera, col, row));
            worst = worst.max((f64::from(depth[i]) - exact).abs());
            pixels += 1;
        }
    }
    (worst, pixels)
}

#[test]
fn a_flat_gaussian_renders_the_depth_of_its_own_plane() {
    for median in [false, true] {
        let (ray_error, pixels) = plane_error(SplatDepth::Ray, 40.0, median);
        // Linearised around the mean's ray: a second-order error of about
        // z (tan 40° · 1.2 σ / z)² ≈ 1.3e-3 at the edge of the alpha ≥ 1/2 region.
        assert!(pixels > 50, "{pixels} pixels");
        assert!(ray_error < 2e-3, "ray depth off the plane by {ray_error}");
        // The mean's depth is a flat step: off the tilted plane by tan 40° × the offset.
        let (mean_error, _) = plane_error(SplatDepth::Mean, 40.0, median);
        assert!(
            mean_error > 2e-2,
            "mean depth off the plane by {mean_error}"
        );
    }
}

#[test]
fn a_gaussian_facing_the_camera_renders_the_same_depth_either_way() {
    let (ray, _) = plane_error(SplatDepth::Ray, 0.0, true);
    let (mean, _) = plane_error(SplatDepth::Mean, 0.0, true);
    assert!(ray < 1e-6 && mean < 1e-6, "{ray} {mean}");
}

#[test]
fn degenerate_and_grazing_gaussians_give_finite_depth_within_their_reach() {
    // Edge-on, nearly edge-on, a zero scale (exp(−200) underflows), an enormous one, a
    // needle along the view ray, and an isotropic blob off-axis.
    let q = |deg: f32| Quat::from_rotation_y(deg.to_radians());
    let means = [
        Vec3::new(-0.3, -0.3, 2.0),
        Vec3::new(0.3, -0.3, 2.0),
        Vec3::new(-0.3, 0.3, 2.0),
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::new(0.3, 0.3, 2.0),
        Vec3::new(0.4, 0.0, 2.5),
    ];
    let rotations = [q(90.0), q(89.999), q(30.0), q(10.0), q(0.0), q(0.0)];
    let log_scales = [
        Vec3::new(0.05f32.ln(), 0.05f32.ln(), 1e-6f32.ln()),
        Vec3::new(0.05f32.ln(), 0.05f32.ln(), 1e-6f32.ln()),
        Vec3::new(0.05f32.ln(), 0.05f32.ln(), -200.0),
        Vec3::new(80.0, 0.05f32.ln(), 0.05f32.ln()),
        Vec3::new(1e-4f32.ln(), 1e-4f32.ln(), 0.3f32.ln()),
        Vec3::splat(0.05f32.ln()),
    ];
    let set = set(&means, &rotations, &log_scales);
    let out = render(&set, &camera(), &options(SplatDepth::Ray)).expect("renders");
    for image in [out.images.depth, out.images.median_depth] {
        let image = image.expect("depth");
        assert!(image.iter().all(|d| d.is_finite() && *d >= 0.0));
    }
    // Each splat alone: its depths lie within 3 × its largest scale of its mean's depth.
    for k in [0, 1, 2, 4, 5] {
        let one = self::set(&means[k..=k], &rotations[k..=k], &log_scales[k..=k]);
        let out = render(&one, &camera(), &options(SplatDepth::Ray)).expect("renders");
        let reach = 3.0 * log_scales[k].max_element().exp() + 1e-5;
        for d in out.images.median_depth.expect("median depth") {
            assert!(
                d == 0.0 || (d - means[k].z).abs() <= reach,
                "splat {k}: {d}"
            );
        }
    }
}

#[test]
fn ray_depth_has_no_backward_pass() {
    let set = set(
        &[Vec3::new(0.0, 0.0, 2.0)],
        &[Quat::IDENTITY],
        &[Vec3::splat(-3.0)],
    );
    let Err(err) = render_with_grad::<f32, _>(&set, &camera(), &options(SplatDepth::Ray)) else {
        panic!("ray depth was differentiated");
    };
    assert_eq!(err, GradError::RayDepth);
}
