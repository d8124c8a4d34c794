//! The opacity field (docs/conventions.md §6): the opacity of a point is the smallest, over the
//! views that see it, of the opacity accumulated along the view's ray from the camera up to the
//! point, each Gaussian contributing its density at the ray's point of highest density once
//! the point lies beyond it, and before that nothing ([`RayModel::Peak`]) or its density at the
//! point itself ([`RayModel::Gof`], GOF's definition). Evaluated over [`Views`]: with every
//! view's bins held, each point walks the views starting from a hint (the view that last put a
//! neighbour or the edge's outer end outside), so an outside point usually needs one walk;
//! when the bins do not fit the budget, one view at a time over all points, so memory does not
//! grow with the number of views. Both give the same values.

use glam::DVec3;
use rayon::prelude::*;

use super::gaussians::Prepared;
use super::order::z_order;
use super::view::{Hit, ViewBins};
use super::views::Views;

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
    /// With [`RayModel::Gof`], the squared whitened distance of a point before the peak is
    /// that of the peak plus `sharpness` times its distance to the peak along the ray, squared
    /// (1: GOF's, the density at the point itself; larger: a steeper ramp, the level set
    /// closer to the Gaussians' centres).
    pub sharpness: f32,
}

impl Default for AlphaRules {
    fn default() -> Self {
        Self {
            min_alpha: 1.0 / 255.0,
            max_alpha: 0.999,
            model: RayModel::default(),
            sharpness: 1.0,
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
    /// In [`Mode::Sign`], the view that put the point below the level ([`NO_VIEW`] when none
    /// did or when not known): the hint for its neighbours.
    pub decider: Vec<u16>,
}

/// No view (a [`Field::decider`] or a hint).
pub(crate) const NO_VIEW: u16 = u16::MAX;

/// Points walked in sequence, in Z-order, sharing the last deciding view as their hint.
const CHUNK: usize = 256;

/// The `k`-th view to walk when starting from `first`: `first`, then the others in order.
#[inline]
fn nth_view(first: usize, k: usize) -> usize {
    if k == 0 {
        first
    } else if k <= first {
        k - 1
    } else {
        k
    }
}

/// Accumulated opacity `1 - Π(1 - α_g)` along `view`'s ray up to `x` (which `hit` locates),
/// stopping once it reaches `stop`; with `COLOR`, also `Σ c_g α_g T_g` into `color`.
///
/// The tile's Gaussians come by their box's nearest depth, so once that exceeds the point's
/// depth no later Gaussian's reach box meets the segment from the camera to the point.
#[inline]
pub(crate) fn accumulate<const COLOR: bool>(
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
        let mut q = (u + v * t).length_squared();
        if peak > 1.0 && rules.sharpness != 1.0 {
            q += (f64::from(rules.sharpness) - 1.0) * vv * (peak - 1.0) * (peak - 1.0);
        }
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

/// The field at `points` (walked in `order`, a Z-order of them). `hints[i]`, when given and
/// not [`NO_VIEW`], is the view point `i` walks first (held views only); otherwise the view
/// that last decided a point of the same chunk. The values, `seen` and the signs do not depend
/// on the hints or on the thread count; in [`Mode::Sign`] the value of an outside point is
/// some value below the level.
pub(crate) fn evaluate(
    p: &Prepared,
    views: &mut Views,
    points: &[DVec3],
    order: &[u32],
    hints: Option<&[u16]>,
    mode: Mode,
    rules: AlphaRules,
) -> Field {
    let n = points.len();
    let mut field = Field {
        value: vec![1.0; n],
        seen: vec![false; n],
        decider: vec![NO_VIEW; n],
    };
    if let Some(held) = views.held() {
        let out: Vec<(f64, bool, u16)> = order
            .par_chunks(CHUNK)
            .flat_map_iter(|chunk| {
                let mut last = 0usize;
                chunk.iter().map(move |&i| {
                    let i = i as usize;
                    let x = points[i];
                    let first = hints
                        .map(|h| h[i])
                        .filter(|&h| h != NO_VIEW)
                        .map_or(last, usize::from);
                    let (mut value, mut seen, mut decider) = (1.0f64, false, NO_VIEW);
                    for k in 0..held.len() {
                        let v = nth_view(first, k);
                        let view = &held[v];
                        let stop = match mode {
                            Mode::Exact => value,
                            Mode::Sign { level } => level.min(value),
                        };
                        let Some(hit) = view.locate(x) else { continue };
                        seen = true;
                        if view.is_certain(hit) {
                            continue;
                        }
                        let acc = accumulate::<false>(p, view, hit, x, stop, rules, &mut [0.0; 3]);
                        value = value.min(acc);
                        if let Mode::Sign { level } = mode
                            && value < level
                        {
                            decider = v as u16;
                            last = v;
                            break;
                        }
                    }
                    (value, seen, decider)
                })
            })
            .collect();
        for (&i, (value, seen, decider)) in order.iter().zip(out) {
            let i = i as usize;
            (field.value[i], field.seen[i], field.decider[i]) = (value, seen, decider);
        }
        return field;
    }
    let mut value = vec![1.0f64; n];
    let mut seen = vec![false; n];
    let mut decider = vec![NO_VIEW; n];
    for v in 0..views.len() {
        let view = views.stream(p, v);
        value
            .par_iter_mut()
            .zip(seen.par_iter_mut())
            .zip(decider.par_iter_mut())
            .zip(order.par_iter())
            .with_min_len(512)
            .for_each(|(((value, seen), decider), &i)| {
                let x = points[i as usize];
                let stop = match mode {
                    Mode::Exact => *value,
                    Mode::Sign { level } if *value < level => return,
                    Mode::Sign { level } => level.min(*value),
                };
                let Some(hit) = view.locate(x) else { return };
                *seen = true;
                if view.is_certain(hit) {
                    return;
                }
                let acc = accumulate::<false>(p, view, hit, x, stop, rules, &mut [0.0; 3]);
                *value = value.min(acc);
                if let Mode::Sign { level } = mode
                    && *value < level
                {
                    *decider = v as u16;
                }
            });
    }
    for (k, &i) in order.iter().enumerate() {
        let i = i as usize;
        (field.value[i], field.seen[i], field.decider[i]) = (value[k], seen[k], decider[k]);
    }
    field
}

/// Colours at `points`: in the view where the point's accumulated opacity is smallest, the
/// colours composited up to it divided by that opacity (grey 0.5 where nothing is in front).
/// With held views each point walks `hints[i]` first (its smallest opacity is then usually
/// known after one walk and bounds the others); a tie between views then goes to the hint
/// rather than to the first view in order.
pub(crate) fn colors(
    p: &Prepared,
    views: &mut Views,
    points: &[DVec3],
    hints: &[u16],
    rules: AlphaRules,
) -> Vec<[f32; 3]> {
    let order = z_order(points);
    let mut out = vec![[0.5f32; 3]; points.len()];
    // A view certain to be at or above the level cannot beat a smallest opacity below it.
    let level = views.certified_level().unwrap_or(f64::NEG_INFINITY);
    let walk = |view: &ViewBins, x: DVec3, best: &mut (f64, [f32; 3])| {
        let Some(hit) = view.locate(x) else { return };
        if best.0 < level && view.is_certain(hit) {
            return;
        }
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
    };
    if let Some(held) = views.held() {
        let best: Vec<[f32; 3]> = order
            .par_iter()
            .with_min_len(CHUNK)
            .map(|&i| {
                let i = i as usize;
                let first = match hints.get(i) {
                    Some(&h) if h != NO_VIEW => usize::from(h),
                    _ => 0,
                };
                let mut best = (f64::INFINITY, [0.5f32; 3]);
                for k in 0..held.len() {
                    walk(&held[nth_view(first, k)], points[i], &mut best);
                }
                best.1
            })
            .collect();
        for (&i, rgb) in order.iter().zip(best) {
            out[i as usize] = rgb;
        }
        return out;
    }
    let mut best = vec![(f64::INFINITY, [0.5f32; 3]); points.len()];
    for v in 0..views.len() {
        let view = views.stream(p, v);
        best.par_iter_mut()
            .zip(order.par_iter())
            .with_min_len(512)
            .for_each(|(best, &i)| walk(view, points[i as usize], best));
    }
    for (k, &i) in order.iter().enumerate() {
        out[i as usize] = best[k].1;
    }
    out
}
