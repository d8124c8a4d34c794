//! Render consistency: whether a mesh shows what the Gaussians it came from show, seen from
//! views the extraction did not use (docs/conventions.md §8, "Render consistency"). A real
//! avatar has no ground-truth mesh; its own Gaussians are the reference.
//!
//! Per view, the Gaussians are rendered (3DGS, gsplat's rules: alpha, median depth, normals)
//! and the mesh ray cast (z-depth, face normals). Over all views:
//! - **IoU**: pixels where the mesh is hit and the Gaussians' alpha > 0.5, over pixels where
//!   either is;
//! - **depth error**: |mesh z-depth − the Gaussians' median z-depth| over the pixels both
//!   cover, its median and 90th percentile;
//! - **normal angle**: the median angle between the mesh's face normal and the Gaussians'
//!   composited normal (normalised) over the pixels both cover.

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::mesh_render::{MeshRenderOptions, MeshRenderer, NormalFrame};
use trisplat_geometry::{Camera, TriMesh, bounding_sphere, sphere_rig};
use trisplat_splat::GaussianSet;
use trisplat_splat::render::{Outputs, RenderOptions, render};

use crate::error::PipelineError;
pub use crate::records::RenderConsistency;

/// Views of the default consistency rig.
pub const CONSISTENCY_VIEWS: usize = 16;
/// Width and height of the default consistency rig's images, pixels.
pub const CONSISTENCY_RESOLUTION: u32 = 384;
/// Vertical field of view of the consistency rig, degrees (as the tsdf rig's).
pub const CONSISTENCY_FOV_DEG: f64 = 40.0;
/// The alpha above which the Gaussians cover a pixel.
pub const COVERED_ALPHA: f32 = 0.5;
/// The rotation of the consistency rig's lattice about the axis (1, 1, 1), degrees, so that its
/// views fall between those of the extraction's sphere rig (an unrelated angle).
pub const HELD_OUT_ROTATION_DEG: f64 = 37.0;

/// The consistency rig around `set`: [`CONSISTENCY_VIEWS`]-style Fibonacci sphere of `views`
/// cameras of `resolution`² pixels framing the bounding sphere of the Gaussians' means, the
/// lattice turned by [`HELD_OUT_ROTATION_DEG`] about (1, 1, 1) away from the extraction rig's
/// directions.
///
/// # Errors
/// [`PipelineError::Consistency`] for an empty or non-finite set or a bad size.
pub fn held_out_rig(
    set: &GaussianSet,
    views: usize,
    resolution: u32,
) -> Result<Vec<Camera>, PipelineError> {
    let bad = |problem: &str| PipelineError::Consistency {
        problem: problem.to_owned(),
    };
    let (center, radius) = bounding_sphere(&[], set.means())
        .ok_or_else(|| bad("no finite Gaussian to frame (empty set or infinite means)"))?;
    let lattice = sphere_rig(
        center,
        radius,
        views,
        (resolution, resolution),
        CONSISTENCY_FOV_DEG,
    )
    .map_err(|e| bad(&format!("cannot make the rig: {e}")))?;
    let turn =
        glam::DQuat::from_axis_angle(DVec3::ONE.normalize(), HELD_OUT_ROTATION_DEG.to_radians());
    lattice
        .iter()
        .map(|c| {
            let eye = center + turn * (c.position() - center);
            let mut cam = Camera::look_at(
                c.name.clone(),
                eye,
                center,
                DVec3::Y,
                (resolution, resolution),
                CONSISTENCY_FOV_DEG,
            )
            .map_err(|e| bad(&format!("cannot make the rig: {e}")))?;
            cam.id = c.id;
            Ok(cam)
        })
        .collect()
}

/// What the Gaussians show from each view, rendered once and compared with any number of
/// meshes (the methods of a frame).
#[derive(Debug)]
pub struct GaussianViews {
    cameras: Vec<Camera>,
    /// Per view, per pixel: the median depth where alpha > 0.5, else 0.
    depth: Vec<Vec<f32>>,
    /// Per view, per pixel: the composited normal (world frame), normalised where covered.
    normal: Vec<Vec<[f32; 3]>>,
}

impl GaussianViews {
    /// Renders `set` (world space) from `cameras`.
    ///
    /// # Errors
    /// [`PipelineError::Consistency`] when a view cannot be rendered.
    pub fn render(set: &GaussianSet, cameras: &[Camera]) -> Result<Self, PipelineError> {
        let options = RenderOptions {
            outputs: Outputs {
                rgb: false,
                alpha: true,
                depth: false,
                median_depth: true,
                normal: true,
            },
            normal_frame: NormalFrame::World,
            ..RenderOptions::default()
        };
        let mut depth = Vec::with_capacity(cameras.len());
        let mut normal = Vec::with_capacity(cameras.len());
        for camera in cameras {
            let out = render(set, camera, &options).map_err(|e| PipelineError::Consistency {
                problem: format!("cannot render the Gaussians from {}: {e}", camera.name),
            })?;
            let images = out.images;
            let (Some(alpha), Some(median), Some(n)) =
                (images.alpha, images.median_depth, images.normal)
            else {
                return Err(PipelineError::Internal {
                    what: "a render without the images asked for",
                });
            };
            let mut d = median;
            let mut normals = vec![[0.0f32; 3]; d.len()];
            for (i, z) in d.iter_mut().enumerate() {
                let v = glam::Vec3::new(n[3 * i], n[3 * i + 1], n[3 * i + 2]);
                if alpha[i] > COVERED_ALPHA && z.is_finite() && *z > 0.0 {
                    normals[i] = v.normalize_or_zero().to_array();
                } else {
                    *z = 0.0;
                }
            }
            depth.push(d);
            normal.push(normals);
        }
        Ok(Self {
            cameras: cameras.to_vec(),
            depth,
            normal,
        })
    }

    /// The cameras.
    #[must_use]
    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    /// Compares `mesh` (world space, as the Gaussians) with the rendered views.
    ///
    /// # Errors
    /// [`PipelineError::Consistency`] when the mesh cannot be ray cast (coordinates beyond the
    /// spatial index's range).
    pub fn score(&self, mesh: &TriMesh) -> Result<RenderConsistency, PipelineError> {
        // A mesh far from the world origin is ray cast at its local origin, the cameras moved
        // with it (f64), as `trisplat render --mesh` does.
        let origin = mesh.bounds().map_or(DVec3::ZERO, |b| b.local_origin());
        let moved;
        let mesh = if origin == DVec3::ZERO {
            mesh
        } else {
            let mut m = mesh.clone();
            m.translate(-origin);
            moved = m;
            &moved
        };
        let renderer = MeshRenderer::new(
            mesh,
            MeshRenderOptions {
                frame: NormalFrame::World,
                ..MeshRenderOptions::default()
            },
        )
        .map_err(|e| PipelineError::Consistency {
            problem: format!("cannot ray cast the mesh: {e}"),
        })?;
        let per_view: Vec<ViewTally> = (0..self.cameras.len())
            .into_par_iter()
            .map(|v| self.tally(v, &renderer, origin))
            .collect();
        let mut errors = Vec::new();
        let mut angles = Vec::new();
        let (mut gaussian_pixels, mut mesh_pixels) = (0, 0);
        for t in per_view {
            gaussian_pixels += t.gaussian;
            mesh_pixels += t.mesh;
            errors.extend(t.errors);
            angles.extend(t.angles);
        }
        let both_pixels = errors.len();
        let union = gaussian_pixels + mesh_pixels - both_pixels;
        Ok(RenderConsistency {
            iou: if union == 0 {
                1.0
            } else {
                both_pixels as f64 / union as f64
            },
            depth_error_median: percentile(&mut errors, 0.5),
            depth_error_p90: percentile(&mut errors, 0.9),
            normal_angle_deg: percentile(&mut angles, 0.5),
            views: self.cameras.len(),
            gaussian_pixels,
            mesh_pixels,
            both_pixels,
        })
    }

    /// One view's counts, depth errors and normal angles.
    fn tally(&self, view: usize, renderer: &MeshRenderer, origin: DVec3) -> ViewTally {
        let maps = renderer.render(&self.cameras[view].translated(-origin));
        let (depth, normal) = (&self.depth[view], &self.normal[view]);
        let mut t = ViewTally::default();
        for (i, (&g, &m)) in depth.iter().zip(&maps.depth).enumerate() {
            let (seen, hit) = (g > 0.0, m > 0.0);
            t.gaussian += usize::from(seen);
            t.mesh += usize::from(hit);
            if seen && hit {
                t.errors.push((f64::from(m) - f64::from(g)).abs());
                let a = glam::Vec3::from_array(normal[i]).as_dvec3();
                let b = glam::Vec3::from_array(maps.normal[i]).as_dvec3();
                if a != DVec3::ZERO && b != DVec3::ZERO {
                    let cos = a.normalize().dot(b.normalize()).clamp(-1.0, 1.0);
                    t.angles.push(cos.acos().to_degrees());
                }
            }
        }
        t
    }
}

/// One view's contribution to a [`RenderConsistency`].
#[derive(Default)]
struct ViewTally {
    gaussian: usize,
    mesh: usize,
    errors: Vec<f64>,
    angles: Vec<f64>,
}

/// The `q`-quantile of `values` by linear interpolation between order statistics (numpy's
/// default); `None` when empty. Reorders `values`.
fn percentile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_unstable_by(f64::total_cmp);
    let at = q * (values.len() - 1) as f64;
    let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
    Some(values[lo] + (values[hi] - values[lo]) * (at - lo as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_set_has_no_rig() {
        let empty = GaussianSet::try_new(trisplat_splat::GaussianParts::default()).expect("empty");
        let e = held_out_rig(&empty, 8, 64).expect_err("no Gaussian to frame");
        assert!(e.to_string().contains("no finite Gaussian"), "{e}");
    }

    #[test]
    fn percentiles_interpolate_as_numpy() {
        let mut v = [4.0, 1.0, 3.0, 2.0];
        assert_eq!(percentile(&mut v, 0.5), Some(2.5));
        assert!((percentile(&mut v, 0.9).expect("q") - 3.7).abs() < 1e-12);
        assert_eq!(percentile(&mut [], 0.5), None);
    }
}
