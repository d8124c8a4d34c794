//! Vertex colours of a mesh from the Gaussians near it (`--vertex-colors gaussians`,
//! docs/conventions.md §10).
//!
//! The colour of a vertex at `x` is the mean of the SH degree-0 colours `c_g` (the
//! view-independent part, `0.5 + C0 * f_dc`, clamped to [0, 1]) of its
//! [`COLOR_NEIGHBORS`] nearest Gaussian means, each weighted by its opacity times its density
//! at `x`: `w_g = α_g exp(-½ (x - μ_g)ᵀ Σ_g⁻¹ (x - μ_g))` (each scale floored at
//! [`FLAT_AXIS_FLOOR`] of the Gaussian's largest, so that a flat 2DGS surfel has a density off
//! its plane). A vertex where every weight vanishes (far outside the Gaussians' support) takes
//! its nearest Gaussian's colour. Ties between equally near Gaussians go by index (the k-d
//! tree's rule), so the colours depend on nothing but the mesh and the set.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::Rgba;
use trisplat_geometry::spatial::PointIndex;
use trisplat_splat::{GaussianSet, eval_rgb};

/// How many nearest Gaussians colour a vertex.
pub const COLOR_NEIGHBORS: usize = 16;

/// The smallest scale of a Gaussian's axis, as a share of its largest axis, in the density
/// that weights its colour.
pub const FLAT_AXIS_FLOOR: f64 = 0.01;

/// Each of `positions`' colour from the Gaussians of `set` (same frame and coordinates), opaque
/// RGBA in [0, 1]; `None` when the set is empty or its means cannot be indexed.
#[must_use]
pub fn gaussian_colors(positions: &[DVec3], set: &GaussianSet) -> Option<Vec<Rgba>> {
    if positions.is_empty() {
        return Some(Vec::new());
    }
    let index = PointIndex::new(set.means()).ok()?;
    let queries: Vec<Vec3> = positions.iter().map(|p| p.as_vec3()).collect();
    let near = index
        .k_nearest_batch(&queries, COLOR_NEIGHBORS.min(set.len()))
        .ok()?;
    Some(
        positions
            .par_iter()
            .zip(&near)
            .map(|(&x, near)| {
                let mut sum = [0.0f64; 3];
                let mut total = 0.0f64;
                for n in near {
                    let g = n.index as usize;
                    let w = f64::from(set.opacity(g)) * density(set, g, x);
                    if w > 0.0 && w.is_finite() {
                        let c = color_of(set, g);
                        for k in 0..3 {
                            sum[k] += w * f64::from(c[k]);
                        }
                        total += w;
                    }
                }
                if total > 1e-300 {
                    [
                        (sum[0] / total) as f32,
                        (sum[1] / total) as f32,
                        (sum[2] / total) as f32,
                        1.0,
                    ]
                } else {
                    let c = near
                        .first()
                        .map_or([0.5; 3], |n| color_of(set, n.index as usize));
                    [c[0], c[1], c[2], 1.0]
                }
            })
            .collect(),
    )
}

/// Gaussian `g`'s SH degree-0 colour, clamped to [0, 1].
fn color_of(set: &GaussianSet, g: usize) -> [f32; 3] {
    eval_rgb(0, set.sh_coeffs(g), DVec3::Z).map(|c| c.clamp(0.0, 1.0))
}

/// Gaussian `g`'s unnormalised density at `x`: `exp(-½ d²)`, `d` the Mahalanobis distance.
fn density(set: &GaussianSet, g: usize, x: DVec3) -> f64 {
    let r = set.rotation_matrix(g);
    let s = set.scale(g).as_dvec3();
    let floor = (s.max_element() * FLAT_AXIS_FLOOR).max(f64::MIN_POSITIVE);
    let local = r.transpose() * (x - set.means()[g].as_dvec3());
    let m = local / s.max(DVec3::splat(floor));
    let d2 = m.length_squared();
    if d2.is_finite() {
        (-0.5 * d2).exp()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_splat::{GaussianParts, ParameterSpace, ScaleDims, rgb_to_dc};

    /// Opaque round Gaussians of scale 0.1 at `means` with colours `colors`; the last one flat
    /// (a 2DGS-like surfel: third scale 0).
    fn set(means: &[Vec3], colors: &[[f32; 3]], flat_last: bool) -> GaussianSet {
        let n = means.len();
        let mut log_scales = vec![Vec3::splat(0.1f32.ln()); n];
        if flat_last {
            log_scales[n - 1].z = f32::NEG_INFINITY;
        }
        GaussianSet::new_unchecked(GaussianParts {
            means: means.to_vec(),
            log_scales,
            scale_dims: ScaleDims::Three,
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
            opacity_logits: vec![5.0; n],
            sh_degree: 0,
            sh: colors.iter().flat_map(|c| c.map(rgb_to_dc)).collect(),
            binding: None,
            material: None,
            space: ParameterSpace::World,
            extras: Vec::new(),
            property_order: None,
        })
    }

    #[test]
    fn colours_follow_the_densest_gaussians_and_stay_in_range() {
        let red = [1.0, 0.0, 0.0];
        let blue = [0.0, 0.0, 1.0];
        // A third, out of range (clamped): beyond white.
        let bright = [3.0, 3.0, 3.0];
        let g = set(
            &[Vec3::ZERO, Vec3::X, Vec3::new(0.0, 5.0, 0.0)],
            &[red, blue, bright],
            false,
        );
        let at = [
            DVec3::ZERO,
            DVec3::new(0.5, 0.0, 0.0),
            DVec3::new(0.9, 0.0, 0.0),
            DVec3::new(0.0, 5.0, 0.0),
            // Far from everything: the nearest Gaussian's colour (blue).
            DVec3::new(50.0, 0.0, 0.0),
        ];
        let c = gaussian_colors(&at, &g).expect("colours");
        let close = |a: Rgba, b: [f32; 3]| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-4);
        assert!(close(c[0], red), "{:?}", c[0]);
        // Halfway between two equal Gaussians: the mean of their colours.
        assert!(close(c[1], [0.5, 0.0, 0.5]), "{:?}", c[1]);
        assert!(c[2][2] > 0.99, "{:?}", c[2]);
        assert!(close(c[3], [1.0, 1.0, 1.0]), "{:?}", c[3]);
        assert!(close(c[4], blue), "{:?}", c[4]);
        for rgba in &c {
            assert!(rgba.iter().all(|x| (0.0..=1.0).contains(x)));
            assert_eq!(rgba[3], 1.0);
        }
        assert_eq!(gaussian_colors(&at, &g), Some(c));
    }

    #[test]
    fn a_flat_gaussian_still_colours_points_off_its_plane() {
        // A flat green surfel at the origin (last: third scale 0) and a round red Gaussian.
        let g = set(
            &[Vec3::new(0.6, 0.0, 0.0), Vec3::ZERO],
            &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            true,
        );
        // Two sigmas along the surfel, half its floored thickness (0.001) off its plane: the
        // surfel outweighs the red one, four sigmas away, by about 350 to 1.
        let c = gaussian_colors(&[DVec3::new(0.2, 0.0, 0.0005)], &g).expect("colours");
        assert!(c[0][1] > 0.99 && c[0][0] < 0.01, "{:?}", c[0]);
        assert!(gaussian_colors(&[], &g).expect("none").is_empty());
    }
}
