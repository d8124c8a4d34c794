//! The opacity field (GOF's definition, docs/conventions.md §6): the opacity of a point is the
//! smallest, over the views that see it, of the opacity accumulated along the view's ray from
//! the camera up to the point, each Gaussian contributing its density at the ray's point of
//! highest density, or at the point itself when that lies beyond it. Evaluated one view at a
//! time over all points in parallel, so memory does not grow with the number of views.

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::gaussians::Prepared;
use super::view::{Hit, ViewBins};

/// Compositing rules (the renderer's, docs/conventions.md §5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlphaRules {
    /// A Gaussian whose alpha on the ray is below this adds nothing (1/255).
    pub min_alpha: f32,
    /// Alphas are clamped to at most this (gsplat's 0.999).
    pub max_alpha: f32,
}

impl Default for AlphaRules {
    fn default() -> Self {
        Self {
            min_alpha: 1.0 / 255.0,
            max_alpha: 0.999,
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
        let t = if vv > 0.0 {
            (-u.dot(v) / vv).clamp(0.0, 1.0)
        } else {
            1.0
        };
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

/// The field at `points`, views streamed one at a time.
pub(crate) fn evaluate(
    p: &Prepared,
    cameras: &[Camera],
    points: &[DVec3],
    mode: Mode,
    rules: AlphaRules,
) -> Field {
    let mut value = vec![1.0f64; points.len()];
    let mut seen = vec![false; points.len()];
    let mut view = ViewBins::default();
    for camera in cameras {
        view.prepare(p, camera);
        let view = &view;
        value
            .par_iter_mut()
            .zip(seen.par_iter_mut())
            .zip(points.par_iter())
            .with_min_len(512)
            .for_each(|((value, seen), &x)| {
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
    Field { value, seen }
}

/// Colours at `points`: in the view where the point's accumulated opacity is smallest, the
/// colours composited up to it divided by that opacity (grey 0.5 where nothing is in front).
pub(crate) fn colors(
    p: &Prepared,
    cameras: &[Camera],
    points: &[DVec3],
    rules: AlphaRules,
) -> Vec<[f32; 3]> {
    let mut best = vec![(f64::INFINITY, [0.5f32; 3]); points.len()];
    let mut view = ViewBins::default();
    for camera in cameras {
        view.prepare(p, camera);
        let view = &view;
        best.par_iter_mut()
            .zip(points.par_iter())
            .with_min_len(512)
            .for_each(|(best, &x)| {
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
    best.into_iter().map(|(_, c)| c).collect()
}
