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
mod inputs;
pub mod options;
pub mod perspective;
pub mod project;
mod run;
pub mod screen;
pub mod surfel;
pub mod tiles;

pub use composite::{
    CompositeRules, MedianRule, RenderStats, rasterize, rasterize_with_contribution,
};
pub use grad::{
    BackwardStats, DiffParams, GaussianGrads, GaussianParams, GradError, GradRender, ImageGrads,
    Real, backward, backward_into, render_with_grad,
};
pub use image::RenderImages;
pub use inputs::{MAX_PIXELS, RenderError, check_inputs};
pub use options::{Outputs, RenderMode, RenderOptions, Rules, SplatDepth};
pub use run::{RenderOutput, render};
pub use screen::{Sample, ScreenSplats, SplatKernel};
