//! The Delaunay tetrahedralisation of the opacity points carried from frame to frame
//! (issue #34 item 2): a bound avatar's points keep their ids, and between two frames almost
//! every tetrahedron stays Delaunay, so the last frame's tetrahedralisation is moved to the new
//! positions, checked, and repaired where it fails, instead of being rebuilt.
//!
//! - **Check**: every finite tetrahedron must stay positive (exact `orient3d`) and every face
//!   locally Delaunay: the vertex across it is not in conflict with the tetrahedron, with the
//!   predicates and the symbolic perturbation of the from-scratch build (`insphere_sos`,
//!   infinite tetrahedra by orientation, a point coplanar with a hull face as the tetrahedron
//!   behind it). A valid tetrahedralisation whose faces are all locally Delaunay is *the*
//!   Delaunay tetrahedralisation of the (perturbed) points, so when nothing fails it equals a
//!   rebuild.
//! - **Repair**: the points of the failing tetrahedra *hop*; the hole is the union of every
//!   tetrahedron around a hopping point (their stars). The hole's points (sorted by id, so the
//!   perturbation orders them as the global build does) are tetrahedralised from scratch, and
//!   the tetrahedra of that local Delaunay on the hole's side of its boundary faces replace the
//!   hole. This is accepted only when the local tetrahedralisation has every boundary face
//!   (with its orientation), uses every point of the hole, and every boundary face is locally
//!   Delaunay with the tetrahedron outside; then every face of the whole is locally Delaunay
//!   and the result is again the rebuild's. Otherwise (and when the hole is too large, points
//!   coincide, or the point set changed) the caller rebuilds from scratch.
//!
//! The finite tetrahedra come in slot order, not the rebuild's; the marching that follows does
//! not depend on the order of the tetrahedra or of their vertices (module `tets`), so the mesh
//! is the rebuild's bit for bit.

use std::collections::HashMap;

use rayon::prelude::*;

use crate::delaunay3d::{Delaunay3d, FACE_VERTICES, INF, insphere_sos, orient3d};

/// Marker of an unused tetrahedron slot.
const DEAD: u32 = u32::MAX - 1;

/// Largest share of the tetrahedra a repair may replace (beyond it, a rebuild is cheaper).
pub(crate) const MAX_HOLE_SHARE: f64 = 0.15;

/// Times a hole that does not fit is widened (by its face neighbours, then finally to the
/// stars of its points) before the caller rebuilds.
const HOLE_ROUNDS: usize = 3;

/// What [`CarriedTets::update`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Carried {
    /// Tetrahedra (finite and infinite) that failed the check.
    pub failed: usize,
    /// Points that hopped (vertices of failing finite or infinite tetrahedra).
    pub hopped: usize,
    /// Tetrahedra in the hole (replaced).
    pub replaced: usize,
    /// Times the hole was widened.
    pub rounds: usize,
}

/// Why a carried tetrahedralisation cannot be repaired (the caller rebuilds).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum NoRepair {
    /// The number of points changed.
    PointCount,
    /// Two points coincide (a rebuild skips one of them).
    Coincident,
    /// The hole is larger than [`MAX_HOLE_SHARE`] of the tetrahedra.
    TooLarge,
    /// The local tetrahedralisation does not fit the hole or is not Delaunay against its
    /// surroundings.
    NoFit,
}

/// A Delaunay tetrahedralisation kept between frames (all its points are vertices).
#[derive(Clone, Debug)]
pub(crate) struct CarriedTets {
    points: Vec<[f64; 3]>,
    /// Every tetrahedron slot, finite and infinite ([`INF`]), [`DEAD`] when unused.
    tets: Vec<[u32; 4]>,
    /// Neighbours: `[t][i]` across the face opposite vertex `i`.
    nbrs: Vec<[u32; 4]>,
    /// Unused slots.
    free: Vec<u32>,
}

impl CarriedTets {
    /// Keeps `d` for the next frames; `None` when it cannot be carried (fewer than 3
    /// dimensions, or duplicate points that are not vertices).
    pub fn new(d: &Delaunay3d) -> Option<Self> {
        if d.dimension() < 3 || !d.duplicates().is_empty() {
            return None;
        }
        let (tets, nbrs) = d.all_tetrahedra();
        Some(Self {
            points: d.points().to_vec(),
            tets: tets.to_vec(),
            nbrs: nbrs.to_vec(),
            free: Vec::new(),
        })
    }

    /// Number of live tetrahedra, finite and infinite.
    pub fn live_count(&self) -> usize {
        self.tets.len() - self.free.len()
    }

    /// The finite tetrahedra (in slot order; [`canonical`] for comparisons).
    pub fn finite(&self) -> Vec<[u32; 4]> {
        self.tets
            .iter()
            .copied()
            .filter(|t| is_finite(*t))
            .collect()
    }

    /// Moves the points to `points` (same ids) and makes the tetrahedralisation Delaunay
    /// again (see the module docs). On `Err` the state is unusable and the caller rebuilds.
    pub fn update(&mut self, points: Vec<[f64; 3]>) -> Result<Carried, NoRepair> {
        if points.len() != self.points.len() {
            return Err(NoRepair::PointCount);
        }
        if has_coincident(&points) {
            return Err(NoRepair::Coincident);
        }
        self.points = points;
        let failed = self.failing();
        let mut out = Carried {
            failed: failed.len(),
            ..Carried::default()
        };
        if failed.is_empty() {
            return Ok(out);
        }
        out.hopped = failed
            .iter()
            .flat_map(|&t| self.tets[t as usize])
            .filter(|&v| v != INF)
            .collect::<std::collections::HashSet<u32>>()
            .len();
        // The failing tetrahedra and their face neighbours first (a flip's worth), then the
        // stars of all their points, twice.
        let mut hole = self.widen(&failed);
        let live = self.tets.len() - self.free.len();
        for round in 0..=HOLE_ROUNDS {
            if hole.len() as f64 > MAX_HOLE_SHARE * live as f64 {
                return Err(NoRepair::TooLarge);
            }
            let mut in_hole = vec![false; self.tets.len()];
            for &t in &hole {
                in_hole[t as usize] = true;
            }
            let parts = self.components(&hole, &in_hole);
            let plans: Vec<Result<Plan, NoRepair>> = parts
                .par_iter()
                .map(|part| self.plan(part, &in_hole))
                .collect();
            let mut unfit: Vec<u32> = Vec::new();
            let mut error = NoRepair::NoFit;
            for (part, plan) in parts.iter().zip(plans) {
                match plan {
                    Ok(plan) => {
                        out.replaced += part.len();
                        self.splice(part, &plan);
                    }
                    Err(e) => {
                        error = e;
                        unfit.extend_from_slice(part);
                    }
                }
            }
            out.rounds = round;
            if unfit.is_empty() {
                return Ok(out);
            }
            if round == HOLE_ROUNDS {
                return Err(error);
            }
            // Spliced tetrahedra may sit in the stars of the unfit parts' points: the stars
            // are taken in the current tetrahedralisation.
            unfit.retain(|&t| self.tets[t as usize][0] != DEAD);
            hole = if round + 1 < HOLE_ROUNDS {
                self.widen(&unfit)
            } else {
                self.stars(&unfit)
            };
        }
        Err(NoRepair::NoFit)
    }

    /// The face-connected pieces of `hole` (each sorted), in order of their first tetrahedron.
    fn components(&self, hole: &[u32], in_hole: &[bool]) -> Vec<Vec<u32>> {
        let mut done = vec![false; self.tets.len()];
        let mut parts = Vec::new();
        let mut stack = Vec::new();
        for &start in hole {
            if done[start as usize] {
                continue;
            }
            done[start as usize] = true;
            stack.push(start);
            let mut part = Vec::new();
            while let Some(t) = stack.pop() {
                part.push(t);
                for u in self.nbrs[t as usize] {
                    if in_hole[u as usize] && !done[u as usize] {
                        done[u as usize] = true;
                        stack.push(u);
                    }
                }
            }
            part.sort_unstable();
            parts.push(part);
        }
        parts
    }

    #[inline]
    fn p(&self, v: u32) -> [f64; 3] {
        self.points[v as usize]
    }

    /// Whether point `e` conflicts with tetrahedron `tet`, as the from-scratch build decides
    /// it; `behind(k)` is the tetrahedron across the face opposite `tet[k]` (asked only for an
    /// infinite `tet` whose hull face `e` is coplanar with; `None`: unknown, a conflict).
    fn conflict(
        &self,
        tet: [u32; 4],
        behind: impl FnOnce(usize) -> Option<[u32; 4]>,
        e: u32,
    ) -> bool {
        let p = self.p(e);
        if let Some(k) = tet.iter().position(|&x| x == INF) {
            let q = |i: usize| if tet[i] == INF { p } else { self.p(tet[i]) };
            let o = orient3d(q(0), q(1), q(2), q(3));
            if o != 0.0 {
                return o > 0.0;
            }
            return match behind(k) {
                Some(b) => !b.contains(&INF) && self.finite_conflict(b, e),
                None => true,
            };
        }
        self.finite_conflict(tet, e)
    }

    /// [`Self::conflict`] for live tetrahedron `t`.
    fn conflict_of(&self, t: u32, e: u32) -> bool {
        let n = self.nbrs[t as usize];
        self.conflict(
            self.tets[t as usize],
            |k| self.tets.get(n[k] as usize).copied(),
            e,
        )
    }

    fn finite_conflict(&self, tet: [u32; 4], e: u32) -> bool {
        let ids = [tet[0], tet[1], tet[2], tet[3], e];
        insphere_sos(ids.map(|v| self.p(v)), ids) > 0
    }

    /// The vertex of tetrahedron `u` across its face shared with `t`.
    #[inline]
    fn across(&self, u: u32, t: u32) -> Option<(usize, u32)> {
        let j = self.nbrs[u as usize].iter().position(|&x| x == t)?;
        Some((j, self.tets[u as usize][j]))
    }

    /// Whether the face of live tetrahedron `t` opposite vertex `i` fails (its neighbour's
    /// far vertex conflicts with `t`). Faces between two finite tetrahedra are symmetric and
    /// checked from the lower id only.
    fn face_fails(&self, t: u32, i: usize, sphere: Option<&Sphere>) -> bool {
        let tet = self.tets[t as usize];
        let u = self.nbrs[t as usize][i];
        let Some(&other) = self.tets.get(u as usize) else {
            return true;
        };
        if is_finite(tet) && is_finite(other) && u < t {
            return false;
        }
        match self.across(u, t) {
            None => true,
            Some((_, e)) if e == INF => false,
            Some((_, e)) => match sphere.and_then(|s| s.inside(self.p(e))) {
                Some(inside) => inside,
                None => self.conflict_of(t, e),
            },
        }
    }

    /// Live tetrahedra that fail the check: not positive, or with a face that is not locally
    /// Delaunay (both sides listed), sorted.
    fn failing(&self) -> Vec<u32> {
        let mut bad: Vec<u32> = (0..self.tets.len() as u32)
            .into_par_iter()
            .with_min_len(4096)
            .flat_map_iter(|t| {
                let tet = self.tets[t as usize];
                let mut out = [u32::MAX; 5];
                if tet[0] != DEAD {
                    let mut sphere = None;
                    if is_finite(tet) {
                        let [a, b, c, d] = tet.map(|v| self.p(v));
                        if orient3d(a, b, c, d) <= 0.0 {
                            out[4] = t;
                        } else {
                            sphere = Some(Sphere::new(a, b, c, d));
                        }
                    }
                    for i in 0..4 {
                        if self.face_fails(t, i, sphere.as_ref()) {
                            out[4] = t;
                            out[i] = self.nbrs[t as usize][i];
                        }
                    }
                }
                out.into_iter().filter(|&x| x != u32::MAX)
            })
            .collect();
        bad.par_sort_unstable();
        bad.dedup();
        bad
    }

    /// `set` and the tetrahedra sharing a face with it (sorted).
    fn widen(&self, set: &[u32]) -> Vec<u32> {
        let mut out: Vec<u32> = set
            .iter()
            .flat_map(|&t| std::iter::once(t).chain(self.nbrs[t as usize]))
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Every tetrahedron with a finite vertex of one in `set` (sorted): the stars of their
    /// points.
    fn stars(&self, set: &[u32]) -> Vec<u32> {
        let mut points: Vec<(u32, u32)> = set
            .iter()
            .flat_map(|&t| {
                self.tets[t as usize]
                    .into_iter()
                    .filter(|&v| v != INF)
                    .map(move |v| (v, t))
            })
            .collect();
        points.sort_unstable();
        points.dedup_by_key(|x| x.0);
        let mut in_hole = vec![false; self.tets.len()];
        let mut seen: std::collections::HashSet<u32> = std::collections::HashSet::new();
        let mut hole = Vec::new();
        let mut stack = Vec::new();
        for &(v, start) in &points {
            // The star of v: the tetrahedra around it, face-connected through faces with v.
            seen.clear();
            stack.clear();
            stack.push(start);
            seen.insert(start);
            while let Some(t) = stack.pop() {
                if !in_hole[t as usize] {
                    in_hole[t as usize] = true;
                    hole.push(t);
                }
                let tet = self.tets[t as usize];
                for (w, u) in tet.into_iter().zip(self.nbrs[t as usize]) {
                    if w != v && (u as usize) < self.tets.len() && seen.insert(u) {
                        stack.push(u);
                    }
                }
            }
        }
        hole.sort_unstable();
        hole
    }

    /// The local Delaunay tetrahedralisation that replaces `hole` (one face-connected piece;
    /// `in_any_hole` marks every piece being replaced), when it fits (see the module docs);
    /// nothing is changed.
    fn plan(&self, hole: &[u32], in_any_hole: &[bool]) -> Result<Plan, NoRepair> {
        let in_hole = |t: u32| hole.binary_search(&t).is_ok();
        // The hole's points, by id (the local ids then perturb in the global order).
        let mut ids: Vec<u32> = hole
            .iter()
            .flat_map(|&t| self.tets[t as usize])
            .filter(|&v| v != INF)
            .collect();
        ids.sort_unstable();
        ids.dedup();
        let local = Delaunay3d::from_f64(ids.iter().map(|&v| self.p(v)).collect())
            .map_err(|_| NoRepair::NoFit)?;
        if local.dimension() < 3 || !local.duplicates().is_empty() {
            return Err(NoRepair::NoFit);
        }
        let (ltets, lnbrs) = local.all_tetrahedra();
        let global = |v: u32| if v == INF { INF } else { ids[v as usize] };
        let tets: Vec<[u32; 4]> = ltets.iter().map(|t| t.map(global)).collect();
        // Boundary faces of the hole, oriented away from it: key -> (outside tet, its face).
        let mut boundary: HashMap<[u32; 3], (u32, usize)> = HashMap::new();
        for &t in hole {
            let tet = self.tets[t as usize];
            for (i, f) in FACE_VERTICES.iter().enumerate() {
                let u = self.nbrs[t as usize][i];
                if in_hole(u) {
                    continue;
                }
                let (j, _) = self.across(u, t).ok_or(NoRepair::NoFit)?;
                boundary.insert(oriented(f.map(|k| tet[k])), (u, j));
            }
        }
        // The local tetrahedra on the hole's side: from the boundary faces inward.
        let mut stop = vec![0u8; tets.len()];
        let mut seeds = Vec::new();
        for (s, tet) in tets.iter().enumerate() {
            for (j, f) in FACE_VERTICES.iter().enumerate() {
                if let Some(&(u, ju)) = boundary.get(&oriented(f.map(|k| tet[k]))) {
                    stop[s] |= 1 << j;
                    seeds.push(Seed {
                        local: s as u32,
                        face: j,
                        outside: u,
                        outside_face: ju,
                    });
                }
            }
        }
        if seeds.len() != boundary.len() {
            return Err(NoRepair::NoFit);
        }
        let mut inside = vec![false; tets.len()];
        let mut fill: Vec<u32> = Vec::new();
        let mut stack: Vec<u32> = seeds.iter().map(|s| s.local).collect();
        while let Some(s) = stack.pop() {
            if std::mem::replace(&mut inside[s as usize], true) {
                continue;
            }
            fill.push(s);
            for (j, &n) in lnbrs[s as usize].iter().enumerate() {
                if stop[s as usize] >> j & 1 == 0 && !inside[n as usize] {
                    stack.push(n);
                }
            }
        }
        let mut used = vec![false; ids.len()];
        for &s in &fill {
            for v in ltets[s as usize] {
                if v != INF {
                    used[v as usize] = true;
                }
            }
        }
        if used.contains(&false) {
            return Err(NoRepair::NoFit);
        }
        // Every boundary face locally Delaunay, seen from both sides.
        let fits = seeds.iter().all(|seed| {
            let (s, j) = (seed.local as usize, seed.face);
            let (u, ju) = (seed.outside, seed.outside_face);
            let (new, old) = (tets[s], self.tets[u as usize]);
            let from_new = |k: usize| {
                if k == j {
                    Some(old)
                } else {
                    Some(tets[lnbrs[s][k] as usize])
                }
            };
            let from_old = |k: usize| {
                let b = self.nbrs[u as usize][k];
                if k == ju {
                    Some(new)
                } else if in_any_hole[b as usize] {
                    None
                } else {
                    Some(self.tets[b as usize])
                }
            };
            let (e_old, e_new) = (old[ju], new[j]);
            (e_old == INF || !self.conflict(new, from_new, e_old))
                && (e_new == INF || !self.conflict(old, from_old, e_new))
        });
        if !fits {
            return Err(NoRepair::NoFit);
        }
        Ok(Plan {
            tets,
            nbrs: lnbrs.to_vec(),
            fill,
            seeds,
        })
    }

    /// Replaces the tetrahedra of `hole` by `plan`'s.
    fn splice(&mut self, hole: &[u32], plan: &Plan) {
        let mut slots: Vec<u32> = hole.to_vec();
        for &t in hole {
            self.tets[t as usize] = [DEAD; 4];
        }
        while slots.len() < plan.fill.len() {
            match self.free.pop() {
                Some(t) => slots.push(t),
                None => {
                    self.tets.push([DEAD; 4]);
                    self.nbrs.push([DEAD; 4]);
                    slots.push((self.tets.len() - 1) as u32);
                }
            }
        }
        self.free.extend_from_slice(&slots[plan.fill.len()..]);
        slots.truncate(plan.fill.len());
        let mut slot_of = vec![u32::MAX; plan.tets.len()];
        for (&s, &slot) in plan.fill.iter().zip(&slots) {
            slot_of[s as usize] = slot;
        }
        for (&s, &slot) in plan.fill.iter().zip(&slots) {
            self.tets[slot as usize] = plan.tets[s as usize];
            self.nbrs[slot as usize] = plan.nbrs[s as usize].map(|n| slot_of[n as usize]);
        }
        for seed in &plan.seeds {
            let slot = slot_of[seed.local as usize];
            self.nbrs[slot as usize][seed.face] = seed.outside;
            self.nbrs[seed.outside as usize][seed.outside_face] = slot;
        }
    }
}

/// A boundary face of a hole: the local tetrahedron inside it and its face, the tetrahedron
/// outside and its face.
#[derive(Clone, Copy, Debug)]
struct Seed {
    local: u32,
    face: usize,
    outside: u32,
    outside_face: usize,
}

/// A hole's replacement: the local tetrahedralisation (global vertex ids, local neighbours),
/// the local tetrahedra that fill the hole, and its boundary faces.
#[derive(Debug)]
struct Plan {
    tets: Vec<[u32; 4]>,
    nbrs: Vec<[u32; 4]>,
    fill: Vec<u32>,
    seeds: Vec<Seed>,
}

/// A positive tetrahedron's circumsphere for a floating-point in-sphere filter: with
/// `B, C, D, E` the offsets of `b, c, d, e` from `a`, `e` lies inside iff
/// `|E|² O - E·W > 0`, `O = B·(C×D)` (negative for a positive tetrahedron in `orient3d`'s
/// convention), `W = |B|² C×D + |C|² D×B + |D|² B×C`.
struct Sphere {
    a: [f64; 3],
    o: f64,
    w: [f64; 3],
    /// The same with every product's absolute value (the rounding bound's scale).
    o_abs: f64,
    w_abs: [f64; 3],
}

/// Relative rounding bound of the filter: every term has at most ~12 rounded operations
/// (differences, products, sums), so `64 ε` times the sum of the terms' magnitudes bounds the
/// error with a wide margin.
const FILTER_EPS: f64 = 64.0 * f64::EPSILON;

impl Sphere {
    fn new(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Self {
        let sub = |p: [f64; 3]| [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
        let (b, c, d) = (sub(b), sub(c), sub(d));
        let cross = |x: [f64; 3], y: [f64; 3]| {
            [
                x[1] * y[2] - x[2] * y[1],
                x[2] * y[0] - x[0] * y[2],
                x[0] * y[1] - x[1] * y[0],
            ]
        };
        let cross_abs = |x: [f64; 3], y: [f64; 3]| {
            [
                (x[1] * y[2]).abs() + (x[2] * y[1]).abs(),
                (x[2] * y[0]).abs() + (x[0] * y[2]).abs(),
                (x[0] * y[1]).abs() + (x[1] * y[0]).abs(),
            ]
        };
        let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
        let abs = |x: [f64; 3]| x.map(f64::abs);
        let (cd, db, bc) = (cross(c, d), cross(d, b), cross(b, c));
        let (cd_a, db_a, bc_a) = (cross_abs(c, d), cross_abs(d, b), cross_abs(b, c));
        let (nb, nc, nd) = (dot(b, b), dot(c, c), dot(d, d));
        let w = std::array::from_fn(|k| nb * cd[k] + nc * db[k] + nd * bc[k]);
        let w_abs = std::array::from_fn(|k| nb * cd_a[k] + nc * db_a[k] + nd * bc_a[k]);
        Self {
            a,
            o: dot(b, cd),
            w,
            o_abs: dot(abs(b), cd_a),
            w_abs,
        }
    }

    /// Whether `e` lies strictly inside, when the floating-point sign is certain.
    #[inline]
    fn inside(&self, e: [f64; 3]) -> Option<bool> {
        let x = [e[0] - self.a[0], e[1] - self.a[1], e[2] - self.a[2]];
        let n = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
        let det = n * self.o - (x[0] * self.w[0] + x[1] * self.w[1] + x[2] * self.w[2]);
        let scale = n * self.o_abs
            + x[0].abs() * self.w_abs[0]
            + x[1].abs() * self.w_abs[1]
            + x[2].abs() * self.w_abs[2];
        let bound = FILTER_EPS * scale;
        if det > bound {
            Some(true)
        } else if det < -bound {
            Some(false)
        } else {
            None
        }
    }
}

/// Whether a tetrahedron has no vertex at infinity (and is live).
#[inline]
fn is_finite(t: [u32; 4]) -> bool {
    t[0] != DEAD && !t.contains(&INF)
}

/// An oriented triangle rotated so that its smallest vertex comes first.
#[inline]
fn oriented([a, b, c]: [u32; 3]) -> [u32; 3] {
    if a <= b && a <= c {
        [a, b, c]
    } else if b <= c {
        [b, c, a]
    } else {
        [c, a, b]
    }
}

/// `tets` with each one's vertices sorted, in sorted order (to compare tetrahedralisations).
#[cfg(test)]
pub(crate) fn canonical(tets: impl Iterator<Item = [u32; 4]>) -> Vec<[u32; 4]> {
    let mut out: Vec<[u32; 4]> = tets
        .map(|mut t| {
            t.sort_unstable();
            t
        })
        .collect();
    out.par_sort_unstable();
    out
}

/// Whether two points have the same coordinates (as the from-scratch build compares them).
fn has_coincident(points: &[[f64; 3]]) -> bool {
    let mut keys: Vec<[u64; 3]> = points
        .par_iter()
        .map(|p| p.map(|x| (x + 0.0).to_bits()))
        .collect();
    keys.par_sort_unstable();
    keys.windows(2).any(|w| w[0] == w[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points like the opacity method's: clustered centres, each with the 8 corners of a
    /// rotated box around it (exactly co-spherical before rounding).
    fn boxes(n: usize) -> Vec<[f64; 3]> {
        let h = |i: usize, k: u32| {
            ((i as f64 * 12.9898 + f64::from(k) * 78.233).sin() * 43758.5453)
                .fract()
                .abs()
        };
        let mut out = Vec::new();
        for i in 0..n {
            let c = [h(i, 0), h(i, 1), h(i, 2) * 0.5];
            let (a, s) = (h(i, 3) * 6.0, [0.02 + 0.05 * h(i, 4), 0.03, 0.01]);
            let (ca, sa) = (a.cos(), a.sin());
            out.push(c);
            for corner in 0..8 {
                let sign = |bit: u32| if corner >> bit & 1 == 0 { -1.0 } else { 1.0 };
                let l = [s[0] * sign(0), s[1] * sign(1), s[2] * sign(2)];
                out.push([
                    c[0] + ca * l[0] - sa * l[1],
                    c[1] + sa * l[0] + ca * l[1],
                    c[2] + l[2],
                ]);
            }
        }
        out
    }

    /// A smooth non-rigid motion: a twist about z growing with height and a bend.
    fn moved(points: &[[f64; 3]], t: f64) -> Vec<[f64; 3]> {
        points
            .iter()
            .map(|p| {
                let a = t * (0.3 + p[2]);
                let (c, s) = (a.cos(), a.sin());
                [
                    c * p[0] - s * p[1],
                    s * p[0] + c * p[1] + 0.2 * t * p[0] * p[0],
                    p[2] + 0.1 * t * (3.0 * p[0]).sin(),
                ]
            })
            .collect()
    }

    fn rebuilt(points: &[[f64; 3]]) -> Vec<[u32; 4]> {
        let d = Delaunay3d::from_f64(points.to_vec()).expect("delaunay");
        canonical(d.tetrahedra().iter().copied())
    }

    /// Over a track of small non-rigid steps the carried tetrahedralisation equals the
    /// from-scratch one at every frame, and most frames are repaired, not rebuilt.
    #[test]
    fn carried_equals_rebuilt_over_a_track() {
        let rest = boxes(250);
        let first = moved(&rest, 0.0);
        let mut carried =
            CarriedTets::new(&Delaunay3d::from_f64(first).expect("delaunay")).expect("carry");
        let (mut repaired, mut kept, mut refused) = (0, 0, 0);
        for frame in 1..=12 {
            let points = moved(&rest, 0.01 * f64::from(frame));
            match carried.update(points.clone()) {
                Ok(c) => {
                    if c.replaced > 0 {
                        repaired += 1;
                    } else {
                        kept += 1;
                    }
                    assert_eq!(
                        canonical(carried.finite().into_iter()),
                        rebuilt(&points),
                        "frame {frame}"
                    );
                }
                Err(_) => {
                    refused += 1;
                    carried = CarriedTets::new(&Delaunay3d::from_f64(points).expect("delaunay"))
                        .expect("carry");
                }
            }
        }
        assert!(
            repaired >= 8,
            "repaired {repaired}, kept {kept}, refused {refused}"
        );
    }

    /// The in-sphere filter agrees with the exact predicate wherever it decides, and decides
    /// almost everywhere away from co-spherical sets.
    #[test]
    fn sphere_filter_agrees_with_exact() {
        let points = boxes(60);
        let mut decided = 0;
        let mut total = 0;
        for (k, w) in points.windows(5).enumerate() {
            let mut tet = [w[0], w[1], w[2], w[3]];
            let o = orient3d(tet[0], tet[1], tet[2], tet[3]);
            if o == 0.0 {
                continue;
            }
            if o < 0.0 {
                tet.swap(0, 1);
            }
            let s = Sphere::new(tet[0], tet[1], tet[2], tet[3]);
            for e in [w[4], points[(k * 7 + 3) % points.len()]] {
                total += 1;
                let exact = insphere_sos([tet[0], tet[1], tet[2], tet[3], e], [0, 1, 2, 3, 4]);
                if let Some(inside) = s.inside(e) {
                    decided += 1;
                    assert_eq!(inside, exact > 0, "window {k}");
                }
            }
        }
        assert!(decided * 2 > total, "{decided} of {total}");
    }

    /// Without motion nothing fails; a changed point count and coincident points refuse.
    #[test]
    fn still_points_keep_and_bad_updates_refuse() {
        let points = boxes(40);
        let mut carried =
            CarriedTets::new(&Delaunay3d::from_f64(points.clone()).expect("d")).expect("carry");
        let c = carried.update(points.clone()).expect("same points");
        assert_eq!((c.failed, c.replaced), (0, 0));
        assert_eq!(canonical(carried.finite().into_iter()), rebuilt(&points));
        assert_eq!(
            carried.update(points[1..].to_vec()).unwrap_err(),
            NoRepair::PointCount
        );
        let mut twins = points.clone();
        twins[5] = twins[9];
        assert_eq!(carried.update(twins).unwrap_err(), NoRepair::Coincident);
    }
}
