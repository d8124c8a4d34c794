//! The record of a fit at one iteration (a leaf: both fits, SH and neural, make them).

/// The state of a fit at one iteration.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Checkpoint {
    /// Iterations done.
    pub iteration: usize,
    /// Mean training loss over the iterations since the last checkpoint (`None` at 0).
    pub loss: Option<f64>,
    /// Mean rgb L1 and PSNR of the training views over those iterations.
    pub train_l1: Option<f64>,
    /// Mean PSNR (dB) of the training views seen since the last checkpoint.
    pub train_psnr: Option<f64>,
    /// Mean PSNR (dB) over the held-out views (`None` without any).
    pub eval_psnr: Option<f64>,
    /// Mean SSIM over the held-out views.
    pub eval_ssim: Option<f64>,
    /// Mean absolute z-depth error over the held-out targets' masks (scene units; an empty
    /// rendered pixel counts with depth 0). Needs target depth and masks (mesh targets).
    pub eval_depth_l1: Option<f64>,
    /// Mean angle (degrees) between the held-out targets' normals and the rendered ones over
    /// the masks (2DGS: the normal image; 3DGS: normals of the rendered depth).
    pub eval_normal_deg: Option<f64>,
    /// Gaussians.
    pub gaussians: usize,
    /// The SH degree the render used at this iteration (the set's own without a schedule).
    pub sh_degree: u8,
    /// Seconds of optimisation so far (refines included, scoring excluded).
    pub seconds: f64,
}
