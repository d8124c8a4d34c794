//! What the differentiable renderer reads ([`DiffParams`]) and what it returns
//! ([`GaussianGrads`]), and the float type of its per-pixel arithmetic ([`Real`]).

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

use glam::DVec3;

use crate::gaussians::{GaussianSet, ScaleDims};
use crate::sh::sh_coeffs_per_channel;

/// The parameters of world-space Gaussians as the differentiable renderer reads them, in `f64`:
/// the raw (unactivated) values a fitter optimises. Implemented for [`GaussianSet`] (its `f32`
/// values widened) and for [`GaussianParams`] (`f64`, for finite differences and fitters).
pub trait DiffParams: Sync {
    /// Number of Gaussians.
    fn len(&self) -> usize;
    /// Whether the parameters are in world space (false for a bound set's local frames, which
    /// the renderer refuses).
    fn is_world(&self) -> bool {
        true
    }
    /// Whether there are no Gaussians.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// SH degree, 0..=3.
    fn sh_degree(&self) -> u8;
    /// Centre of Gaussian `i`.
    fn mean(&self, i: usize) -> DVec3;
    /// Natural-log scales of Gaussian `i` (`−∞` for the flat axis of a surfel).
    fn log_scale(&self, i: usize) -> DVec3;
    /// Raw rotation quaternion `[w, x, y, z]` of Gaussian `i` (normalised on activation).
    fn rotation(&self, i: usize) -> [f64; 4];
    /// Opacity logit of Gaussian `i`.
    fn opacity_logit(&self, i: usize) -> f64;
    /// Writes the `3 (degree + 1)²` SH coefficients of Gaussian `i` in file order (`f_dc_0..2`,
    /// then `f_rest` channel-major) into the front of `out`.
    fn sh_coeffs(&self, i: usize, out: &mut [f64; 48]);
}

impl DiffParams for GaussianSet {
    fn len(&self) -> usize {
        GaussianSet::len(self)
    }
    fn is_world(&self) -> bool {
        self.space() != crate::gaussians::ParameterSpace::Local
    }
    fn sh_degree(&self) -> u8 {
        GaussianSet::sh_degree(self).min(3)
    }
    fn mean(&self, i: usize) -> DVec3 {
        self.means()[i].as_dvec3()
    }
    fn log_scale(&self, i: usize) -> DVec3 {
        let s = self.log_scales()[i].as_dvec3();
        match self.scale_dims() {
            ScaleDims::Three => s,
            ScaleDims::Two => DVec3::new(s.x, s.y, f64::NEG_INFINITY),
        }
    }
    fn rotation(&self, i: usize) -> [f64; 4] {
        self.rotations()[i].map(f64::from)
    }
    fn opacity_logit(&self, i: usize) -> f64 {
        f64::from(self.opacity_logits()[i])
    }
    fn sh_coeffs(&self, i: usize, out: &mut [f64; 48]) {
        let k = 3 * sh_coeffs_per_channel(DiffParams::sh_degree(self));
        for (o, &c) in out.iter_mut().zip(self.sh_coeffs(i)).take(k) {
            *o = f64::from(c);
        }
    }
}

/// World-space Gaussian parameters in `f64` (the layout of [`crate::GaussianParts`]), for
/// finite-difference checks and for fitters that keep their parameters in double precision.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianParams {
    /// Centres.
    pub means: Vec<[f64; 3]>,
    /// Natural-log scales.
    pub log_scales: Vec<[f64; 3]>,
    /// Raw quaternions `[w, x, y, z]`.
    pub rotations: Vec<[f64; 4]>,
    /// Opacity logits.
    pub opacity_logits: Vec<f64>,
    /// SH degree, 0..=3.
    pub sh_degree: u8,
    /// SH coefficients, `3 (degree + 1)²` per Gaussian in file order.
    pub sh: Vec<f64>,
}

impl GaussianParams {
    /// The parameters of `set` widened to `f64` (degrees above 3 are cut to 3; a surfel's flat
    /// axis gets log-scale `−∞`).
    #[must_use]
    pub fn from_set(set: &GaussianSet) -> Self {
        let n = set.len();
        let degree = DiffParams::sh_degree(set);
        let k = 3 * sh_coeffs_per_channel(degree);
        let mut sh = Vec::with_capacity(n * k);
        let mut buf = [0.0; 48];
        for i in 0..n {
            DiffParams::sh_coeffs(set, i, &mut buf);
            sh.extend_from_slice(&buf[..k]);
        }
        Self {
            means: (0..n)
                .map(|i| DiffParams::mean(set, i).to_array())
                .collect(),
            log_scales: (0..n)
                .map(|i| DiffParams::log_scale(set, i).to_array())
                .collect(),
            rotations: (0..n).map(|i| DiffParams::rotation(set, i)).collect(),
            opacity_logits: (0..n).map(|i| DiffParams::opacity_logit(set, i)).collect(),
            sh_degree: degree,
            sh,
        }
    }

    /// SH coefficients per Gaussian: `3 (degree + 1)²`.
    #[must_use]
    pub fn sh_per_gaussian(&self) -> usize {
        3 * sh_coeffs_per_channel(self.sh_degree.min(3))
    }
}

impl DiffParams for GaussianParams {
    fn len(&self) -> usize {
        self.means.len()
    }
    fn sh_degree(&self) -> u8 {
        self.sh_degree.min(3)
    }
    fn mean(&self, i: usize) -> DVec3 {
        DVec3::from_array(self.means[i])
    }
    fn log_scale(&self, i: usize) -> DVec3 {
        DVec3::from_array(self.log_scales[i])
    }
    fn rotation(&self, i: usize) -> [f64; 4] {
        self.rotations[i]
    }
    fn opacity_logit(&self, i: usize) -> f64 {
        self.opacity_logits[i]
    }
    fn sh_coeffs(&self, i: usize, out: &mut [f64; 48]) {
        let k = self.sh_per_gaussian();
        let src = self.sh.get(i * k..(i + 1) * k).unwrap_or(&[]);
        out[..src.len()].copy_from_slice(src);
    }
}

/// Gradients of a loss with respect to the raw parameters of every Gaussian (zero for Gaussians
/// that were culled), in `f64`, laid out like [`GaussianParams`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianGrads {
    /// d loss / d mean.
    pub means: Vec<[f64; 3]>,
    /// d loss / d log-scale.
    pub log_scales: Vec<[f64; 3]>,
    /// d loss / d raw quaternion `[w, x, y, z]` (through the normalisation: orthogonal to it).
    pub rotations: Vec<[f64; 4]>,
    /// d loss / d opacity logit.
    pub opacity_logits: Vec<f64>,
    /// d loss / d SH coefficient, `3 (degree + 1)²` per Gaussian in file order.
    pub sh: Vec<f64>,
    /// d loss / d projected mean in pixels (the screen-space gradient 3DGS densifies on), summed
    /// over the views of the accumulated backward passes.
    pub means2d: Vec<[f64; 2]>,
}

impl GaussianGrads {
    /// Zero gradients for `n` Gaussians of SH degree `sh_degree`.
    #[must_use]
    pub fn zeros(n: usize, sh_degree: u8) -> Self {
        Self {
            means: vec![[0.0; 3]; n],
            log_scales: vec![[0.0; 3]; n],
            rotations: vec![[0.0; 4]; n],
            opacity_logits: vec![0.0; n],
            sh: vec![0.0; n * 3 * sh_coeffs_per_channel(sh_degree.min(3))],
            means2d: vec![[0.0; 2]; n],
        }
    }

    /// Number of Gaussians.
    #[must_use]
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// Whether there are no Gaussians.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Sets every gradient to zero, keeping the buffers (for the next step of a fitter).
    pub fn clear(&mut self) {
        use rayon::prelude::*;
        self.means.par_iter_mut().for_each(|v| *v = [0.0; 3]);
        self.log_scales.par_iter_mut().for_each(|v| *v = [0.0; 3]);
        self.rotations.par_iter_mut().for_each(|v| *v = [0.0; 4]);
        self.opacity_logits.par_iter_mut().for_each(|v| *v = 0.0);
        self.sh.par_iter_mut().for_each(|v| *v = 0.0);
        self.means2d.par_iter_mut().for_each(|v| *v = [0.0; 2]);
    }
}

/// The float type of the per-pixel forward and backward arithmetic: `f32` (as gsplat; the
/// production path) or `f64` (for finite-difference checks). Per-splat gradient sums are `f64`
/// either way.
pub trait Real:
    Copy
    + Send
    + Sync
    + Default
    + Debug
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// The nearest value of this type.
    fn of(v: f64) -> Self;
    /// Widened to `f64`.
    fn wide(self) -> f64;
    /// `e^(−x)` for `x ≥ 0` (`f32`: the renderer's own [`super::super::project::exp_f32`], so
    /// the alphas equal those of the plain forward).
    fn exp_neg(self) -> Self;
    /// The smallest value above `self`.
    fn next_up(self) -> Self;
    /// The smaller of two values.
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        if other < self { other } else { self }
    }
    /// The larger of two values.
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        if other > self { other } else { self }
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    #[inline(always)]
    fn of(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn wide(self) -> f64 {
        f64::from(self)
    }
    #[inline(always)]
    fn exp_neg(self) -> Self {
        super::super::project::exp_f32(-self)
    }
    fn next_up(self) -> Self {
        f32::next_up(self)
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    #[inline(always)]
    fn of(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn wide(self) -> f64 {
        self
    }
    #[inline(always)]
    fn exp_neg(self) -> Self {
        (-self).exp()
    }
    fn next_up(self) -> Self {
        f64::next_up(self)
    }
}
