//! The seam between the model and the renderer: the model's inputs from a set or from world
//! parameters, its outputs written as the renderer's degree-0 SH and opacity logits, and the
//! renderer's gradients carried back to the outputs.
//!
//! The renderer's degree-0 colour is `SH_C0 · dc + 0.5` (clamped at 0 per channel, held fixed
//! as 3DGS does), so the model's linear RGB is written as `dc = (rgb − 0.5) / SH_C0` and
//! `d/d rgb = d/d dc / SH_C0`; the opacity logit is passed as it is.

use glam::DVec3;

use super::error::NeuralError;
use super::model::{Aabb, Appearance, NeuralInputs};
use crate::gaussians::{GaussianParts, GaussianSet};
use crate::render::{GaussianGrads, GaussianParams};
use crate::sh::SH_C0;

/// Fills `inputs` from world parameters whose coordinates are `origin` away from the world's
/// (the fit's frame of reference).
///
/// # Errors
/// [`NeuralError::Inputs`] for a non-finite value or a zero quaternion.
pub fn inputs_from_params(
    params: &GaussianParams,
    origin: DVec3,
    aabb: &Aabb,
    inputs: &mut NeuralInputs,
) -> Result<(), NeuralError> {
    let means: Vec<[f64; 3]> = params
        .means
        .iter()
        .map(|m| (DVec3::from_array(*m) + origin).to_array())
        .collect();
    inputs.fill(aabb, &means, &params.rotations, &params.log_scales)
}

/// Fills `inputs` from a world-space set whose coordinates are `origin` away from the world's
/// (a set read relative to its local origin).
///
/// # Errors
/// As [`inputs_from_params`].
pub fn inputs_from_set(
    set: &GaussianSet,
    origin: DVec3,
    aabb: &Aabb,
    inputs: &mut NeuralInputs,
) -> Result<(), NeuralError> {
    let means: Vec<[f64; 3]> = set
        .means()
        .iter()
        .map(|m| (m.as_dvec3() + origin).to_array())
        .collect();
    let rots: Vec<[f64; 4]> = set.rotations().iter().map(|q| q.map(f64::from)).collect();
    let scales: Vec<[f64; 3]> = set
        .log_scales()
        .iter()
        .map(|s| {
            let mut s = s.as_dvec3().to_array();
            if set.scale_dims().count() == 2 {
                s[2] = f64::NEG_INFINITY;
            }
            s
        })
        .collect();
    inputs.fill(aabb, &means, &rots, &scales)
}

/// Writes `app` into `params` as opacity logits and degree-0 SH.
///
/// # Panics
/// If `app` is not one entry per Gaussian of `params`.
pub fn bake_params(app: &Appearance<f32>, params: &mut GaussianParams) {
    let n = params.opacity_logits.len();
    assert!(
        app.opacity_logits.len() == n && app.rgb.len() == n,
        "one output per Gaussian"
    );
    params.sh_degree = 0;
    params.sh.clear();
    params.sh.extend(
        app.rgb
            .iter()
            .flat_map(|c| c.map(|v| (f64::from(v) - 0.5) / SH_C0)),
    );
    for (o, &l) in params.opacity_logits.iter_mut().zip(&app.opacity_logits) {
        *o = f64::from(l);
    }
}

/// A copy of `set` with `app` baked in (SH degree 0, the model's opacities), for the plain
/// renderer.
///
/// # Panics
/// If `app` is not one entry per Gaussian of `set`.
#[must_use]
pub fn bake_set(set: &GaussianSet, app: &Appearance<f32>) -> GaussianSet {
    assert!(app.rgb.len() == set.len(), "one output per Gaussian");
    let mut parts: GaussianParts = set.clone().into_parts();
    parts.sh_degree = 0;
    parts.sh = app
        .rgb
        .iter()
        .flat_map(|c| c.map(|v| ((f64::from(v) - 0.5) / SH_C0) as f32))
        .collect();
    parts.opacity_logits.clone_from(&app.opacity_logits);
    // The SH rest coefficients are gone; file-order bookkeeping of f_rest must go with them.
    parts.property_order = None;
    GaussianSet::new_unchecked(parts)
}

/// The renderer's gradients (degree-0 SH, opacity logits) as gradients of the model's outputs.
pub fn appearance_grads(grads: &GaussianGrads, d_logits: &mut Vec<f64>, d_rgb: &mut Vec<[f64; 3]>) {
    d_logits.clear();
    d_logits.extend_from_slice(&grads.opacity_logits);
    d_rgb.clear();
    d_rgb.extend(
        grads
            .sh
            .chunks_exact(3)
            .map(|g| [g[0] / SH_C0, g[1] / SH_C0, g[2] / SH_C0]),
    );
}
