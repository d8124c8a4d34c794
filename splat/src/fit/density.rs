//! Adaptive density control of a bound set during a fit: 3DGS's `densify_and_prune` and
//! `reset_opacity` as GaussianAvatars runs them on Gaussians bound to triangles
//! (docs/conventions.md §5 "Fitting", "Densification").
//!
//! - **Statistics** ([`DensityStats`]): per Gaussian, the sum over the views where it was
//!   visible (not culled by the projection, 3DGS's `radii > 0`) of the norm of its screen-space
//!   mean gradient, and the number of those views. The gradient is taken in 3DGS's units, NDC:
//!   the renderer's `means2d` is `d loss / d pixel`, and a pixel is `(ndc + 1) S / 2` along an
//!   axis of `S` pixels, so `d loss / d ndc = (g_x W / 2, g_y H / 2)`. Its norm, averaged over
//!   the views, is compared with the threshold as in 3DGS (default 0.0002, 3DGS's and
//!   GaussianAvatars'); NDC units make it nearly independent of the image size.
//! - **Clone / split** ([`densify_and_prune`]): a Gaussian whose mean gradient is at least the
//!   threshold is *cloned* (an exact copy, same triangle) when it is small and *split* when it
//!   is large, the size being its largest **world scale at the template's rest pose**,
//!   `max_j exp(log s'_j) k_f` (`k_f` the rest-pose triangle scale; GaussianAvatars'
//!   `get_scaling` in the frame last rendered), against `percent_dense × extent`, `extent` the
//!   3DGS camera extent ([`camera_extent`]). Clones first, then splits of the Gaussians that
//!   were there before (3DGS pads the gradients of the clones with zeros). A split replaces the
//!   parent with `N = 2` children sampled from the parent's Gaussian in its triangle's frame
//!   (`μ' + R' (s' ∘ z)`, `z ~ N(0, I)`: the world-space sampling of 3DGS mapped back to the
//!   triangle), scales `/ (0.8 N) = / 1.6`; every new Gaussian inherits the parent's triangle,
//!   rotation, opacity and colour ([`crate::densify::clone_selected`],
//!   [`crate::densify::split_selected`]).
//! - **Prune**: opacity `< prune_opacity` (0.005), and optionally a world size at rest above
//!   `max_world_size × extent` (3DGS's `big_points_ws`, 0.1, after the first opacity reset),
//!   **never a triangle's last Gaussians** ([`crate::densify::prune`]: when every Gaussian of a
//!   triangle is flagged none is removed, GaussianAvatars' rule).
//! - **Adam**: survivors keep their moments and step counts; clones and children start with
//!   zero moments (3DGS concatenates zeros), removed rows go ([`Adam::remap`]).
//! - **Opacity reset** ([`reset_opacity`]): every opacity to `min(opacity, 0.01)` through the
//!   logit, `logit ← min(logit, logit(0.01))`, and the opacity moments zeroed (3DGS).
//!
//! Sampling is seeded: one stream per (event seed, parent), so runs are reproducible and do not
//! depend on the thread count.

use glam::DVec3;
use trisplat_geometry::TriId;

use crate::densify::{
    DEFAULT_SPLIT_CHILDREN, DEFAULT_SPLIT_SHRINK, DensifyError, SplitOptions, clone_selected,
    prune, split_selected,
};
use crate::fit::adam::Adam;
use crate::fit::bound::{BoundParams, TriangleFrames, to_set};
use crate::render::GaussianParams;

/// 3DGS's `densify_grad_threshold` (mean NDC gradient norm), also GaussianAvatars'.
pub const DEFAULT_GRAD_THRESHOLD: f64 = 0.0002;
/// 3DGS's `percent_dense`: clone at or below this fraction of the extent, split above.
pub const DEFAULT_PERCENT_DENSE: f64 = 0.01;
/// 3DGS's minimum opacity kept by pruning.
pub const DEFAULT_PRUNE_OPACITY: f64 = 0.005;
/// 3DGS's `densify_from_iter`.
pub const DEFAULT_DENSIFY_FROM: usize = 500;
/// 3DGS's `densify_until_iter`.
pub const DEFAULT_DENSIFY_UNTIL: usize = 15_000;
/// 3DGS's `densification_interval`.
pub const DEFAULT_DENSIFY_EVERY: usize = 100;
/// 3DGS's `opacity_reset_interval`.
pub const DEFAULT_OPACITY_RESET_EVERY: usize = 3000;
/// The opacity an opacity reset caps every Gaussian at (3DGS).
pub const RESET_OPACITY: f64 = 0.01;
/// 3DGS's `big_points_ws` fraction of the extent (pruned after the first opacity reset).
pub const DEFAULT_MAX_WORLD_SIZE: f64 = 0.1;

/// When and how a fit densifies and prunes (module docs). Iterations are counted from 1 (the
/// number of steps done), as 3DGS's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DensifyOptions {
    /// Densify after iteration `i` only if `i > from` ([`DEFAULT_DENSIFY_FROM`]).
    pub from: usize,
    /// Statistics are gathered, and densification and opacity resets happen, only before this
    /// iteration ([`DEFAULT_DENSIFY_UNTIL`]).
    pub until: usize,
    /// Densify every this many iterations ([`DEFAULT_DENSIFY_EVERY`]).
    pub every: usize,
    /// Mean NDC gradient norm at or above which a Gaussian densifies
    /// ([`DEFAULT_GRAD_THRESHOLD`]).
    pub grad_threshold: f64,
    /// Clone at or below `percent_dense × extent` (largest world scale at rest), split above
    /// ([`DEFAULT_PERCENT_DENSE`]).
    pub percent_dense: f64,
    /// Prune below this opacity ([`DEFAULT_PRUNE_OPACITY`]).
    pub prune_opacity: f64,
    /// Reset opacities every this many iterations (`None`: never;
    /// [`DEFAULT_OPACITY_RESET_EVERY`]).
    pub opacity_reset_every: Option<usize>,
    /// Also prune Gaussians whose largest world scale at rest is above this fraction of the
    /// extent, once the first opacity reset has happened (3DGS's `big_points_ws`,
    /// [`DEFAULT_MAX_WORLD_SIZE`]; `None`: never).
    pub max_world_size: Option<f64>,
}

impl Default for DensifyOptions {
    fn default() -> Self {
        Self {
            from: DEFAULT_DENSIFY_FROM,
            until: DEFAULT_DENSIFY_UNTIL,
            every: DEFAULT_DENSIFY_EVERY,
            grad_threshold: DEFAULT_GRAD_THRESHOLD,
            percent_dense: DEFAULT_PERCENT_DENSE,
            prune_opacity: DEFAULT_PRUNE_OPACITY,
            opacity_reset_every: Some(DEFAULT_OPACITY_RESET_EVERY),
            max_world_size: None,
        }
    }
}

impl DensifyOptions {
    /// Checks the values: `every ≥ 1`, `from < until`, a finite threshold and `percent_dense`
    /// above 0, `prune_opacity` in `0..1`, `opacity_reset_every ≥ 1`, `max_world_size > 0`.
    ///
    /// # Errors
    /// A message naming the option (as the command line spells it) and the value.
    pub fn check(&self) -> Result<(), String> {
        if self.every == 0 {
            return Err("--densify-every must be at least 1".into());
        }
        if self.from >= self.until {
            return Err(format!(
                "--densify-from {} must be below --densify-until {}",
                self.from, self.until
            ));
        }
        for (name, v) in [
            ("densify-grad", self.grad_threshold),
            ("percent-dense", self.percent_dense),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("--{name} {v}: expected a finite number > 0"));
            }
        }
        let o = self.prune_opacity;
        if !(o.is_finite() && (0.0..1.0).contains(&o)) {
            return Err(format!("--prune-opacity {o}: expected 0 <= value < 1"));
        }
        if self.opacity_reset_every == Some(0) {
            return Err("--opacity-reset-every must be at least 1".into());
        }
        if let Some(w) = self.max_world_size
            && !(w.is_finite() && w > 0.0)
        {
            return Err(format!(
                "--max-world-size {w}: expected a finite number > 0"
            ));
        }
        Ok(())
    }

    /// Whether the statistics are gathered at iteration `done` (1-based): `done < until`.
    #[must_use]
    pub fn gathers(&self, done: usize) -> bool {
        done < self.until
    }

    /// Whether to densify and prune after iteration `done` of `last`: `from < done < until`,
    /// `done` a multiple of `every`, and not after the last iteration.
    #[must_use]
    pub fn densifies_at(&self, done: usize, last: usize) -> bool {
        done > self.from && done < self.until && done.is_multiple_of(self.every) && done < last
    }

    /// Whether to reset the opacities after iteration `done` of `last`: a multiple of
    /// `opacity_reset_every`, below `until`, and not after the last iteration.
    #[must_use]
    pub fn resets_opacity_at(&self, done: usize, last: usize) -> bool {
        self.opacity_reset_every
            .is_some_and(|n| done.is_multiple_of(n) && done < self.until && done < last)
    }
}

/// 3DGS's camera extent (`getNerfppNorm`): 1.1 × the largest distance of a camera centre from
/// their mean (0 for fewer than two distinct centres).
#[must_use]
pub fn camera_extent(centres: &[DVec3]) -> f64 {
    if centres.is_empty() {
        return 0.0;
    }
    let mean = centres.iter().copied().sum::<DVec3>() / centres.len() as f64;
    1.1 * centres.iter().map(|c| c.distance(mean)).fold(0.0, f64::max)
}

/// Densification statistics per Gaussian (module docs): the summed NDC norm of the
/// screen-space mean gradient over the views where it was visible, and their count.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DensityStats {
    grad: Vec<f64>,
    views: Vec<u32>,
}

impl DensityStats {
    /// Zero statistics for `n` Gaussians.
    #[must_use]
    pub fn new(n: usize) -> Self {
        Self {
            grad: vec![0.0; n],
            views: vec![0; n],
        }
    }

    /// Number of Gaussians.
    #[must_use]
    pub fn len(&self) -> usize {
        self.views.len()
    }

    /// Whether there are none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.views.is_empty()
    }

    /// Zero statistics for `n` Gaussians, keeping the buffers.
    pub fn reset(&mut self, n: usize) {
        self.grad.clear();
        self.grad.resize(n, 0.0);
        self.views.clear();
        self.views.resize(n, 0);
    }

    /// Adds one view of `width × height` pixels: `means2d` (`d loss / d pixel` per Gaussian,
    /// [`crate::render::GaussianGrads::means2d`] of this view alone) for the Gaussians
    /// `visible` ([`crate::render::GradRender::visible_ids`]).
    ///
    /// # Panics
    /// When an index is past the count.
    pub fn add_view(&mut self, means2d: &[[f64; 2]], visible: &[u32], width: u32, height: u32) {
        let (hx, hy) = (0.5 * f64::from(width), 0.5 * f64::from(height));
        for &i in visible {
            let i = i as usize;
            let [gx, gy] = means2d[i];
            self.grad[i] += (gx * hx).hypot(gy * hy);
            self.views[i] += 1;
        }
    }

    /// The mean gradient norm of Gaussian `i` over the views it was visible in (0 if none).
    #[must_use]
    pub fn mean_grad(&self, i: usize) -> f64 {
        match self.views[i] {
            0 => 0.0,
            v => self.grad[i] / f64::from(v),
        }
    }

    /// Views each Gaussian was visible in.
    #[must_use]
    pub fn views(&self) -> &[u32] {
        &self.views
    }
}

/// What one [`densify_and_prune`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DensifyCounts {
    /// Gaussians cloned (one copy each).
    pub cloned: usize,
    /// Gaussians split (each replaced by its children).
    pub split: usize,
    /// Gaussians removed by pruning (after cloning and splitting).
    pub pruned: usize,
    /// Flagged Gaussians kept because they were their triangle's last.
    pub spared: usize,
    /// Gaussians after.
    pub count: usize,
}

/// The result of [`densify_and_prune`]: what it did and where each Gaussian came from.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DensifyStep {
    /// Counts.
    pub counts: DensifyCounts,
    /// For each Gaussian after the step, the Gaussian before it that it is, or is a clone or
    /// child of (to carry per-Gaussian data such as a source set's extras along).
    pub origins: Vec<usize>,
}

/// The largest world scale of Gaussian `i` with its triangle at the frames `rest`:
/// `max_j exp(log s'_j) k_f`.
#[must_use]
pub fn world_max_scale(bound: &BoundParams, rest: &TriangleFrames, i: usize) -> f64 {
    let s = bound.local.log_scales[i];
    s[0].max(s[1]).max(s[2]).exp() * rest.scale[bound.triangles[i] as usize]
}

/// The clone and split masks of `bound` (module docs): mean gradient `≥ grad_threshold`, and
/// world scale at rest `≤` (clone) or `>` (split) `percent_dense × extent`.
///
/// # Panics
/// When `stats` is for another count.
#[must_use]
pub fn select(
    bound: &BoundParams,
    stats: &DensityStats,
    rest: &TriangleFrames,
    extent: f64,
    options: &DensifyOptions,
) -> (Vec<bool>, Vec<bool>) {
    assert_eq!(
        stats.len(),
        bound.len(),
        "select: statistics for another count"
    );
    let limit = options.percent_dense * extent;
    (0..bound.len())
        .map(|i| {
            let hot = stats.mean_grad(i) >= options.grad_threshold;
            let small = world_max_scale(bound, rest, i) <= limit;
            (hot && small, hot && !small)
        })
        .unzip()
}

/// One densification step on a bound set and its Adam state (module docs): clone, split, then
/// prune by opacity (and by world size when `prune_large` and `options.max_world_size`), never
/// a triangle's last Gaussians. `seed` seeds the split's sampling (pass one per event).
///
/// # Errors
/// [`DensifyError`] from the shared operations (a binding past the frames).
///
/// # Panics
/// When `stats` or `adam` are for another count.
#[allow(clippy::too_many_arguments)]
pub fn densify_and_prune(
    bound: &mut BoundParams,
    adam: &mut Adam,
    stats: &DensityStats,
    rest: &TriangleFrames,
    extent: f64,
    options: &DensifyOptions,
    prune_large: bool,
    seed: u64,
) -> Result<DensifyStep, DensifyError> {
    assert_eq!(
        adam.len(),
        bound.len(),
        "densify: Adam state for another count"
    );
    let n0 = bound.len();
    let (clone_mask, split_mask) = select(bound, stats, rest, extent, options);
    // The structural steps run on an f32 copy (the shared operations); the parameters of
    // survivors and clones are then gathered from the f64 ones, the split children's means and
    // scales taken from the sampled copy.
    let set0 = to_set(bound);
    let cloned = clone_selected(&set0, &clone_mask, None)?;
    let mut mask1 = split_mask;
    mask1.resize(cloned.set.len(), false);
    let split = SplitOptions {
        children: DEFAULT_SPLIT_CHILDREN,
        shrink: DEFAULT_SPLIT_SHRINK,
        seed,
    };
    let splitted = split_selected(&cloned.set, &mask1, &split, None)?;
    let n_split = mask1.iter().filter(|&&m| m).count();
    let kept = cloned.set.len() - n_split;
    let origin2: Vec<usize> = splitted
        .sources
        .iter()
        .map(|&s| cloned.sources[s])
        .collect();
    // Prune flags on the split set (children inherit the parent's opacity).
    let limit = match (prune_large, options.max_world_size) {
        (true, Some(w)) => w * extent,
        _ => f64::INFINITY,
    };
    let p = &bound.local;
    let flags: Vec<bool> = (0..splitted.set.len())
        .map(|j| {
            let o = origin2[j];
            let opacity = 1.0 / (1.0 + (-p.opacity_logits[o]).exp());
            let ls = splitted.set.log_scales()[j];
            let t = bound.triangles[o] as usize;
            let size = f64::from(ls.max_element()).exp() * rest.scale[t];
            opacity < options.prune_opacity || size > limit
        })
        .collect();
    let pruned = prune(&splitted.set, &flags, None)?;
    let sources = &pruned.result.sources;

    let k = p.sh_per_gaussian();
    let n = sources.len();
    let mut out = GaussianParams {
        means: Vec::with_capacity(n),
        log_scales: Vec::with_capacity(n),
        rotations: Vec::with_capacity(n),
        opacity_logits: Vec::with_capacity(n),
        sh_degree: p.sh_degree,
        sh: Vec::with_capacity(n * k),
    };
    let mut triangles = Vec::with_capacity(n);
    let mut map = Vec::with_capacity(n);
    let mut origins = Vec::with_capacity(n);
    for &j in sources {
        let o = origin2[j];
        let child = j >= kept;
        let new = child || splitted.sources[j] >= n0;
        if child {
            out.means
                .push(splitted.set.means()[j].as_dvec3().to_array());
            out.log_scales
                .push(splitted.set.log_scales()[j].as_dvec3().to_array());
        } else {
            out.means.push(p.means[o]);
            out.log_scales.push(p.log_scales[o]);
        }
        out.rotations.push(p.rotations[o]);
        out.opacity_logits.push(p.opacity_logits[o]);
        out.sh.extend_from_slice(&p.sh[o * k..(o + 1) * k]);
        triangles.push(bound.triangles[o]);
        map.push((!new).then_some(o));
        origins.push(o);
    }
    debug_assert!(pruned.result.set.binding().is_some_and(|b| {
        b.triangles
            .iter()
            .zip(&triangles)
            .all(|(a, &t)| *a == TriId(t))
    }));
    let counts = DensifyCounts {
        cloned: cloned.sources.len() - n0,
        split: n_split,
        pruned: splitted.set.len() - n,
        spared: pruned.spared,
        count: n,
    };
    *bound = BoundParams {
        local: out,
        triangles,
    };
    adam.remap(&map);
    Ok(DensifyStep { counts, origins })
}

/// 3DGS's opacity reset: every opacity logit to `min(logit, logit(max_opacity))`
/// ([`RESET_OPACITY`]) and the opacity moments of `adam` zeroed.
pub fn reset_opacity(bound: &mut BoundParams, adam: &mut Adam, max_opacity: f64) {
    let cap = (max_opacity / (1.0 - max_opacity)).ln();
    for l in &mut bound.local.opacity_logits {
        *l = l.min(cap);
    }
    adam.zero_opacity_moments();
}
