//! Linear-blend-skinning deformation of bound Gaussians (docs/conventions.md §4 `lbs` mode, for bodies with a
//! glTF skin).
//!
//! Each Gaussian takes the skinning weights of its triangle: the barycentric blend, at the
//! Gaussian's rest position (its closest point on the rest triangle), of the three vertices'
//! weights over the skinning palette ([`VertexSkinning`]). At a frame it is moved by the blended
//! transform relative to rest, `M = B(t) B(rest)⁻¹` with `B = Σ_k w_k P_k` (affine, `f64`):
//! `mu = M mu_rest`, `R = polar(M) R_rest` (the rotation factor of the linear part, computed by
//! Higham's scaled Newton iteration), `s = s_rest` (optionally times `√(area ratio)`, see
//! [`LbsDeformer::with_adaptive_scale`]). A Gaussian at a vertex therefore follows the skinned
//! vertex exactly (morph targets aside: the blend moves the rest shape only).
//!
//! The rest parameters are the set's local parameters baked in the GaussianAvatars convention on
//! the template's rest shape (what `trisplat bind --convention gaussianavatars` writes).
//!
//! Fallbacks: a blended rest matrix that is singular (weights of opposite joints cancelling)
//! makes `M = B(t)` applied to the rest position as is; a linear part without a proper polar
//! factor (singular, or `det ≤ 0`) keeps the rest rotation. Outputs are checked finite.

use glam::{DMat3, DMat4, DQuat, DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::VertexSkinning;
use trisplat_geometry::spatial::closest_point_on_triangle;

use crate::deform::{DeformError, DeformMode, Deformer, WorldGeometry};
use crate::frames::{FrameOptions, corners_of};
use crate::gaussians::{GaussianSet, ScaleDims, to_wxyz};

/// Relative size of `|det|` (against the cube of the largest column) below which a blended
/// rest matrix counts as singular.
pub const SINGULAR_BLEND_TOL: f64 = 1e-12;

/// Convergence tolerance of the polar Newton iteration (relative change, Frobenius).
pub const POLAR_TOL: f64 = 1e-13;

/// Iteration limit of the polar Newton iteration (quadratic convergence: ~5 for any
/// well-conditioned matrix, 1-2 for a near-rotation).
pub const POLAR_MAX_ITERATIONS: usize = 30;

/// Errors specific to LBS.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LbsError {
    /// Binding or frame checks of the underlying deformation.
    #[error(transparent)]
    Deform(#[from] DeformError),
    /// The skinning data does not have one row per template vertex.
    #[error("the skinning has {got} vertices, the template {expected}")]
    SkinningVertices {
        /// Template vertices.
        expected: usize,
        /// Skinning rows.
        got: usize,
    },
    /// A palette does not have the length the skinning refers to.
    #[error("the palette has {got} matrices, the skinning needs {expected}")]
    PaletteLength {
        /// Needed.
        expected: usize,
        /// Given.
        got: usize,
    },
    /// The skinning refers to a palette entry past its palette.
    #[error("the skinning refers to palette entry {entry}, but the palette has {palette_len}")]
    PaletteEntry {
        /// The entry.
        entry: usize,
        /// Palette length.
        palette_len: usize,
    },
    /// A palette matrix is not finite.
    #[error("palette matrix {index} is not finite")]
    NonFinitePalette {
        /// Index in the palette.
        index: usize,
    },
}

/// The rotation factor `Q` of the polar decomposition `A = Q H` (`H` symmetric positive
/// definite) of a non-singular `A` with `det A > 0`, by Higham's scaled Newton iteration
/// `X ← (ζ X + X⁻ᵀ / ζ) / 2`, `ζ = (|X⁻¹|_F / |X|_F)^½`. `None` for a singular, reflecting or
/// non-finite `A`.
#[must_use]
pub fn polar_rotation(a: DMat3) -> Option<DMat3> {
    let frob = |m: DMat3| m.to_cols_array().iter().map(|v| v * v).sum::<f64>().sqrt();
    let det = a.determinant();
    let size = frob(a);
    if !(det.is_finite() && size.is_finite()) || det <= SINGULAR_BLEND_TOL * size.powi(3) {
        return None;
    }
    let mut x = a;
    for _ in 0..POLAR_MAX_ITERATIONS {
        let inv = x.inverse();
        let zeta = (frob(inv) / frob(x)).sqrt();
        let next = (x * zeta + inv.transpose() * (1.0 / zeta)) * 0.5;
        let change = frob(next - x);
        x = next;
        if !x.is_finite() {
            return None;
        }
        if change <= POLAR_TOL * frob(x) {
            break;
        }
    }
    Some(x)
}

/// Per-Gaussian data of the LBS rig.
#[derive(Clone, Copy, Debug)]
struct RestGaussian {
    mean: DVec3,
    rotation: DQuat,
    /// `B(rest)⁻¹` (identity when the blend is singular).
    inverse_rest: DMat4,
}

/// Deforms bound Gaussians by linear blend skinning, frame after frame, for one template.
#[derive(Clone, Debug)]
pub struct LbsDeformer {
    /// Row `g` of the blended influences: `offsets[g]..offsets[g + 1]`.
    offsets: Vec<u32>,
    entries: Vec<u32>,
    weights: Vec<f64>,
    palette_len: usize,
    rest: Vec<RestGaussian>,
    rest_log_scales: Vec<Vec3>,
    /// Adaptive scale: the template's rest triangle areas (empty when off).
    rest_areas: Vec<f64>,
    triangles: Vec<[u32; 3]>,
    vertex_count: usize,
    binding: Vec<u32>,
}

fn blend(entries: &[u32], weights: &[f64], palette: &[DMat4]) -> DMat4 {
    let mut m = DMat4::ZERO;
    for (&e, &w) in entries.iter().zip(weights) {
        m += palette[e as usize] * w;
    }
    m
}

fn linear(m: &DMat4) -> DMat3 {
    DMat3::from_cols(
        m.x_axis.truncate(),
        m.y_axis.truncate(),
        m.z_axis.truncate(),
    )
}

fn triangle_area(positions: &[DVec3], t: [u32; 3]) -> f64 {
    let v = corners_of(positions, t);
    0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length()
}

impl LbsDeformer {
    /// A rig for `set` (bound, local parameters in the GaussianAvatars convention) on
    /// `template` (its rest shape), with the template's `skinning` and the palette of the rest
    /// pose (`rest_palette`, e.g. [`trisplat_geometry::animation::GltfTemplate::palette_at`]
    /// with `None`).
    ///
    /// # Errors
    /// [`LbsError::Deform`] for a set that is not bound/local or binds past the template,
    /// [`LbsError::SkinningVertices`], [`LbsError::PaletteLength`], [`LbsError::PaletteEntry`],
    /// [`LbsError::NonFinitePalette`].
    pub fn new(
        set: &GaussianSet,
        template: &TriMesh,
        skinning: &VertexSkinning,
        rest_palette: &[DMat4],
    ) -> Result<Self, LbsError> {
        let vertex_count = template.vertex_count();
        if skinning.offsets.len() != vertex_count + 1 {
            return Err(LbsError::SkinningVertices {
                expected: vertex_count,
                got: skinning.offsets.len().saturating_sub(1),
            });
        }
        check_palette(rest_palette, skinning.palette_len)?;
        if let Some(index) = skinning
            .entries
            .iter()
            .position(|&e| e as usize >= skinning.palette_len)
        {
            return Err(LbsError::PaletteEntry {
                entry: skinning.entries[index] as usize,
                palette_len: skinning.palette_len,
            });
        }
        let options = FrameOptions::for_positions(template.positions());
        let baker = Deformer::with_options(template, DeformMode::Binding, options);
        let mut world = WorldGeometry::default();
        baker.deform_geometry(set, template.positions(), &mut world)?;
        let binding: Vec<u32> = set
            .binding()
            .map(|b| b.triangles.iter().map(|t| t.0).collect())
            .unwrap_or_default();
        let positions = template.positions();
        let tris = template.triangles();
        // Blended influences per Gaussian: the union of the three vertices' rows, weighted by
        // the barycentric weights of the rest mean's closest point on its triangle.
        let rows: Vec<(Vec<u32>, Vec<f64>, RestGaussian)> = (0..set.len())
            .into_par_iter()
            .map(|g| {
                let t = tris[binding[g] as usize];
                let v = corners_of(positions, t);
                let mean = world.means[g].as_dvec3();
                let (_, bary) = closest_point_on_triangle(mean, v[0], v[1], v[2]);
                let mut merged: Vec<(u32, f64)> = Vec::with_capacity(12);
                for (corner, &b) in t.iter().zip(&bary) {
                    if b == 0.0 {
                        continue;
                    }
                    for (e, w) in skinning.influences(*corner as usize) {
                        merged.push((e as u32, w * b));
                    }
                }
                merged.sort_by_key(|&(e, _)| e);
                let mut entries = Vec::with_capacity(merged.len());
                let mut weights: Vec<f64> = Vec::with_capacity(merged.len());
                for (e, w) in merged {
                    if entries.last() == Some(&e) {
                        if let Some(last) = weights.last_mut() {
                            *last += w;
                        }
                    } else {
                        entries.push(e);
                        weights.push(w);
                    }
                }
                let b_rest = blend(&entries, &weights, rest_palette);
                let l = linear(&b_rest);
                let size = l
                    .x_axis
                    .length()
                    .max(l.y_axis.length())
                    .max(l.z_axis.length());
                let inverse_rest = if l.determinant().abs() > SINGULAR_BLEND_TOL * size.powi(3)
                    && b_rest.inverse().is_finite()
                {
                    b_rest.inverse()
                } else {
                    DMat4::IDENTITY
                };
                let [w, x, y, z] = world.rotations[g].map(f64::from);
                let rest = RestGaussian {
                    mean,
                    rotation: DQuat::from_xyzw(x, y, z, w),
                    inverse_rest,
                };
                (entries, weights, rest)
            })
            .collect();
        let mut offsets = Vec::with_capacity(set.len() + 1);
        offsets.push(0u32);
        let mut entries = Vec::new();
        let mut weights = Vec::new();
        let mut rest = Vec::with_capacity(set.len());
        for (e, w, r) in rows {
            entries.extend(e);
            weights.extend(w);
            offsets.push(u32::try_from(entries.len()).unwrap_or(u32::MAX));
            rest.push(r);
        }
        Ok(Self {
            offsets,
            entries,
            weights,
            palette_len: skinning.palette_len,
            rest,
            rest_log_scales: world.log_scales,
            rest_areas: Vec::new(),
            triangles: tris.to_vec(),
            vertex_count,
            binding,
        })
    }

    /// Scales every Gaussian by `√(area_frame / area_rest)` of its triangle (3DFilmPCA's
    /// adaptive scale), so Gaussians on stretched skin grow with it; frames must then come with
    /// their vertex positions. Triangles with zero rest area keep scale factor 1.
    #[must_use]
    pub fn with_adaptive_scale(mut self, template: &TriMesh) -> Self {
        self.rest_areas = template
            .triangles()
            .iter()
            .map(|&t| triangle_area(template.positions(), t))
            .collect();
        self
    }

    /// Whether adaptive scale is on (then [`Self::deform`] needs frame positions).
    #[must_use]
    pub fn adaptive_scale(&self) -> bool {
        !self.rest_areas.is_empty()
    }

    /// Deforms `set` (the one the rig was built for) with the palette of a frame; with adaptive
    /// scale, `positions` are the frame's template vertices. Returns a world-space set (SH,
    /// opacities and extras copied, no binding).
    ///
    /// # Errors
    /// [`LbsError::PaletteLength`], [`LbsError::NonFinitePalette`]; with adaptive scale
    /// [`DeformError::VertexCount`] when `positions` are missing or of the wrong length;
    /// [`DeformError::NonFiniteOutput`].
    pub fn deform(
        &self,
        set: &GaussianSet,
        palette: &[DMat4],
        positions: Option<&[DVec3]>,
    ) -> Result<GaussianSet, LbsError> {
        check_palette(palette, self.palette_len)?;
        if set.len() != self.rest.len() {
            return Err(DeformError::VertexCount {
                expected: self.rest.len(),
                got: set.len(),
            }
            .into());
        }
        let ln_area: Vec<f32> = if self.adaptive_scale() {
            let p = positions.unwrap_or(&[]);
            if p.len() != self.vertex_count {
                return Err(DeformError::VertexCount {
                    expected: self.vertex_count,
                    got: p.len(),
                }
                .into());
            }
            self.triangles
                .par_iter()
                .zip(&self.rest_areas)
                .map(|(&t, &a0)| {
                    let a = triangle_area(p, t);
                    if a0 > 0.0 && a.is_finite() {
                        (0.5 * (a.max(f64::MIN_POSITIVE) / a0).ln()) as f32
                    } else {
                        0.0
                    }
                })
                .collect()
        } else {
            Vec::new()
        };
        let surfel = set.scale_dims() == ScaleDims::Two;
        let out: Vec<(Vec3, [f32; 4], Vec3)> = (0..self.rest.len())
            .into_par_iter()
            .with_min_len(1024)
            .map(|g| {
                let (a, b) = (self.offsets[g] as usize, self.offsets[g + 1] as usize);
                let r = &self.rest[g];
                let m = blend(&self.entries[a..b], &self.weights[a..b], palette) * r.inverse_rest;
                let mean = m.transform_point3(r.mean);
                let rotation = match polar_rotation(linear(&m)) {
                    Some(q) => (DQuat::from_mat3(&q) * r.rotation).normalize(),
                    None => r.rotation,
                };
                let mut ls = self.rest_log_scales[g];
                if let Some(&f) = ln_area.get(self.binding[g] as usize) {
                    ls += Vec3::splat(f);
                }
                if surfel {
                    ls.z = 0.0;
                }
                (mean.as_vec3(), to_wxyz(rotation), ls)
            })
            .collect();
        if let Some(index) = out.iter().position(|(m, q, s)| {
            !(m.is_finite() && s.is_finite() && q.iter().all(|v| v.is_finite()))
        }) {
            return Err(DeformError::NonFiniteOutput { index }.into());
        }
        let mut means = Vec::with_capacity(out.len());
        let mut rotations = Vec::with_capacity(out.len());
        let mut log_scales = Vec::with_capacity(out.len());
        for (m, q, s) in out {
            means.push(m);
            rotations.push(q);
            log_scales.push(s);
        }
        let geometry = WorldGeometry {
            means,
            rotations,
            log_scales,
        };
        Ok(geometry.into_set(set))
    }
}

fn check_palette(palette: &[DMat4], expected: usize) -> Result<(), LbsError> {
    if palette.len() != expected {
        return Err(LbsError::PaletteLength {
            expected,
            got: palette.len(),
        });
    }
    match palette.iter().position(|m| !m.is_finite()) {
        Some(index) => Err(LbsError::NonFinitePalette { index }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::rng::Rng;

    #[test]
    fn polar_rotation_of_rotation_times_spd() {
        let mut rng = Rng::new(4);
        for _ in 0..500 {
            let q = crate::test_util::random_rotation(&mut rng);
            let r = DMat3::from_quat(q);
            let b = crate::test_util::random_matrix(&mut rng);
            // H = BᵀB + I/2 is symmetric positive definite.
            let h = b.transpose() * b + DMat3::IDENTITY * 0.5;
            let got = polar_rotation(r * h * 3.0).unwrap();
            let err = (got - r)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(err < 1e-12, "{err}");
        }
        assert_eq!(polar_rotation(DMat3::ZERO), None);
        assert_eq!(
            polar_rotation(DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0))),
            None
        );
        assert_eq!(polar_rotation(DMat3::IDENTITY * f64::NAN), None);
    }
}
