//! The Gaussians as the opacity field sees them: plain arrays in, checked and whitened once.

use glam::{DQuat, DVec3, Vec3};

use super::error::OpacityError;

/// World-space Gaussians for the opacity field, as plain arrays (this crate never sees a
/// renderer's Gaussian set): activated scales (standard deviations along the local axes),
/// normalisable rotations `(w, x, y, z)`, activated opacities in [0, 1] and one linear RGB colour
/// each (for vertex colours).
#[derive(Clone, Debug, Default)]
pub struct OpacityGaussians {
    /// Means.
    pub means: Vec<Vec3>,
    /// Standard deviations along the local axes (all finite and > 0).
    pub scales: Vec<Vec3>,
    /// Rotations, quaternions `(w, x, y, z)` (normalised here).
    pub rotations: Vec<[f32; 4]>,
    /// Opacities in [0, 1].
    pub opacities: Vec<f32>,
    /// Colours (any range; clamped to [0, 1] when written as vertex colours).
    pub colors: Vec<[f32; 3]>,
}

/// The kept Gaussians (opacity at or above the cut), checked, with what every view needs.
#[derive(Debug)]
pub(crate) struct Prepared {
    /// Means, f64.
    pub means: Vec<DVec3>,
    /// The Gaussians' axes scaled by their standard deviations (columns of `R S`).
    pub axes: Vec<[DVec3; 3]>,
    /// Whitening rows: `R_k / s_k`, so `M x` maps a world offset to unit-variance coordinates.
    pub whiten: Vec<[[f32; 3]; 3]>,
    /// Opacities.
    pub opacity: Vec<f32>,
    /// Largest squared whitened distance at which `opacity · exp(-q/2)` reaches the alpha cut
    /// (`2 ln(opacity / min_alpha)`); beyond it the Gaussian adds nothing.
    pub q_max: Vec<f64>,
    /// Colours.
    pub colors: Vec<[f32; 3]>,
    /// Index of each kept Gaussian in the input.
    pub source: Vec<u32>,
}

impl Prepared {
    /// Checks every Gaussian and keeps those whose opacity is at least `cut` (and can reach
    /// `min_alpha`).
    ///
    /// # Errors
    /// [`OpacityError`] naming the first bad Gaussian, or when none is kept.
    pub fn new(g: &OpacityGaussians, cut: f32, min_alpha: f32) -> Result<Self, OpacityError> {
        let n = g.means.len();
        for (what, got) in [
            ("scales", g.scales.len()),
            ("rotations", g.rotations.len()),
            ("opacities", g.opacities.len()),
            ("colors", g.colors.len()),
        ] {
            if got != n {
                return Err(OpacityError::LengthMismatch {
                    what,
                    got,
                    expected: n,
                });
            }
        }
        if n == 0 {
            return Err(OpacityError::Empty);
        }
        let mut out = Self {
            means: Vec::new(),
            axes: Vec::new(),
            whiten: Vec::new(),
            opacity: Vec::new(),
            q_max: Vec::new(),
            colors: Vec::new(),
            source: Vec::new(),
        };
        let floor = cut.max(min_alpha);
        for index in 0..n {
            let (mean, scale, rotation, opacity) = (
                g.means[index],
                g.scales[index],
                g.rotations[index],
                g.opacities[index],
            );
            if !mean.is_finite() {
                return Err(OpacityError::BadMean {
                    index,
                    mean: mean.to_array(),
                });
            }
            if !(scale.is_finite() && scale.min_element() > 0.0) {
                return Err(OpacityError::BadScale {
                    index,
                    scale: scale.to_array(),
                });
            }
            let [w, x, y, z] = rotation.map(f64::from);
            let q = DQuat::from_xyzw(x, y, z, w);
            let norm = q.length();
            if !(norm.is_finite() && norm > 0.0) {
                return Err(OpacityError::BadRotation { index, rotation });
            }
            if !(0.0..=1.0).contains(&opacity) {
                return Err(OpacityError::BadOpacity { index, opacity });
            }
            if opacity < floor {
                continue;
            }
            let r = glam::DMat3::from_quat(q / norm);
            let s = scale.as_dvec3();
            let cols = [r.x_axis, r.y_axis, r.z_axis];
            out.means.push(mean.as_dvec3());
            out.axes.push([cols[0] * s.x, cols[1] * s.y, cols[2] * s.z]);
            out.whiten.push([
                (cols[0] / s.x).as_vec3().to_array(),
                (cols[1] / s.y).as_vec3().to_array(),
                (cols[2] / s.z).as_vec3().to_array(),
            ]);
            out.opacity.push(opacity);
            out.q_max
                .push(2.0 * (f64::from(opacity) / f64::from(min_alpha)).ln());
            out.colors.push(g.colors[index]);
            out.source.push(index as u32);
        }
        if out.means.is_empty() {
            return Err(OpacityError::AllBelowCut {
                count: n,
                cut: floor,
            });
        }
        Ok(out)
    }

    /// Number of kept Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// `M x` for Gaussian `g` (whitened coordinates of the world offset `x`).
    #[inline]
    pub fn whitened(&self, g: usize, x: DVec3) -> DVec3 {
        let m = &self.whiten[g];
        let row = |k: usize| {
            f64::from(m[k][0]) * x.x + f64::from(m[k][1]) * x.y + f64::from(m[k][2]) * x.z
        };
        DVec3::new(row(0), row(1), row(2))
    }
}

/// The points the tetrahedralisation is built on: each kept Gaussian's mean, then the 8
/// corners of its 3-sigma box (`mean + R · diag(3 s) · (±1, ±1, ±1)`), GOF's `get_tetra_points`.
pub(crate) fn tetra_points(p: &Prepared) -> Vec<DVec3> {
    let mut points = Vec::with_capacity(p.len() * 9);
    points.extend_from_slice(&p.means);
    for (mean, axes) in p.means.iter().zip(&p.axes) {
        for corner in 0..8u32 {
            let sign = |bit: u32| if corner >> bit & 1 == 0 { -3.0 } else { 3.0 };
            points.push(*mean + axes[0] * sign(0) + axes[1] * sign(1) + axes[2] * sign(2));
        }
    }
    points
}
