//! What the two appearance fits (`--appearance brdf` and `mlp`) share: their common options and
//! the checks of them, the training (frame, view) pairs, one photometric step (render, loss,
//! the renderer's backward pass) and the checkpoints (the training statistics since the last
//! one, held-out PSNR and SSIM).

use trisplat_geometry::rng::Rng;
use trisplat_splat::GaussianSet;
use trisplat_splat::ScaleDims;
use trisplat_splat::fit::loss::{Ssim, l1, psnr};
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, ImageGrads, RenderMode, RenderOptions, backward_into,
    render_with_grad,
};

use super::checkpoint::Checkpoint;
use super::inputs::{FitError, FitFrame, Target};
use super::photometric::{SsimCache, photometric_loss};

/// The options both appearance fits take (from the `fit` command's common ones).
#[derive(Clone, Debug)]
pub struct CommonOptions {
    /// Optimisation steps.
    pub iterations: usize,
    /// `λ` of D-SSIM.
    pub lambda_dssim: f64,
    /// Weight of the alpha L1 against the target mask.
    pub alpha_weight: f64,
    /// Renderer options.
    pub render: RenderOptions,
    /// Seed of the view order and of the model's initialisation.
    pub seed: u64,
    /// Score the held-out views every N iterations.
    pub eval_every: usize,
    /// Stop after the iteration that spends this many seconds.
    pub time_budget: Option<f64>,
}

impl CommonOptions {
    /// Refuses options out of range.
    ///
    /// # Errors
    /// [`FitError::BadOption`] naming the option.
    pub(super) fn check(&self) -> Result<(), FitError> {
        let bad = |m: String| Err(FitError::BadOption(m));
        if self.iterations == 0 || self.eval_every == 0 {
            return bad("--iterations and --eval-every must be at least 1".into());
        }
        if self.render.mode == RenderMode::Perspective {
            return bad("fitting in perspective mode is not supported: use 3dgs or 2dgs".into());
        }
        if !(self.lambda_dssim.is_finite() && (0.0..=1.0).contains(&self.lambda_dssim)) {
            return bad(format!(
                "--lambda-dssim {}: expected 0..1",
                self.lambda_dssim
            ));
        }
        if !(self.alpha_weight.is_finite() && self.alpha_weight >= 0.0) {
            return bad(format!(
                "--alpha-weight {}: expected >= 0",
                self.alpha_weight
            ));
        }
        if let Some(t) = self.time_budget
            && !(t.is_finite() && t > 0.0)
        {
            return bad(format!(
                "--time-budget {t}: expected a number of seconds > 0"
            ));
        }
        Ok(())
    }
}

/// Refuses a learning rate that is not a finite number `>= 0`, naming its option.
///
/// # Errors
/// [`FitError::BadOption`].
pub(super) fn check_rates(rates: &[(&str, f64)]) -> Result<(), FitError> {
    match rates.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
        Some((name, v)) => Err(FitError::BadOption(format!(
            "--{name} {v}: expected a finite number >= 0"
        ))),
        None => Ok(()),
    }
}

/// The (frame, view) pairs a fit trains on, after checking what every fit needs: surfels fitted
/// in 2dgs mode, at least one training view, and each target (training or held out) fitting its
/// camera, with a mask when `--alpha-weight` asks for one.
///
/// # Errors
/// [`FitError::BadOption`] for 2-scale surfels outside 2dgs mode, [`FitError::Target`] for no
/// training view or a target that does not fit.
pub(super) fn training_pairs(
    set: &GaussianSet,
    frames: &[FitFrame],
    held_out: &[FitFrame],
    options: &CommonOptions,
) -> Result<Vec<(usize, usize)>, FitError> {
    if set.scale_dims() == ScaleDims::Two && options.render.mode != RenderMode::Surfel2d {
        return Err(FitError::BadOption(
            "the Gaussians are 2-scale surfels: fit them in 2dgs mode (--mode 2dgs)".into(),
        ));
    }
    let pairs: Vec<(usize, usize)> = frames
        .iter()
        .enumerate()
        .flat_map(|(f, fr)| (0..fr.targets.len()).map(move |v| (f, v)))
        .collect();
    if pairs.is_empty() {
        return Err(FitError::Target("no training views".into()));
    }
    for fr in frames.iter().chain(held_out) {
        for t in &fr.targets {
            let px = t.camera.width as usize * t.camera.height as usize;
            if t.rgb.len() != 3 * px || t.alpha.as_ref().is_some_and(|a| a.len() != px) {
                return Err(FitError::Target(format!(
                    "view '{}': the images do not fit the camera",
                    t.camera.name
                )));
            }
            if options.alpha_weight > 0.0 && t.alpha.is_none() {
                return Err(FitError::Target(format!(
                    "view '{}': --alpha-weight needs a target mask",
                    t.camera.name
                )));
            }
        }
    }
    Ok(pairs)
}

/// One (frame, view) pair drawn uniformly with `rng` (`pairs` is not empty).
pub(super) fn draw(rng: &mut Rng, pairs: &[(usize, usize)]) -> (usize, usize) {
    pairs[((rng.uniform_f64() * pairs.len() as f64) as usize).min(pairs.len() - 1)]
}

/// Reused buffers of [`photometric_step`].
#[derive(Default)]
pub(super) struct StepBuffers {
    ssim: SsimCache,
    g_rgb: Vec<f32>,
    g_alpha: Vec<f32>,
}

/// The training statistics of one step.
#[derive(Clone, Copy, Debug)]
pub(super) struct StepLoss {
    /// The whole loss.
    pub loss: f64,
    /// The rgb L1.
    pub l1: f64,
    /// The rendered view's PSNR against the target.
    pub psnr: f64,
}

/// Renders `world` (degree-0 colours, `n` Gaussians) for `target` at `iteration`, takes the
/// loss `(1 − λ) L1 + λ D-SSIM` on rgb plus `w_alpha` × the alpha L1, and writes the renderer's
/// gradients with respect to `world` into `g_world` (resized to `n`, degree 0).
///
/// # Errors
/// [`FitError::Render`] when the renderer or its backward pass refuses.
pub(super) fn photometric_step(
    world: &GaussianParams,
    target: &Target,
    options: &CommonOptions,
    iteration: usize,
    b: &mut StepBuffers,
    g_world: &mut GaussianGrads,
) -> Result<StepLoss, FitError> {
    let camera = &target.camera;
    let render_err = |source| FitError::Render {
        iteration,
        view: camera.name.clone(),
        source,
    };
    let fwd = render_with_grad::<f32, _>(world, camera, &options.render).map_err(render_err)?;
    let size = (camera.width as usize, camera.height as usize);
    let photometric = photometric_loss(
        &fwd.rgb,
        &target.rgb,
        size,
        options.lambda_dssim,
        &mut b.ssim,
        &mut b.g_rgb,
    );
    let mut loss = photometric.loss;
    let alpha_term = options.alpha_weight > 0.0;
    if alpha_term && let Some(a) = &target.alpha {
        b.g_alpha.clear();
        b.g_alpha.resize(size.0 * size.1, 0.0);
        loss += options.alpha_weight * l1(&fwd.alpha, a, options.alpha_weight, &mut b.g_alpha);
    }
    let image_grads = ImageGrads {
        rgb: Some(&b.g_rgb[..]),
        alpha: alpha_term.then_some(&b.g_alpha[..]),
        ..ImageGrads::default()
    };
    let n = world.means.len();
    if g_world.len() != n || g_world.sh.len() != 3 * n {
        *g_world = GaussianGrads::zeros(n, 0);
    } else {
        g_world.clear();
    }
    backward_into(world, camera, &options.render, &fwd, &image_grads, g_world)
        .map_err(render_err)?;
    Ok(StepLoss {
        loss,
        l1: photometric.l1,
        psnr: psnr(&fwd.rgb, &target.rgb),
    })
}

/// The training statistics since the last checkpoint.
#[derive(Default)]
pub(super) struct Running {
    loss: f64,
    l1: f64,
    psnr: f64,
    steps: usize,
}

impl Running {
    /// Adds one step.
    pub(super) fn add(&mut self, s: StepLoss) {
        self.loss += s.loss;
        self.l1 += s.l1;
        self.psnr += s.psnr;
        self.steps += 1;
    }

    /// The checkpoint at `iteration` (the held-out scores `eval`: PSNR and SSIM), the
    /// statistics then started again.
    pub(super) fn checkpoint(
        &mut self,
        iteration: usize,
        eval: (Option<f64>, Option<f64>),
        gaussians: usize,
        seconds: f64,
    ) -> Checkpoint {
        let mean = |v: f64| (self.steps > 0).then(|| v / self.steps as f64);
        let c = Checkpoint {
            iteration,
            loss: mean(self.loss),
            train_l1: mean(self.l1),
            train_psnr: mean(self.psnr),
            eval_psnr: eval.0,
            eval_ssim: eval.1,
            eval_depth_l1: None,
            eval_normal_deg: None,
            gaussians,
            sh_degree: 0,
            seconds,
        };
        *self = Self::default();
        c
    }
}

/// The mean PSNR and SSIM over the held-out targets (`None` without any view rendered):
/// `render(f, target)` places the set for frame `f` and renders the target's camera, `None`
/// when the renderer refuses (that view is then skipped).
///
/// # Errors
/// What `render` returns.
pub(super) fn held_out_scores(
    held_out: &[FitFrame],
    mut render: impl FnMut(usize, &Target) -> Result<Option<Vec<f32>>, FitError>,
) -> Result<(Option<f64>, Option<f64>), FitError> {
    let (mut ps, mut ss, mut count) = (0.0, 0.0, 0usize);
    for (f, fr) in held_out.iter().enumerate() {
        for t in &fr.targets {
            let Some(rgb) = render(f, t)? else {
                continue;
            };
            ps += psnr(&rgb, &t.rgb);
            let mut s = Ssim::new(t.camera.width as usize, t.camera.height as usize);
            ss += s.ssim(&rgb, &t.rgb, 3, 0.0, None);
            count += 1;
        }
    }
    let mean = |v: f64| (count > 0).then(|| v / count as f64);
    Ok((mean(ps), mean(ss)))
}

/// Renders `world` from `camera` for [`held_out_scores`]: its rgb, `None` when the renderer
/// refuses.
pub(super) fn render_rgb(
    world: &GaussianParams,
    target: &Target,
    options: &RenderOptions,
) -> Option<Vec<f32>> {
    render_with_grad::<f32, _>(world, &target.camera, options)
        .ok()
        .map(|o| o.rgb)
}
