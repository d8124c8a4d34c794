//! Why the opacity field cannot be meshed.

use crate::delaunay3d::DelaunayError;

/// Why [`super::opacity_mesh`] (or [`super::opacity_at`]) failed. Every variant names the
/// offending Gaussian or the stage; the caller adds the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum OpacityError {
    /// The input arrays have different lengths.
    #[error("Gaussian arrays differ in length: {what} has {got}, means have {expected}")]
    LengthMismatch {
        /// Which array.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The number of means.
        expected: usize,
    },
    /// No Gaussian at all.
    #[error("no Gaussians")]
    Empty,
    /// A scale is zero, negative or not finite (the field needs invertible covariances).
    #[error("Gaussian {index}: scale {scale:?} is not finite and positive on every axis")]
    BadScale {
        /// Index of the Gaussian.
        index: usize,
        /// Its scales.
        scale: [f32; 3],
    },
    /// A mean is not finite.
    #[error("Gaussian {index}: mean {mean:?} is not finite")]
    BadMean {
        /// Index of the Gaussian.
        index: usize,
        /// Its mean.
        mean: [f32; 3],
    },
    /// A rotation quaternion is zero or not finite.
    #[error("Gaussian {index}: rotation {rotation:?} is zero or not finite")]
    BadRotation {
        /// Index of the Gaussian.
        index: usize,
        /// Its quaternion (w, x, y, z).
        rotation: [f32; 4],
    },
    /// An opacity is not in [0, 1].
    #[error("Gaussian {index}: opacity {opacity} is not in [0, 1]")]
    BadOpacity {
        /// Index of the Gaussian.
        index: usize,
        /// Its opacity.
        opacity: f32,
    },
    /// Every Gaussian's opacity is below the cut: none can be seen.
    #[error("all {count} Gaussians have an opacity below the cut {cut}: nothing to mesh")]
    AllBelowCut {
        /// Number of Gaussians.
        count: usize,
        /// The cut.
        cut: f32,
    },
    /// A median-depth map (`--field median`) does not fit its camera or holds a depth that
    /// is negative or not finite.
    #[error("depth map {view} ({name}): {problem}")]
    BadDepthMap {
        /// Index of the view.
        view: usize,
        /// The camera's name.
        name: String,
        /// What is wrong.
        problem: String,
    },
    /// The median-depth rules are out of range.
    #[error(
        "median-depth rules: margin {margin} must be finite and >= 0, surface {surface} in 0..=margin, carve views {carve_views} in 1..=16"
    )]
    BadDepthRules {
        /// The margin, pixel footprints.
        margin: f32,
        /// Where the vertices go, pixel footprints in front of the median depth.
        surface: f32,
        /// Views that must carve a point.
        carve_views: u16,
    },
    /// No camera was given.
    #[error("no cameras")]
    NoCameras,
    /// No point of the Gaussians projects into any camera's image.
    #[error("no camera sees the Gaussians (none of their {points} points projects into an image)")]
    NotSeen {
        /// Number of points tested.
        points: usize,
    },
    /// The points span less than three dimensions (all coplanar, collinear or coincident).
    #[error(
        "the Gaussians' points are degenerate (affine dimension {dimension} < 3: coplanar, collinear or coincident)"
    )]
    Degenerate {
        /// Affine dimension of the distinct points.
        dimension: u8,
    },
    /// The tetrahedralisation failed.
    #[error("tetrahedralisation: {0}")]
    Delaunay(#[from] DelaunayError),
    /// No tetrahedron crosses the level: the field is everywhere above or everywhere below it.
    #[error(
        "the opacity field does not cross {level} anywhere ({inside} of {points} points inside)"
    )]
    NoSurface {
        /// The level.
        level: f32,
        /// Points at or above the level.
        inside: usize,
        /// Points.
        points: usize,
    },
}
