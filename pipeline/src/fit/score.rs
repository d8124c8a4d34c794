//! Scoring the held-out views of a fit.

use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, to_world};
use trisplat_splat::fit::loss::{Ssim, psnr};
use trisplat_splat::render::{GaussianParams, RenderOptions, render_with_grad};

use super::FitFrame;

/// Mean PSNR and SSIM of the held-out views (`None` without any).
pub(super) fn evaluate(
    bound: &BoundParams,
    held_out: &[FitFrame],
    frames: &[TriangleFrames],
    render: &RenderOptions,
) -> (Option<f64>, Option<f64>) {
    let mut world = GaussianParams::default();
    let (mut p, mut s, mut n) = (0.0, 0.0, 0usize);
    for (f, fr) in held_out.iter().enumerate() {
        to_world(bound, &frames[f], &mut world);
        for t in &fr.targets {
            let Ok(out) = render_with_grad::<f32, _>(&world, &t.camera, render) else {
                continue;
            };
            p += psnr(&out.rgb, &t.rgb);
            let mut ssim = Ssim::new(t.camera.width as usize, t.camera.height as usize);
            s += ssim.ssim(&out.rgb, &t.rgb, 3, 0.0, None);
            n += 1;
        }
    }
    if n == 0 {
        (None, None)
    } else {
        (Some(p / n as f64), Some(s / n as f64))
    }
}

