//! The 2DGS surfel backward pass against torch autograd
//! (`tests/reference/ref_render_surfel_grad.py`: gsplat 1.5.3's own torch 2DGS projection and
//! SH, hbb1's per-pixel rules and compositing written in torch, the depth distortion as an
//! explicit pairwise sum, all in float64; pins in `tests/reference/requirements-gsplat.txt`) on
//! a random degree-3 scene with a grazing surfel and a needle, normals in the camera and the
//! world frame.
//!
//! The loss is linear in the rgb, alpha, depth and normal images with the script's weights
//! (below) plus the script's `distortion_weight` times the summed distortion. Errors per
//! quantity are `max |ours − torch| / max |torch|` over its values.

mod reference_json;

use reference_json::{floats, max_rel, rows};
use serde_json::Value;
use trisplat_geometry::mesh_render::NormalFrame;
use trisplat_geometry::read_cameras_json;
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, GradRender, ImageGrads, Real, RenderMode, RenderOptions,
    backward, render_with_grad,
};

/// Our `f64` path against torch's `f64` autograd: the same formulas, so rounding only.
const MAX_REL_ERR_F64: f64 = 1e-9;
/// Our `f32` compositing (the production path; the surfel kernel itself is `f64`) against
/// torch's `f64`.
const MAX_REL_ERR_F32: f64 = 2e-4;

/// The script's loss weights for row-major pixel `i` (and channel `c`).
struct Weights {
    rgb: Vec<f64>,
    alpha: Vec<f64>,
    depth: Vec<f64>,
    normal: Vec<f64>,
}

fn weights(pixels: usize) -> Weights {
    let per_channel = |f: fn(f64, f64) -> f64| {
        (0..pixels)
            .flat_map(move |i| (0..3).map(move |c| f(i as f64, f64::from(c))))
            .collect::<Vec<_>>()
    };
    Weights {
        rgb: per_channel(|i, c| (0.1 * i + 0.7 * c + 0.3).sin()),
        alpha: (0..pixels).map(|i| (0.13 * i as f64).cos()).collect(),
        depth: (0..pixels)
            .map(|i| 0.2 * (0.05 * i as f64 + 1.0).sin())
            .collect(),
        normal: per_channel(|i, c| 0.3 * (0.07 * i + 0.5 * c).cos()),
    }
}

fn run<F: Real>(
    params: &GaussianParams,
    camera: &trisplat_geometry::Camera,
    options: &RenderOptions,
    lambda: f64,
) -> (GradRender<F>, GaussianGrads) {
    let pixels = camera.width as usize * camera.height as usize;
    let w = weights(pixels);
    let cast = |v: &[f64]| v.iter().map(|&x| F::of(x)).collect::<Vec<F>>();
    let (wr, wa, wd, wn) = (
        cast(&w.rgb),
        cast(&w.alpha),
        cast(&w.depth),
        cast(&w.normal),
    );
    let fwd = render_with_grad::<F, _>(params, camera, options).unwrap();
    let g = backward(
        params,
        camera,
        options,
        &fwd,
        &ImageGrads {
            rgb: Some(&wr),
            alpha: Some(&wa),
            depth: Some(&wd),
            normal: Some(&wn),
            distortion: F::of(lambda),
        },
    )
    .unwrap();
    (fwd, g)
}

fn compare(case: &str) {
    let dir = trisplat_fixtures::path("reference/render_surfel_grad");
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{case}.json"))).unwrap())
            .unwrap();
    let cams = read_cameras_json(&dir.join("cameras.json")).unwrap();
    let camera = cams
        .iter()
        .find(|c| c.name == doc["camera"].as_str().unwrap())
        .unwrap();
    let p = &doc["params"];
    let params = GaussianParams {
        means: rows(&p["means"]),
        log_scales: rows(&p["log_scales"]),
        rotations: rows(&p["rotations"]),
        opacity_logits: floats(&p["opacity_logits"]),
        sh_degree: p["sh_degree"].as_u64().unwrap() as u8,
        sh: floats(&p["sh"]),
    };
    let bg = floats(&doc["background"]);
    let options = RenderOptions {
        mode: RenderMode::Surfel2d,
        near: doc["near"].as_f64().unwrap() as f32,
        normal_frame: match doc["normal_frame"].as_str().unwrap() {
            "world" => NormalFrame::World,
            _ => NormalFrame::Camera,
        },
        background: [bg[0] as f32, bg[1] as f32, bg[2] as f32],
        ..RenderOptions::default()
    };
    let lambda = doc["distortion_weight"].as_f64().unwrap();
    let flat3 = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let flat4 = |v: &[[f64; 4]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let errors = |images: [Vec<f64>; 5], g: &GaussianGrads| {
        let gr = &doc["grads"];
        let im = &doc["images"];
        [
            ("rgb", max_rel(&images[0], &floats(&im["rgb"]))),
            ("alpha", max_rel(&images[1], &floats(&im["alpha"]))),
            ("depth", max_rel(&images[2], &floats(&im["depth"]))),
            ("normal", max_rel(&images[3], &floats(&im["normal"]))),
            (
                "distortion",
                max_rel(&images[4], &floats(&im["distortion"])),
            ),
            (
                "d/d means",
                max_rel(&flat3(&g.means), &floats(&gr["means"])),
            ),
            (
                "d/d log-scales",
                max_rel(&flat3(&g.log_scales), &floats(&gr["log_scales"])),
            ),
            (
                "d/d quaternions",
                max_rel(&flat4(&g.rotations), &floats(&gr["rotations"])),
            ),
            (
                "d/d opacity logits",
                max_rel(&g.opacity_logits, &floats(&gr["opacity_logits"])),
            ),
            ("d/d SH", max_rel(&g.sh, &floats(&gr["sh"]))),
        ]
    };
    let (f64_fwd, g64) = run::<f64>(&params, camera, &options, lambda);
    assert_eq!(
        f64_fwd.visible() as u64,
        doc["visible"].as_u64().unwrap(),
        "{case}: visible surfels"
    );
    let (f32_fwd, g32) = run::<f32>(&params, camera, &options, lambda);
    let wide = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
    let images64 = [
        f64_fwd.rgb.clone(),
        f64_fwd.alpha.clone(),
        f64_fwd.depth.clone(),
        f64_fwd.normal.clone(),
        f64_fwd.distortion.clone(),
    ];
    let images32 = [
        wide(&f32_fwd.rgb),
        wide(&f32_fwd.alpha),
        wide(&f32_fwd.depth),
        wide(&f32_fwd.normal),
        wide(&f32_fwd.distortion),
    ];
    for (precision, errs, bound) in [
        ("f64", errors(images64, &g64), MAX_REL_ERR_F64),
        ("f32", errors(images32, &g32), MAX_REL_ERR_F32),
    ] {
        for (what, e) in errs {
            println!("{case} ({precision}): {what} relative error {e:.2e}");
            assert!(
                e <= bound,
                "{case} ({precision}): {what} {e:.2e} > {bound:.0e}"
            );
        }
    }
}

#[test]
fn surfel_scene_camera_normals_against_torch() {
    compare("random");
}

#[test]
fn surfel_scene_world_normals_against_torch() {
    compare("random_world");
}
