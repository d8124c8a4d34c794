//! The plain renderer's entry point, [`render`]: checks the inputs, projects with the mode's
//! kernel and runs the shared sort and composite stages (module documentation of [`super`]).

use std::time::Instant;

use trisplat_geometry::Camera;

use super::composite::{CompositeRules, RenderStats, rasterize_with_contribution};
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
    check_inputs(set, camera, options)?;
    let run = Run {
        n: set.len(),
        start: Instant::now(),
        size: (camera.width, camera.height),
        options,
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
    } = *run;
    let mut stats = RenderStats {
        project_s: start.elapsed().as_secs_f64(),
        ..RenderStats::default()
    };
    let (images, by_screen) = rasterize_with_contribution(
        screen,
        kernel,
        size,
        rules,
        options.outputs,
        options.background,
        options.contribution,
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
