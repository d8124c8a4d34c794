//! What a fit takes and how it fails: the target views, the frames they belong to, and the
//! fitter's error (a leaf the fitter, its targets and its scores share).

use glam::DVec3;
use trisplat_geometry::Camera;
use trisplat_splat::DensifyError;
use trisplat_splat::fit::bound::BoundError;
use trisplat_splat::render::GradError;

use crate::refine::RefineError;

/// Why a fit cannot run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FitError {
    /// An option out of range, or options that need what is not there yet.
    #[error("{0}")]
    BadOption(String),
    /// The Gaussians cannot be fitted as bound parameters.
    #[error("the Gaussians: {0}")]
    Bound(#[from] BoundError),
    /// A target does not fit its camera or cannot be read.
    #[error("{0}")]
    Target(String),
    /// The renderer or its backward pass refused.
    #[error("iteration {iteration}, view '{view}': {source}")]
    Render {
        /// Iteration.
        iteration: usize,
        /// Camera name.
        view: String,
        /// Cause.
        source: GradError,
    },
    /// A densification step failed.
    #[error("densify after iteration {iteration}: {source}")]
    Densify {
        /// Iteration.
        iteration: usize,
        /// Cause.
        source: DensifyError,
    },
    /// A refine round failed.
    #[error("refine after iteration {iteration}: {source}")]
    Refine {
        /// Iteration.
        iteration: usize,
        /// Cause.
        source: RefineError,
    },
    /// The parameters left the finite numbers (learning rates too high).
    #[error("iteration {0}: the parameters are no longer finite (lower the learning rates)")]
    NonFinite(usize),
}

/// One target view: a camera and its images (row-major; rgb `[H, W, 3]`, normals `[H, W, 3]`
/// in the camera frame, OpenCV axes).
#[derive(Clone, Debug)]
pub struct Target {
    /// The camera.
    pub camera: Camera,
    /// rgb in 0..1 (the background where nothing is seen).
    pub rgb: Vec<f32>,
    /// Mask / alpha in 0..1.
    pub alpha: Option<Vec<f32>>,
    /// z-depth, 0 where nothing is seen.
    pub depth: Option<Vec<f32>>,
    /// Unit normals facing the camera, camera frame.
    pub normal: Option<Vec<f32>>,
}

/// One animation frame to fit: the template's positions and the frame's target views.
#[derive(Clone, Debug)]
pub struct FitFrame {
    /// Animation frame index (for reports).
    pub frame: usize,
    /// The template's vertex positions at that frame.
    pub positions: Vec<DVec3>,
    /// Its views.
    pub targets: Vec<Target>,
}
