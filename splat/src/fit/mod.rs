//! What a fitter needs besides the renderer's backward pass (docs/conventions.md §5 "Fitting"):
//! image losses with their gradients ([`loss`]), Adam with per-group learning rates and
//! per-Gaussian state ([`adam`]), and bound (local, per-triangle) parameters with the chain rule
//! from world-space gradients to them ([`bound`]), GaussianAvatars/3DGS adaptive density control
//! on a bound set ([`density`]) and the SH degree schedule ([`sh_schedule`]).

pub mod adam;
pub mod bound;
pub mod density;
pub mod loss;
pub mod sh_schedule;
