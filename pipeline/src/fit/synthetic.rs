//! A synthetic avatar with known materials, for scoring a material fit as HRAvatar (CVPR 2025,
//! Table 3) does: a bound set made flat along each triangle's normal, given albedo, roughness
//! and F0 that vary smoothly over the surface, and the start of a fit of it (the same Gaussians
//! turned by random rotations, without materials: HRAvatar's initial grey albedo, roughness 0.9,
//! F0 0.04).
//!
//! The materials are functions of the Gaussian's rest position `p` mapped into `[-1, 1]³` by
//! the template's bounding box (centre and largest half-extent, so the same pattern on any
//! template): albedo `(0.5 + 0.35 sin 3x, 0.5 + 0.35 cos 2.5y, 0.45 + 0.3 sin(2z + 1))`,
//! roughness `0.45 + 0.3 sin(4y + x)` (0.15-0.75), F0 `0.2 + 0.15 cos 3x` (0.05-0.35).

use glam::{DQuat, DVec3};
use trisplat_geometry::rng::Rng;
use trisplat_geometry::{Camera, TriMesh};
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, to_world};
use trisplat_splat::material::{Material, MaterialEdits, effective_material, normal_of};
use trisplat_splat::render::{GaussianParams, RenderOptions};
use trisplat_splat::{GaussianSet, rgb_to_dc};

use super::brdf_score::{MaterialScores, material_scores};
use super::inputs::FitError;

/// Log-scale subtracted from the local axis nearest each triangle's normal (a factor e^-2.5).
const FLATTEN: f32 = 2.5;

/// The truth (`set` flattened, with known materials) and the start of its fit (the truth's
/// Gaussians turned by 0.3-1 rad about random axes drawn with `seed`, grey degree-0 colour and
/// no materials) of a set bound to `mesh` (module documentation).
///
/// # Errors
/// [`FitError::BadOption`] when `set` is not bound to `mesh` (or `mesh` is empty).
pub fn synthetic_materials(
    set: &GaussianSet,
    mesh: &TriMesh,
    seed: u64,
) -> Result<(GaussianSet, GaussianSet), FitError> {
    let bad = |m: String| FitError::BadOption(format!("the synthetic avatar: {m}"));
    let binding = set
        .binding()
        .ok_or_else(|| bad("the set is not bound to triangles".into()))?;
    let bounds = mesh
        .bounds()
        .ok_or_else(|| bad("the template is empty".into()))?;
    let centre = bounds.center();
    let half = (0.5 * (bounds.max - bounds.min)).max_element().max(1e-12);
    let frames = TriangleFrames::binding(mesh, mesh.positions());
    let mut parts = set.clone().into_parts();
    let mut material = Material::default();
    for i in 0..parts.means.len() {
        let t = binding.triangles[i].index();
        if t >= mesh.triangle_count() {
            return Err(bad(format!(
                "Gaussian {i} is bound to triangle {t}; the template has {}",
                mesh.triangle_count()
            )));
        }
        let [a, b, c] = mesh.triangles()[t].map(|v| mesh.positions()[v as usize]);
        let normal = (b - a).cross(c - a).normalize_or_zero();
        let local = frames.rotation[t].transpose() * normal;
        let axis = (0..3)
            .max_by(|&x, &y| local[x].abs().total_cmp(&local[y].abs()))
            .unwrap_or(2);
        parts.log_scales[i][axis] -= FLATTEN;
        let rest =
            frames.rotation[t] * parts.means[i].as_dvec3() * frames.scale[t] + frames.origin[t];
        let p = ((rest - centre) / half).as_vec3();
        material.albedo.push([
            0.5 + 0.35 * (3.0 * p.x).sin(),
            0.5 + 0.35 * (2.5 * p.y).cos(),
            0.45 + 0.3 * (2.0 * p.z + 1.0).sin(),
        ]);
        material
            .roughness
            .push(0.45 + 0.3 * (4.0 * p.y + p.x).sin());
        material.f0.push(0.2 + 0.15 * (3.0 * p.x).cos());
    }
    let mut init = parts.clone();
    parts.material = Some(material);
    let mut rng = Rng::new(seed);
    for q in &mut init.rotations {
        let axis = DVec3::new(
            rng.uniform_f64() - 0.5,
            rng.uniform_f64() - 0.5,
            rng.uniform_f64() - 0.5,
        )
        .normalize();
        let turn = DQuat::from_axis_angle(axis, 0.3 + 0.7 * rng.uniform_f64());
        let local = DQuat::from_xyzw(
            f64::from(q[1]),
            f64::from(q[2]),
            f64::from(q[3]),
            f64::from(q[0]),
        );
        let r = local * turn;
        *q = [r.w as f32, r.x as f32, r.y as f32, r.z as f32];
    }
    init.material = None;
    init.sh_degree = 0;
    init.sh = vec![rgb_to_dc(0.5); 3 * init.means.len()];
    let make = |p| GaussianSet::try_new(p).map_err(|e| bad(e.to_string()));
    Ok((make(parts)?, make(init)?))
}

/// World parameters of a bound set at `mesh`'s rest pose (binding mode) and the material it is
/// shaded with ([`effective_material`]: its own, else grey from its colour, roughness 0.9, F0
/// 0.04).
///
/// # Errors
/// [`FitError`] when `set` is not bound to `mesh` with local parameters.
pub fn rest_world(
    set: &GaussianSet,
    mesh: &TriMesh,
) -> Result<(GaussianParams, Material), FitError> {
    let bound = BoundParams::from_set(set, mesh.triangle_count())?;
    let mut out = GaussianParams::default();
    to_world(
        &bound,
        &TriangleFrames::binding(mesh, mesh.positions()),
        &mut out,
    );
    Ok((out, effective_material(set, &MaterialEdits::default())))
}

/// A fitted set against the synthetic truth, both bound to `mesh` (at its rest pose):
/// HRAvatar's Table 3 scores on `cameras` ([`material_scores`]) and the mean over the Gaussians
/// of `|cos|` between the two sets' shortest axes.
///
/// # Errors
/// [`FitError`] when a set is not bound to `mesh`, the counts differ, or a render fails.
pub fn synthetic_scores(
    truth: &GaussianSet,
    fitted: &GaussianSet,
    mesh: &TriMesh,
    cameras: &[Camera],
    options: &RenderOptions,
) -> Result<(MaterialScores, f64), FitError> {
    if truth.len() != fitted.len() {
        return Err(FitError::BadOption(format!(
            "the fitted set has {} Gaussians, the truth {}",
            fitted.len(),
            truth.len()
        )));
    }
    let (t, tm) = rest_world(truth, mesh)?;
    let (f, fm) = rest_world(fitted, mesh)?;
    let scores = material_scores((&t, &tm), (&f, &fm), cameras, options)?;
    // Any eye: `|cos|` does not depend on which way each normal is turned.
    let eye = DVec3::new(0.0, 0.0, 1e6);
    let n = t.means.len().max(1);
    let cos = (0..t.means.len())
        .map(|i| {
            normal_of(&t, i, eye)
                .normal
                .dot(normal_of(&f, i, eye).normal)
                .abs()
        })
        .sum::<f64>()
        / n as f64;
    Ok((scores, cos))
}
