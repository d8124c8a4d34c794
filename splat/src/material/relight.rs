//! Relit renders: each Gaussian's material (its own, or one derived from its colour), edited
//! ([`MaterialEdits`]), shaded per view under an [`Environment`] ([`shade_gaussians`]), the
//! colours composited by the ordinary renderer in place of the SH colour ([`render_relit`]),
//! and the material maps albedo, roughness and specular composited the same way.

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::attributes::{DEFAULT_F0, DEFAULT_ROUGHNESS, Material};
use super::shade::Environment;
use crate::densify::shortest_axis;
use crate::gaussians::{GaussianParts, GaussianSet};
use crate::render::{Outputs, RenderError, RenderOptions, RenderOutput, render};
use crate::sh::{SH_C0, rgb_to_dc};

/// Changes to the materials before shading (`trisplat render --albedo-scale --roughness --f0`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialEdits {
    /// Factor on every albedo (the product clamped to 0..=1).
    pub albedo_scale: f32,
    /// Roughness of every Gaussian, in place of its own.
    pub roughness: Option<f32>,
    /// F0 of every Gaussian, in place of its own.
    pub f0: Option<f32>,
}

impl Default for MaterialEdits {
    fn default() -> Self {
        Self {
            albedo_scale: 1.0,
            roughness: None,
            f0: None,
        }
    }
}

impl MaterialEdits {
    /// Why these edits cannot apply: a scale that is negative or not finite, a roughness or F0
    /// outside 0..=1.
    ///
    /// # Errors
    /// A message naming the value.
    pub fn check(&self) -> Result<(), String> {
        if !(self.albedo_scale.is_finite() && self.albedo_scale >= 0.0) {
            return Err(format!(
                "albedo scale {} must be finite and >= 0",
                self.albedo_scale
            ));
        }
        for (name, v) in [("roughness", self.roughness), ("F0", self.f0)] {
            if let Some(v) = v.filter(|v| !(0.0..=1.0).contains(v)) {
                return Err(format!("{name} {v} must be in 0..=1"));
            }
        }
        Ok(())
    }
}

/// The material `set` is shaded with: its own, or, for a set without one, an albedo from its
/// degree-0 colour (`SH_C0 f_dc + ½`, clamped to 0..=1) with [`DEFAULT_ROUGHNESS`] and
/// [`DEFAULT_F0`]; then `edits` applied.
#[must_use]
pub fn effective_material(set: &GaussianSet, edits: &MaterialEdits) -> Material {
    let mut m = set.material().cloned().unwrap_or_else(|| {
        let albedo = (0..set.len())
            .map(|i| {
                let dc = &set.sh_coeffs(i)[..3];
                std::array::from_fn(|c| (SH_C0 * f64::from(dc[c]) + 0.5).clamp(0.0, 1.0) as f32)
            })
            .collect();
        Material {
            albedo,
            roughness: vec![DEFAULT_ROUGHNESS; set.len()],
            f0: vec![DEFAULT_F0; set.len()],
        }
    });
    if edits.albedo_scale != 1.0 {
        for a in &mut m.albedo {
            *a = a.map(|v| (v * edits.albedo_scale).clamp(0.0, 1.0));
        }
    }
    if let Some(r) = edits.roughness {
        m.roughness.fill(r);
    }
    if let Some(f0) = edits.f0 {
        m.f0.fill(f0);
    }
    m
}

/// Per-Gaussian results of shading one view.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Relit {
    /// Outgoing radiance per Gaussian.
    pub colors: Vec<[f32; 3]>,
    /// Its specular part per Gaussian.
    pub specular: Vec<[f32; 3]>,
}

/// Shades every Gaussian of `set` (world space) seen from `eye`: normal = the shortest axis
/// (the flat axis of a surfel) turned towards `eye`, view vector = mean to `eye`.
///
/// # Panics
/// If `material` does not have one entry per Gaussian.
#[must_use]
pub fn shade_gaussians(
    set: &GaussianSet,
    material: &Material,
    eye: DVec3,
    env: &Environment,
) -> Relit {
    assert_eq!(
        material.albedo.len(),
        set.len(),
        "one material per Gaussian"
    );
    let (colors, specular) = (0..set.len())
        .into_par_iter()
        .map(|i| {
            let to_eye = eye - set.means()[i].as_dvec3();
            let v = to_eye.try_normalize().unwrap_or(DVec3::Z);
            let axis = shortest_axis(set, i);
            let n = if axis.dot(v) < 0.0 { -axis } else { axis };
            let s = env.shade(
                n,
                v,
                material.albedo[i],
                material.roughness[i],
                material.f0[i],
            );
            (s.color, s.specular)
        })
        .unzip();
    Relit { colors, specular }
}

/// `set` with its colour replaced by `colors` (SH degree 0, `f_dc = (c − ½) / SH_C0`); the
/// geometry and opacity are kept, the binding, material and extras are not.
///
/// # Panics
/// If `colors` does not have one entry per Gaussian.
#[must_use]
pub fn with_colors(set: &GaussianSet, colors: &[[f32; 3]]) -> GaussianSet {
    assert_eq!(colors.len(), set.len(), "one colour per Gaussian");
    GaussianSet::new_unchecked(GaussianParts {
        means: set.means().to_vec(),
        log_scales: set.log_scales().to_vec(),
        scale_dims: set.scale_dims(),
        rotations: set.rotations().to_vec(),
        opacity_logits: set.opacity_logits().to_vec(),
        sh_degree: 0,
        sh: colors.iter().flat_map(|c| c.map(rgb_to_dc)).collect(),
        binding: None,
        material: None,
        space: set.space(),
        extras: Vec::new(),
        property_order: None,
    })
}

/// Which material maps [`render_relit`] composites besides the render's own outputs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MaterialMaps {
    /// `[H, W, 3]` `Σ w albedo`.
    pub albedo: bool,
    /// `[H, W]` `Σ w roughness`.
    pub roughness: bool,
    /// `[H, W, 3]` `Σ w k_s L_spec`.
    pub specular: bool,
}

/// A relit render: the renderer's images (rgb relit) and the material maps asked for.
#[derive(Clone, Debug, PartialEq)]
pub struct RelitRender {
    /// The render (its rgb is the relit colour over the background).
    pub output: RenderOutput,
    /// `[H, W, 3]` composited albedo (no background).
    pub albedo: Option<Vec<f32>>,
    /// `[H, W]` composited roughness.
    pub roughness: Option<Vec<f32>>,
    /// `[H, W, 3]` composited specular radiance.
    pub specular: Option<Vec<f32>>,
}

/// Renders `set` (world space) relit under `env` as seen by `camera`: the colours of
/// [`shade_gaussians`] composited by [`render`] with `options`, and each map of `maps` by a
/// render of its per-Gaussian values (rgb only, black background; weighted sums like the
/// normal map, not divided by alpha).
///
/// # Errors
/// [`RenderError`] as [`render`].
///
/// # Panics
/// If `material` does not have one entry per Gaussian.
pub fn render_relit(
    set: &GaussianSet,
    material: &Material,
    camera: &Camera,
    env: &Environment,
    options: &RenderOptions,
    maps: MaterialMaps,
) -> Result<RelitRender, RenderError> {
    let relit = shade_gaussians(set, material, camera.position(), env);
    let output = render(&with_colors(set, &relit.colors), camera, options)?;
    let map_options = RenderOptions {
        outputs: Outputs {
            rgb: true,
            ..Outputs::NONE
        },
        background: [0.0; 3],
        contribution: false,
        ..*options
    };
    let composite = |colors: &[[f32; 3]]| -> Result<Vec<f32>, RenderError> {
        let out = render(&with_colors(set, colors), camera, &map_options)?;
        Ok(out.images.rgb.unwrap_or_default())
    };
    let albedo = maps
        .albedo
        .then(|| composite(&material.albedo))
        .transpose()?;
    let roughness = if maps.roughness {
        let grey: Vec<[f32; 3]> = material.roughness.iter().map(|&r| [r; 3]).collect();
        Some(composite(&grey)?.into_iter().step_by(3).collect())
    } else {
        None
    };
    let specular = maps
        .specular
        .then(|| composite(&relit.specular))
        .transpose()?;
    Ok(RelitRender {
        output,
        albedo,
        roughness,
        specular,
    })
}
