//! Adam (Kingma & Ba) with one learning rate per parameter group and its state kept per
//! Gaussian, so that a set whose count changes (densify, prune, re-initialisation) keeps the
//! moments of the Gaussians that stay ([`Adam::remap`]) or starts afresh ([`Adam::reset`]).
//!
//! Each Gaussian has its own step count, so the bias correction of a new Gaussian starts at
//! step 1 (torch's Adam, which 3DGS uses, keeps one step count per tensor; a Gaussian added at
//! step 10,000 then gets almost no bias correction of its zeroed moments).

use crate::render::{GaussianGrads, GaussianParams};

/// Learning rates per parameter group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearningRates {
    /// Means (local units: triangle scales `k_f` for bound sets).
    pub means: f64,
    /// Log-scales.
    pub log_scales: f64,
    /// Raw quaternions.
    pub rotations: f64,
    /// Opacity logits.
    pub opacities: f64,
    /// SH DC coefficients (`f_dc_*`).
    pub sh_dc: f64,
    /// Higher SH coefficients (`f_rest_*`).
    pub sh_rest: f64,
}

impl LearningRates {
    /// GaussianAvatars' rates for bound (local) parameters: means 0.005 (in triangle scales;
    /// 3DGS's 1.6e-4 is in scene units × extent), log-scales 0.017, rotations 0.001, opacities
    /// 0.05, SH DC 0.0025, SH rest 0.0025 / 20 (3DGS's).
    pub const BOUND: Self = Self {
        means: 0.005,
        log_scales: 0.017,
        rotations: 0.001,
        opacities: 0.05,
        sh_dc: 0.0025,
        sh_rest: 0.0025 / 20.0,
    };

    /// 3DGS's rates for world-space parameters (`position_lr_init` 1.6e-4 to be multiplied by
    /// the scene extent, scaling 0.005, rotation 0.001, opacity 0.025, features 0.0025 and /20).
    pub const WORLD_3DGS: Self = Self {
        means: 1.6e-4,
        log_scales: 0.005,
        rotations: 0.001,
        opacities: 0.025,
        sh_dc: 0.0025,
        sh_rest: 0.0025 / 20.0,
    };
}

impl Default for LearningRates {
    fn default() -> Self {
        Self::BOUND
    }
}

/// Adam's state for one set of Gaussians (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    /// Learning rates.
    pub lr: LearningRates,
    /// β1 (0.9).
    pub beta1: f64,
    /// β2 (0.999).
    pub beta2: f64,
    /// ε (1e-15, as 3DGS).
    pub eps: f64,
    sh_per_gaussian: usize,
    /// Per Gaussian: steps taken.
    steps: Vec<u32>,
    /// First and second moments per group, flattened like the parameters.
    m: Moments,
    v: Moments,
}

#[derive(Clone, Debug, Default, PartialEq)]
struct Moments {
    means: Vec<f64>,
    log_scales: Vec<f64>,
    rotations: Vec<f64>,
    opacities: Vec<f64>,
    sh: Vec<f64>,
}

impl Moments {
    fn zeros(n: usize, k: usize) -> Self {
        Self {
            means: vec![0.0; 3 * n],
            log_scales: vec![0.0; 3 * n],
            rotations: vec![0.0; 4 * n],
            opacities: vec![0.0; n],
            sh: vec![0.0; k * n],
        }
    }

    fn remap(&self, map: &[Option<usize>], k: usize) -> Self {
        let mut out = Self::zeros(map.len(), k);
        for (new, old) in map.iter().enumerate() {
            if let Some(old) = *old {
                let copy = |dst: &mut [f64], src: &[f64], w: usize| {
                    dst[new * w..(new + 1) * w].copy_from_slice(&src[old * w..(old + 1) * w]);
                };
                copy(&mut out.means, &self.means, 3);
                copy(&mut out.log_scales, &self.log_scales, 3);
                copy(&mut out.rotations, &self.rotations, 4);
                copy(&mut out.opacities, &self.opacities, 1);
                copy(&mut out.sh, &self.sh, k);
            }
        }
        out
    }
}

impl Adam {
    /// Fresh state for `n` Gaussians with `sh_per_gaussian` SH coefficients each.
    #[must_use]
    pub fn new(lr: LearningRates, n: usize, sh_per_gaussian: usize) -> Self {
        Self {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            sh_per_gaussian,
            steps: vec![0; n],
            m: Moments::zeros(n, sh_per_gaussian),
            v: Moments::zeros(n, sh_per_gaussian),
        }
    }

    /// Number of Gaussians the state is for.
    #[must_use]
    pub fn len(&self) -> usize {
        self.steps.len()
    }

    /// Whether the state is for no Gaussians.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    /// Forgets every moment and step: fresh state for `n` Gaussians.
    pub fn reset(&mut self, n: usize) {
        let (beta1, beta2, eps) = (self.beta1, self.beta2, self.eps);
        *self = Self {
            beta1,
            beta2,
            eps,
            ..Self::new(self.lr, n, self.sh_per_gaussian)
        };
    }

    /// New state after the set changed: Gaussian `i` of the new set takes the state of old
    /// Gaussian `map[i]` (a clone, a survivor of pruning), or fresh state for `None`.
    ///
    /// # Panics
    /// When an index in `map` is past the old count.
    pub fn remap(&mut self, map: &[Option<usize>]) {
        let k = self.sh_per_gaussian;
        self.m = self.m.remap(map, k);
        self.v = self.v.remap(map, k);
        self.steps = map
            .iter()
            .map(|o| o.map_or(0, |old| self.steps[old]))
            .collect();
    }

    /// Zeroes the opacity logits' moments of every Gaussian (steps kept): what 3DGS's opacity
    /// reset does to the optimiser (`replace_tensor_to_optimizer`).
    pub fn zero_opacity_moments(&mut self) {
        self.m.opacities.fill(0.0);
        self.v.opacities.fill(0.0);
    }

    /// The first and second moments of Gaussian `i`'s opacity logit and its step count (for
    /// tests and diagnostics).
    ///
    /// # Panics
    /// When `i` is past the count.
    #[must_use]
    pub fn opacity_state(&self, i: usize) -> (f64, f64, u32) {
        (self.m.opacities[i], self.v.opacities[i], self.steps[i])
    }

    /// The first moments of Gaussian `i`'s mean (for tests and diagnostics).
    ///
    /// # Panics
    /// When `i` is past the count.
    #[must_use]
    pub fn mean_moments(&self, i: usize) -> ([f64; 3], [f64; 3]) {
        let m = &self.m.means[3 * i..3 * i + 3];
        let v = &self.v.means[3 * i..3 * i + 3];
        ([m[0], m[1], m[2]], [v[0], v[1], v[2]])
    }

    /// One step on `params` with gradients `grads` (same count and SH layout as the state).
    ///
    /// # Panics
    /// When the counts differ.
    pub fn step(&mut self, params: &mut GaussianParams, grads: &GaussianGrads) {
        let n = self.len();
        assert_eq!(
            params.means.len(),
            n,
            "adam: parameter count differs from the state"
        );
        assert_eq!(
            grads.len(),
            n,
            "adam: gradient count differs from the state"
        );
        let k = self.sh_per_gaussian;
        assert_eq!(
            params.sh.len(),
            n * k,
            "adam: SH layout differs from the state"
        );
        for s in &mut self.steps {
            *s = s.saturating_add(1);
        }
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        let steps = &self.steps;
        // Per Gaussian: lr_t = lr √(1 − β2^t) / (1 − β1^t).
        let corr = |i: usize| {
            let t = steps[i] as i32;
            (1.0 - b2.powi(t)).sqrt() / (1.0 - b1.powi(t))
        };
        let update = |p: &mut [f64],
                      g: &[f64],
                      m: &mut [f64],
                      v: &mut [f64],
                      w: usize,
                      lr: &dyn Fn(usize) -> f64| {
            for (j, (((p, &g), m), v)) in p
                .iter_mut()
                .zip(g)
                .zip(m.iter_mut())
                .zip(v.iter_mut())
                .enumerate()
            {
                let i = j / w;
                *m = b1 * *m + (1.0 - b1) * g;
                *v = b2 * *v + (1.0 - b2) * g * g;
                *p -= lr(j % w) * corr(i) * *m / (v.sqrt() + eps);
            }
        };
        let lr = self.lr;
        update(
            params.means.as_flattened_mut(),
            grads.means.as_flattened(),
            &mut self.m.means,
            &mut self.v.means,
            3,
            &|_| lr.means,
        );
        update(
            params.log_scales.as_flattened_mut(),
            grads.log_scales.as_flattened(),
            &mut self.m.log_scales,
            &mut self.v.log_scales,
            3,
            &|_| lr.log_scales,
        );
        update(
            params.rotations.as_flattened_mut(),
            grads.rotations.as_flattened(),
            &mut self.m.rotations,
            &mut self.v.rotations,
            4,
            &|_| lr.rotations,
        );
        update(
            &mut params.opacity_logits,
            &grads.opacity_logits,
            &mut self.m.opacities,
            &mut self.v.opacities,
            1,
            &|_| lr.opacities,
        );
        if k > 0 {
            update(
                &mut params.sh,
                &grads.sh,
                &mut self.m.sh,
                &mut self.v.sh,
                k,
                &|c| if c < 3 { lr.sh_dc } else { lr.sh_rest },
            );
        }
    }
}
