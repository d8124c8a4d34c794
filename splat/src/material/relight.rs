//! Relit renders: each Gaussian's material (its own, or one derived from its colour), edited
//! ([`MaterialEdits`]), shaded per view under an [`Environment`] ([`shade_gaussians`]), the
//! colours composited by the ordinary renderer in place of the SH colour ([`render_relit`]),
//! and the material maps albedo, roughness and specular composited the same way.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::attributes::{DEFAULT_F0, DEFAULT_ROUGHNESS, Material};
use super::shade::Environment;
use crate::densify::shortest_axis;
use crate::gaussians::{GaussianParts, GaussianSet};
use crate::render::{Outputs, RenderError, RenderOptions, RenderOutput, check_inputs, render};
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

/// Shades every Gaussian of `set` (world space) seen from `eye`: normal = `normals[i]` when
/// given (e.g. [`crate::Deformer::shading_normals`], `J⁻ᵀ n` in Jacobian mode), else the shortest
/// axis (the flat axis of a surfel), turned towards `eye`; view vector = mean to `eye`.
///
/// # Panics
/// If `material` (or `normals`) does not have one entry per Gaussian.
#[must_use]
pub fn shade_gaussians(
    set: &GaussianSet,
    normals: Option<&[Vec3]>,
    material: &Material,
    eye: DVec3,
    env: &Environment,
) -> Relit {
    assert_eq!(
        material.albedo.len(),
        set.len(),
        "one material per Gaussian"
    );
    check_normals(set, normals);
    let (colors, specular) = (0..set.len())
        .into_par_iter()
        .map(|i| {
            let (n, v) = normal_and_view(set, normals, i, eye);
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

/// Gradients of a loss with respect to every Gaussian's material.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MaterialGrads {
    /// `∂L/∂albedo` per Gaussian.
    pub albedo: Vec<[f32; 3]>,
    /// `∂L/∂roughness` per Gaussian.
    pub roughness: Vec<f32>,
    /// `∂L/∂F0` per Gaussian.
    pub f0: Vec<f32>,
}

/// The material gradients of a loss whose gradient with respect to each Gaussian's relit
/// colour (as [`shade_gaussians`] computes it, from `eye`) is `d_colors`. From the
/// differentiable renderer run on [`with_colors`]'s degree-0 set, `d_colors = ∂L/∂f_dc / SH_C0`
/// (where the colour is not clamped at 0). Normals and views are held fixed here; the
/// gradient through them is [`super::relit_backward`]'s. `normals` as [`shade_gaussians`].
///
/// # Panics
/// If `material`, `d_colors` (or `normals`) does not have one entry per Gaussian.
#[must_use]
pub fn material_grads(
    set: &GaussianSet,
    normals: Option<&[Vec3]>,
    material: &Material,
    eye: DVec3,
    env: &Environment,
    d_colors: &[[f32; 3]],
) -> MaterialGrads {
    assert_eq!(
        material.albedo.len(),
        set.len(),
        "one material per Gaussian"
    );
    assert_eq!(
        d_colors.len(),
        set.len(),
        "one colour gradient per Gaussian"
    );
    check_normals(set, normals);
    let grads: Vec<_> = (0..set.len())
        .into_par_iter()
        .map(|i| {
            let (n, v) = normal_and_view(set, normals, i, eye);
            env.shade_grad(
                n,
                v,
                material.albedo[i],
                material.roughness[i],
                material.f0[i],
                d_colors[i],
            )
        })
        .collect();
    MaterialGrads {
        albedo: grads.iter().map(|g| g.albedo).collect(),
        roughness: grads.iter().map(|g| g.roughness).collect(),
        f0: grads.iter().map(|g| g.f0).collect(),
    }
}

fn check_normals(set: &GaussianSet, normals: Option<&[Vec3]>) {
    if let Some(n) = normals {
        assert_eq!(n.len(), set.len(), "one normal per Gaussian");
    }
}

/// Gaussian `i`'s shading normal (`normals[i]` or the shortest axis, facing `eye`) and view
/// vector (mean to `eye`). A given normal that cannot be normalised falls back to the axis.
fn normal_and_view(
    set: &GaussianSet,
    normals: Option<&[Vec3]>,
    i: usize,
    eye: DVec3,
) -> (DVec3, DVec3) {
    let to_eye = eye - set.means()[i].as_dvec3();
    let v = to_eye.try_normalize().unwrap_or(DVec3::Z);
    let axis = normals
        .and_then(|n| n[i].as_dvec3().try_normalize())
        .unwrap_or_else(|| shortest_axis(set, i));
    let n = if axis.dot(v) < 0.0 { -axis } else { axis };
    (n, v)
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
/// [`shade_gaussians`] (with `normals` when given) composited by [`render`] with `options`, and each map of `maps` by a
/// render of its per-Gaussian values (rgb only, black background; weighted sums like the
/// normal map, not divided by alpha).
///
/// # Errors
/// [`RenderError`] as [`render`].
///
/// # Panics
/// If `material` (or `normals`) does not have one entry per Gaussian.
pub fn render_relit(
    set: &GaussianSet,
    normals: Option<&[Vec3]>,
    material: &Material,
    camera: &Camera,
    env: &Environment,
    options: &RenderOptions,
    maps: MaterialMaps,
) -> Result<RelitRender, RenderError> {
    check_inputs(set, camera, options)?;
    let relit = shade_gaussians(set, normals, material, camera.position(), env);
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

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::envmap::EnvMap;

    use crate::material::shade::EnvOptions;

    /// `material_grads` against central differences of `Σ g · colour` over a few Gaussians.
    #[test]
    fn material_grads_match_finite_differences() {
        let n = 5;
        let set = GaussianSet::try_new(GaussianParts {
            means: (0..n)
                .map(|i| glam::Vec3::new(i as f32 * 0.1, 0.0, 0.0))
                .collect(),
            log_scales: vec![glam::Vec3::new(-2.0, -2.5, -5.0); n],
            rotations: (0..n).map(|i| [1.0, 0.1 * i as f32, 0.2, -0.1]).collect(),
            opacity_logits: vec![0.0; n],
            sh: vec![0.0; 3 * n],
            ..GaussianParts::default()
        })
        .unwrap();
        let texels = (0..32 * 16)
            .map(|k| [(k % 7) as f32 * 0.3, (k % 5) as f32 * 0.2, 1.0])
            .collect();
        let env = Environment::new(
            &EnvMap::try_new(32, 16, texels).unwrap(),
            EnvOptions::default(),
        )
        .unwrap();
        let material = Material {
            albedo: (0..n).map(|i| [0.2, 0.1 * i as f32 + 0.3, 0.7]).collect(),
            roughness: (0..n).map(|i| 0.12 + 0.17 * i as f32).collect(),
            f0: (0..n).map(|i| 0.05 + 0.2 * i as f32).collect(),
        };
        let eye = DVec3::new(0.3, 0.4, 2.0);
        let g: Vec<[f32; 3]> = (0..n).map(|i| [0.5, -0.3, 0.1 * i as f32]).collect();
        let loss = |m: &Material| -> f64 {
            let relit = shade_gaussians(&set, None, m, eye, &env);
            relit
                .colors
                .iter()
                .zip(&g)
                .map(|(c, g)| (0..3).map(|k| f64::from(c[k] * g[k])).sum::<f64>())
                .sum()
        };
        let grads = material_grads(&set, None, &material, eye, &env, &g);
        let h = 1e-3f32;
        for i in 0..n {
            let mut up = material.clone();
            let mut down = material.clone();
            up.f0[i] += h;
            down.f0[i] -= h;
            let fd = (loss(&up) - loss(&down)) / (2.0 * f64::from(h));
            assert!((f64::from(grads.f0[i]) - fd).abs() < 1e-3, "F0 {i}: {fd}");
            let mut up = material.clone();
            let mut down = material.clone();
            up.roughness[i] += h;
            down.roughness[i] -= h;
            let fd = (loss(&up) - loss(&down)) / (2.0 * f64::from(h));
            assert!(
                (f64::from(grads.roughness[i]) - fd).abs() < 2e-2 * fd.abs().max(0.1),
                "r {i}: {fd}"
            );
            let mut up = material.clone();
            let mut down = material.clone();
            up.albedo[i][2] += h;
            down.albedo[i][2] -= h;
            let fd = (loss(&up) - loss(&down)) / (2.0 * f64::from(h));
            assert!(
                (f64::from(grads.albedo[i][2]) - fd).abs() < 1e-3,
                "albedo {i}: {fd}"
            );
        }
    }
}
