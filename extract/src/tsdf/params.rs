//! The resolved fusion parameters, [`TsdfParams`], and their check.

use super::error::TsdfError;

/// Resolved fusion parameters (all finite and positive).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TsdfParams {
    /// Voxel edge length.
    pub voxel: f64,
    /// Truncation distance of the signed distance.
    pub trunc: f64,
    /// Depths beyond this are ignored (`f64::INFINITY`: none).
    pub depth_trunc: f64,
}

impl TsdfParams {
    /// Checks every field.
    ///
    /// # Errors
    /// [`TsdfError::Parameter`] naming the first field that is not finite and positive
    /// (`depth_trunc` may be `+∞`).
    pub fn validate(&self) -> Result<(), TsdfError> {
        for (name, value) in [("voxel", self.voxel), ("trunc", self.trunc)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(TsdfError::Parameter { name, value });
            }
        }
        if self.depth_trunc.is_nan() || self.depth_trunc <= 0.0 {
            return Err(TsdfError::Parameter {
                name: "depth_trunc",
                value: self.depth_trunc,
            });
        }
        Ok(())
    }
}

/// How a voxel reads the depth at its projection (`--depth-lookup`, docs/conventions.md §6).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum DepthLookup {
    /// The pixel whose centre is nearest (Open3D's rule): a sloped surface becomes steps a
    /// pixel wide, which sink convex shapes by part of a pixel footprint once the voxel is
    /// below about a third of it.
    Nearest,
    /// Bilinear between the four pixel centres around the projection when all four are valid
    /// and agree within [`super::MAX_CELL_SPREAD_PIXELS`] footprints (or the truncation), else
    /// the nearest pixel. The default: the error keeps falling with the voxel.
    #[default]
    Bilinear,
}

impl DepthLookup {
    /// The lookup's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Nearest => "nearest",
            Self::Bilinear => "bilinear",
        }
    }
}
