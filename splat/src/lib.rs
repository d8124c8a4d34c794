//! Triangle-bound Gaussians for trisplat: Gaussian sets in the INRIA 3DGS layout
//! ([`GaussianSet`]), spherical-harmonics colour ([`eval_rgb`]), triangle frames for the
//! GaussianAvatars and SurFhead conventions ([`frame`]), binding to a template ([`init_bound`]),
//! deformation of bound Gaussians with a moving template ([`Deformer`], [`LbsDeformer`]),
//! densification and pruning ([`split_selected`], [`prune`]), the CPU splatting renderer and its
//! backward pass ([`render`]) and what a fitter needs besides it ([`fit`]).
//!
//! Conventions follow `docs/conventions.md` §3 (files) and §4 (binding).
//!
//! **Paths.** The implementation modules are private and their public items are re-exported
//! here, at the root (`trisplat_splat::Deformer`, `trisplat_splat::eval_rgb`). Modules stay
//! public only where users address a namespace as such:
//! - [`render`], the renderer (its own items at `render::`, e.g. `render::RenderOptions`);
//! - [`fit`], the fitting pieces, one namespace each (`fit::adam`, `fit::loss`, ...);
//! - [`material`], relightable Gaussians (HRAvatar's material attributes, split-sum shading);
//! - [`neural`], the hash-grid MLP appearance model (`neural::NeuralAppearance`, ...);
//! - the file formats [`ply`], [`spz`] and [`gltf_splat`], whose readers and writers share
//!   names and constants (`read_gaussians`, `OPAQUE_LOGIT`, ...).

/// The math types of this crate's API (glam 0.34), re-exported so callers use the same version.
pub use glam;

mod axes;
mod bind;
mod deform;
mod densify;
pub mod fit;
mod frames;
mod gaussians;
pub mod gltf_splat;
mod lanes;
mod lbs;
pub mod material;
pub mod neural;
pub mod ply;
pub mod render;
mod sh;
pub mod spz;
mod svd;
#[cfg(test)]
mod test_util;
mod wasserstein;

pub use axes::{Axes, change_axes};
pub use bind::{
    AttachLimits, AttachStats, BindError, BindOptions, DEFAULT_INITIAL_OPACITY, attach,
    attach_checked, attach_to_triangles, attach_to_vertices, init_bound,
};
pub use deform::{Collapsed, DeformError, DeformMode, Deformer, FrameHold, WorldGeometry};
pub use densify::{
    DEFAULT_NEIGHBOURS, DEFAULT_SPLIT_CHILDREN, DEFAULT_SPLIT_SHRINK, Densified, DensifyError,
    Gate, Pruned, SEED_NORMAL, SEED_OUTLIER, SEED_W2_SQ, SplitOptions, TriangleCounts, W2Pairs,
    clone_selected, normal_deviation_mask, normal_inconsistency_mask, outlier_mask, prune,
    seed_w2_gate, shortest_axis, split_selected, w2_gate, w2_sq_to_children, w2_sq_to_nearest,
    w2_to_nearest,
};
pub use frames::{
    CanonicalTriangle, Convention, DEFAULT_DEGENERATE_TOL, DEFAULT_MIN_SCALE_REL,
    FALLBACK_MIN_SCALE, FrameOptions, Jacobian, TriangleFrame, cofactor, corners_of,
    deformation_gradient, edge_matrix, frame, gaussian_avatars_frame, is_degenerate,
    surfhead_frame, transform_normal,
};
pub use gaussians::{
    Binding, BindingEncoding, ExtraProperty, GaussianError, GaussianParts, GaussianReport,
    GaussianSet, MAX_LOG_SCALE, MAX_REPORTED_ISSUES, ParameterSpace, PropertyValues, SH_MAX_DEGREE,
    ScalarType, ScaleDims, logit, normalize_wxyz, quat_from_rotation, sigmoid, to_wxyz,
};
pub use lbs::{
    LbsDeformer, LbsError, POLAR_MAX_ITERATIONS, POLAR_TOL, SINGULAR_BLEND_TOL, polar_rotation,
};
pub use sh::{
    SH_C0, SH_C1, SH_C2, SH_C3, ShChange, eval_rgb, rgb_to_dc, sh_basis, sh_coeffs_per_channel,
};
pub use svd::{
    JACOBI_MAX_SWEEPS, JACOBI_SMALL_ROTATION, JACOBI_TOL, MIN_OUTPUT_SCALE, rotation_and_scales,
    rotation_and_scales_svd,
};
pub use wasserstein::{bures_sq, covariance_axes, gaussian_w2_sq, w2_sq};
