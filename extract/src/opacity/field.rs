//! The opacity field (docs/conventions.md §6): the opacity of a point is the smallest, over the
//! views that see it, of the opacity accumulated along the view's ray from the camera up to the
//! point, each Gaussian contributing its density at the ray's point of highest density once
//! the point lies beyond it, and before that nothing ([`RayModel::Peak`]) or its density at the
//! point itself ([`RayModel::Gof`], GOF's definition). Evaluated one view at a
//! time over all points in parallel, so memory does not grow with the number of views.

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::gaussians::Prepared;
use super::order::z_order;
use super::view::{Hit, ViewBins};

/// How a Gaussian adds to the opacity accumulated along a ray up to a point (docs/conventions.md
/// §6). Either way it adds its density at the ray's point of highest density (the peak) once
/// the point lies beyond that peak.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RayModel {
    /// GOF's (the default): before the peak, the density at the point itself, so opacity ramps
    /// up through the front half of each Gaussian and the level set lies in front of the
    /// median depth (by ~1.2 σ for one opaque Gaussian).
    #[default]
    Gof,
    /// Nothing before the peak: the accumulated opacity steps up at each Gaussian's peak, so its
    /// level 1/2 is the depth where the renderer's transmittance halves (the median depth with
    /// ray-peak depths, §5). A single layer of Gaussians then has no inside (the smallest over
    /// views of a step is a step seen from the front), so thin or one-layer parts vanish.
    Peak,
}

/// Compositing rules (the renderer's, docs/conventions.md §5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlphaRules {
    /// A Gaussian whose alpha on the ray is below this adds nothing (1/255).
    pub min_alpha: f32,
    /// Alphas are clamped to at most this (gsplat's 0.999).
    pub max_alpha: f32,
    /// What a Gaussian adds before its peak.
    pub model: RayModel,
}

impl Default for AlphaRules {
    fn default() -> Self {
        Self {
            min_alpha: 1.0 / 255.0,
            max_alpha: 0.999,
            model: RayModel::default(),
        }
    }
}

/// How much of the field an evaluation needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Mode {
    /// The exact minimum over views.
    Exact,
    /// Only which side of `level` each point is on: values below `level` are exact, values at
    /// or above it are only known to be at or above it.
    Sign {
        /// The level.
        level: f64,
    },
}

/// The field at a set of points.
#[derive(Debug)]
pub(crate) struct Field {
    /// The opacity (1 where no view sees the point, as GOF).
    pub value: Vec<f64>,
    /// Whether any view sees the point.
    pub seen: Vec<bool>,
}

/// Accumulated opacity `1 - Π(1 - α_g)` along `view`'s ray up to `x` (which `hit` locates),
/// stopping once it reaches `stop`; with `COLOR`, also `Σ c_g α_g T_g` into `color`.
///
/// The tile's Gaussians come by their box's nearest depth, so once that exceeds the point's
/// depth no later Gaussian's reach box meets the segment from the camera to the point.
#[inline]
fn accumulate<const COLOR: bool>(
    p: &Prepared,
    view: &ViewBins,
    hit: Hit,
    x: DVec3,
    stop: f64,
    rules: AlphaRules,
    color: &mut [f64; 3],
) -> f64 {
    let d = x - view.origin;
    let z = hit.z;
    let (min_alpha, max_alpha) = (f64::from(rules.min_alpha), f64::from(rules.max_alpha));
    let mut transmittance = 1.0f64;
    for &k in view.tile(hit.tile) {
        let g = &view.packed[k as usize];
        if f64::from(g.zmin) > z {
            break;
        }
        let m = &g.whiten;
        let row = |r: usize| {
            f64::from(m[r][0]) * d.x + f64::from(m[r][1]) * d.y + f64::from(m[r][2]) * d.z
        };
        let v = DVec3::new(row(0), row(1), row(2));
        let u = DVec3::from_array(g.centre);
        let vv = v.length_squared();
        let peak = if vv > 0.0 { -u.dot(v) / vv } else { 0.0 };
        if peak > 1.0 && rules.model == RayModel::Peak {
            continue;
        }
        let t = peak.clamp(0.0, 1.0);
        let q = (u + v * t).length_squared();
        if q > f64::from(g.q_max) {
            continue;
        }
        let alpha = (f64::from(g.opacity) * (-0.5 * q).exp()).min(max_alpha);
        if alpha < min_alpha {
            continue;
        }
        if COLOR {
            let c = p.colors[g.index as usize];
            for k in 0..3 {
                color[k] += f64::from(c[k]) * alpha * transmittance;
            }
        }
        transmittance *= 1.0 - alpha;
        if 1.0 - transmittance >= stop {
            break;
        }
    }
    1.0 - transmittance
}

/// The field at `points`, views streamed one at a time. The points are walked in Z-order so
/// that neighbours share their tiles' Gaussians in cache; the result is in input order.
pub(crate) fn evaluate(
    p: &Prepared,
    cameras: &[Camera],
    points: &[DVec3],
    mode: Mode,
    rules: AlphaRules,
) -> Field {
    let order = z_order(points);
    let mut value = vec![1.0f64; points.len()];
    let mut seen = vec![false; points.len()];
    let mut view = ViewBins::default();
    for camera in cameras {
        view.prepare(p, camera);
        let view = &view;
        value
            .par_iter_mut()
            .zip(seen.par_iter_mut())
            .zip(order.par_iter())
            .with_min_len(512)
            .for_each(|((value, seen), &i)| {
                let x = points[i as usize];
                let stop = match mode {
                    Mode::Exact => *value,
                    Mode::Sign { level } if *value < level => return,
                    Mode::Sign { level } => level.min(*value),
                };
                let Some(hit) = view.locate(x) else { return };
                *seen = true;
                let acc = accumulate::<false>(p, view, hit, x, stop, rules, &mut [0.0; 3]);
                *value = value.min(acc);
            });
    }
    let mut field = Field {
        value: vec![1.0; points.len()],
        seen: vec![false; points.len()],
    };
    for (k, &i) in order.iter().enumerate() {
        field.value[i as usize] = value[k];
        field.seen[i as usize] = seen[k];
    }
    field
}

/// Colours at `points`: in the view where the point's accumulated opacity is smallest, the
/// colours composited up to it divided by that opacity (grey 0.5 where nothing is in front).
pub(crate) fn colors(
    p: &Prepared,
    cameras: &[Camera],
    points: &[DVec3],
    rules: AlphaRules,
) -> Vec<[f32; 3]> {
    let order = z_order(points);
    let mut best = vec![(f64::INFINITY, [0.5f32; 3]); points.len()];
    let mut view = ViewBins::default();
    for camera in cameras {
        view.prepare(p, camera);
        let view = &view;
        best.par_iter_mut()
            .zip(order.par_iter())
            .with_min_len(512)
            .for_each(|(best, &i)| {
                let x = points[i as usize];
                let Some(hit) = view.locate(x) else { return };
                let mut c = [0.0f64; 3];
                let acc = accumulate::<true>(p, view, hit, x, best.0, rules, &mut c);
                if acc < best.0 {
                    let rgb = if acc > 0.0 {
                        c.map(|v| (v / acc) as f32)
                    } else {
                        [0.5; 3]
                    };
                    *best = (acc, rgb);
                }
            });
    }
    let mut out = vec![[0.5f32; 3]; points.len()];
    for (k, &i) in order.iter().enumerate() {
        out[i as usize] = best[k].1;
    }
    out
}
