//! The photometric term both fits minimise (the Gaussians' and the neural appearance's):
//! `(1 − λ)·L1 + λ·(1 − SSIM)` of the rendered colour against the target, as 3DGS trains.

use trisplat_splat::fit::loss::{Ssim, l1};

/// An SSIM evaluator kept while the image size stays (its window buffers are sized to it).
#[derive(Default)]
pub(super) struct SsimCache(Option<((usize, usize), Ssim)>);

impl SsimCache {
    /// The evaluator for `width` × `height` images, made anew when the size changes.
    fn for_size(&mut self, width: usize, height: usize) -> &mut Ssim {
        let key = (width, height);
        if self.0.as_ref().is_some_and(|(k, _)| *k != key) {
            self.0 = None;
        }
        &mut self
            .0
            .get_or_insert_with(|| (key, Ssim::new(width, height)))
            .1
    }
}

/// The photometric term of one view.
pub(super) struct Photometric {
    /// `(1 − λ)·L1 + λ·(1 − SSIM)`.
    pub loss: f64,
    /// The mean absolute error alone (reported).
    pub l1: f64,
}

/// `(1 − lambda)·L1 + lambda·(1 − SSIM)` of `rendered` against `target` (RGB, `width` ×
/// `height`); `grad` is set to the term's gradient with respect to `rendered`.
pub(super) fn photometric_loss(
    rendered: &[f32],
    target: &[f32],
    (width, height): (usize, usize),
    lambda: f64,
    ssim: &mut SsimCache,
    grad: &mut Vec<f32>,
) -> Photometric {
    grad.clear();
    grad.resize(3 * width * height, 0.0);
    let l1v = l1(rendered, target, 1.0 - lambda, grad);
    let s = if lambda > 0.0 {
        ssim.for_size(width, height)
            .ssim(rendered, target, 3, -lambda, Some(grad))
    } else {
        1.0
    };
    Photometric {
        loss: (1.0 - lambda) * l1v + lambda * (1.0 - s),
        l1: l1v,
    }
}
