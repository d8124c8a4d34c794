//! [`GaussianSet`]: Gaussians as a structure of arrays, in the raw (pre-activation) form of the
//! INRIA 3DGS files, with activation helpers.
//!
//! Stored values are raw, as in the files (docs/conventions.md §3): log-scales, opacity logits, and rotations as
//! un-normalised quaternions with **w first**. Activation happens on read: scale = exp(log-scale),
//! opacity = sigmoid(logit), rotation = normalize(quaternion). A set may be bound to the triangles
//! of a template mesh ([`Binding`]), in which case its parameters are usually in the triangle's
//! local frame ([`ParameterSpace::Local`], the GaussianAvatars layout).

use std::fmt;

use glam::{DMat3, DQuat, Vec3};
use trisplat_geometry::TriId;

use crate::material::attributes::Material;

/// Highest spherical-harmonics degree of the 3DGS files.
pub const SH_MAX_DEGREE: u8 = 3;

/// Largest log-scale accepted: `exp` of it is still finite in `f32` (`ln(f32::MAX)` ≈ 88.72).
pub const MAX_LOG_SCALE: f32 = 88.0;

/// How many issues a [`GaussianReport`] lists before it only counts.
pub const MAX_REPORTED_ISSUES: usize = 100;

pub use crate::sh::sh_coeffs_per_channel;

/// Whether Gaussians carry three scales (3DGS) or two (2DGS surfels, flat along local z).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ScaleDims {
    /// Three log-scales (`scale_0..2`).
    #[default]
    Three,
    /// Two log-scales (`scale_0..1`); the third axis has zero extent. The stored third log-scale
    /// is ignored and [`GaussianSet::scale`] returns 0 for it.
    Two,
}

impl ScaleDims {
    /// Number of stored scales (2 or 3).
    #[must_use]
    pub fn count(self) -> usize {
        match self {
            Self::Three => 3,
            Self::Two => 2,
        }
    }
}

/// Which frame the means, rotations and scales are expressed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ParameterSpace {
    /// World space: the file is viewable as is.
    #[default]
    World,
    /// The local frame of each Gaussian's bound triangle (GaussianAvatars): needs a [`Binding`]
    /// and a template to become world space (see [`crate::deform`]).
    Local,
}

/// PLY scalar types, shared with the general PLY reader of the geometry crate.
pub use trisplat_geometry::io::ply::ScalarType;

/// Values of one per-Gaussian property, in the type the file stored them in (so they are written
/// back bit for bit): the general PLY reader's typed column.
pub use trisplat_geometry::io::ply::ScalarColumn as PropertyValues;

/// An extra per-Gaussian property kept by name (normals, a `transform` float, ...).
#[derive(Clone, Debug, PartialEq)]
pub struct ExtraProperty {
    /// The property name in the file.
    pub name: String,
    /// One value per Gaussian, in the stored type.
    pub values: PropertyValues,
}

/// How a binding is stored in a PLY file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BindingEncoding {
    /// GaussianAvatars: a `float` property `binding_0` holding the triangle index.
    #[default]
    Float,
    /// An integer property `binding` of the given type.
    Integer(ScalarType),
}

/// The parent triangle of each Gaussian.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Binding {
    /// One triangle per Gaussian.
    pub triangles: Vec<TriId>,
    /// How to write it back.
    pub encoding: BindingEncoding,
}

/// One problem found by [`GaussianSet::report`] (and the error of [`GaussianSet::try_new`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GaussianError {
    /// An array does not have one entry (or one block of entries) per Gaussian.
    #[error("{field} has {len} values, expected {expected}")]
    LengthMismatch {
        /// Which array.
        field: &'static str,
        /// Its length.
        len: usize,
        /// The length it should have.
        expected: usize,
    },
    /// A NaN or infinite value.
    #[error("Gaussian {index}: {field} is not finite")]
    NonFinite {
        /// Gaussian index.
        index: usize,
        /// Which parameter.
        field: &'static str,
    },
    /// A log-scale so large that its exponential overflows `f32`.
    #[error("Gaussian {index}: log-scale {value} exceeds {MAX_LOG_SCALE}")]
    ScaleOverflow {
        /// Gaussian index.
        index: usize,
        /// The log-scale.
        value: f32,
    },
    /// A rotation quaternion with all four components zero (it has no direction).
    #[error("Gaussian {index}: rotation quaternion is zero")]
    ZeroQuaternion {
        /// Gaussian index.
        index: usize,
    },
    /// A binding to a triangle the template does not have.
    #[error(
        "Gaussian {index}: bound to triangle {triangle}, but the template has {triangle_count}"
    )]
    BindingOutOfRange {
        /// Gaussian index.
        index: usize,
        /// The triangle it names.
        triangle: TriId,
        /// Number of triangles of the template.
        triangle_count: usize,
    },
    /// Local parameters without a binding cannot be placed in the world.
    #[error("parameters are in local triangle frames but there is no binding")]
    LocalWithoutBinding,
    /// A material attribute (albedo, roughness, F0) that is not finite or outside `0..=1`.
    #[error("Gaussian {index}: {field} {value} is not in 0..=1")]
    MaterialOutOfRange {
        /// Gaussian index.
        index: usize,
        /// Which attribute.
        field: &'static str,
        /// The value.
        value: f32,
    },
    /// SH degree above 3.
    #[error("SH degree {degree} is above {SH_MAX_DEGREE}")]
    ShDegree {
        /// The degree.
        degree: u8,
    },
}

/// Every problem of a [`GaussianSet`] (the first [`MAX_REPORTED_ISSUES`] listed, all counted).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianReport {
    /// The problems found, at most [`MAX_REPORTED_ISSUES`].
    pub issues: Vec<GaussianError>,
    /// How many problems there are in all.
    pub total: usize,
}

impl GaussianReport {
    /// Whether nothing is wrong.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        self.total == 0
    }

    fn push(&mut self, issue: GaussianError) {
        if self.issues.len() < MAX_REPORTED_ISSUES {
            self.issues.push(issue);
        }
        self.total += 1;
    }
}

impl fmt::Display for GaussianReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.total == 0 {
            return write!(f, "valid");
        }
        write!(f, "{} problem(s)", self.total)?;
        for issue in &self.issues {
            write!(f, "; {issue}")?;
        }
        Ok(())
    }
}

/// The parts of a [`GaussianSet`], with public fields, for building and taking apart.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianParts {
    /// Centres.
    pub means: Vec<Vec3>,
    /// Natural-log scales; with [`ScaleDims::Two`] the third component is ignored.
    pub log_scales: Vec<Vec3>,
    /// Three scales or two (2DGS surfels).
    pub scale_dims: ScaleDims,
    /// Raw rotation quaternions `[w, x, y, z]` (normalised on activation).
    pub rotations: Vec<[f32; 4]>,
    /// Opacity logits (opacity = sigmoid).
    pub opacity_logits: Vec<f32>,
    /// SH degree, 0..=3.
    pub sh_degree: u8,
    /// SH coefficients, `3 (degree + 1)²` per Gaussian in file order: `f_dc_0..2`, then `f_rest`
    /// channel-major (red coefficients 1..K-1, then green, then blue).
    pub sh: Vec<f32>,
    /// Parent triangles, if bound.
    pub binding: Option<Binding>,
    /// Physically based material attributes (HRAvatar), if any.
    pub material: Option<Material>,
    /// The frame the parameters are in.
    pub space: ParameterSpace,
    /// Extra per-Gaussian properties, in file order.
    pub extras: Vec<ExtraProperty>,
    /// The vertex property names of the file this set was read from, in file order. Writers
    /// keep this order for the properties they write and append the others; `None` writes the
    /// INRIA order.
    pub property_order: Option<Vec<String>>,
}

/// Gaussians as a structure of arrays (see the module documentation for conventions).
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianSet {
    parts: GaussianParts,
}

impl GaussianSet {
    /// Builds a set, checking lengths, finiteness, quaternions, the SH degree and that local
    /// parameters come with a binding. Binding indices are checked against a template with
    /// [`GaussianSet::report`].
    ///
    /// # Errors
    /// The first problem found ([`GaussianSet::report`] lists them all).
    pub fn try_new(parts: GaussianParts) -> Result<Self, GaussianError> {
        let set = Self { parts };
        let mut report = GaussianReport::default();
        set.check_into(None, &mut report, true);
        match report.issues.into_iter().next() {
            Some(first) => Err(first),
            None => Ok(set),
        }
    }

    /// Builds a set from parts known to be valid (e.g. the output of a deformation of a valid
    /// set). Nothing is checked; activation of a zero quaternion then gives the identity rotation.
    #[must_use]
    pub fn new_unchecked(parts: GaussianParts) -> Self {
        Self { parts }
    }

    /// Takes the set apart.
    #[must_use]
    pub fn into_parts(self) -> GaussianParts {
        self.parts
    }

    /// Every problem of the set; with `triangle_count`, also bindings past the template's
    /// triangles.
    #[must_use]
    pub fn report(&self, triangle_count: Option<usize>) -> GaussianReport {
        let mut report = GaussianReport::default();
        self.check_into(triangle_count, &mut report, false);
        report
    }

    fn check_into(&self, triangle_count: Option<usize>, r: &mut GaussianReport, first_only: bool) {
        let p = &self.parts;
        let n = p.means.len();
        if p.sh_degree > SH_MAX_DEGREE {
            r.push(GaussianError::ShDegree {
                degree: p.sh_degree,
            });
            return;
        }
        let sh_stride = 3 * sh_coeffs_per_channel(p.sh_degree);
        let mut lengths: Vec<(&'static str, usize, usize)> = vec![
            ("log_scales", p.log_scales.len(), n),
            ("rotations", p.rotations.len(), n),
            ("opacity_logits", p.opacity_logits.len(), n),
            ("sh", p.sh.len(), n * sh_stride),
        ];
        if let Some(b) = &p.binding {
            lengths.push(("binding", b.triangles.len(), n));
        }
        if let Some(m) = &p.material {
            lengths.push(("albedo", m.albedo.len(), n));
            lengths.push(("roughness", m.roughness.len(), n));
            lengths.push(("reflectance", m.f0.len(), n));
        }
        for e in &p.extras {
            lengths.push(("extra property", e.values.len(), n));
        }
        let mut bad_length = false;
        for (field, len, expected) in lengths {
            if len != expected {
                r.push(GaussianError::LengthMismatch {
                    field,
                    len,
                    expected,
                });
                bad_length = true;
            }
        }
        if p.space == ParameterSpace::Local && p.binding.is_none() {
            r.push(GaussianError::LocalWithoutBinding);
        }
        if bad_length || (first_only && r.total > 0) {
            return;
        }
        let dims = p.scale_dims.count();
        for i in 0..n {
            if first_only && r.total > 0 {
                return;
            }
            if !p.means[i].is_finite() {
                r.push(GaussianError::NonFinite {
                    index: i,
                    field: "mean",
                });
            }
            let ls = p.log_scales[i].to_array();
            if ls[..dims].iter().any(|v| !v.is_finite()) {
                r.push(GaussianError::NonFinite {
                    index: i,
                    field: "log-scale",
                });
            } else if let Some(&value) = ls[..dims].iter().find(|&&v| v > MAX_LOG_SCALE) {
                r.push(GaussianError::ScaleOverflow { index: i, value });
            }
            let q = p.rotations[i];
            if q.iter().any(|v| !v.is_finite()) {
                r.push(GaussianError::NonFinite {
                    index: i,
                    field: "rotation",
                });
            } else if q.iter().all(|&v| v == 0.0) {
                r.push(GaussianError::ZeroQuaternion { index: i });
            }
            if !p.opacity_logits[i].is_finite() {
                r.push(GaussianError::NonFinite {
                    index: i,
                    field: "opacity",
                });
            }
            if p.sh[i * sh_stride..(i + 1) * sh_stride]
                .iter()
                .any(|v| !v.is_finite())
            {
                r.push(GaussianError::NonFinite {
                    index: i,
                    field: "SH coefficient",
                });
            }
            if let Some((field, value)) = p.material.as_ref().and_then(|m| m.out_of_range_at(i)) {
                r.push(GaussianError::MaterialOutOfRange {
                    index: i,
                    field,
                    value,
                });
            }
            if let (Some(b), Some(count)) = (&p.binding, triangle_count) {
                let t = b.triangles[i];
                if t.index() >= count {
                    r.push(GaussianError::BindingOutOfRange {
                        index: i,
                        triangle: t,
                        triangle_count: count,
                    });
                }
            }
        }
    }

    /// The Gaussians at `indices`, in that order (repeats allowed), with every property, the
    /// binding and the property order carried along.
    ///
    /// # Panics
    /// If an index is `>= self.len()`.
    #[must_use]
    pub fn select(&self, indices: &[usize]) -> Self {
        let p = &self.parts;
        let stride = 3 * sh_coeffs_per_channel(p.sh_degree);
        let pick = |v: &[f32]| indices.iter().map(|&i| v[i]).collect::<Vec<f32>>();
        let parts = GaussianParts {
            means: indices.iter().map(|&i| p.means[i]).collect(),
            log_scales: indices.iter().map(|&i| p.log_scales[i]).collect(),
            scale_dims: p.scale_dims,
            rotations: indices.iter().map(|&i| p.rotations[i]).collect(),
            opacity_logits: pick(&p.opacity_logits),
            sh_degree: p.sh_degree,
            sh: indices
                .iter()
                .flat_map(|&i| p.sh[i * stride..(i + 1) * stride].iter().copied())
                .collect(),
            binding: p.binding.as_ref().map(|b| Binding {
                triangles: indices.iter().map(|&i| b.triangles[i]).collect(),
                encoding: b.encoding,
            }),
            material: p.material.as_ref().map(|m| m.select(indices)),
            space: p.space,
            extras: p
                .extras
                .iter()
                .map(|e| ExtraProperty {
                    name: e.name.clone(),
                    values: e.values.gather(indices),
                })
                .collect(),
            property_order: p.property_order.clone(),
        };
        Self { parts }
    }

    /// Number of Gaussians.
    #[must_use]
    pub fn len(&self) -> usize {
        self.parts.means.len()
    }

    /// Whether the set is empty.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.parts.means.is_empty()
    }

    /// Centres (world or local, see [`GaussianSet::space`]).
    #[must_use]
    pub fn means(&self) -> &[Vec3] {
        &self.parts.means
    }

    /// Raw log-scales.
    #[must_use]
    pub fn log_scales(&self) -> &[Vec3] {
        &self.parts.log_scales
    }

    /// Three scales or two.
    #[must_use]
    pub fn scale_dims(&self) -> ScaleDims {
        self.parts.scale_dims
    }

    /// Raw quaternions, `[w, x, y, z]`.
    #[must_use]
    pub fn rotations(&self) -> &[[f32; 4]] {
        &self.parts.rotations
    }

    /// Raw opacity logits.
    #[must_use]
    pub fn opacity_logits(&self) -> &[f32] {
        &self.parts.opacity_logits
    }

    /// SH degree 0..=3.
    #[must_use]
    pub fn sh_degree(&self) -> u8 {
        self.parts.sh_degree
    }

    /// All SH coefficients (layout in [`GaussianParts::sh`]).
    #[must_use]
    pub fn sh(&self) -> &[f32] {
        &self.parts.sh
    }

    /// The `3 (degree + 1)²` SH coefficients of Gaussian `i`.
    ///
    /// # Panics
    /// If `i >= self.len()`.
    #[must_use]
    pub fn sh_coeffs(&self, i: usize) -> &[f32] {
        let stride = 3 * sh_coeffs_per_channel(self.parts.sh_degree);
        &self.parts.sh[i * stride..(i + 1) * stride]
    }

    /// The binding, if any.
    #[must_use]
    pub fn binding(&self) -> Option<&Binding> {
        self.parts.binding.as_ref()
    }

    /// The material attributes, if any.
    #[must_use]
    pub fn material(&self) -> Option<&Material> {
        self.parts.material.as_ref()
    }

    /// The set with `material` in place of its own (`None` removes it).
    ///
    /// # Errors
    /// [`GaussianError::LengthMismatch`] or [`GaussianError::MaterialOutOfRange`]; the set is
    /// then unchanged.
    pub fn set_material(&mut self, material: Option<Material>) -> Result<(), GaussianError> {
        if let Some(m) = &material {
            let n = self.len();
            for (field, len) in [
                ("albedo", m.albedo.len()),
                ("roughness", m.roughness.len()),
                ("reflectance", m.f0.len()),
            ] {
                if len != n {
                    return Err(GaussianError::LengthMismatch {
                        field,
                        len,
                        expected: n,
                    });
                }
            }
            if let Some((index, field, value)) = m.first_out_of_range() {
                return Err(GaussianError::MaterialOutOfRange {
                    index,
                    field,
                    value,
                });
            }
        }
        self.parts.material = material;
        Ok(())
    }

    /// The frame the parameters are in.
    #[must_use]
    pub fn space(&self) -> ParameterSpace {
        self.parts.space
    }

    /// Extra properties in file order.
    #[must_use]
    pub fn extras(&self) -> &[ExtraProperty] {
        &self.parts.extras
    }

    /// The property order of the file this set was read from (see
    /// [`GaussianParts::property_order`]).
    #[must_use]
    pub fn property_order(&self) -> Option<&[String]> {
        self.parts.property_order.as_deref()
    }

    /// The extra property called `name`.
    #[must_use]
    pub fn extra(&self, name: &str) -> Option<&ExtraProperty> {
        self.parts.extras.iter().find(|e| e.name == name)
    }

    /// Activated scales of Gaussian `i`: `exp(log_scale)`, 0 for the flat axis of a surfel.
    ///
    /// # Panics
    /// If `i >= self.len()`.
    #[must_use]
    pub fn scale(&self, i: usize) -> Vec3 {
        let s = self.parts.log_scales[i].exp();
        match self.parts.scale_dims {
            ScaleDims::Three => s,
            ScaleDims::Two => Vec3::new(s.x, s.y, 0.0),
        }
    }

    /// Activated opacity of Gaussian `i`: `sigmoid(logit)`.
    ///
    /// # Panics
    /// If `i >= self.len()`.
    #[must_use]
    pub fn opacity(&self, i: usize) -> f32 {
        sigmoid(self.parts.opacity_logits[i])
    }

    /// Normalised rotation of Gaussian `i` (computed in `f64`).
    ///
    /// A zero quaternion can only be present in a set made with [`GaussianSet::new_unchecked`];
    /// it activates to the identity.
    ///
    /// # Panics
    /// If `i >= self.len()`.
    #[must_use]
    pub fn rotation(&self, i: usize) -> DQuat {
        normalize_wxyz(self.parts.rotations[i]).unwrap_or(DQuat::IDENTITY)
    }

    /// Rotation matrix of Gaussian `i` (columns: the Gaussian's axes in the parameter frame).
    ///
    /// # Panics
    /// If `i >= self.len()`.
    #[must_use]
    pub fn rotation_matrix(&self, i: usize) -> DMat3 {
        DMat3::from_quat(self.rotation(i))
    }

    /// Covariance `Σ = R S Sᵀ Rᵀ` of Gaussian `i`, in `f64`.
    ///
    /// # Panics
    /// If `i >= self.len()`.
    #[must_use]
    pub fn covariance(&self, i: usize) -> DMat3 {
        let r = self.rotation_matrix(i);
        let s = self.scale(i).as_dvec3();
        let m = DMat3::from_cols(r.x_axis * s.x, r.y_axis * s.y, r.z_axis * s.z);
        m * m.transpose()
    }

    /// Colour of Gaussian `i` seen from `camera_centre` (docs/conventions.md §3), see [`crate::sh::eval_rgb`].
    ///
    /// # Panics
    /// If `i >= self.len()`.
    #[must_use]
    pub fn color(&self, i: usize, camera_centre: Vec3) -> [f32; 3] {
        let dir = self.parts.means[i].as_dvec3() - camera_centre.as_dvec3();
        crate::sh::eval_rgb(self.parts.sh_degree, self.sh_coeffs(i), dir)
    }
}

/// `sigmoid(x) = 1 / (1 + exp(-x))`, evaluated in `f64` (no overflow for any finite `x`).
#[must_use]
pub fn sigmoid(x: f32) -> f32 {
    let x = f64::from(x);
    let y = if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    };
    y as f32
}

/// The inverse of [`sigmoid`]: `ln(p / (1 - p))`, in `f64`.
#[must_use]
pub fn logit(p: f32) -> f32 {
    let p = f64::from(p);
    (p / (1.0 - p)).ln() as f32
}

/// Normalises a raw `[w, x, y, z]` quaternion in `f64`; `None` when it is zero or not finite.
#[must_use]
pub fn normalize_wxyz(q: [f32; 4]) -> Option<DQuat> {
    let [w, x, y, z] = q.map(f64::from);
    let norm = (w * w + x * x + y * y + z * z).sqrt();
    (norm > 0.0 && norm.is_finite())
        .then(|| DQuat::from_xyzw(x / norm, y / norm, z / norm, w / norm))
}

/// A unit quaternion as `[w, x, y, z]` in `f32`, the sign chosen with `w ≥ 0`.
#[must_use]
pub fn to_wxyz(q: DQuat) -> [f32; 4] {
    let q = if q.w < 0.0 { -q } else { q };
    [q.w as f32, q.x as f32, q.y as f32, q.z as f32]
}

/// The rotation of a `f64` matrix whose columns are orthonormal, as a unit quaternion (Shepperd's
/// method, stable for every rotation).
#[must_use]
pub fn quat_from_rotation(m: DMat3) -> DQuat {
    let (m00, m11, m22) = (m.x_axis.x, m.y_axis.y, m.z_axis.z);
    let trace = m00 + m11 + m22;
    // m[row][col] = col_axis.row
    let (m01, m02) = (m.y_axis.x, m.z_axis.x);
    let (m10, m12) = (m.x_axis.y, m.z_axis.y);
    let (m20, m21) = (m.x_axis.z, m.y_axis.z);
    let q = if trace > 0.0 {
        let s = (trace + 1.0).sqrt() * 2.0;
        DQuat::from_xyzw((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    } else if m00 > m11 && m00 > m22 {
        let s = (1.0 + m00 - m11 - m22).sqrt() * 2.0;
        DQuat::from_xyzw(0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    } else if m11 > m22 {
        let s = (1.0 + m11 - m00 - m22).sqrt() * 2.0;
        DQuat::from_xyzw((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    } else {
        let s = (1.0 + m22 - m00 - m11).sqrt() * 2.0;
        DQuat::from_xyzw((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    };
    q.normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f32 inputs, f64 arithmetic: agreement of two f64 evaluations of the same formula.
    const F64_TOL: f64 = 1e-12;

    fn one(q: [f32; 4]) -> GaussianParts {
        GaussianParts {
            means: vec![Vec3::new(1.0, 2.0, 3.0)],
            log_scales: vec![Vec3::new(0.0, -1.0, -29.0)],
            rotations: vec![q],
            opacity_logits: vec![0.0],
            sh: vec![0.1, 0.2, 0.3],
            ..GaussianParts::default()
        }
    }

    #[test]
    fn activation_and_covariance() {
        let set = GaussianSet::try_new(one([2.0, 0.0, 0.0, 2.0])).unwrap();
        assert_eq!(set.opacity(0), 0.5);
        let s = set.scale(0);
        assert!(
            s.z > 0.0 && s.z.is_finite(),
            "exp(-29) must stay positive: {s}"
        );
        // 90 degrees about z (q = (1, 0, 0, 1)/sqrt 2): x -> y.
        let r = set.rotation_matrix(0);
        assert!((r.x_axis - glam::DVec3::Y).length() < F64_TOL);
        let cov = set.covariance(0);
        // Hand: R diag(s^2) R^T; x axis scale 1 goes to y, y axis scale e^-1 goes to -x.
        let sy = f64::from(s.y);
        assert!((cov.y_axis.y - 1.0).abs() < F64_TOL);
        assert!((cov.x_axis.x - sy * sy).abs() < F64_TOL);
        assert!(cov.x_axis.y.abs() < F64_TOL);
        assert!(cov.z_axis.z > 0.0);
        assert_eq!(sigmoid(1000.0), 1.0);
        assert_eq!(sigmoid(-1000.0), 0.0);
        assert!((sigmoid(logit(0.1)) - 0.1).abs() < 1e-7);
    }

    #[test]
    fn invalid_sets_are_refused_with_index() {
        assert_eq!(
            GaussianSet::try_new(one([0.0; 4])),
            Err(GaussianError::ZeroQuaternion { index: 0 })
        );
        let mut p = one([1.0, 0.0, 0.0, 0.0]);
        p.means[0].x = f32::NAN;
        assert!(matches!(
            GaussianSet::try_new(p),
            Err(GaussianError::NonFinite {
                index: 0,
                field: "mean"
            })
        ));
        let mut p = one([1.0, 0.0, 0.0, 0.0]);
        p.sh.push(0.0);
        assert!(matches!(
            GaussianSet::try_new(p),
            Err(GaussianError::LengthMismatch { field: "sh", .. })
        ));
        let mut p = one([1.0, 0.0, 0.0, 0.0]);
        p.log_scales[0].y = 100.0;
        assert!(matches!(
            GaussianSet::try_new(p),
            Err(GaussianError::ScaleOverflow { index: 0, .. })
        ));
        let mut p = one([1.0, 0.0, 0.0, 0.0]);
        p.space = ParameterSpace::Local;
        assert_eq!(
            GaussianSet::try_new(p.clone()),
            Err(GaussianError::LocalWithoutBinding)
        );
        p.binding = Some(Binding {
            triangles: vec![TriId(5)],
            encoding: BindingEncoding::Float,
        });
        let set = GaussianSet::try_new(p).unwrap();
        let report = set.report(Some(5));
        assert_eq!(report.total, 1);
        assert!(matches!(
            report.issues[0],
            GaussianError::BindingOutOfRange { index: 0, .. }
        ));
        assert!(set.report(Some(6)).is_valid());
    }

    #[test]
    fn report_lists_everything() {
        let mut p = one([0.0; 4]);
        p.means[0].y = f32::INFINITY;
        p.opacity_logits[0] = f32::NAN;
        let set = GaussianSet::new_unchecked(p);
        let r = set.report(None);
        assert_eq!(r.total, 3, "{r}");
        // Unchecked zero quaternion activates to the identity.
        assert_eq!(set.rotation(0), DQuat::IDENTITY);
    }

    #[test]
    fn quaternion_matrix_round_trip() {
        let mut rng = trisplat_geometry::rng::Rng::new(3);
        for _ in 0..1000 {
            let q = [0; 4].map(|_: i32| rng.uniform_f32() * 2.0 - 1.0);
            let Some(q) = normalize_wxyz(q) else { continue };
            let back = quat_from_rotation(DMat3::from_quat(q));
            assert!(back.dot(q).abs() > 1.0 - 1e-12, "{q} vs {back}");
        }
    }

    #[test]
    fn surfel_third_scale_is_zero() {
        let mut p = one([1.0, 0.0, 0.0, 0.0]);
        p.scale_dims = ScaleDims::Two;
        p.log_scales[0].z = f32::NAN; // ignored
        let set = GaussianSet::try_new(p).unwrap();
        assert_eq!(set.scale(0).z, 0.0);
        assert_eq!(set.covariance(0).z_axis.z, 0.0);
    }
}
