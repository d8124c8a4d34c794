//! Image losses of a fitter with their exact gradients with respect to the rendered images
//! (docs/conventions.md §5 "Fitting").
//!
//! Every loss returns its value (in `f64`) and **adds** `scale ×` its gradient into a buffer
//! laid out like the rendered image, so several losses weighted by their `λ` fill one
//! [`crate::render::ImageGrads`] without temporaries. Images are row-major; colour images
//! interleaved `[H, W, C]`. Sums are in `f64` whatever the image type ([`Real`]).
//!
//! - [`l1`]: `mean |x − y|` over every value (gradient `sign(x − y) / N`, 0 where equal).
//! - [`Ssim`]: the SSIM of 3DGS's `ssim()` (11×11 Gaussian window, σ = 1.5, zero padding,
//!   `C1 = 0.01²`, `C2 = 0.03²`, the map averaged over every pixel and channel); D-SSIM is
//!   `1 − SSIM`. Its interior equals scikit-image's `structural_similarity(gaussian_weights=True,
//!   sigma=1.5, use_sample_covariance=False, data_range=1)` (tested against a fixture).
//! - [`masked_l1`]: `Σ m |x − y| / Σ m` with per-pixel weights `m` (depth against a target depth,
//!   weighted by the target's alpha).
//! - [`DepthNormal`]: 2DGS's depth–normal consistency, `Σ α (1 − n · N(d)) / P` with `N(d)` the
//!   normal of the depth map's points from central differences and `n` the rendered normal
//!   (camera frame), `α` a weight held fixed (2DGS detaches it); gradients with respect to both
//!   the normal and the depth image.

use rayon::prelude::*;
use trisplat_geometry::Camera;

use crate::render::Real;

/// 3DGS's `λ_dssim`: loss = `(1 − λ) L1 + λ (1 − SSIM)`.
pub const DEFAULT_LAMBDA_DSSIM: f64 = 0.2;
/// SSIM window side (3DGS, scikit-image with σ = 1.5 and truncate 3.5).
pub const SSIM_WINDOW: usize = 11;
/// SSIM window standard deviation in pixels.
pub const SSIM_SIGMA: f64 = 1.5;
/// SSIM's `C1 = (0.01 L)²` with data range `L = 1`.
pub const SSIM_C1: f64 = 0.01 * 0.01;
/// SSIM's `C2 = (0.03 L)²`.
pub const SSIM_C2: f64 = 0.03 * 0.03;

/// Mean absolute difference of `pred` and `target` over every value; adds `scale × d/d pred`
/// into `grad`.
///
/// # Panics
/// When the three slices differ in length.
pub fn l1<F: Real>(pred: &[F], target: &[F], scale: f64, grad: &mut [F]) -> f64 {
    assert_eq!(pred.len(), target.len(), "l1: image sizes differ");
    assert_eq!(pred.len(), grad.len(), "l1: gradient size differs");
    if pred.is_empty() {
        return 0.0;
    }
    let n = pred.len() as f64;
    let g = scale / n;
    let sum: f64 = pred
        .par_iter()
        .zip(target)
        .zip(grad.par_iter_mut())
        .with_min_len(4096)
        .map(|((&p, &t), gr)| {
            let d = p.wide() - t.wide();
            if d != 0.0 {
                *gr += F::of(g * d.signum());
            }
            d.abs()
        })
        .sum();
    sum / n
}

/// Weighted mean absolute difference `Σ m |x − y| / Σ m` (one weight per value, e.g. the
/// target's alpha for a depth image); 0 when every weight is 0. Adds `scale × d/d pred`.
///
/// # Panics
/// When the slices differ in length.
pub fn masked_l1<F: Real>(
    pred: &[F],
    target: &[F],
    weights: &[F],
    scale: f64,
    grad: &mut [F],
) -> f64 {
    assert_eq!(pred.len(), target.len(), "masked_l1: image sizes differ");
    assert_eq!(pred.len(), weights.len(), "masked_l1: weight size differs");
    assert_eq!(pred.len(), grad.len(), "masked_l1: gradient size differs");
    let total: f64 = weights.iter().map(|w| w.wide()).sum();
    if total <= 0.0 {
        return 0.0;
    }
    let g = scale / total;
    let sum: f64 = pred
        .par_iter()
        .zip(target)
        .zip(weights)
        .zip(grad.par_iter_mut())
        .with_min_len(4096)
        .map(|(((&p, &t), &w), gr)| {
            let d = p.wide() - t.wide();
            let w = w.wide();
            if d != 0.0 && w != 0.0 {
                *gr += F::of(g * w * d.signum());
            }
            w * d.abs()
        })
        .sum();
    sum / total
}

/// Peak signal-to-noise ratio of `pred` against `target` for values in 0..1:
/// `10 log10(1 / MSE)` (infinite for equal images).
#[must_use]
pub fn psnr<F: Real>(pred: &[F], target: &[F]) -> f64 {
    let n = pred.len().min(target.len()).max(1) as f64;
    let se: f64 = pred
        .iter()
        .zip(target)
        .map(|(&p, &t)| (p.wide() - t.wide()).powi(2))
        .sum();
    -10.0 * (se / n).log10()
}

/// The normalised 1-D Gaussian window of SSIM.
fn window() -> [f64; SSIM_WINDOW] {
    let r = (SSIM_WINDOW / 2) as f64;
    let mut w = [0.0; SSIM_WINDOW];
    for (i, v) in w.iter_mut().enumerate() {
        let x = i as f64 - r;
        *v = (-x * x / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let s: f64 = w.iter().sum();
    w.map(|v| v / s)
}

/// SSIM (3DGS's definition, module docs) with reusable buffers: make one per image size and
/// call [`Ssim::ssim`] per image pair.
#[derive(Clone, Debug)]
pub struct Ssim {
    width: usize,
    height: usize,
    window: [f64; SSIM_WINDOW],
    channels: Vec<ChannelBuf>,
}

/// One channel's planes (`H × W` each).
#[derive(Clone, Debug, Default)]
struct ChannelBuf {
    /// Filtered x, y, x², y², xy.
    mx: Vec<f64>,
    my: Vec<f64>,
    mxx: Vec<f64>,
    myy: Vec<f64>,
    mxy: Vec<f64>,
    /// The SSIM map.
    map: Vec<f64>,
    /// dS/dμx, dS/dE[x²], dS/dE[xy] per pixel (then filtered), scaled.
    ta: Vec<f64>,
    tb: Vec<f64>,
    tc: Vec<f64>,
    scratch: Vec<f64>,
}

impl ChannelBuf {
    fn resize(&mut self, px: usize) {
        for v in [
            &mut self.mx,
            &mut self.my,
            &mut self.mxx,
            &mut self.myy,
            &mut self.mxy,
            &mut self.map,
            &mut self.ta,
            &mut self.tb,
            &mut self.tc,
            &mut self.scratch,
        ] {
            v.resize(px, 0.0);
        }
    }
}

impl Ssim {
    /// A workspace for `width × height` images.
    #[must_use]
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            window: window(),
            channels: Vec::new(),
        }
    }

    /// The mean SSIM of `pred` against `target` (`[H, W, channels]`, values in 0..1) over every
    /// pixel and channel; with `grad`, adds `scale × d SSIM / d pred` into it. D-SSIM's gradient
    /// is that of SSIM with `scale` negated.
    ///
    /// # Panics
    /// When a slice does not hold `width × height × channels` values.
    pub fn ssim<F: Real>(
        &mut self,
        pred: &[F],
        target: &[F],
        channels: usize,
        scale: f64,
        grad: Option<&mut [F]>,
    ) -> f64 {
        let (w, h) = (self.width, self.height);
        let px = w * h;
        assert_eq!(pred.len(), px * channels, "ssim: prediction size");
        assert_eq!(target.len(), px * channels, "ssim: target size");
        if px == 0 || channels == 0 {
            return 1.0;
        }
        self.channels.resize_with(channels, ChannelBuf::default);
        let window = self.window;
        let n = (px * channels) as f64;
        let want_grad = grad.is_some();
        let sum: f64 = self
            .channels
            .par_iter_mut()
            .enumerate()
            .map(|(c, buf)| {
                buf.resize(px);
                channel(
                    &window,
                    w,
                    h,
                    (pred, target, channels, c),
                    buf,
                    want_grad,
                    scale / n,
                )
            })
            .sum();
        if let Some(grad) = grad {
            assert_eq!(grad.len(), px * channels, "ssim: gradient size");
            for (c, buf) in self.channels.iter().enumerate() {
                for (i, &v) in buf.ta.iter().enumerate() {
                    grad[i * channels + c] += F::of(v);
                }
            }
        }
        sum / n
    }

    /// The per-pixel SSIM map of channel `c` of `pred` against `target` (`[H, W, channels]`),
    /// `[H, W]` row-major.
    ///
    /// # Panics
    /// As [`Ssim::ssim`].
    #[must_use]
    pub fn map<F: Real>(
        &mut self,
        pred: &[F],
        target: &[F],
        channels: usize,
        c: usize,
    ) -> Vec<f64> {
        let px = self.width * self.height;
        assert_eq!(pred.len(), px * channels, "ssim: prediction size");
        assert_eq!(target.len(), px * channels, "ssim: target size");
        let mut buf = ChannelBuf::default();
        buf.resize(px);
        let window = self.window;
        channel(
            &window,
            self.width,
            self.height,
            (pred, target, channels, c),
            &mut buf,
            false,
            0.0,
        );
        buf.map
    }
}

/// One channel of SSIM: fills `buf`'s moments and map and, with `want_grad`, leaves
/// `g_scale × d map-sum / d x` in `buf.ta`; returns the map's sum.
fn channel<F: Real>(
    window: &[f64; SSIM_WINDOW],
    w: usize,
    h: usize,
    (pred, target, channels, c): (&[F], &[F], usize, usize),
    buf: &mut ChannelBuf,
    want_grad: bool,
    g_scale: f64,
) -> f64 {
    let px = w * h;
    for i in 0..px {
        let x = pred[i * channels + c].wide();
        let y = target[i * channels + c].wide();
        buf.mx[i] = x;
        buf.my[i] = y;
        buf.mxx[i] = x * x;
        buf.myy[i] = y * y;
        buf.mxy[i] = x * y;
    }
    for plane in [
        &mut buf.mx,
        &mut buf.my,
        &mut buf.mxx,
        &mut buf.myy,
        &mut buf.mxy,
    ] {
        filter(window, w, h, plane, &mut buf.scratch);
    }
    let mut sum = 0.0;
    for i in 0..px {
        let (mx, my) = (buf.mx[i], buf.my[i]);
        let a1 = 2.0 * mx * my + SSIM_C1;
        let a2 = 2.0 * (buf.mxy[i] - mx * my) + SSIM_C2;
        let b1 = mx * mx + my * my + SSIM_C1;
        let b2 = (buf.mxx[i] - mx * mx) + (buf.myy[i] - my * my) + SSIM_C2;
        let s = a1 * a2 / (b1 * b2);
        buf.map[i] = s;
        sum += s;
        if want_grad {
            buf.ta[i] =
                g_scale * (2.0 * my * (a2 - a1) / (b1 * b2) - 2.0 * mx * s * (1.0 / b1 - 1.0 / b2));
            buf.tb[i] = g_scale * (-s / b2);
            buf.tc[i] = g_scale * (2.0 * a1 / (b1 * b2));
        }
    }
    if want_grad {
        // The window is symmetric and the padding zero: the filter is its own adjoint.
        for plane in [&mut buf.ta, &mut buf.tb, &mut buf.tc] {
            filter(window, w, h, plane, &mut buf.scratch);
        }
        for i in 0..px {
            let x = pred[i * channels + c].wide();
            let y = target[i * channels + c].wide();
            buf.ta[i] += 2.0 * x * buf.tb[i] + y * buf.tc[i];
        }
    }
    sum
}

/// Separable Gaussian filter of one `H × W` plane in place, zero padding, same size.
fn filter(window: &[f64; SSIM_WINDOW], w: usize, h: usize, plane: &mut [f64], scratch: &mut [f64]) {
    let r = (SSIM_WINDOW / 2) as isize;
    // Rows into scratch.
    for y in 0..h {
        let row = &plane[y * w..(y + 1) * w];
        let out = &mut scratch[y * w..(y + 1) * w];
        for (x, o) in out.iter_mut().enumerate() {
            let mut s = 0.0;
            for (k, &wk) in window.iter().enumerate() {
                let xx = x as isize + k as isize - r;
                if xx >= 0 && (xx as usize) < w {
                    s += wk * row[xx as usize];
                }
            }
            *o = s;
        }
    }
    // Columns back into the plane.
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (k, &wk) in window.iter().enumerate() {
                let yy = y as isize + k as isize - r;
                if yy >= 0 && (yy as usize) < h {
                    s += wk * scratch[yy as usize * w + x];
                }
            }
            plane[y * w + x] = s;
        }
    }
}

/// 2DGS's depth–normal consistency (module docs) for one camera, with reusable buffers.
#[derive(Clone, Debug, Default)]
pub struct DepthNormal {
    /// Per pixel: the unnormalised depth normal `c = dy × dx` (camera frame), 0 where undefined.
    cross: Vec<[f64; 3]>,
    /// d loss / d point, per pixel.
    point_grad: Vec<[f64; 3]>,
}

impl DepthNormal {
    /// The loss `Σ_p α_p (1 − n_p · N_p) / P` over the `P` pixels of `camera`, `N_p` the unit
    /// normal of the depth map's points from central differences (`N = normalize(dy × dx)`,
    /// facing the camera; undefined, and left out, on the border and where the pixel or one of
    /// its four neighbours has depth ≤ 0), `n` the rendered normal image `[H, W, 3]` in the
    /// camera frame (OpenCV axes), `α` the weight image `[H, W]` (the rendered alpha, held
    /// fixed). Adds `scale ×` the gradients into `grad_normal` and `grad_depth` when given.
    ///
    /// # Panics
    /// When an image does not fit the camera.
    #[allow(clippy::too_many_arguments)]
    pub fn loss<F: Real>(
        &mut self,
        camera: &Camera,
        depth: &[F],
        normal: &[F],
        weight: &[F],
        scale: f64,
        grad_depth: Option<&mut [F]>,
        grad_normal: Option<&mut [F]>,
    ) -> f64 {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let px = w * h;
        assert_eq!(depth.len(), px, "depth_normal: depth size");
        assert_eq!(normal.len(), 3 * px, "depth_normal: normal size");
        assert_eq!(weight.len(), px, "depth_normal: weight size");
        if px == 0 {
            return 0.0;
        }
        let ray = |i: usize, j: usize| {
            [
                (j as f64 + 0.5 - camera.cx) / camera.fx,
                (i as f64 + 0.5 - camera.cy) / camera.fy,
                1.0,
            ]
        };
        let point = |i: usize, j: usize| {
            let d = depth[i * w + j].wide();
            ray(i, j).map(|r| r * d)
        };
        let valid = |i: usize, j: usize| depth[i * w + j].wide() > 0.0;
        self.cross.clear();
        self.cross.resize(px, [0.0; 3]);
        let g = scale / px as f64;
        let mut sum = 0.0;
        let want = grad_depth.is_some() || grad_normal.is_some();
        if want {
            self.point_grad.clear();
            self.point_grad.resize(px, [0.0; 3]);
        }
        let mut grad_normal = grad_normal;
        for i in 1..h.saturating_sub(1) {
            for j in 1..w.saturating_sub(1) {
                let p = i * w + j;
                let a = weight[p].wide();
                if a == 0.0
                    || !(valid(i, j)
                        && valid(i - 1, j)
                        && valid(i + 1, j)
                        && valid(i, j - 1)
                        && valid(i, j + 1))
                {
                    continue;
                }
                let dx = sub(point(i, j + 1), point(i, j - 1));
                let dy = sub(point(i + 1, j), point(i - 1, j));
                let c = cross(dy, dx);
                let len = dot(c, c).sqrt();
                if len <= 0.0 || !len.is_finite() {
                    continue;
                }
                let nn = c.map(|v| v / len);
                let n = [0, 1, 2].map(|k| normal[3 * p + k].wide());
                let cos = dot(n, nn);
                sum += a * (1.0 - cos);
                if !want {
                    continue;
                }
                if let Some(gn) = grad_normal.as_deref_mut() {
                    for k in 0..3 {
                        gn[3 * p + k] += F::of(-g * a * nn[k]);
                    }
                }
                // d/dN = −g a n; through the normalisation to c, then to the points.
                let g_nn = n.map(|v| -g * a * v);
                let along = dot(nn, g_nn);
                let g_c = [0, 1, 2].map(|k| (g_nn[k] - nn[k] * along) / len);
                let g_dy = cross(dx, g_c);
                let g_dx = cross(g_c, dy);
                let pg = &mut self.point_grad;
                add(&mut pg[(i + 1) * w + j], g_dy, 1.0);
                add(&mut pg[(i - 1) * w + j], g_dy, -1.0);
                add(&mut pg[i * w + j + 1], g_dx, 1.0);
                add(&mut pg[i * w + j - 1], g_dx, -1.0);
                self.cross[p] = c;
            }
        }
        if let Some(gd) = grad_depth {
            for i in 0..h {
                for j in 0..w {
                    let p = i * w + j;
                    let v = dot(self.point_grad[p], ray(i, j));
                    if v != 0.0 {
                        gd[p] += F::of(v);
                    }
                }
            }
        }
        sum / px as f64
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn add(acc: &mut [f64; 3], v: [f64; 3], s: f64) {
    for k in 0..3 {
        acc[k] += s * v[k];
    }
}
