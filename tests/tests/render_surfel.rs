//! 2DGS surfel rendering against a float64 re-implementation of hbb1's diff-surfel-rasterization
//! forward pass (`tests/reference/ref_render_surfel.py` → `fixtures/data/reference/render_surfel/`):
//! 22 surfels (random ones, an edge-on one, a sub-pixel one drawn by the low-pass filter alone,
//! invisible, near-plane and behind-camera ones, a large one) seen by two cameras (one with
//! fx ≠ fy and an off-centre principal point), every output compared.

use std::path::Path;

use glam::Vec3;
use serde::Deserialize;
use trisplat_geometry::io::read_npy;
use trisplat_geometry::mesh_render::NormalFrame;
use trisplat_geometry::read_cameras_json;
use trisplat_splat::render::{Outputs, RenderMode, RenderOptions, RenderStats, rasterize};
use trisplat_splat::render::{SURFEL_NEAR, SURFEL_RULES, project_surfels};
use trisplat_splat::{GaussianParts, GaussianSet, ScaleDims};

/// Alpha, rgb and composited normals: absolute error (the issue asks 1e-4 for alpha). Ours
/// composites in f32 like hbb1's kernel; the reference is f64.
const MAX_ABS_ERROR: f32 = 1e-4;
/// Expected and median depth: relative error where the reference alpha is positive.
const MAX_DEPTH_RELATIVE_ERROR: f32 = 1e-4;
/// Unit length of per-surfel normals.
const UNIT_TOLERANCE: f32 = 1e-6;

#[derive(Deserialize)]
struct Surfel {
    mean: [f32; 3],
    rotation: [f32; 4],
    log_scale: [f32; 2],
    opacity_logit: f32,
    f_dc: [f32; 3],
}

#[derive(Deserialize)]
struct Scene {
    near: f32,
    background: [f32; 3],
    surfels: Vec<Surfel>,
}

fn dir() -> std::path::PathBuf {
    trisplat_fixtures::path("reference/render_surfel")
}

fn load_scene(path: &Path) -> (Scene, GaussianSet) {
    let text = std::fs::read_to_string(path).expect("scene.json");
    let scene: Scene = serde_json::from_str(&text).expect("scene");
    let s = &scene.surfels;
    let set = GaussianSet::try_new(GaussianParts {
        means: s.iter().map(|g| Vec3::from_array(g.mean)).collect(),
        log_scales: s
            .iter()
            .map(|g| Vec3::new(g.log_scale[0], g.log_scale[1], 0.0))
            .collect(),
        scale_dims: ScaleDims::Two,
        rotations: s.iter().map(|g| g.rotation).collect(),
        opacity_logits: s.iter().map(|g| g.opacity_logit).collect(),
        sh_degree: 0,
        sh: s.iter().flat_map(|g| g.f_dc).collect(),
        ..GaussianParts::default()
    })
    .expect("valid surfels");
    (scene, set)
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn surfels_match_hbb1_reference() {
    let (scene, set) = load_scene(&dir().join("scene.json"));
    assert_eq!(scene.near, SURFEL_NEAR);
    let cameras = read_cameras_json(&dir().join("cameras.json")).expect("cameras");
    let options = RenderOptions {
        mode: RenderMode::Surfel2d,
        outputs: Outputs::ALL,
        background: scene.background,
        near: SURFEL_NEAR,
        normal_frame: NormalFrame::Camera,
        ..RenderOptions::default()
    };
    for cam in &cameras {
        let (screen, kernel) = project_surfels(&set, cam, &options);
        // Invisible (opacity < 1/255), near-plane and behind-camera surfels are culled.
        assert!(screen.len() < set.len(), "{}", cam.name);
        for n in &screen.normals {
            assert!((Vec3::from_array(*n).length() - 1.0).abs() < UNIT_TOLERANCE);
            assert!(n[2] <= 0.0, "faces the camera");
        }
        let mut stats = RenderStats::default();
        let img = rasterize(
            &screen,
            &kernel,
            (cam.width, cam.height),
            &SURFEL_RULES,
            options.outputs,
            options.background,
            &mut stats,
        );
        assert!(img.is_finite());
        let read = |name: &str| {
            read_npy(&dir().join(format!("{}_{name}.npy", cam.name)))
                .expect("reference")
                .data
        };
        let (alpha_ref, depth_ref, median_ref) = (read("alpha"), read("depth"), read("median"));
        let alpha = img.alpha.as_deref().expect("alpha");
        let depth = img.depth.as_deref().expect("depth");
        let median = img.median_depth.as_deref().expect("median");
        let normal = img.normal.as_deref().expect("normal");
        let rgb = img.rgb.as_deref().expect("rgb");
        let alpha_err = max_abs(alpha, &alpha_ref);
        let rgb_err = max_abs(rgb, &read("rgb"));
        let normal_err = max_abs(normal, &read("normal"));
        let mut depth_err = 0.0f32;
        let mut median_err = 0.0f32;
        let mut covered = 0;
        for p in 0..alpha.len() {
            if alpha_ref[p] > 0.0 {
                covered += 1;
                depth_err = depth_err.max((depth[p] - depth_ref[p]).abs() / depth_ref[p]);
                let m = median_ref[p].abs().max(f32::MIN_POSITIVE);
                median_err = median_err.max((median[p] - median_ref[p]).abs() / m);
                // A composited normal is a weighted sum of unit normals: |N| <= alpha.
                let n = Vec3::from_slice(&normal[3 * p..3 * p + 3]).length();
                assert!(n <= alpha[p] + MAX_ABS_ERROR, "{n} > {}", alpha[p]);
            } else {
                assert_eq!(alpha[p], 0.0);
                assert_eq!(depth[p], 0.0);
            }
        }
        println!(
            "{}: {covered} covered pixels, {} visible surfels; max errors: alpha {alpha_err:.2e}, \
             rgb {rgb_err:.2e}, normal {normal_err:.2e}, depth (rel) {depth_err:.2e}, \
             median depth (rel) {median_err:.2e}",
            cam.name,
            screen.len()
        );
        assert!(covered > 1000);
        assert!(alpha_err <= MAX_ABS_ERROR, "alpha {alpha_err}");
        assert!(rgb_err <= MAX_ABS_ERROR, "rgb {rgb_err}");
        assert!(normal_err <= MAX_ABS_ERROR, "normal {normal_err}");
        assert!(depth_err <= MAX_DEPTH_RELATIVE_ERROR, "depth {depth_err}");
        assert!(
            median_err <= MAX_DEPTH_RELATIVE_ERROR,
            "median {median_err}"
        );
    }
}

#[test]
fn surfel_extremes_render_finite_images() {
    // A camera at the origin looking down +z (world = camera axes).
    let camera = |w: u32, h: u32| {
        trisplat_geometry::Camera::try_new(
            0,
            "c",
            w,
            h,
            (0.6 * f64::from(h), 0.6 * f64::from(h)),
            (0.5 * f64::from(w), 0.5 * f64::from(h)),
            glam::DMat3::IDENTITY,
            glam::DVec3::ZERO,
        )
        .expect("camera")
    };
    let g = |mean: [f32; 3], rotation: [f32; 4], log_scale: f32, opacity_logit: f32| Surfel {
        mean,
        rotation,
        log_scale: [log_scale, log_scale],
        opacity_logit,
        f_dc: [0.5, -0.5, 0.1],
    };
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let edge_on = [h, 0.0, h, 0.0];
    let surfels = vec![
        g([0.0, 0.0, -2.0], [1.0, 0.0, 0.0, 0.0], -2.0, 2.0), // behind the camera
        g([0.0, 0.0, 0.2], [1.0, 0.0, 0.0, 0.0], -2.0, 2.0),  // on the near plane
        g([0.1, 0.1, 2.0], [1.0, 0.0, 0.0, 0.0], -29.0, 2.0), // sub-pixel
        g([0.0, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], 6.9, 0.0),   // scale 1e3: fills the view
        g([0.0, 0.0, 2.0], [1.0, 0.0, 0.0, 0.0], -1.0, -69.0), // opacity ~1e-30
        g([0.0, 0.0, 1.5], edge_on, -1.0, 2.0),               // edge-on through the centre
        g([-0.2, 0.1, 1.0], [0.9, 0.3, -0.2, 0.1], -1.5, 1.0),
    ];
    let s = &surfels;
    let set = GaussianSet::try_new(GaussianParts {
        means: s.iter().map(|g| Vec3::from_array(g.mean)).collect(),
        log_scales: s
            .iter()
            .map(|g| Vec3::new(g.log_scale[0], g.log_scale[1], 0.0))
            .collect(),
        scale_dims: ScaleDims::Two,
        rotations: s.iter().map(|g| g.rotation).collect(),
        opacity_logits: s.iter().map(|g| g.opacity_logit).collect(),
        sh_degree: 0,
        sh: s.iter().flat_map(|g| g.f_dc).collect(),
        ..GaussianParts::default()
    })
    .expect("valid");
    let options = RenderOptions {
        mode: RenderMode::Surfel2d,
        outputs: Outputs::ALL,
        near: SURFEL_NEAR,
        ..RenderOptions::default()
    };
    let empty = set.select(&[]);
    for (w, h) in [(1, 1), (40, 30)] {
        let cam = camera(w, h);
        for set in [&set, &empty] {
            let (screen, kernel) = project_surfels(set, &cam, &options);
            for n in &screen.normals {
                assert!((Vec3::from_array(*n).length() - 1.0).abs() < UNIT_TOLERANCE);
            }
            let img = rasterize(
                &screen,
                &kernel,
                (w, h),
                &SURFEL_RULES,
                options.outputs,
                options.background,
                &mut RenderStats::default(),
            );
            assert!(img.is_finite());
            let alpha = img.alpha.expect("alpha");
            assert!(alpha.iter().all(|a| (0.0..=1.0).contains(a)));
            if set.is_empty() {
                assert!(alpha.iter().all(|&a| a == 0.0));
            } else {
                // The huge surfel covers every pixel.
                assert!(alpha.iter().all(|&a| a > 0.4), "{alpha:?}");
            }
        }
    }
}
