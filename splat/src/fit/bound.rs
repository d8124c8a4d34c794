//! Bound (local) Gaussian parameters in `f64` and the chain rule from world-space gradients to
//! them, in the GaussianAvatars binding convention (docs/conventions.md §4, `binding` mode).
//!
//! Per triangle frame `(R_f, k_f, c_f)` of the posed template, a Gaussian's world parameters are
//! `μ = k_f R_f μ' + c_f`, `log s = log s' + ln k_f`, `q = q_f ⊗ q'` (raw, not normalised: the
//! renderer normalises and `|q_f ⊗ q'| = |q'|`), opacity and SH unchanged. So
//! `∂L/∂μ' = k_f R_fᵀ ∂L/∂μ`, `∂L/∂log s' = ∂L/∂log s`, `∂L/∂q' = L(q_f)ᵀ ∂L/∂q` with `L(a)` the
//! matrix of `b ↦ a ⊗ b`. The triangle frames are held fixed (the template is given, not
//! fitted). Jacobian-mode (SurFhead) sets are not supported here.
//!
//! **The shading normal** (`fit --appearance brdf --fit-normals`, issue #33): the deformer's
//! normal is `J⁻ᵀ` of the local shortest axis ([`crate::Deformer::shading_normals`]); in this
//! binding mode `J = k_f R_f`, so `normalize(J⁻ᵀ R' e_k) = R_f R' e_k`, the shortest axis of the
//! placed quaternion `q_f ⊗ q'`. The material backward differentiates that axis with respect to
//! the world quaternion and [`grads_to_local`] applies `L(q_f)ᵀ`: that is the `J⁻ᵀ` chain, no
//! separate term (checked against central differences of the deformer's own normals on a posed
//! template: `pipeline/tests/fit_brdf.rs`, `the_normal_gradient_follows_the_deformed_normal`).
//! The log-scales reach the normal only through which axis is shortest (piecewise constant), so
//! they get its gradient from the footprint alone. A Jacobian-mode `J` (not a similarity) would
//! need `∂/∂q' normalize(J⁻ᵀ R(q') e_k)` and, for the footprint, the gradient through the SVD
//! that turns `J Σ Jᵀ` into a rotation and scales; neither is implemented, since these bound
//! parameters are binding mode's only.

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;

use crate::frames::{FrameOptions, corners_of, gaussian_avatars_frame};
use crate::gaussians::{GaussianParts, GaussianSet, ParameterSpace, ScaleDims, quat_from_rotation};
use crate::render::{DiffParams, GaussianGrads, GaussianParams};

/// Why a set cannot be fitted as bound parameters.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BoundError {
    /// The set is not bound, or its parameters are not local.
    #[error("the Gaussians are not bound to triangles with local parameters (bind them first)")]
    NotBound,
    /// A binding names a triangle the template does not have.
    #[error("Gaussian {index}: bound to triangle {triangle}, but the template has {count}")]
    BindingOutOfRange {
        /// Gaussian.
        index: usize,
        /// Its triangle.
        triangle: usize,
        /// Template triangles.
        count: usize,
    },
}

/// The local parameters of bound Gaussians in `f64` (the layout of [`GaussianParams`]) and the
/// triangle of each.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundParams {
    /// Local parameters (means in the triangle frame, in units of `k_f`).
    pub local: GaussianParams,
    /// Triangle index per Gaussian.
    pub triangles: Vec<u32>,
}

impl BoundParams {
    /// The local parameters of a bound set, checked against a template of `triangle_count`
    /// triangles.
    ///
    /// # Errors
    /// [`BoundError`] for an unbound or world-space set, a binding past the template.
    pub fn from_set(set: &GaussianSet, triangle_count: usize) -> Result<Self, BoundError> {
        let binding = set.binding().ok_or(BoundError::NotBound)?;
        if set.space() != ParameterSpace::Local {
            return Err(BoundError::NotBound);
        }
        if let Some((index, t)) = binding
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.index() >= triangle_count)
        {
            return Err(BoundError::BindingOutOfRange {
                index,
                triangle: t.index(),
                count: triangle_count,
            });
        }
        let triangles = binding.triangles.iter().map(|t| t.index() as u32).collect();
        // `DiffParams` refuses nothing here: `from_set` only reads the arrays.
        Ok(Self {
            local: GaussianParams::from_set(set),
            triangles,
        })
    }

    /// Number of Gaussians.
    #[must_use]
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether there are none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// `set` (the bound set these parameters came from, same count) with its parameters
    /// replaced by these, rounded to `f32`; binding, extras and property order kept.
    ///
    /// # Panics
    /// When `set` has another number of Gaussians.
    #[must_use]
    pub fn write_into(&self, set: &GaussianSet) -> GaussianSet {
        assert_eq!(set.len(), self.len(), "write_into: Gaussian counts differ");
        let mut parts = set.clone().into_parts();
        let p = &self.local;
        parts.means = p
            .means
            .iter()
            .map(|m| DVec3::from_array(*m).as_vec3())
            .collect();
        parts.log_scales = p
            .log_scales
            .iter()
            .map(|s| DVec3::from_array(*s).as_vec3())
            .collect();
        parts.rotations = p.rotations.iter().map(|q| q.map(|v| v as f32)).collect();
        parts.opacity_logits = p.opacity_logits.iter().map(|&v| v as f32).collect();
        let k = p.sh_per_gaussian();
        let k_set = parts.sh.len() / set.len().max(1);
        for i in 0..self.len() {
            for j in 0..k.min(k_set) {
                parts.sh[i * k_set + j] = p.sh[i * k + j] as f32;
            }
        }
        parts.space = ParameterSpace::Local;
        GaussianSet::new_unchecked(parts)
    }
}

/// The GaussianAvatars frames of every triangle of one posed template.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleFrames {
    /// `R_f`.
    pub rotation: Vec<DMat3>,
    /// `q_f` (unit, `[w, x, y, z]`).
    pub quaternion: Vec<[f64; 4]>,
    /// `k_f`.
    pub scale: Vec<f64>,
    /// `c_f` (centroid).
    pub origin: Vec<DVec3>,
}

impl TriangleFrames {
    /// The frames of `template`'s triangles with its vertices at `positions` (the template's
    /// own for the rest pose), with the frame options [`crate::deform::Deformer::new`] uses.
    ///
    /// # Panics
    /// When `positions` has fewer vertices than the triangles index.
    #[must_use]
    pub fn binding(template: &TriMesh, positions: &[DVec3]) -> Self {
        let options = FrameOptions::for_positions(template.positions());
        let frames: Vec<_> = template
            .triangles()
            .par_iter()
            .map(|t| gaussian_avatars_frame(corners_of(positions, *t), &options))
            .collect();
        Self {
            rotation: frames.iter().map(|f| f.rotation).collect(),
            quaternion: frames
                .iter()
                .map(|f| {
                    let q: DQuat = quat_from_rotation(f.rotation);
                    [q.w, q.x, q.y, q.z]
                })
                .collect(),
            scale: frames.iter().map(|f| f.scale).collect(),
            origin: frames.iter().map(|f| f.origin).collect(),
        }
    }
}

/// `a ⊗ b` for `[w, x, y, z]` quaternions.
#[must_use]
pub fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// `L(a)ᵀ g`: the gradient with respect to `b` of `g · (a ⊗ b)`.
#[must_use]
pub fn quat_mul_vjp(a: [f64; 4], g: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [gw, gx, gy, gz] = g;
    [
        aw * gw + ax * gx + ay * gy + az * gz,
        -ax * gw + aw * gx + az * gy - ay * gz,
        -ay * gw - az * gx + aw * gy + ax * gz,
        -az * gw + ay * gx - ax * gy + aw * gz,
    ]
}

/// The world-space parameters of `bound` with the template's frames `frames` into `out`
/// (resized; SH and opacities copied).
pub fn to_world(bound: &BoundParams, frames: &TriangleFrames, out: &mut GaussianParams) {
    let p = &bound.local;
    let n = bound.len();
    out.means.resize(n, [0.0; 3]);
    out.log_scales.resize(n, [0.0; 3]);
    out.rotations.resize(n, [1.0, 0.0, 0.0, 0.0]);
    out.opacity_logits.clear();
    out.opacity_logits.extend_from_slice(&p.opacity_logits);
    out.sh_degree = p.sh_degree;
    out.sh.clear();
    out.sh.extend_from_slice(&p.sh);
    out.means
        .par_iter_mut()
        .zip(out.log_scales.par_iter_mut())
        .zip(out.rotations.par_iter_mut())
        .enumerate()
        .with_min_len(1024)
        .for_each(|(i, ((m, s), q))| {
            let t = bound.triangles[i] as usize;
            let k = frames.scale[t];
            let local = DVec3::from_array(p.means[i]);
            *m = (frames.rotation[t] * local * k + frames.origin[t]).to_array();
            let ln_k = k.ln();
            *s = p.log_scales[i].map(|v| v + ln_k);
            *q = quat_mul(frames.quaternion[t], p.rotations[i]);
        });
}

/// The gradients with respect to `bound`'s local parameters from those with respect to the
/// world parameters [`to_world`] made with the same `frames` (module docs); `out` is resized.
/// `means2d` is copied (it is per Gaussian, not per parameter).
pub fn grads_to_local(
    bound: &BoundParams,
    frames: &TriangleFrames,
    world: &GaussianGrads,
    out: &mut GaussianGrads,
) {
    let n = bound.len();
    out.means.resize(n, [0.0; 3]);
    out.rotations.resize(n, [0.0; 4]);
    out.log_scales.clear();
    out.log_scales.extend_from_slice(&world.log_scales);
    out.opacity_logits.clear();
    out.opacity_logits.extend_from_slice(&world.opacity_logits);
    out.sh.clear();
    out.sh.extend_from_slice(&world.sh);
    out.means2d.clear();
    out.means2d.extend_from_slice(&world.means2d);
    out.means
        .par_iter_mut()
        .zip(out.rotations.par_iter_mut())
        .enumerate()
        .with_min_len(1024)
        .for_each(|(i, (m, q))| {
            let t = bound.triangles[i] as usize;
            let g = DVec3::from_array(world.means[i]);
            *m = (frames.rotation[t].transpose() * g * frames.scale[t]).to_array();
            *q = quat_mul_vjp(frames.quaternion[t], world.rotations[i]);
        });
}

/// Whether `p` is usable by the renderer as world parameters (every value finite).
#[must_use]
pub fn all_finite(p: &GaussianParams) -> bool {
    (0..p.len()).all(|i| {
        p.mean(i).is_finite()
            && p.log_scale(i).is_finite()
            && p.rotation(i).iter().all(|v| v.is_finite())
            && p.opacity_logit(i).is_finite()
    }) && p.sh.iter().all(|v| v.is_finite())
}

/// A bound [`GaussianSet`] from `bound` without a source set: parameters rounded to `f32`,
/// binding from the triangles, no extras.
#[must_use]
pub fn to_set(bound: &BoundParams) -> GaussianSet {
    let p = &bound.local;
    let parts = GaussianParts {
        means: p
            .means
            .iter()
            .map(|m| DVec3::from_array(*m).as_vec3())
            .collect(),
        log_scales: p
            .log_scales
            .iter()
            .map(|s| DVec3::from_array(*s).as_vec3())
            .collect(),
        scale_dims: ScaleDims::Three,
        rotations: p.rotations.iter().map(|q| q.map(|v| v as f32)).collect(),
        opacity_logits: p.opacity_logits.iter().map(|&v| v as f32).collect(),
        sh_degree: p.sh_degree,
        sh: p.sh.iter().map(|&v| v as f32).collect(),
        binding: Some(crate::gaussians::Binding {
            triangles: bound
                .triangles
                .iter()
                .map(|&t| trisplat_geometry::TriId(t))
                .collect(),
            encoding: crate::gaussians::BindingEncoding::default(),
        }),
        material: None,
        space: ParameterSpace::Local,
        extras: Vec::new(),
        property_order: None,
    };
    GaussianSet::new_unchecked(parts)
}
