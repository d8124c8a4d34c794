//! Neural appearance (issue 33, the static-head seed; docs/conventions.md §5 "Neural
//! appearance"): each Gaussian's opacity and colour from a multiresolution hash encoding of its
//! position plus its rotation and log-scales through a geometry MLP (opacity logit and a
//! feature), then the feature and the view direction through a colour MLP (linear RGB).
//!
//! - [`config`]: the shape ([`NeuralConfig`]) and the flat MLP layout;
//! - [`grid`]: the hash grid's addressing (dense or instant-ngp's spatial hash per level);
//! - [`model`]: the parameters, the normalisation box, inputs and outputs;
//! - [`dense`]: batched dense layers and their backward;
//! - [`pass`]: forward and backward over many Gaussians (rayon, per-thread scratch);
//! - [`adam`]: Adam, dense on the MLPs, lazy on the tables;
//! - [`bake`]: the seam to the renderer (outputs as degree-0 SH and opacity logits, gradients back);
//! - [`file`]: the weights as safetensors beside the PLY;
//! - [`real`]: `f32` (production) or `f64` (finite-difference checks).

pub mod adam;
pub mod bake;
pub mod config;
pub mod dense;
pub mod error;
pub mod file;
pub mod grid;
pub mod model;
pub mod pass;
pub mod real;

pub use adam::{NeuralAdam, NeuralLearningRates};
pub use bake::{appearance_grads, bake_params, bake_set, inputs_from_params, inputs_from_set};
pub use config::NeuralConfig;
pub use error::NeuralError;
pub use file::{read_weights, weights_path, write_weights};
pub use model::{Aabb, Appearance, NeuralAppearance, NeuralInputs};
pub use pass::{NeuralGrads, Workspace, backward, forward};
