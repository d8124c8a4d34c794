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
