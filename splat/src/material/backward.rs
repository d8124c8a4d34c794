//! The relit colour's backward pass through the geometry: per Gaussian, the gradient of a loss
//! with respect to its raw quaternion (through the shading normal) and its mean (through the
//! view vector), added to the renderer's [`GaussianGrads`], besides the material gradients.
//!
//! The normal of Gaussian `i` ([`normal_of`]) is column `k` of `R(q / |q|)`, `k` the axis of the
//! smallest log-scale (ties go to the first of x, y, z, as [`crate::densify::shortest_axis`];
//! a surfel's flat axis has log-scale `−∞`, so it is always its third), times `s = ±1` so that
//! it faces the camera (`n · (eye − μ) ≥ 0`). Both `k` and `s` are piecewise constant: the
//! log-scales get no gradient from the shading (at a tie of two smallest scales, or a normal
//! exactly edge-on, the colour jumps and no derivative exists; the gradient returned is that of
//! the branch the forward took), and the quaternion's gradient is `∂L/∂q = VJP(q ↦ R(q/|q|))`
//! of the matrix gradient whose only non-zero column is `k`, `s ∂L/∂n` (the renderer's
//! quaternion VJP, so it is orthogonal to `q`). The view vector `v = (eye − μ)/|eye − μ|` gives
//! `∂L/∂μ = −(I − v vᵀ) ∂L/∂v / |eye − μ|`.
//!
//! In a bound or deformed set the world quaternion is what the placing produced (binding mode:
//! the triangle's frame times the local one; the caller carries the world gradient back, as
//! for the renderer's; in binding mode that chain is the deformer's `J⁻ᵀ`, see
//! [`crate::fit::bound`]). Jacobian-mode deformation moves the normal by a general `J⁻ᵀ` and is
//! not differentiated here (the fits place sets in binding mode only).

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::attributes::Material;
use super::env_grad::EnvGrad;
use super::relight::{MaterialGrads, Relit};
use super::shade::Environment;
use crate::render::{DiffParams, GaussianGrads, normalized, quaternion_vjp, rotation_matrix};
use crate::sh::SH_C0;

/// The shading normal of one Gaussian and what its backward pass needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalTrace {
    /// The unit normal, facing the eye.
    pub normal: DVec3,
    /// The unit view vector, mean to eye.
    pub view: DVec3,
    /// `|eye − μ|` (0 when the eye is at the mean; the view is then +Z).
    pub distance: f64,
    /// Which column of the rotation matrix (the shortest axis: 0, 1 or 2).
    pub axis: usize,
    /// `±1`: the column turned to face the eye.
    pub sign: f64,
    /// The unit quaternion and the raw one's norm.
    qn: [f64; 4],
    qnorm: f64,
}

/// Gaussian `i`'s shading normal and view seen from `eye` (module documentation).
#[must_use]
pub fn normal_of<P: DiffParams + ?Sized>(params: &P, i: usize, eye: DVec3) -> NormalTrace {
    let to_eye = eye - params.mean(i);
    let distance = to_eye.length();
    let view = if distance > 0.0 && distance.is_finite() {
        to_eye / distance
    } else {
        DVec3::Z
    };
    let (qn, qnorm) = normalized(params.rotation(i));
    let rot: DMat3 = rotation_matrix(qn);
    let s = params.log_scale(i);
    let axis = if s.x <= s.y && s.x <= s.z {
        0
    } else if s.y <= s.z {
        1
    } else {
        2
    };
    let column = rot.col(axis);
    let sign = if column.dot(view) < 0.0 { -1.0 } else { 1.0 };
    NormalTrace {
        normal: column * sign,
        view,
        distance,
        axis,
        sign,
        qn,
        qnorm,
    }
}

/// Shades every Gaussian of `params` (world space, `f64`) seen from `eye` with the normal of
/// [`normal_of`]: the colours [`relit_backward`] differentiates.
///
/// # Panics
/// If `material` does not have one entry per Gaussian.
#[must_use]
pub fn shade_params<P: DiffParams + ?Sized>(
    params: &P,
    material: &Material,
    eye: DVec3,
    env: &Environment,
) -> Relit {
    assert_eq!(
        material.albedo.len(),
        params.len(),
        "one material per Gaussian"
    );
    let (colors, specular) = (0..params.len())
        .into_par_iter()
        .map(|i| {
            let t = normal_of(params, i, eye);
            let s = env.shade(
                t.normal,
                t.view,
                material.albedo[i],
                material.roughness[i],
                material.f0[i],
            );
            (s.color, s.specular)
        })
        .unzip();
    Relit { colors, specular }
}

/// The colour gradients `∂L/∂c = ∂L/∂f_dc / SH_C0` of a degree-0 set's SH gradients
/// (`sh` laid out as [`GaussianGrads::sh`], 3 per Gaussian), written into `out`.
pub fn color_grads_from_sh(sh: &[f64], out: &mut Vec<[f32; 3]>) {
    out.clear();
    out.extend(
        sh.chunks_exact(3)
            .map(|g| std::array::from_fn(|c| (g[c] / SH_C0) as f32)),
    );
}

/// The backward pass of [`shade_params`]: given `d_colors[i] = ∂L/∂c_i`, returns the material
/// gradients and adds `∂L/∂q` and `∂L/∂μ` of every Gaussian into `geometry` (the renderer's
/// gradients of the same step; log-scales get nothing, see the module documentation).
///
/// # Panics
/// If `material`, `d_colors` or `geometry` does not have one entry per Gaussian.
#[must_use]
pub fn relit_backward<P: DiffParams + ?Sized>(
    params: &P,
    material: &Material,
    eye: DVec3,
    env: &Environment,
    d_colors: &[[f32; 3]],
    geometry: &mut GaussianGrads,
) -> MaterialGrads {
    let n = params.len();
    assert_eq!(material.albedo.len(), n, "one material per Gaussian");
    assert_eq!(d_colors.len(), n, "one colour gradient per Gaussian");
    assert_eq!(geometry.len(), n, "one geometry gradient per Gaussian");
    let mut out = MaterialGrads {
        albedo: vec![[0.0; 3]; n],
        roughness: vec![0.0; n],
        f0: vec![0.0; n],
    };
    geometry
        .rotations
        .par_iter_mut()
        .zip(geometry.means.par_iter_mut())
        .zip(out.albedo.par_iter_mut())
        .zip(out.roughness.par_iter_mut())
        .zip(out.f0.par_iter_mut())
        .enumerate()
        .for_each(|(i, ((((g_q, g_mu), g_albedo), g_r), g_f0))| {
            let t = normal_of(params, i, eye);
            let g = env.shade_grad(
                t.normal,
                t.view,
                material.albedo[i],
                material.roughness[i],
                material.f0[i],
                d_colors[i],
            );
            *g_albedo = g.albedo;
            *g_r = g.roughness;
            *g_f0 = g.f0;
            let mut g_rot = [DVec3::ZERO; 3];
            g_rot[t.axis] = g.normal * t.sign;
            let dq = quaternion_vjp(t.qn, t.qnorm, g_rot);
            for (a, d) in g_q.iter_mut().zip(dq) {
                *a += d;
            }
            if t.distance > 0.0 && t.distance.is_finite() {
                let v = t.view;
                let g_mean = -(g.view - v * v.dot(g.view)) / t.distance;
                for (a, d) in g_mu.iter_mut().zip(g_mean.to_array()) {
                    *a += d;
                }
            }
        });
    out
}

/// The environment's part of the backward pass of [`shade_params`]: adds to `out` (shaped by
/// [`EnvGrad::zeros`] of `env`) the gradient of the loss whose colour gradients are `d_colors`
/// with respect to `env`'s irradiance coefficients and prefiltered texels (normals and views
/// held as the forward took them); [`EnvGrad::to_texels`] carries it to the map's texels.
///
/// # Panics
/// If `material` or `d_colors` does not have one entry per Gaussian.
pub fn relit_env_backward<P: DiffParams + ?Sized>(
    params: &P,
    material: &Material,
    eye: DVec3,
    env: &Environment,
    d_colors: &[[f32; 3]],
    out: &mut EnvGrad,
) {
    let n = params.len();
    assert_eq!(material.albedo.len(), n, "one material per Gaussian");
    assert_eq!(d_colors.len(), n, "one colour gradient per Gaussian");
    let sum = (0..n)
        .into_par_iter()
        .with_min_len(1024)
        .fold(
            || EnvGrad::zeros(env),
            |mut acc, i| {
                if d_colors[i] != [0.0; 3] {
                    let t = normal_of(params, i, eye);
                    env.shade_env_grad(
                        t.normal,
                        t.view,
                        material.albedo[i],
                        material.roughness[i],
                        material.f0[i],
                        d_colors[i],
                        &mut acc,
                    );
                }
                acc
            },
        )
        .reduce_with(|mut a, b| {
            a.add(&b);
            a
        });
    if let Some(sum) = sum {
        out.add(&sum);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::shade::EnvOptions;
    use crate::render::GaussianParams;
    use trisplat_geometry::envmap::EnvMap;

    /// A smooth map (low-frequency in direction), so the bilinear kinks barely bend the colour.
    fn smooth_env(rotation_deg: f64) -> Environment {
        let (w, h) = (64u32, 32u32);
        let mut texels = Vec::new();
        for j in 0..h {
            for i in 0..w {
                let d = EnvMap::direction(
                    (f64::from(i) + 0.5) / f64::from(w),
                    (f64::from(j) + 0.5) / f64::from(h),
                );
                texels.push([
                    (1.2 + d.x + 0.5 * d.y) as f32,
                    (1.0 + 0.8 * d.z * d.y + 0.3 * d.x) as f32,
                    (0.8 + 0.6 * (d.y * 2.0).sin()) as f32,
                ]);
            }
        }
        Environment::new(
            &EnvMap::try_new(w, h, texels).unwrap(),
            EnvOptions {
                rotation_deg,
                intensity: 1.0,
            },
        )
        .unwrap()
    }

    /// `relit_backward`'s quaternion and mean gradients against central differences of
    /// `Σ g · c` (the shading in f32, so a step of 1e-3 and a tolerance of a few per cent of
    /// the largest quotient).
    #[test]
    fn rotation_and_mean_gradients_match_finite_differences() {
        let env = smooth_env(25.0);
        let n = 8;
        let mut rng = trisplat_geometry::rng::Rng::new(5);
        let mut u = move || f64::from(rng.uniform_f32());
        let mut params = GaussianParams {
            sh_degree: 0,
            ..GaussianParams::default()
        };
        for i in 0..n {
            params.means.push([u() - 0.5, u() - 0.5, u() - 0.5]);
            // Distinct scales (no ties); surfel-like for some.
            let flat = if i % 3 == 0 { f64::NEG_INFINITY } else { -4.0 };
            params.log_scales.push([-2.0 - u(), -2.5 - u(), flat]);
            params
                .rotations
                .push([u() + 0.2, u() - 0.5, u() - 0.5, u() - 0.5]);
            params.opacity_logits.push(0.0);
            params.sh.extend([0.0; 3]);
        }
        let material = Material {
            albedo: (0..n)
                .map(|_| [u() as f32, u() as f32, u() as f32])
                .collect(),
            roughness: (0..n).map(|_| (0.05 + 0.9 * u()) as f32).collect(),
            f0: (0..n).map(|_| (0.02 + 0.9 * u()) as f32).collect(),
        };
        let eye = DVec3::new(0.4, 0.3, 3.0);
        let g: Vec<[f32; 3]> = (0..n)
            .map(|_| [u() as f32 - 0.3, u() as f32 - 0.3, u() as f32 - 0.3])
            .collect();
        let loss = |p: &GaussianParams| -> f64 {
            let relit = shade_params(p, &material, eye, &env);
            relit
                .colors
                .iter()
                .zip(&g)
                .map(|(c, g)| {
                    (0..3)
                        .map(|k| f64::from(c[k]) * f64::from(g[k]))
                        .sum::<f64>()
                })
                .sum()
        };
        let mut geometry = GaussianGrads::zeros(n, 0);
        let _ = relit_backward(&params, &material, eye, &env, &g, &mut geometry);
        let h = 1e-3;
        let (mut worst, mut scale) = (0.0f64, 0.0f64);
        for i in 0..n {
            for k in 0..4 {
                let (mut up, mut down) = (params.clone(), params.clone());
                up.rotations[i][k] += h;
                down.rotations[i][k] -= h;
                let fd = (loss(&up) - loss(&down)) / (2.0 * h);
                worst = worst.max((fd - geometry.rotations[i][k]).abs());
                scale = scale.max(fd.abs());
            }
            for k in 0..3 {
                let (mut up, mut down) = (params.clone(), params.clone());
                up.means[i][k] += h;
                down.means[i][k] -= h;
                let fd = (loss(&up) - loss(&down)) / (2.0 * h);
                worst = worst.max((fd - geometry.means[i][k]).abs());
                scale = scale.max(fd.abs());
            }
            // The log-scales (no tie) move nothing.
            let mut up = params.clone();
            up.log_scales[i][1] += h;
            assert_eq!(loss(&up), loss(&params));
        }
        assert!(scale > 0.05, "a degenerate case: {scale}");
        assert!(worst < 3e-2 * scale, "worst {worst} of {scale}");
    }

    /// At a tie of the two smallest scales the first axis is the normal (x before y before z).
    #[test]
    fn ties_take_the_first_axis() {
        let params = GaussianParams {
            means: vec![[0.0; 3]],
            log_scales: vec![[-3.0, -3.0, -1.0]],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]],
            opacity_logits: vec![0.0],
            sh_degree: 0,
            sh: vec![0.0; 3],
        };
        let t = normal_of(&params, 0, DVec3::new(-1.0, 0.0, 0.5));
        assert_eq!((t.axis, t.sign), (0, -1.0));
        assert_eq!(t.normal, DVec3::NEG_X);
    }
}
