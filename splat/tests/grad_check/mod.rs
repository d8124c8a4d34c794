//! The finite-difference check shared by the backward-pass tests (`render_grad`, 3DGS, and
//! `render_grad_surfel`, 2DGS): a loss linear in the images with seeded random weights per pixel,
//! the parameter groups, and each group's relative error `max |analytic − fd| / max |fd|`
//! (relative to the group's scale, so components that are zero up to rounding do not count as
//! relative errors of 1).

// Each test uses the parts for its mode (3DGS has no normal weights or distortion).
#![allow(dead_code)]

use trisplat_geometry::Camera;
use trisplat_geometry::rng::Rng;
use trisplat_splat::GaussianSet;
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, ImageGrads, RenderOptions, backward, render_with_grad,
};

/// The bound on the relative error of each parameter group.
pub const MAX_REL_ERR: f64 = 1e-3;
/// Central-difference step (parameters are of order 0.1 to 1; the loss is evaluated in `f64`).
const STEP: f64 = 1e-6;

/// Seeded random per-pixel loss weights; `normal` is empty for a 3DGS loss, `lambda` weighs the
/// summed depth distortion (2DGS only).
pub struct Loss {
    pub rgb: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
    pub normal: Vec<f64>,
    pub lambda: f64,
}

impl Loss {
    /// Weights on rgb, alpha and depth (the 3DGS outputs).
    pub fn new(pixels: usize, seed: u64) -> Self {
        Self::drawn(pixels, seed, None)
    }

    /// Weights on rgb, alpha, depth and normal, and `lambda` times the distortion (2DGS).
    pub fn surfel(pixels: usize, seed: u64, lambda: f64) -> Self {
        Self::drawn(pixels, seed, Some(lambda))
    }

    fn drawn(pixels: usize, seed: u64, surfel_lambda: Option<f64>) -> Self {
        let mut rng = Rng::new(seed);
        let mut draw = |n: usize| (0..n).map(|_| rng.uniform_f64() - 0.5).collect::<Vec<_>>();
        let (rgb, alpha, depth) = (draw(3 * pixels), draw(pixels), draw(pixels));
        let normal = surfel_lambda.map_or_else(Vec::new, |_| draw(3 * pixels));
        Self {
            rgb,
            alpha,
            depth,
            normal,
            lambda: surfel_lambda.unwrap_or(0.0),
        }
    }

    /// The loss of the `f64` forward.
    pub fn value(&self, params: &GaussianParams, camera: &Camera, options: &RenderOptions) -> f64 {
        let out = render_with_grad::<f64, _>(params, camera, options).unwrap();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        dot(&out.rgb, &self.rgb)
            + dot(&out.alpha, &self.alpha)
            + dot(&out.depth, &self.depth)
            + dot(&out.normal, &self.normal)
            + self.lambda * out.distortion_total()
    }

    /// The image gradients of the loss (its weights).
    pub fn image_grads(&self) -> ImageGrads<'_, f64> {
        ImageGrads {
            rgb: Some(&self.rgb),
            alpha: Some(&self.alpha),
            depth: Some(&self.depth),
            normal: (!self.normal.is_empty()).then_some(&self.normal[..]),
            distortion: self.lambda,
        }
    }

    /// The weights in `f32`, for the `f32` backward: (rgb, alpha, depth, normal).
    pub fn weights_f32(&self) -> [Vec<f32>; 4] {
        let w = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<_>>();
        [
            w(&self.rgb),
            w(&self.alpha),
            w(&self.depth),
            w(&self.normal),
        ]
    }

    /// The analytic gradients of the loss.
    pub fn grads(
        &self,
        params: &GaussianParams,
        camera: &Camera,
        options: &RenderOptions,
    ) -> GaussianGrads {
        let fwd = render_with_grad::<f64, _>(params, camera, options).unwrap();
        backward(params, camera, options, &fwd, &self.image_grads()).unwrap()
    }

    /// [`Loss::grads`] on a pool of `threads` threads.
    pub fn grads_on(
        &self,
        threads: usize,
        params: &GaussianParams,
        camera: &Camera,
        options: &RenderOptions,
    ) -> GaussianGrads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| self.grads(params, camera, options))
    }
}

/// The parameter groups.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Group {
    Means,
    LogScales,
    Rotations,
    Opacity,
    Sh,
}

/// Every group, SH last.
pub const GROUPS: [Group; 5] = [
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

/// Relative error of each of `groups` over Gaussians `which`, given the analytic gradients `g`;
/// asserts that every analytic component is finite and that no group's gradient is all zero (a
/// test that compares zeros with zeros proves nothing).
pub fn group_errors(
    params: &GaussianParams,
    camera: &Camera,
    options: &RenderOptions,
    (which, groups): (&[usize], &[Group]),
    (loss, g): (&Loss, &GaussianGrads),
    label: &str,
) -> Vec<(Group, f64)> {
    let k = params.sh_per_gaussian();
    let mut out = Vec::new();
    for &group in groups {
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
                let a = analytic(g, group, i, c, k);
                assert!(a.is_finite(), "{label}: {group:?} {i} {c} not finite");
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

/// Asserts every group's relative error is within [`MAX_REL_ERR`]; returns the largest.
pub fn assert_within_bound(errors: &[(Group, f64)], label: &str) -> f64 {
    let mut overall = 0.0f64;
    for &(group, rel) in errors {
        assert!(
            rel <= MAX_REL_ERR,
            "{label}: {group:?} relative error {rel:.2e}"
        );
        overall = overall.max(rel);
    }
    overall
}

/// The largest absolute difference of two images.
pub fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
}

/// Per group, the `f32` backward's largest difference from the `f64` one relative to the
/// `f64` gradient's scale.
pub fn f32_against_f64(g32: &GaussianGrads, g64: &GaussianGrads) -> [f64; 5] {
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
    [
        rel(&flat3(&g32.means), &flat3(&g64.means)),
        rel(&flat3(&g32.log_scales), &flat3(&g64.log_scales)),
        rel(&flat4(&g32.rotations), &flat4(&g64.rotations)),
        rel(&g32.opacity_logits, &g64.opacity_logits),
        rel(&g32.sh, &g64.sh),
    ]
}

/// The degree-3 fixture scene `render/random_deg3.ply` and its cameras.
pub fn fixture_scene() -> (GaussianSet, Vec<Camera>) {
    let set =
        trisplat_splat::ply::read_gaussians(&trisplat_fixtures::path("render/random_deg3.ply"))
            .unwrap();
    let cams = trisplat_geometry::read_cameras_json(&trisplat_fixtures::path(
        "render/random_cameras.json",
    ))
    .unwrap();
    (set, cams)
}

/// Gaussian indices by their screen-space gradient in `g`, largest first.
pub fn by_screen_gradient(g: &GaussianGrads) -> Vec<usize> {
    let mut order: Vec<usize> = (0..g.means2d.len()).collect();
    let norm = |i: usize| g.means2d[i][0].hypot(g.means2d[i][1]);
    order.sort_by(|&a, &b| norm(b).total_cmp(&norm(a)));
    order
}
