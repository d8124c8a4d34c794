//! The opacity method's inputs from a Gaussian set (`trisplat opacity-mesh`, and the main job's
//! `--method opacity`): the set as the extract crate's plain arrays, the rig the tsdf method
//! uses, and the rendered median-depth maps of the median-depth field.

use glam::{DVec3, Vec3};
use trisplat_extract::opacity::{DepthView, OpacityGaussians};
use trisplat_geometry::{Camera, bounding_sphere, sphere_rig};
use trisplat_splat::render::{Outputs, RenderOptions, render};
use trisplat_splat::{GaussianSet, eval_rgb};

use crate::config::DEFAULT_FOV_DEG;
use crate::consistency::COVERED_ALPHA;
use crate::error::PipelineError;

/// The world-space `set` as the opacity field reads it: activated scales (a 2DGS surfel's flat
/// axis is 0, which the field refuses), rotations, opacities, and the SH DC colour (the view-
/// independent part).
#[must_use]
pub fn opacity_gaussians(set: &GaussianSet) -> OpacityGaussians {
    let n = set.len();
    OpacityGaussians {
        means: set.means().to_vec(),
        scales: (0..n).map(|i| set.scale(i)).collect(),
        rotations: set.rotations().to_vec(),
        opacities: (0..n).map(|i| set.opacity(i)).collect(),
        colors: (0..n)
            .map(|i| eval_rgb(0, set.sh_coeffs(i), DVec3::Z))
            .collect(),
    }
}

/// The tsdf method's rig (`views` cameras of `resolution`² pixels, 40° field of view, on a
/// Fibonacci sphere) around the bounding sphere of the points the opacity method
/// tetrahedralises, each Gaussian's mean and the corners of its 3-sigma box, so that every one
/// of them is in every image (non-finite corners are left to the field's checks).
///
/// # Errors
/// [`PipelineError::BadOption`] when no point is finite or the rig is invalid (no views, empty
/// images).
pub fn opacity_rig(
    set: &GaussianSet,
    views: usize,
    resolution: u32,
) -> Result<Vec<Camera>, PipelineError> {
    let bad = |expected| PipelineError::BadOption {
        name: "views",
        value: views as f64,
        expected,
    };
    let mut points: Vec<Vec3> = Vec::with_capacity(set.len() * 9);
    for i in 0..set.len() {
        let mean = set.means()[i].as_dvec3();
        let r = set.rotation_matrix(i);
        let s = set.scale(i).as_dvec3() * 3.0;
        points.push(mean.as_vec3());
        for corner in 0..8u32 {
            let sign = |bit: u32| if corner >> bit & 1 == 0 { -1.0 } else { 1.0 };
            let c = mean
                + r.x_axis * (s.x * sign(0))
                + r.y_axis * (s.y * sign(1))
                + r.z_axis * (s.z * sign(2));
            points.push(c.as_vec3());
        }
    }
    points.retain(|p| p.is_finite());
    let (center, radius) =
        bounding_sphere(&[], &points).ok_or(bad("Gaussians with finite means"))?;
    sphere_rig(
        center,
        radius,
        views,
        (resolution, resolution),
        DEFAULT_FOV_DEG,
    )
    .map_err(|_| bad("at least one view of a non-empty image"))
}

/// The median-depth maps of `set` (world space) from `cameras`, rendered as render consistency
/// renders them (docs/conventions.md §8: the default renderer, 3DGS with gsplat's rules): per
/// pixel the median depth where alpha > 1/2 and the depth is finite and positive, else 0; with
/// `colors`, the rendered colour divided by alpha (the colour of what the pixel composites,
/// black background) for vertex colours.
///
/// # Errors
/// [`PipelineError::Render`] (frame `frame`) when a view cannot be rendered.
pub fn median_depth_views(
    set: &GaussianSet,
    cameras: &[Camera],
    colors: bool,
    frame: usize,
) -> Result<Vec<DepthView>, PipelineError> {
    let options = RenderOptions {
        outputs: Outputs {
            rgb: colors,
            alpha: true,
            depth: false,
            median_depth: true,
            normal: false,
        },
        ..RenderOptions::default()
    };
    cameras
        .iter()
        .map(|camera| {
            let out = render(set, camera, &options).map_err(|cause| PipelineError::Render {
                frame,
                camera: camera.name.clone(),
                cause,
            })?;
            let images = out.images;
            let (Some(alpha), Some(mut depth)) = (images.alpha, images.median_depth) else {
                return Err(PipelineError::Internal {
                    what: "a render without the images asked for",
                });
            };
            for (z, a) in depth.iter_mut().zip(&alpha) {
                if !(*a > COVERED_ALPHA && z.is_finite() && *z > 0.0) {
                    *z = 0.0;
                }
            }
            let rgb = match images.rgb.filter(|_| colors) {
                Some(rgb) => alpha
                    .iter()
                    .enumerate()
                    .map(|(i, &a)| {
                        if a > 0.0 {
                            [rgb[3 * i] / a, rgb[3 * i + 1] / a, rgb[3 * i + 2] / a]
                        } else {
                            [0.5; 3]
                        }
                    })
                    .collect(),
                None => Vec::new(),
            };
            Ok(DepthView {
                camera: camera.clone(),
                depth,
                rgb,
            })
        })
        .collect()
}
