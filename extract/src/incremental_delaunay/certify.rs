//! Motion-bounded certificates for hop detection (Verlet-list style).
//!
//! At hop threshold `τ = 0` the assignment of a Gaussian changes only when another deformed
//! triangle becomes nearer than its own, and proving that it did not for ~100k Gaussians every
//! frame is what an update spends its time on. A certificate makes that proof almost free for
//! most Gaussians.
//!
//! # The bound
//! Distances are invariant under rigid motions, and a point-triangle distance changes by at
//! most `|Δq|` when the point moves by `Δq` and by at most `δ` when every corner moves by at
//! most `δ` (the moved triangle contains the moved closest point, and vice versa). Each chart
//! `T` carries a *rigid local frame* `A_f` built from its deformed corners at frame `f`
//! (origin at corner 0, axes by Gram-Schmidt, so `A_f` is an isometry however the triangle is
//! shaped) and, from its last *snapshot* at frame `f0`, the set `N` of triangles that were near
//! it and the local coordinates `s(v) = A_{f0} v(f0)` of their vertices. At frame `f`,
//! `δ(f) = max_{v ∈ N} |A_f v(f) − s(v)|` bounds how much the neighbourhood moved relative to
//! the chart; for a rigidly moving neighbourhood it is 0 however far it travelled.
//!
//! After an exact check of Gaussian `i` at frame `f_i` (own distance `d_T`, threshold
//! `r = d_T − hop`), its certificate keeps the local position `l_i = A_{f_i} q_i(f_i)`, `d_T`,
//! `e_i = δ(f_i)` and a lower bound `g_i` of `min_{U ≠ T} d_U(f_i) − r`. For `U ∈ N`, with
//! `|A_f v(f) − A_{f_i} v(f_i)| ≤ δ(f) + e_i` by the triangle inequality through `s(v)`,
//! `d_U(f) − r(f) ≥ g_i − 2 |A_f q_i(f) − l_i| − 2 (δ(f) + e_i)`; when that exceeds the
//! slack, no triangle of `N` can take the Gaussian. Triangles outside `N` are excluded by one
//! BVH range query per chart and frame with radius `max_i |q_i − c| + d_T⁺_i` (centroid `c`,
//! `d_T⁺` the certified upper bound of the own distance): every triangle it returns must be in
//! `N`, or the chart takes a new snapshot. Gaussians whose certificate does not hold get the
//! exact search, which renews their certificate.
//!
//! The drift of a neighbourhood from its snapshot only grows while the template keeps moving
//! one way, and every bound pays it every frame. Once it exceeds [`REBASE_REL`] of the chart
//! size, the chart *rebases*: the snapshot keeps its triangles and frontier, its coordinates
//! are taken afresh at the current frame, and every member's certificate is issued again from
//! the bounds it has now (exact where this frame computed them). The drift is then paid once.
//!
//! A certificate is kept in two parts: the position and the two numbers the test of every
//! frame needs (own distance, and the lowest of all competitors' bounds), 20 bytes, and the
//! competitors' bounds and ids, read only for the Gaussians that test does not settle.
//!
//! The slack ([`FILTER_MARGIN_REL`](super::FILTER_MARGIN_REL) of the template diagonal plus the
//! coordinate magnitude) is far above the rounding of the computed distances, so a certified
//! Gaussian's own triangle is strictly nearest in the computed distances too: the result is
//! exactly the exact search's, ties included (a tie has gap 0 and is never certified). The
//! computed distance to a nearly flat triangle is that of its edges (see
//! `closest_point_on_triangle`), which is not continuous in the corners, so a chart whose
//! neighbourhood holds a triangle flatter than [`FLAT_RATIO`] is always checked exactly.

use glam::{DMat3, DVec3};

/// A triangle counts as flat for certificates when its squared doubled area is at most this
/// fraction of its longest edge to the fourth (flatter than 1e-4 relative): there the computed
/// distance may switch to the edges-only treatment of degenerate triangles (at 1e-14), so the
/// motion bound is not used near it.
pub const FLAT_RATIO: f64 = 1e-8;

/// A chart takes a new snapshot of its neighbourhood with a query this much wider (relative to
/// the chart's circumradius about its centroid) than its Gaussians need, so that triangles
/// moving a little do not leave the snapshot at once.
pub const SNAPSHOT_MARGIN_REL: f64 = 0.1;

/// A chart moves its snapshot to the current frame (keeping its triangles, re-issuing every
/// certificate from its current bounds) once its neighbourhood has drifted from the snapshot
/// by more than this fraction of the chart's circumradius: fit residual plus the spread of
/// the fit's singular values times the circumradius. Bounds lose that drift once, instead of
/// carrying the growing drift of an old snapshot every frame (measured best between 0.04 and
/// 0.08 on the `delaunay` benchmark; 0.01 and 0.02 re-issue too often).
pub const REBASE_REL: f64 = 0.05;

/// Whether the triangle `v` is flat in the sense of [`FLAT_RATIO`] (or not finite).
pub(crate) fn is_flat(v: [DVec3; 3]) -> bool {
    let longest = (v[1] - v[0])
        .length_squared()
        .max((v[2] - v[0]).length_squared())
        .max((v[2] - v[1]).length_squared());
    let n2 = (v[1] - v[0]).cross(v[2] - v[0]).length_squared();
    // NaN (non-finite corners) counts as flat.
    n2.partial_cmp(&(FLAT_RATIO * longest * longest)) != Some(std::cmp::Ordering::Greater)
}

/// An isometry of space built from a triangle: origin at its corner 0, first axis along edge
/// 0-1, second in the plane of the triangle, third along the normal.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LocalFrame {
    origin: DVec3,
    axes: [DVec3; 3],
}

impl LocalFrame {
    /// The frame of triangle `v`, or `None` for a triangle flat in the sense of
    /// [`FLAT_RATIO`] (the axes would be ill-defined; any isometry would do for correctness,
    /// but such charts are checked exactly anyway).
    pub(crate) fn of(v: [DVec3; 3]) -> Option<Self> {
        if is_flat(v) {
            return None;
        }
        let x = (v[1] - v[0]).try_normalize()?;
        let e2 = v[2] - v[0];
        // Two Gram-Schmidt passes: orthogonal to rounding whatever the angle.
        let y = e2 - x * x.dot(e2);
        let y = y.try_normalize()?;
        let y = (y - x * x.dot(y)).try_normalize()?;
        let z = x.cross(y);
        Some(Self {
            origin: v[0],
            axes: [x, y, z],
        })
    }

    /// Local coordinates of `p`.
    pub(crate) fn apply(&self, p: DVec3) -> DVec3 {
        let d = p - self.origin;
        DVec3::new(
            self.axes[0].dot(d),
            self.axes[1].dot(d),
            self.axes[2].dot(d),
        )
    }
}

/// A chart's neighbourhood at its last snapshot (frame `f0`), in the chart's rigid local
/// frame then, moved so that its vertices' mean is the origin.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Snapshot {
    /// Triangles that were near the chart: the chart, then the others by their boxes'
    /// distances from its centroid then, nearest first.
    pub(crate) triangles: Vec<u32>,
    /// BVH nodes whose subtrees hold every other triangle (see `TriangleBvh::frontier`).
    pub(crate) frontier: Vec<u32>,
    /// Their template vertices, each once.
    ids: Vec<u32>,
    /// The vertices' snapshot coordinates: local coordinates less their mean.
    coords: Vec<DVec3>,
    /// Inverse of the regularised Gram matrix `Σ s sᵀ + w ẑ ẑᵀ` of `coords` (see
    /// [`Snapshot::fit`]).
    gram_inverse: DMat3,
    /// The regularisation weight `w`.
    weight: f64,
}

/// An affine map from snapshot coordinates to the current frame (the least-squares fit of the
/// neighbourhood's motion), with bounds of its singular values and of how far the
/// neighbourhood's vertices are from following it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fit {
    linear: DMat3,
    inverse: DMat3,
    translation: DVec3,
    /// Lower bound of the smallest singular value of `linear` (`> 0`).
    pub(crate) sigma_lo: f64,
    /// Upper bound of the largest singular value of `linear`.
    pub(crate) sigma_hi: f64,
    /// Largest distance of a snapshot vertex's current position from its mapped snapshot
    /// position.
    pub(crate) residual: f64,
}

impl Snapshot {
    /// The snapshot of `triangles` (the chart first) whose corners are `corners` (template
    /// vertex ids) at positions `positions`, in `frame` (built from the chart triangle).
    /// `None` when a vertex is missing or the vertices' Gram matrix is singular.
    pub(crate) fn new(
        frame: &LocalFrame,
        triangles: Vec<u32>,
        frontier: Vec<u32>,
        corners: &[[u32; 3]],
        positions: &[glam::DVec3],
    ) -> Option<Self> {
        let mut ids: Vec<u32> = triangles
            .iter()
            .filter_map(|&t| corners.get(t as usize))
            .flatten()
            .copied()
            .collect();
        ids.sort_unstable();
        ids.dedup();
        let mut snapshot = Self {
            triangles,
            frontier,
            coords: Vec::with_capacity(ids.len()),
            ids,
            gram_inverse: DMat3::ZERO,
            weight: 0.0,
        };
        snapshot
            .take_coordinates(frame, positions)
            .then_some(snapshot)
    }

    /// Sets `coords` to the vertices' current positions in `frame`, centred, and the
    /// matching Gram matrix; `false` when it is singular (or a vertex is missing).
    fn take_coordinates(&mut self, frame: &LocalFrame, positions: &[glam::DVec3]) -> bool {
        self.coords.clear();
        for &k in &self.ids {
            match positions.get(k as usize) {
                Some(&p) => self.coords.push(frame.apply(p)),
                None => return false,
            }
        }
        if self.coords.is_empty() {
            return false;
        }
        let mean = self.coords.iter().sum::<DVec3>() / self.coords.len() as f64;
        let mut gram = DMat3::ZERO;
        for s in &mut self.coords {
            *s -= mean;
            gram += DMat3::from_cols(*s * s.x, *s * s.y, *s * s.z);
        }
        // The normal of the chart is the local z axis; a flat neighbourhood says nothing about
        // how it maps, so it is tied to the chart's current unit normal with this weight.
        let weight = (gram.x_axis.x + gram.y_axis.y + gram.z_axis.z).max(f64::MIN_POSITIVE);
        gram.z_axis.z += weight;
        let gram_inverse = gram.inverse();
        (self.gram_inverse, self.weight) = (gram_inverse, weight);
        gram_inverse.is_finite()
    }

    /// Moves the snapshot to the current frame and returns its fit there: the same triangles
    /// and frontier, their vertices' coordinates taken afresh in `frame` (built from the
    /// chart's current corners `v`). Certificates issued under the old snapshot are void
    /// afterwards; the caller issues new ones from its current bounds. `None`, with the
    /// snapshot unchanged, when the new Gram matrix is singular or the new fit fails. `saved`
    /// and `current` are scratch space.
    pub(crate) fn rebase(
        &mut self,
        frame: &LocalFrame,
        v: [DVec3; 3],
        positions: &[glam::DVec3],
        saved: &mut Vec<DVec3>,
        current: &mut Vec<DVec3>,
    ) -> Option<Fit> {
        saved.clear();
        saved.extend_from_slice(&self.coords);
        let before = (self.gram_inverse, self.weight);
        let fit = if self.take_coordinates(frame, positions) {
            self.fit(v, positions, current)
        } else {
            None
        };
        if fit.is_none() {
            std::mem::swap(&mut self.coords, saved);
            (self.gram_inverse, self.weight) = before;
        }
        fit
    }

    /// The fit for the chart's current corners `v`; `None` when the triangle is flat or the
    /// map is (nearly) singular. `current` is scratch space (the vertices' positions, loaded
    /// once for both passes).
    pub(crate) fn fit(
        &self,
        v: [DVec3; 3],
        positions: &[glam::DVec3],
        current: &mut Vec<DVec3>,
    ) -> Option<Fit> {
        let normal = (v[1] - v[0]).cross(v[2] - v[0]).try_normalize()?;
        let mut cross = DMat3::from_cols(DVec3::ZERO, DVec3::ZERO, normal * self.weight);
        let mut sum = DVec3::ZERO;
        current.clear();
        for (&k, &s) in self.ids.iter().zip(&self.coords) {
            let p = *positions.get(k as usize)?;
            cross += DMat3::from_cols(p * s.x, p * s.y, p * s.z);
            sum += p;
            current.push(p);
        }
        let linear = cross * self.gram_inverse;
        // The coordinates are centred, so the fit maps their origin to the positions' mean.
        let translation = sum / self.coords.len().max(1) as f64;
        // Gershgorin bounds of the eigenvalues of LᵀL.
        let c = [linear.x_axis, linear.y_axis, linear.z_axis];
        let mut lo = f64::INFINITY;
        let mut hi = 0.0f64;
        for i in 0..3 {
            let diag = c[i].length_squared();
            let off: f64 = (0..3)
                .filter(|&j| j != i)
                .map(|j| c[i].dot(c[j]).abs())
                .sum();
            lo = lo.min(diag - off);
            hi = hi.max(diag + off);
        }
        // Only nearly rigid maps are used (a map shrinking by half is far past any motion
        // a certificate survives).
        if !(lo > 0.25 && hi.is_finite()) {
            return None;
        }
        let inverse = linear.inverse();
        if !inverse.is_finite() {
            return None;
        }
        let mut worst = 0.0f64;
        for (&p, &s) in current.iter().zip(&self.coords) {
            worst = worst.max((p - (linear * s + translation)).length_squared());
        }
        Some(Fit {
            linear,
            inverse,
            translation,
            sigma_lo: lo.sqrt(),
            sigma_hi: hi.sqrt(),
            residual: worst.sqrt(),
        })
    }
}

impl Fit {
    /// Snapshot coordinates of a current point (approximately; bounds use
    /// [`Fit::mismatch`]).
    pub(crate) fn pull_back(&self, q: DVec3) -> DVec3 {
        self.inverse * (q - self.translation)
    }

    /// Distance between a current point and the image of snapshot point `s`.
    #[inline]
    pub(crate) fn mismatch(&self, q: DVec3, s: DVec3) -> f64 {
        (q - (self.linear * s + self.translation)).length()
    }
}

/// Most close competitors a certificate lists (see [`CLOSE_GAP_REL`]); 2 measured faster than
/// 1 or 3 on the `delaunay` benchmark.
pub const MAX_CLOSE: usize = 2;

/// A competitor triangle whose distance is within this fraction of the chart's circumradius of
/// the Gaussian's own distance is listed in its certificate and compared exactly every frame
/// (up to [`MAX_CLOSE`] of them); the motion bound covers only the farther ones.
pub const CLOSE_GAP_REL: f64 = 0.15;

/// Listed close competitors: lower bounds of their distances (`+∞` in empty slots) and their
/// ids (`u32::MAX` in empty slots).
pub(crate) type Close = ([f64; MAX_CLOSE], [u32; MAX_CLOSE]);

/// What an exact check proved about one Gaussian, pulled back to the chart's snapshot
/// coordinates (see the module documentation): the part every update reads. Stored in f32
/// (20 bytes): the bounds are rounded outward and the position's rounding is part of the
/// measured mismatch, so the rounding never weakens the proof. The rest of the proof, read
/// only when this part is inconclusive, is the Gaussian's [`Competitors`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Certificate {
    /// The deformed mean in snapshot coordinates.
    local: [f32; 3],
    /// Upper bound of its distance to the chart triangle there.
    own: f32,
    /// Lower bound of its distance to every other triangle of the snapshot there (the
    /// minimum of [`Competitors`]' bounds); `-∞`: no certificate.
    lower: f32,
}

/// The competitors' side of a [`Certificate`], in the same snapshot coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Competitors {
    /// Lower bound of the distance to every other triangle of the snapshot not in `close`.
    other: f32,
    /// Lower bounds of the distances to the triangles in `close` (`+∞` where none).
    near: [f32; MAX_CLOSE],
    /// Competitors compared exactly when the bounds do not settle them (`u32::MAX`: none).
    pub(crate) close: [u32; MAX_CLOSE],
}

/// A certificate's bounds at the current frame (see [`Certificate::bounds`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bounds {
    /// Upper bound of the own distance.
    pub(crate) own: f64,
    /// Lower bound of every other distance.
    pub(crate) lower: f64,
    /// How far the Gaussian and its neighbourhood are from following the fit (what the
    /// competitors' bounds need, see [`Competitors::other_bound`]).
    pub(crate) error: f64,
}

impl Certificate {
    /// No certificate: the next update checks the Gaussian exactly.
    pub(crate) const NONE: Self = Self {
        local: [0.0; 3],
        own: f32::INFINITY,
        lower: f32::NEG_INFINITY,
    };

    /// The certificate of a Gaussian at `q` with own distance at most `own`, the triangles
    /// `close` at distances at least `near` (slot by slot) and every other triangle at
    /// distance at least `other`, under `fit`.
    pub(crate) fn issue(
        fit: &Fit,
        q: DVec3,
        own: f64,
        (near, close): Close,
        other: f64,
    ) -> (Self, Competitors) {
        let local = fit.pull_back(q).as_vec3();
        let error = fit.mismatch(q, local.as_dvec3()) + fit.residual;
        let down = |x: f64| round_down((x - error) / fit.sigma_hi);
        let mut listed = [f32::INFINITY; MAX_CLOSE];
        for ((l, &n), &t) in listed.iter_mut().zip(&near).zip(&close) {
            if t != u32::MAX {
                *l = down(n);
            }
        }
        let competitors = Competitors {
            other: down(other),
            near: listed,
            close,
        };
        let lower = listed.iter().fold(competitors.other, |m, &n| m.min(n));
        let certificate = Self {
            local: local.to_array(),
            own: round_up((own + error) / fit.sigma_lo),
            lower,
        };
        (certificate, competitors)
    }

    /// Whether it certifies anything.
    pub(crate) fn is_some(&self) -> bool {
        self.lower > f32::NEG_INFINITY
    }

    /// Bounds for the Gaussian now at `q`.
    #[inline]
    pub(crate) fn bounds(&self, fit: &Fit, q: DVec3) -> Bounds {
        let local = glam::Vec3::from_array(self.local).as_dvec3();
        let error = fit.mismatch(q, local) + fit.residual;
        Bounds {
            own: fit.sigma_hi * f64::from(self.own) + error,
            lower: fit.sigma_lo * f64::from(self.lower) - error,
            error,
        }
    }
}

impl Competitors {
    /// No competitors (pairs with [`Certificate::NONE`]).
    pub(crate) const NONE: Self = Self {
        other: f32::NEG_INFINITY,
        near: [f32::INFINITY; MAX_CLOSE],
        close: [u32::MAX; MAX_CLOSE],
    };

    /// Lower bound of every unlisted distance now (`error` from [`Certificate::bounds`]).
    #[inline]
    pub(crate) fn other_bound(&self, fit: &Fit, error: f64) -> f64 {
        fit.sigma_lo * f64::from(self.other) - error
    }

    /// Lower bounds of the listed competitors' distances now (`+∞` for empty slots).
    #[inline]
    pub(crate) fn near_bounds(&self, fit: &Fit, error: f64) -> [f64; MAX_CLOSE] {
        self.near.map(|n| fit.sigma_lo * f64::from(n) - error)
    }
}

/// The smallest f32 not below `x`; `+∞` for NaN (an upper bound that bounds nothing).
fn round_up(x: f64) -> f32 {
    if x.is_nan() {
        return f32::INFINITY;
    }
    let y = x as f32;
    if f64::from(y) < x { y.next_up() } else { y }
}

/// The largest f32 not above `x`; `-∞` for NaN (a lower bound that bounds nothing).
fn round_down(x: f64) -> f32 {
    if x.is_nan() {
        return f32::NEG_INFINITY;
    }
    let y = x as f32;
    if f64::from(y) > x { y.next_down() } else { y }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::{LocalFrame, Snapshot};

    /// Two triangles of a unit square in z = 0.
    fn square() -> (Vec<[u32; 3]>, Vec<DVec3>) {
        let positions = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        (vec![[0, 1, 2], [0, 2, 3]], positions)
    }

    fn corners(positions: &[DVec3], t: [u32; 3]) -> [DVec3; 3] {
        t.map(|k| positions[k as usize])
    }

    #[test]
    fn rebase_maps_a_moved_neighbourhood_exactly_and_fails_without_change() {
        let (triangles, rest) = square();
        let v = corners(&rest, triangles[0]);
        let frame = LocalFrame::of(v).expect("frame");
        let mut snap =
            Snapshot::new(&frame, vec![0, 1], Vec::new(), &triangles, &rest).expect("snapshot");
        let (mut saved, mut current) = (Vec::new(), Vec::new());
        // Stretched by 20% along x: the old fit follows it with no residual.
        let moved: Vec<DVec3> = rest
            .iter()
            .map(|p| DVec3::new(1.2 * p.x, p.y, p.z))
            .collect();
        let v_moved = corners(&moved, triangles[0]);
        let old = snap.fit(v_moved, &moved, &mut current).expect("fit");
        assert!(old.residual < 1e-12 && old.sigma_hi > 1.15, "{old:?}");
        // Rebased there, the map is a rotation again (singular values 1).
        let frame_moved = LocalFrame::of(v_moved).expect("frame");
        let new = snap
            .rebase(&frame_moved, v_moved, &moved, &mut saved, &mut current)
            .expect("rebase");
        assert!(new.residual < 1e-12, "{new:?}");
        assert!((new.sigma_lo - 1.0).abs() < 1e-9 && (new.sigma_hi - 1.0).abs() < 1e-9);
        // Every vertex in one point: no fit, and the snapshot stays as it was.
        let before = snap.clone();
        let collapsed = vec![DVec3::splat(0.5); 4];
        let v_collapsed = corners(&collapsed, triangles[0]);
        assert!(
            snap.rebase(
                &frame_moved,
                v_collapsed,
                &collapsed,
                &mut saved,
                &mut current
            )
            .is_none()
        );
        assert_eq!(snap, before);
    }
}
