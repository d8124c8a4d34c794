//! Why fusion fails: [`TsdfError`], shared by the images, the parameters, the volume and the
//! whole fusion.

use std::path::PathBuf;

use trisplat_geometry::io::IoError;

/// Why fusion failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TsdfError {
    /// A parameter is not a finite positive number (or not allowed for another reason).
    #[error("{name} = {value} must be a finite number > 0")]
    Parameter {
        /// Parameter name (`voxel`, `trunc`, `depth_trunc`, `depth_scale`).
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// No default scale: the cameras' optical axes do not meet (one camera, or all parallel).
    #[error(
        "cannot estimate the scene radius from {cameras} camera(s) whose optical axes do not \
         meet: give the voxel size (and the depth truncation)"
    )]
    NoScale {
        /// Number of cameras.
        cameras: usize,
    },
    /// A depth or colour image does not have the camera's size.
    #[error("{what}: image is {found}, but the camera is {}x{}", expected.0, expected.1)]
    ImageSize {
        /// The image (file and camera, or in-memory image).
        what: String,
        /// The camera's (width, height).
        expected: (u32, u32),
        /// What was found.
        found: String,
    },
    /// No depth or colour file for a camera.
    #[error("{}: no such file (camera {camera}; a .png next to it is also accepted)", path.display())]
    MissingImage {
        /// The `.npy` path looked for.
        path: PathBuf,
        /// The camera's image name.
        camera: String,
    },
    /// An image file cannot be decoded.
    #[error("{}: {message}", path.display())]
    ImageFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A `.npy` file cannot be read.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The number of depth (or colour) images differs from the number of cameras.
    #[error("{images} {what} images for {cameras} cameras")]
    FrameCount {
        /// `"depth"` or `"colour"`.
        what: &'static str,
        /// Number of images.
        images: usize,
        /// Number of cameras.
        cameras: usize,
    },
    /// The volume keeps colours but a frame has no colour image.
    #[error("camera {camera}: the volume is coloured but the frame has no colour image")]
    NoColor {
        /// The camera's image name.
        camera: String,
    },
    /// The observed depth needs more blocks than allowed (the voxel is too small for the scene).
    #[error(
        "the depth maps need more than {limit} voxel blocks of 8^3 at voxel {voxel}; use a \
         larger voxel"
    )]
    TooManyBlocks {
        /// The block limit.
        limit: usize,
        /// The voxel size.
        voxel: f64,
    },
    /// A back-projected point is too far from the origin for the voxel size (index beyond 2³⁰).
    #[error("camera {camera}: depth points lie more than 2^30 voxels from the origin")]
    OutOfRange {
        /// The camera's image name.
        camera: String,
    },
}
