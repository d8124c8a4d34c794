//! Scores of a material fit against known materials, as HRAvatar (CVPR 2025, Table 3) reports
//! them on synthetic avatars: the albedo maps' LMSE and the normal maps' cosine similarity.
//!
//! Both sets (world parameters, the same means and opacities) are rendered per camera by the
//! 3DGS or 2DGS renderer with the given options: the albedo map is the composited albedo
//! `Σ w albedo` (black background, not divided by alpha), the normal map the composited
//! per-Gaussian normal `Σ w n` ([`normal_of`]: shortest axis facing the camera).
//!
//! - **LMSE** (local mean squared error, Grosse et al. 2009, the MIT intrinsic-images
//!   benchmark's): over windows of 20 × 20 pixels every 10 pixels, each window's squared error
//!   after the best scale of the prediction (`α = Σ t p / Σ p²` over the window's masked pixels,
//!   the three channels sharing it; 0 when `Σ p² ≤ 1e-5`), summed and divided by the windows'
//!   `Σ t²`. The mask: the truth's alpha above ½. Per view, then the mean over the views.
//! - **Normal cosine**: the mean over the pixels where both alphas exceed ½ of
//!   `cos∠(n_truth, n_fit)` of the (re-normalised) composited normals; the mean over the views.

use trisplat_geometry::Camera;
use trisplat_splat::material::{Material, normal_of};
use trisplat_splat::render::{GaussianParams, RenderOptions, render_with_grad};
use trisplat_splat::rgb_to_dc;

use super::inputs::FitError;

/// LMSE window size and step (Grosse et al.).
pub const LMSE_WINDOW: usize = 20;

/// The scores of [`material_scores`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct MaterialScores {
    /// Mean over the views of the albedo maps' LMSE (lower is better).
    pub albedo_lmse: f64,
    /// Mean over the views of the normal maps' cosine similarity (1 is best).
    pub normal_cosine: f64,
    /// Views scored.
    pub views: usize,
}

/// `params` with colours `colors` as degree-0 SH.
fn with_colors(params: &GaussianParams, colors: impl Iterator<Item = [f32; 3]>) -> GaussianParams {
    GaussianParams {
        sh_degree: 0,
        sh: colors
            .flat_map(|c| c.map(|v| f64::from(rgb_to_dc(v))))
            .collect(),
        ..params.clone()
    }
}

/// One view's albedo map `[H, W, 3]`, normal map `[H, W, 3]` and alpha `[H, W]`.
struct Maps {
    albedo: Vec<f32>,
    normal: Vec<f32>,
    alpha: Vec<f32>,
}

/// Renders `params`' albedo and normal maps and alpha from `camera`.
fn maps(
    params: &GaussianParams,
    material: &Material,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<Maps, FitError> {
    let black = RenderOptions {
        background: [0.0; 3],
        ..*options
    };
    let err = |source| FitError::Render {
        iteration: 0,
        view: camera.name.clone(),
        source,
    };
    let albedo = render_with_grad::<f32, _>(
        &with_colors(params, material.albedo.iter().copied()),
        camera,
        &black,
    )
    .map_err(err)?;
    let eye = camera.position();
    // (n + 1) / 2 composited: Σ w n = 2 C − alpha.
    let halves = (0..params.means.len()).map(|i| {
        let n = normal_of(params, i, eye).normal;
        [
            (0.5 * (n.x + 1.0)) as f32,
            (0.5 * (n.y + 1.0)) as f32,
            (0.5 * (n.z + 1.0)) as f32,
        ]
    });
    let normal =
        render_with_grad::<f32, _>(&with_colors(params, halves), camera, &black).map_err(err)?;
    let normals = normal
        .rgb
        .chunks_exact(3)
        .zip(&normal.alpha)
        .flat_map(|(c, &a)| [2.0 * c[0] - a, 2.0 * c[1] - a, 2.0 * c[2] - a])
        .collect();
    Ok(Maps {
        albedo: albedo.rgb,
        normal: normals,
        alpha: albedo.alpha,
    })
}

/// The LMSE of `pred` against `truth` (`[H, W, 3]`) inside `mask` (module documentation).
#[must_use]
pub fn lmse(truth: &[f32], pred: &[f32], mask: &[bool], width: usize, height: usize) -> f64 {
    let (k, step) = (LMSE_WINDOW, LMSE_WINDOW / 2);
    let (mut ssq, mut total) = (0.0f64, 0.0f64);
    let mut y = 0;
    while y + k <= height {
        let mut x = 0;
        while x + k <= width {
            let (mut tp, mut pp, mut tt) = (0.0f64, 0.0f64, 0.0f64);
            for j in y..y + k {
                for i in x..x + k {
                    let p = j * width + i;
                    if !mask[p] {
                        continue;
                    }
                    for c in 0..3 {
                        let (t, e) = (f64::from(truth[3 * p + c]), f64::from(pred[3 * p + c]));
                        tp += t * e;
                        pp += e * e;
                        tt += t * t;
                    }
                }
            }
            let alpha = if pp > 1e-5 { tp / pp } else { 0.0 };
            // Σ (t − α p)² = Σ t² − 2 α Σ t p + α² Σ p².
            ssq += (tt - 2.0 * alpha * tp + alpha * alpha * pp).max(0.0);
            total += tt;
            x += step;
        }
        y += step;
    }
    if total > 0.0 { ssq / total } else { 0.0 }
}

/// Scores `fitted` (world parameters and material) against `truth` over `cameras` (module
/// documentation). Views where the truth covers no pixel are skipped.
///
/// # Errors
/// [`FitError::Render`] when a camera cannot be rendered.
pub fn material_scores(
    truth: (&GaussianParams, &Material),
    fitted: (&GaussianParams, &Material),
    cameras: &[Camera],
    options: &RenderOptions,
) -> Result<MaterialScores, FitError> {
    let mut scores = MaterialScores::default();
    for camera in cameras {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let Maps {
            albedo: ta,
            normal: tn,
            alpha: talpha,
        } = maps(truth.0, truth.1, camera, options)?;
        let Maps {
            albedo: fa,
            normal: fnorm,
            alpha: falpha,
        } = maps(fitted.0, fitted.1, camera, options)?;
        let mask: Vec<bool> = talpha.iter().map(|&a| a > 0.5).collect();
        let (mut cos, mut count) = (0.0f64, 0usize);
        for p in 0..w * h {
            if !(mask[p] && falpha[p] > 0.5) {
                continue;
            }
            let a = glam::DVec3::new(
                f64::from(tn[3 * p]),
                f64::from(tn[3 * p + 1]),
                f64::from(tn[3 * p + 2]),
            );
            let b = glam::DVec3::new(
                f64::from(fnorm[3 * p]),
                f64::from(fnorm[3 * p + 1]),
                f64::from(fnorm[3 * p + 2]),
            );
            if let (Some(a), Some(b)) = (a.try_normalize(), b.try_normalize()) {
                cos += a.dot(b);
                count += 1;
            }
        }
        if count == 0 {
            continue;
        }
        scores.albedo_lmse += lmse(&ta, &fa, &mask, w, h);
        scores.normal_cosine += cos / count as f64;
        scores.views += 1;
    }
    if scores.views > 0 {
        scores.albedo_lmse /= scores.views as f64;
        scores.normal_cosine /= scores.views as f64;
    }
    Ok(scores)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lmse_is_scale_invariant_and_zero_for_a_match() {
        let (w, h) = (40, 30);
        let truth: Vec<f32> = (0..w * h * 3).map(|k| (k % 17) as f32 / 17.0).collect();
        let mask = vec![true; w * h];
        let scaled: Vec<f32> = truth.iter().map(|v| v * 0.5).collect();
        assert!(lmse(&truth, &scaled, &mask, w, h) < 1e-12);
        let flat = vec![0.5f32; w * h * 3];
        let e = lmse(&truth, &flat, &mask, w, h);
        assert!(e > 0.1 && e < 1.0, "{e}");
        assert_eq!(lmse(&truth, &vec![0.0; w * h * 3], &mask, w, h), 1.0);
    }
}
