//! The 3DGS backward pass against torch autograd (`tests/reference/ref_render_grad.py`: gsplat
//! 1.5.3's own torch projection and SH, compositing after its CUDA kernel written in torch, all
//! in float64; pins in `tests/reference/requirements-gsplat.txt`) on a random degree-3 scene
//! (plain and antialiased) and on a subset of the degree-3 fixture `render/random_deg3.ply`.
//!
//! The loss is linear in the images with the script's weights (below). Errors per quantity are
//! `max |ours − torch| / max |torch|` over its values.

use std::path::Path;

mod reference_json;

use reference_json::{floats, max_rel, rows};
use serde_json::Value;
use trisplat_geometry::read_cameras_json;
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, GradRender, ImageGrads, Real, RenderOptions, backward,
    render_with_grad,
};

/// Our `f64` path against torch's `f64` autograd: the same formulas, so rounding only.
const MAX_REL_ERR_F64: f64 = 1e-9;
/// Our `f32` path (the production one: per-pixel arithmetic in `f32` like gsplat's kernels)
/// against torch's `f64`.
const MAX_REL_ERR_F32: f64 = 2e-4;

/// The script's loss weights for row-major pixel `i` (and channel `c`).
fn weights(pixels: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let rgb = (0..pixels)
        .flat_map(|i| (0..3).map(move |c| (0.1 * i as f64 + 0.7 * c as f64 + 0.3).sin()))
        .collect();
    let alpha = (0..pixels).map(|i| (0.13 * i as f64).cos()).collect();
    let depth = (0..pixels)
        .map(|i| 0.2 * (0.05 * i as f64 + 1.0).sin())
        .collect();
    (rgb, alpha, depth)
}

fn run<F: Real>(
    params: &GaussianParams,
    camera: &trisplat_geometry::Camera,
    options: &RenderOptions,
) -> (GradRender<F>, GaussianGrads) {
    let pixels = camera.width as usize * camera.height as usize;
    let (wr, wa, wd) = weights(pixels);
    let cast = |v: &[f64]| v.iter().map(|&x| F::of(x)).collect::<Vec<F>>();
    let (wr, wa, wd) = (cast(&wr), cast(&wa), cast(&wd));
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
            ..ImageGrads::default()
        },
    )
    .unwrap();
    (fwd, g)
}

fn compare(case: &str) {
    let dir = trisplat_fixtures::path("reference/render_grad");
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
        antialiased: doc["antialiased"].as_bool().unwrap(),
        background: [bg[0] as f32, bg[1] as f32, bg[2] as f32],
        ..RenderOptions::default()
    };
    let flat3 = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let flat4 = |v: &[[f64; 4]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let errors = |fwd_images: [Vec<f64>; 3], g: &GaussianGrads| {
        let gr = &doc["grads"];
        let im = &doc["images"];
        [
            ("rgb", max_rel(&fwd_images[0], &floats(&im["rgb"]))),
            ("alpha", max_rel(&fwd_images[1], &floats(&im["alpha"]))),
            ("depth", max_rel(&fwd_images[2], &floats(&im["depth"]))),
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
    let (f64_fwd, g64) = run::<f64>(&params, camera, &options);
    assert_eq!(
        f64_fwd.visible() as u64,
        doc["visible"].as_u64().unwrap(),
        "{case}: visible Gaussians"
    );
    let (f32_fwd, g32) = run::<f32>(&params, camera, &options);
    let wide = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
    for (precision, errs, bound) in [
        (
            "f64",
            errors(
                [
                    f64_fwd.rgb.clone(),
                    f64_fwd.alpha.clone(),
                    f64_fwd.depth.clone(),
                ],
                &g64,
            ),
            MAX_REL_ERR_F64,
        ),
        (
            "f32",
            errors(
                [
                    wide(&f32_fwd.rgb),
                    wide(&f32_fwd.alpha),
                    wide(&f32_fwd.depth),
                ],
                &g32,
            ),
            MAX_REL_ERR_F32,
        ),
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
fn random_scene_against_torch() {
    compare("random");
}

#[test]
fn random_scene_antialiased_against_torch() {
    compare("random_aa");
}

#[test]
fn degree3_fixture_against_torch() {
    compare("deg3_fixture");
}

#[test]
fn the_fixture_subset_is_the_ply_rows() {
    // The deg3 case's parameters are rows of the fixture PLY (so the comparison is on real file
    // values, not a copy that could drift).
    let dir = trisplat_fixtures::path("reference/render_grad");
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("deg3_fixture.json")).unwrap())
            .unwrap();
    let set = trisplat_splat::ply::read_gaussians(Path::new(&trisplat_fixtures::path(
        "render/random_deg3.ply",
    )))
    .unwrap();
    let idx: Vec<usize> = doc["ply_indices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let sub = GaussianParams::from_set(&set.select(&idx));
    assert_eq!(sub.means, rows::<3>(&doc["params"]["means"]));
    assert_eq!(sub.sh, floats(&doc["params"]["sh"]));
}
