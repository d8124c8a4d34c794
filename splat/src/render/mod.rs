//! The CPU splatting renderer (docs/conventions.md §5): 3DGS EWA splatting with gsplat's rules, 2DGS surfels,
//! and perspective-aware evaluation; rgb, alpha, expected/median depth and normal maps.
//!
//! The pipeline has three stages, timed separately in [`RenderStats`]:
//! 1. **project** (per mode): visible Gaussians become [`ScreenSplats`] (screen box, depth,
//!    colour, normal) plus a [`SplatKernel`] that evaluates each at a pixel
//!    ([`project::project_ewa`] + [`project::EwaKernel`] for 3DGS);
//! 2. **sort**: binning into 16×16 tiles and a per-tile depth sort ([`tiles::TileBins`]);
//! 3. **composite**: front to back per pixel with the mode's [`CompositeRules`]
//!    ([`composite::rasterize`], generic over the kernel).
//!
//! Stages 2 and 3 are shared by every mode: see [`screen`] for how a mode plugs in. All stages
//! run in parallel with rayon; the images do not depend on the thread count.

pub mod composite;
pub mod grad;
pub mod image;
pub mod options;
pub mod perspective;
pub mod project;
pub mod screen;
pub mod surfel;
pub mod tiles;

use std::time::Instant;

use trisplat_geometry::Camera;

pub use composite::{
    CompositeRules, MedianRule, RenderStats, rasterize, rasterize_with_contribution,
};
pub use grad::{
    BackwardStats, DiffParams, GaussianGrads, GaussianParams, GradError, GradRender, ImageGrads,
    Real, backward, backward_into, render_with_grad,
};
pub use image::RenderImages;
pub use options::{Outputs, RenderMode, RenderOptions, Rules, SplatDepth};
pub use screen::{Sample, ScreenSplats, SplatKernel};

use crate::{GaussianSet, ParameterSpace};

/// Largest image the renderer accepts, in pixels (16384 × 16384).
pub const MAX_PIXELS: u64 = 1 << 28;

/// Why a render cannot be done.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// The Gaussians are in local triangle frames (a bound GaussianAvatars file).
    #[error(
        "the Gaussians are in local triangle frames (bound to a template); bake them to world space first (trisplat deform)"
    )]
    LocalParameters,
    /// The near/far planes are not `0 < near < far`.
    #[error("near {near} and far {far} planes must satisfy 0 < near < far")]
    BadClipPlanes {
        /// Near plane.
        near: f32,
        /// Far plane.
        far: f32,
    },
    /// The background colour is not finite.
    #[error("background colour {0:?} is not finite")]
    BadBackground([f32; 3]),
    /// The image has more than [`MAX_PIXELS`] pixels.
    #[error("image {width}x{height} exceeds the {MAX_PIXELS}-pixel limit")]
    ImageTooLarge {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
}

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

/// Checks what every mode needs: world-space Gaussians, valid clip planes and background, an
/// image size within [`MAX_PIXELS`].
///
/// # Errors
/// The first problem found.
pub fn check_inputs(
    set: &GaussianSet,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<(), RenderError> {
    if set.space() == ParameterSpace::Local {
        return Err(RenderError::LocalParameters);
    }
    let (near, far) = (options.near, options.far);
    if !(near > 0.0 && far > near && near.is_finite()) {
        return Err(RenderError::BadClipPlanes { near, far });
    }
    if !options.background.iter().all(|v| v.is_finite()) {
        return Err(RenderError::BadBackground(options.background));
    }
    if u64::from(camera.width) * u64::from(camera.height) > MAX_PIXELS {
        return Err(RenderError::ImageTooLarge {
            width: camera.width,
            height: camera.height,
        });
    }
    Ok(())
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
