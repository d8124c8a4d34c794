//! One incremental step: the hop search over every chart (motion certificates first, exact
//! checks where they do not settle), then the moves, the re-triangulation of the touched
//! charts and the new vertices.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::spatial::TriangleBvh;

use super::certify::{
    Bounds, CLOSE_GAP_REL, Certificate, Close, Fit, LocalFrame, MAX_CLOSE, REBASE_REL,
    SNAPSHOT_MARGIN_REL, Snapshot,
};
use super::error::DelaunayError;
use super::options::FILTER_MARGIN_REL;
use super::rebuild::flat_triangles;
use super::state::{ChartState, IncrementalDelaunay};
use super::stats::FrameStats;

/// Charts per task of the hop search (their means are loaded together).
const CHART_BATCH: usize = 64;

/// Shared inputs of the per-chart hop search of one frame.
struct SearchContext<'a> {
    bvh: &'a TriangleBvh,
    positions: &'a [DVec3],
    /// Flat triangles (see [`FLAT_RATIO`](super::FLAT_RATIO)); `None` when there are none.
    flat: Option<&'a [bool]>,
}

/// Per-thread buffers of the hop search.
#[derive(Default)]
struct Scratch {
    stack: Vec<u32>,
    found: Vec<u32>,
    /// Candidate triangles: id, padded box (min, max), squared box distance from the centroid.
    candidates: Vec<(u32, DVec3, DVec3, f64)>,
    /// Gaussians to check exactly: index in the chart, id, deformed mean, squared distance
    /// to the chart.
    pending: Vec<(usize, u32, DVec3, f64)>,
    /// Per BVH node, the token of the last frontier computation that marked it.
    marks: Vec<u32>,
    token: u32,
    frontier: Vec<u32>,
    /// The deformed means of a batch of charts' members.
    gathered: Vec<DVec3>,
    /// A snapshot's vertices while it is rebased.
    saved: Vec<DVec3>,
    /// A snapshot's vertices at their current positions (see `Snapshot::fit`).
    vertices: Vec<DVec3>,
    /// Per member while rebasing: its current bounds (own, listed competitors, others).
    current: Vec<(f64, [f64; MAX_CLOSE], f64)>,
    /// Members whose certificate did not settle them at once.
    unsettled: Vec<Unsettled>,
    /// Members checked against their exact own distance this frame: index in the chart,
    /// own distance, lower bounds of the listed competitors' and of every other distance.
    exact: Vec<(usize, f64, [f64; MAX_CLOSE], f64)>,
}

impl Scratch {
    /// A fresh token for `marks`, sized to `len` nodes.
    fn next_token(&mut self, len: usize) -> u32 {
        if self.marks.len() != len || self.token == u32::MAX {
            self.marks.clear();
            self.marks.resize(len, 0);
            self.token = 0;
        }
        self.token += 1;
        self.token
    }
}

thread_local! {
    /// Buffers of the hop search on this thread, kept between frames.
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
}

/// A chart member whose certificate did not settle it at once (see
/// [`IncrementalDelaunay::hops_of_chart`]).
#[derive(Clone, Copy, Debug)]
struct Unsettled {
    /// Index in the chart's member list.
    k: usize,
    /// Deformed mean.
    q: DVec3,
    /// Distance of `q` from the chart's centroid.
    from_centre: f64,
    /// The certificate's bounds now.
    bounds: Bounds,
}

/// The charts' part of a frame update, gathered per rayon task.
#[derive(Default)]
struct Outcome {
    /// (Gaussian, new chart).
    moves: Vec<(u32, u32)>,
    /// Gaussians checked exactly.
    checked: usize,
    /// Gaussians checked against their close competitors only.
    checked_close: usize,
    /// Charts that took a new snapshot.
    refreshed: usize,
}

impl Outcome {
    fn merge(mut self, mut other: Self) -> Self {
        self.moves.append(&mut other.moves);
        self.checked += other.checked;
        self.checked_close += other.checked_close;
        self.refreshed += other.refreshed;
        self
    }
}

impl IncrementalDelaunay {
    pub(super) fn step(
        &mut self,
        positions: &[DVec3],
        means: &[Vec3],
    ) -> Result<FrameStats, DelaunayError> {
        let Some(mut bvh) = self.bvh.take() else {
            return self.rebuild_now(positions, means);
        };
        bvh.refit(positions)?;
        self.flat = flat_triangles(&bvh);
        if !self.certified {
            self.states = self
                .members
                .iter()
                .map(|list| ChartState::empty(list.len()))
                .collect();
            self.certified = true;
        }
        let mut states = std::mem::take(&mut self.states);
        let context = SearchContext {
            bvh: &bvh,
            positions,
            flat: self.flat.contains(&true).then_some(self.flat.as_slice()),
        };
        let outcome = self
            .members
            .par_chunks(CHART_BATCH)
            .zip(states.par_chunks_mut(CHART_BATCH))
            .enumerate()
            .fold(Outcome::default, |mut acc, (batch, (lists, states))| {
                SCRATCH.with_borrow_mut(|scratch| {
                    // The batch's means in one pass: the ids mostly follow the charts, so
                    // this streams through memory instead of missing the cache per chart.
                    let mut gathered = std::mem::take(&mut scratch.gathered);
                    gathered.clear();
                    for list in lists {
                        gathered.extend(list.iter().map(|&g| means[g as usize].as_dvec3()));
                    }
                    let mut start = 0;
                    for (j, (list, state)) in lists.iter().zip(states).enumerate() {
                        let a = (batch * CHART_BATCH + j) as u32;
                        let chart_means = &gathered[start..start + list.len()];
                        start += list.len();
                        self.hops_of_chart(
                            &context,
                            a,
                            list,
                            chart_means,
                            state,
                            scratch,
                            &mut acc,
                        );
                    }
                    scratch.gathered = gathered;
                });
                acc
            })
            .reduce(Outcome::default, Outcome::merge);
        self.bvh = Some(bvh);
        self.states = states;
        let searches = outcome.checked;
        let mut moves = outcome.moves;
        moves.sort_unstable();
        // The charts the moves touch, with the member lists their meshes were made from.
        let mut dirty: Vec<u32> = moves
            .iter()
            .flat_map(|&(g, c)| [self.assigned.get(g as usize).copied().unwrap_or(c), c])
            .collect();
        dirty.sort_unstable();
        dirty.dedup();
        let before: Vec<Vec<u32>> = dirty
            .iter()
            .map(|&t| self.members.get(t as usize).cloned().unwrap_or_default())
            .collect();
        let hopped = moves.len();
        for (g, c) in moves {
            let i = g as usize;
            let a = self.assigned[i];
            if let Some(list) = self.members.get_mut(a as usize)
                && let Ok(k) = list.binary_search(&g)
            {
                list.remove(k);
                if let Some(state) = self.states.get_mut(a as usize) {
                    state.remove(k);
                }
            }
            if let Some(list) = self.members.get_mut(c as usize)
                && let Err(k) = list.binary_search(&g)
            {
                list.insert(k, g);
                if let Some(state) = self.states.get_mut(c as usize) {
                    state.insert_empty(k);
                }
            }
            self.assigned[i] = c;
            self.anchors[i] = self.anchor(i, c);
        }
        self.remesh(&dirty, before);
        self.since_rebuild += 1;
        self.lift(positions, means);
        Ok(FrameStats {
            rebuilt: false,
            hopped,
            charts_redone: dirty.len(),
            searches,
            ..FrameStats::default()
        })
    }

    /// Hop targets of the Gaussians of chart `a` at this frame, new certificates, and the
    /// chart's new snapshot. Exactly the answer of a full BVH search per Gaussian (the nearest
    /// triangle, ties to the smallest id, under the hop threshold), found cheaper: a Gaussian
    /// whose motion certificate still holds cannot have hopped (module `certify`); the others
    /// are checked exactly against the triangles of one range query per chart, which also
    /// proves that no triangle from outside the chart's snapshot came near. A chart without a
    /// snapshot, or with a newcomer in its neighbourhood, checks all its Gaussians and takes a
    /// new snapshot.
    #[expect(
        clippy::too_many_arguments,
        reason = "one chart's step of the hop search, all inputs named"
    )]
    fn hops_of_chart(
        &self,
        cx: &SearchContext<'_>,
        a: u32,
        list: &[u32],
        means: &[DVec3],
        state: &mut ChartState,
        scratch: &mut Scratch,
        out: &mut Outcome,
    ) {
        if list.is_empty() {
            return;
        }
        let bvh = cx.bvh;
        let hop = self.hop_distance;
        let v = bvh.corners(a as usize).unwrap_or([DVec3::ZERO; 3]);
        let centre = (v[0] + v[1] + v[2]) / 3.0;
        let size = v.iter().map(|p| (*p - centre).length()).fold(0.0, f64::max);
        let margin = SNAPSHOT_MARGIN_REL * size;
        let slack = FILTER_MARGIN_REL * (self.diagonal + centre.abs().max_element() + size);
        let usable = |snap: &Snapshot| match cx.flat {
            None => true,
            Some(flat) => snap.triangles.iter().all(|&t| !flat[t as usize]),
        };
        let (moves_before, checked_close_before) = (out.moves.len(), out.checked_close);
        if let Some(snap) = state.snapshot.as_mut()
            && state.certificates.len() == list.len()
            && usable(snap)
            && let Some(fit) = snap.fit(v, cx.positions, &mut scratch.vertices)
        {
            // First the bounds of every member; the few they do not settle afterwards.
            let mut reach = 0.0f64;
            scratch.unsettled.clear();
            for (k, (c, &q)) in state.certificates.iter().zip(means).enumerate() {
                let from_centre = (q - centre).length();
                let bounds = c.bounds(&fit, q);
                if bounds.lower - (bounds.own - hop) > own_slack(slack, q, from_centre, bounds.own)
                {
                    // Every other triangle is certainly farther.
                    reach = reach.max(from_centre + (bounds.own - hop).max(0.0));
                } else {
                    scratch.unsettled.push(Unsettled {
                        k,
                        q,
                        from_centre,
                        bounds,
                    });
                }
            }
            scratch.pending.clear();
            scratch.exact.clear();
            // Move the snapshot to this frame (below) when the neighbourhood has drifted from
            // it; the certificates are then issued afresh from the bounds found here.
            let drift = fit.residual + (fit.sigma_hi - fit.sigma_lo) * size;
            let rebase = drift > REBASE_REL * size;
            for u in &scratch.unsettled {
                let (k, q, from_centre) = (u.k, u.q, u.from_centre);
                let g = list[k];
                let (d2, _) = bvh.distance_sq(q, a);
                let r = d2.sqrt() - hop;
                if state.certificates[k].is_some() {
                    let competitors = &state.competitors[k];
                    let other = competitors.other_bound(&fit, u.bounds.error);
                    let own_slack = own_slack(slack, q, from_centre, u.bounds.own);
                    if other - r > own_slack {
                        // The unlisted triangles by the bound against the exact own distance;
                        // the listed competitors likewise when their bound suffices, else
                        // exactly. Triangles outside the snapshot are excluded by the test
                        // below, whatever the outcome.
                        reach = reach.max(from_centre + r.max(0.0));
                        let mut near = competitors.near_bounds(&fit, u.bounds.error);
                        let mut close = competitors.close;
                        let mut any = false;
                        for (t, n) in close.iter_mut().zip(&near) {
                            if n - r > own_slack {
                                *t = u32::MAX;
                            }
                            any |= *t != u32::MAX;
                        }
                        if any {
                            // Only the listed competitors whose own bound is inconclusive.
                            if let Some(t) = self.close_check(bvh, q, a, d2, &close, &mut near) {
                                out.moves.push((g, t));
                            }
                            out.checked_close += 1;
                        }
                        if rebase {
                            scratch.exact.push((k, d2.sqrt(), near, other));
                        }
                        continue;
                    }
                }
                reach = reach.max(from_centre + r.max(0.0));
                scratch.pending.push((k, g, q, d2));
            }
            let pending = !scratch.pending.is_empty();
            let radius = reach + slack + if pending { 0.5 * margin } else { 0.0 };
            let inside =
                !bvh.any_within(&snap.frontier, centre, radius * radius, &mut scratch.stack);
            if inside {
                let fit = if rebase {
                    Self::rebase(v, cx.positions, means, state, scratch, &fit).unwrap_or(fit)
                } else {
                    fit
                };
                if pending {
                    // The snapshot's triangles, nearest first when it was taken: close to the
                    // order a sort would give now, without sorting (see `exact_check`).
                    scratch.candidates.clear();
                    if let Some(snap) = &state.snapshot {
                        for &t in snap.triangles.iter().filter(|&&t| t != a) {
                            let (lo, hi) = bvh.leaf_box(t);
                            scratch.candidates.push((t, lo, hi, 0.0));
                        }
                    }
                    for &(k, g, q, d2) in &scratch.pending {
                        let from_centre = (q - centre).length();
                        let cap = radius - from_centre;
                        let lead = from_centre + slack;
                        let candidates = &scratch.candidates;
                        match self.exact_check(bvh, q, a, d2, candidates, cap, size, lead) {
                            Ok((near, far)) => {
                                (state.certificates[k], state.competitors[k]) =
                                    Certificate::issue(&fit, q, d2.sqrt(), near, far);
                            }
                            Err(t) => out.moves.push((g, t)),
                        }
                    }
                }
                out.checked += scratch.pending.len();
                return;
            }
        }
        // Check every Gaussian and take a new snapshot; forget what this chart found above.
        out.moves.truncate(moves_before);
        out.checked_close = checked_close_before;
        out.refreshed += 1;
        scratch.pending.clear();
        let mut reach = 0.0f64;
        for (k, (&g, &q)) in list.iter().zip(means).enumerate() {
            let (d2, _) = bvh.distance_sq(q, a);
            reach = reach.max((q - centre).length() + (d2.sqrt() - hop).max(0.0));
            scratch.pending.push((k, g, q, d2));
        }
        state.clear(list.len());
        let radius = reach + slack + margin;
        scratch.found.clear();
        bvh.triangles_within(
            centre,
            radius * radius,
            &mut scratch.found,
            &mut scratch.stack,
        );
        let no_flat = cx
            .flat
            .is_none_or(|flat| scratch.found.iter().all(|&t| !flat[t as usize]));
        self.gather_candidates(bvh, a, centre, scratch);
        let snap = match LocalFrame::of(v) {
            Some(frame) if no_flat => {
                // The chart, then the others nearest first (the order later checks use).
                let mut triangles = Vec::with_capacity(scratch.candidates.len() + 1);
                triangles.push(a);
                triangles.extend(scratch.candidates.iter().map(|c| c.0));
                let token = scratch.next_token(bvh.node_count());
                bvh.frontier(&triangles, &mut scratch.marks, token, &mut scratch.frontier);
                let frontier = scratch.frontier.clone();
                Snapshot::new(&frame, triangles, frontier, &self.triangles, cx.positions)
            }
            _ => None,
        };
        let fit = snap
            .as_ref()
            .and_then(|s| s.fit(v, cx.positions, &mut scratch.vertices));
        for &(k, g, q, d2) in &scratch.pending {
            let from_centre = (q - centre).length();
            let cap = radius - from_centre;
            let lead = from_centre + slack;
            match self.exact_check(bvh, q, a, d2, &scratch.candidates, cap, size, lead) {
                Ok((near, far)) => {
                    if let Some(fit) = &fit {
                        (state.certificates[k], state.competitors[k]) =
                            Certificate::issue(fit, q, d2.sqrt(), near, far);
                    }
                }
                Err(t) => out.moves.push((g, t)),
            }
        }
        out.checked += list.len();
        state.snapshot = if fit.is_some() { snap } else { None };
    }

    /// Moves a chart's snapshot to this frame (the chart triangle's corners are `v`, its
    /// members' means `means`; `fit` maps the old snapshot here) and issues every member's
    /// certificate afresh from its
    /// current bounds: the exact ones found this frame (`scratch.exact`), else its old
    /// certificate's. Returns the new fit, or `None` (and nothing changed) when the chart
    /// triangle is flat or the new fit fails.
    fn rebase(
        v: [DVec3; 3],
        positions: &[DVec3],
        means: &[DVec3],
        state: &mut ChartState,
        scratch: &mut Scratch,
        fit: &Fit,
    ) -> Option<Fit> {
        let frame = LocalFrame::of(v)?;
        // Current bounds of every member, under the old fit.
        scratch.current.clear();
        let mut exact = scratch.exact.iter().peekable();
        for (k, (&q, (c, competitors))) in means
            .iter()
            .zip(state.certificates.iter().zip(&state.competitors))
            .enumerate()
        {
            let bounds = match exact.next_if(|e| e.0 == k) {
                Some(&(_, own, near, other)) => (own, near, other),
                None => {
                    let b = c.bounds(fit, q);
                    (
                        b.own,
                        competitors.near_bounds(fit, b.error),
                        competitors.other_bound(fit, b.error),
                    )
                }
            };
            scratch.current.push(bounds);
        }
        let snap = state.snapshot.as_mut()?;
        let new_fit = snap.rebase(
            &frame,
            v,
            positions,
            &mut scratch.saved,
            &mut scratch.vertices,
        )?;
        for (k, (&q, &(own, near, other))) in means.iter().zip(&scratch.current).enumerate() {
            let close = (near, state.competitors[k].close);
            (state.certificates[k], state.competitors[k]) =
                Certificate::issue(&new_fit, q, own, close, other);
        }
        Some(new_fit)
    }

    /// Fills `scratch.candidates` with the triangles of `scratch.found` other than `a`, with
    /// their padded boxes, nearest box to `centre` first.
    fn gather_candidates(&self, bvh: &TriangleBvh, a: u32, centre: DVec3, scratch: &mut Scratch) {
        scratch.candidates.clear();
        for &t in &scratch.found {
            if t != a {
                let (lo, hi) = bvh.leaf_box(t);
                let gap = (lo - centre).max(centre - hi).max(DVec3::ZERO);
                scratch.candidates.push((t, lo, hi, gap.length_squared()));
            }
        }
        scratch
            .candidates
            .sort_unstable_by(|x, y| x.3.total_cmp(&y.3).then(x.0.cmp(&y.0)));
    }

    /// Exact hop check of a Gaussian at `q` in chart `a` (own squared distance `d2`) against
    /// `candidates`, which hold every triangle nearer than `cap`: `Err(target)` when it hops
    /// (the nearest triangle, ties to the smallest id, under the hop threshold), else
    /// `Ok(((near, close), other))`: up to [`certify::MAX_CLOSE`](super::certify::MAX_CLOSE) triangles `close` nearer
    /// than the own distance plus [`certify::CLOSE_GAP_REL`] times `size`, `near` their
    /// distances (`+∞` in empty slots), and `other ≤ d_U` for every other triangle `U ≠ a`
    /// (and `≤ cap`). Candidates sorted by their boxes' squared distances `gap2` from a point
    /// at most `lead` (plus rounding slack) from `q` end the search early: once a box is
    /// farther from that point than `lead` plus everything still needed, so are the rest.
    /// Candidates in any other order carry `gap2 = 0` and are each tested by their box.
    #[expect(
        clippy::too_many_arguments,
        reason = "one search step, all inputs named"
    )]
    fn exact_check(
        &self,
        bvh: &TriangleBvh,
        q: DVec3,
        a: u32,
        d2: f64,
        candidates: &[(u32, DVec3, DVec3, f64)],
        cap: f64,
        size: f64,
        lead: f64,
    ) -> Result<(Close, f64), u32> {
        let hop = self.hop_distance;
        let d = d2.sqrt();
        let r = d - hop;
        let can_hop = hop == 0.0 || r > 0.0;
        let near = d + CLOSE_GAP_REL * size;
        // Strictly nearer than r: with a hop threshold, (d², t) < (r², 0) means d² < r².
        let mut best = if hop > 0.0 { (r * r, 0u32) } else { (d2, a) };
        let mut found = false;
        let mut far = cap;
        // Close competitors by distance, ascending.
        let mut close = [(f64::INFINITY, u32::MAX); MAX_CLOSE];
        let mut count = 0;
        for &(t, lo, hi, gap2) in candidates {
            // Candidates come nearest box first: past this one, every remaining box is at
            // least `√gap2 - lead` from `q`, and each bound below only shrinks.
            let keep = if count == MAX_CLOSE {
                close[MAX_CLOSE - 1].0
            } else {
                near
            };
            let needed = far.max(keep).max(if can_hop { best.0.sqrt() } else { 0.0 });
            let reach = lead + needed;
            if gap2 > reach * reach {
                break;
            }
            let lower = (lo - q)
                .max(q - hi)
                .max(DVec3::ZERO)
                .length_squared()
                .sqrt();
            if (!can_hop || lower * lower > best.0) && lower >= far && lower >= keep {
                continue;
            }
            let (du2, _) = bvh.distance_sq(q, t);
            if can_hop && (du2, t) < best {
                best = (du2, t);
                found = true;
            }
            let du = du2.sqrt();
            if du < near {
                // Insert in order; the largest falls out to the far bound.
                let mut item = (du, t);
                for slot in &mut close {
                    if item.0 < slot.0 {
                        std::mem::swap(slot, &mut item);
                    }
                }
                if item.1 == u32::MAX {
                    count += 1;
                } else {
                    far = far.min(item.0);
                }
            } else {
                far = far.min(du);
            }
        }
        if found {
            Err(best.1)
        } else {
            Ok(((close.map(|c| c.0), close.map(|c| c.1)), far))
        }
    }

    /// Exact comparison of a Gaussian's own triangle `a` (squared distance `d2`) with its
    /// listed competitors (`u32::MAX`: an empty or skipped slot): the hop target when one of
    /// them wins (as [`Self::exact_check`]).
    fn close_check(
        &self,
        bvh: &TriangleBvh,
        q: DVec3,
        a: u32,
        d2: f64,
        close: &[u32; MAX_CLOSE],
        near: &mut [f64; MAX_CLOSE],
    ) -> Option<u32> {
        let hop = self.hop_distance;
        let r = d2.sqrt() - hop;
        if hop > 0.0 && r <= 0.0 {
            return None;
        }
        let mut best = if hop > 0.0 { (r * r, 0u32) } else { (d2, a) };
        let mut found = false;
        for (&t, n) in close.iter().zip(near.iter_mut()) {
            if t == u32::MAX {
                continue;
            }
            let (du2, _) = bvh.distance_sq(q, t);
            *n = du2.sqrt();
            if (du2, t) < best {
                best = (du2, t);
                found = true;
            }
        }
        found.then_some(best.1)
    }
}

/// The margin by which a Gaussian at `q` (at `from_centre` from its chart's centroid, own
/// distance at most `own`) must be nearer its own triangle than any other to count as
/// certainly nearer: `slack` (the chart's) plus [`FILTER_MARGIN_REL`] of the magnitudes
/// involved, far above the rounding of the computed distances.
fn own_slack(slack: f64, q: DVec3, from_centre: f64, own: f64) -> f64 {
    slack + FILTER_MARGIN_REL * (q.abs().max_element() + from_centre + own)
}
