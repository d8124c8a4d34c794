//! The backward pass of the 3DGS and 2DGS renderers: gradients of a loss on the rgb, alpha and
//! expected-depth images (2DGS: also the normal image and the depth distortion) with respect to
//! every Gaussian's mean, log-scales, raw quaternion, opacity logit and SH coefficients
//! (docs/conventions.md §5 "Gradients"). The two calls are in [`pass`]; both modes run the same
//! tile loops ([`tile`]) with their own kernel ([`ewa`] for 3DGS, [`surfel`] for 2DGS), the same
//! (tile, splat) slots ([`slots`]) and the same colour and quaternion VJPs ([`project`]).
//!
//! Two calls, as in gsplat and the 3DGS reference code:
//! 1. [`render_with_grad`] renders rgb, alpha and expected depth by the rules of
//!    [`crate::render::render`] (3DGS mode, gsplat's or the original rules; 2DGS mode) and keeps what the backward
//!    pass needs: the projected splats in depth order, the tile lists, and per pixel the final
//!    transmittance, the depth sum and the number of tile-list entries up to the last one that
//!    contributed. The plain [`crate::render::render`] is untouched and stores none of it.
//! 2. [`backward`] (or [`backward_into`], which accumulates over views) takes the loss's
//!    gradients with respect to the images ([`ImageGrads`]) and walks each tile's list back to
//!    front from the last contributor, recovering every splat's transmittance from the final one
//!    (`T_k = T_{k+1} / (1 − α_k)`), so no per-splat state is stored. Tile rows run in parallel;
//!    each tile writes per-(tile, splat) sums in `f64` into its own slots of one buffer, which
//!    are then reduced per splat in tile order (so gradients do not depend on the thread
//!    count) and carried through the projection ([`project`]) to the raw parameters.
//!
//! The per-pixel arithmetic is generic over [`Real`]: `f32` recomputes exactly the alphas of the
//! forward (the production path), `f64` serves finite-difference checks
//! (with [`GaussianParams`]).

mod ewa;
mod params;
mod pass;
mod project;
mod slots;
mod surfel;
mod surfel_project;
mod tile;

pub use params::{DiffParams, GaussianGrads, GaussianParams, Real};
pub use pass::{BackwardStats, GradError, GradRender, backward, backward_into, render_with_grad};
/// The quaternion and SH-direction pieces the relit shading's backward pass
/// ([`crate::material`]) chains through.
pub(crate) use project::{normalized, quaternion_vjp, rotation_matrix, sh_basis_grad};
pub use surfel::{DIST_FAR, DIST_NEAR};
pub use tile::ImageGrads;
