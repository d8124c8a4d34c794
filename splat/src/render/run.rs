//! The plain renderer's entry point, [`render`]: checks the inputs, projects with the mode's
//! kernel and runs the shared sort and composite stages (module documentation of [`super`]).

use std::time::Instant;

use trisplat_geometry::Camera;

use super::composite::{CompositeRules, Extra, RenderStats, rasterize_extra};
use super::image::RenderImages;
use super::inputs::{RenderError, check_inputs};
use super::options::{RenderMode, RenderOptions, Rules};
use super::screen::{ScreenSplats, SplatKernel};
use super::{perspective, project, surfel};
use crate::gaussians::GaussianSet;

/// The images of one render and how long its stages took.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOutput {
    /// The requested images.
    pub images: RenderImages,
    /// Stage timings and counts.
    pub stats: RenderStats,
    /// With [`RenderOptions::contribution`]: per Gaussian of the set, the largest blending
    /// weight `w = α·T` it received at any pixel (0 when culled or hidden everywhere).
    pub contribution: Option<Vec<f32>>,
}

/// Renders `set` (world space) as seen by `camera` with the mode of `options` (3DGS EWA
/// splatting with gsplat's or the original rules, 2DGS surfels with [`surfel::SURFEL_RULES`],
/// or perspective-aware evaluation with [`perspective::PERSPECTIVE_RULES`]). `options.near` is
/// used as given in every mode (hbb1's 2DGS code uses [`surfel::SURFEL_NEAR`]).
///
/// # Errors
/// [`RenderError`] for local (bound, unbaked) Gaussians, bad options or too large images.
pub fn render(
    set: &GaussianSet,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<RenderOutput, RenderError> {
    render_with(set, camera, options, None)
}

/// [`render`], and the front depth ([`super::RenderImages::front_depth`]): per pixel, the
/// z-depth of the splat at which the accumulated alpha first reaches `front_alpha` (0 where
/// it never does), by the same rules as the median depth (which is this at ½). Where a ray
/// crosses semi-transparent splats before its median depth (fuzzy hair in front of a skull),
/// the front depth says where they begin.
///
/// # Errors
/// As [`render`], and [`RenderError::BadFrontAlpha`] when `front_alpha` is not in (0, 1).
pub fn render_front(
    set: &GaussianSet,
    camera: &Camera,
    options: &RenderOptions,
    front_alpha: f32,
) -> Result<RenderOutput, RenderError> {
    if !(front_alpha > 0.0 && front_alpha < 1.0) {
        return Err(RenderError::BadFrontAlpha(front_alpha));
    }
    render_with(set, camera, options, Some(front_alpha))
}

/// [`render`] with the front depth at `front_alpha` when given.
fn render_with(
    set: &GaussianSet,
    camera: &Camera,
    options: &RenderOptions,
    front_alpha: Option<f32>,
) -> Result<RenderOutput, RenderError> {
    check_inputs(set, camera, options)?;
    let run = Run {
        n: set.len(),
        start: Instant::now(),
        size: (camera.width, camera.height),
        options,
        front_alpha,
    };
    match options.mode {
        RenderMode::Gaussian3d => {
            let (screen, kernel) = project::project_ewa(set, camera, options);
            let rules = match options.rules {
                Rules::Gsplat => CompositeRules::GSPLAT,
                Rules::Original3dgs => CompositeRules::ORIGINAL_3DGS,
            };
            Ok(finish(&screen, &kernel, &rules, &run))
        }
        RenderMode::Surfel2d => {
            let (screen, kernel) = surfel::project_surfels(set, camera, options);
            Ok(finish(&screen, &kernel, &surfel::SURFEL_RULES, &run))
        }
        RenderMode::Perspective => {
            let (screen, kernel) = perspective::project_perspective(set, camera, options);
            Ok(finish(
                &screen,
                &kernel,
                &perspective::PERSPECTIVE_RULES,
                &run,
            ))
        }
    }
}

/// One call of [`render`], as its shared stages see it.
struct Run<'a> {
    /// Gaussians in the set.
    n: usize,
    /// When the projection started.
    start: Instant,
    /// Image width and height.
    size: (u32, u32),
    options: &'a RenderOptions,
    front_alpha: Option<f32>,
}

/// The shared sort and composite stages after a mode's projection.
fn finish<K: SplatKernel>(
    screen: &ScreenSplats,
    kernel: &K,
    rules: &CompositeRules,
    run: &Run<'_>,
) -> RenderOutput {
    let Run {
        n,
        start,
        size,
        options,
        front_alpha,
    } = *run;
    let mut stats = RenderStats {
        project_s: start.elapsed().as_secs_f64(),
        ..RenderStats::default()
    };
    let extra = Extra {
        contribution: options.contribution,
        front_alpha,
    };
    let (images, by_screen) = rasterize_extra(
        screen,
        kernel,
        size,
        rules,
        options.outputs,
        options.background,
        extra,
        &mut stats,
    );
    let contribution = by_screen.map(|by_screen| {
        let mut by_set = vec![0.0; n];
        for (&id, w) in screen.ids.iter().zip(by_screen) {
            by_set[id as usize] = w;
        }
        by_set
    });
    RenderOutput {
        images,
        stats,
        contribution,
    }
}
