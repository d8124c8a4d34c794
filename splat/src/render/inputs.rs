//! What every render needs of its inputs, checked before any work: world-space Gaussians,
//! valid clip planes and background, an image within [`MAX_PIXELS`]; and why a render cannot be
//! done ([`RenderError`]).

use trisplat_geometry::Camera;

use super::options::RenderOptions;
use crate::gaussians::{GaussianSet, ParameterSpace};

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
    /// The front alpha of [`super::render_front`] is not in (0, 1).
    #[error("front alpha {0} must lie in (0, 1)")]
    BadFrontAlpha(f32),
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
    check_view(set.space() != ParameterSpace::Local, camera, options)
}

/// [`check_inputs`] for parameters that are in world space (`world`) or not.
///
/// # Errors
/// The first problem found.
pub(crate) fn check_view(
    world: bool,
    camera: &Camera,
    options: &RenderOptions,
) -> Result<(), RenderError> {
    if !world {
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
