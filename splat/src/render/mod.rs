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
//!
//! The stage modules are private: their public items are re-exported here (`render::render`,
//! `render::SURFEL_RULES`, `render::render_with_grad`, ...). The plain entry point is in `run`,
//! the input checks in `inputs`, the differentiable renderer (both passes) in `grad`.

mod composite;
mod grad;
/// The relit shading's backward pass ([`crate::material`]) chains through these.
pub(crate) use grad::{normalized, quaternion_vjp, rotation_matrix, sh_basis_grad};
mod image;
mod inputs;
mod options;
mod perspective;
mod pinhole;
mod project;
mod run;
mod screen;
mod surfel;
mod tiles;

pub use composite::{
    ALPHA_THRESHOLD, CompositeRules, GSPLAT_MAX_ALPHA, MEDIAN_TRANSMITTANCE, MedianRule,
    ORIGINAL_MAX_ALPHA, RenderStats, STOP_TRANSMITTANCE, rasterize, rasterize_with_contribution,
};
pub use grad::{
    BackwardStats, DIST_FAR, DIST_NEAR, DiffParams, GaussianGrads, GaussianParams, GradError,
    GradRender, ImageGrads, Real, backward, backward_into, render_with_grad,
};
pub use image::{
    IMAGE_KINDS, RenderImages, depth_picture, file_stem, image_files, normal_picture, turbo,
};
pub use inputs::{MAX_PIXELS, RenderError, check_inputs};
pub use options::{
    DEFAULT_FAR, DEFAULT_NEAR, ORIGINAL_3DGS_NEAR, Outputs, RenderMode, RenderOptions, Rules,
    SplatDepth,
};
pub use perspective::{
    BOX_MARGIN, PERSPECTIVE_RULES, PerspectiveKernel, PerspectiveSplat, ProjectedPerspective,
    RayMax, project_perspective,
};
pub use project::{
    EPS_2D, EwaKernel, EwaSplat, FRUSTUM_MARGIN, GSPLAT_EXTENT, ORIGINAL_EXTENT, exp_f32, exp_neg4,
    project_ewa,
};
pub use run::{RenderOutput, render, render_front};
pub use screen::{Sample, ScreenEntry, ScreenSplats, SplatKernel};
pub use surfel::{
    FILTER_INV_SQUARE, FILTER_SIZE, ProjectedSurfel, SURFEL_EXTENT, SURFEL_NEAR, SURFEL_RULES,
    SurfelKernel, SurfelSample, SurfelSplat, project_surfel, project_surfels,
};
pub use tiles::{TILE_SIZE, TileBins, TileRect, depth_order, sort_key, tile_range};
