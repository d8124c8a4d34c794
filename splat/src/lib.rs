//! Triangle-bound Gaussians for trisplat: Gaussian sets in the INRIA 3DGS layout
//! ([`GaussianSet`]), spherical-harmonics colour ([`sh`]), PLY reading and writing ([`ply`]),
//! triangle frames for the GaussianAvatars and SurFhead conventions ([`frames`]) and deformation
//! of bound Gaussians with a moving template ([`deform`]).
//!
//! Conventions follow `docs/conventions.md` §3 (files) and §4 (binding).

/// The math types of this crate's API (glam 0.34), re-exported so callers use the same version.
pub use glam;

pub mod axes;
pub mod bind;
pub mod deform;
pub mod densify;
pub mod fit;
pub mod frames;
pub mod gaussians;
pub mod gltf_splat;
pub mod lanes;
pub mod lbs;
pub mod ply;
pub mod render;
pub mod sh;
pub mod spz;
mod svd;
#[cfg(test)]
mod test_util;
pub mod wasserstein;

pub use gaussians::{
    Binding, BindingEncoding, ExtraProperty, GaussianError, GaussianParts, GaussianReport,
    GaussianSet, ParameterSpace, PropertyValues, ScalarType, ScaleDims,
};
