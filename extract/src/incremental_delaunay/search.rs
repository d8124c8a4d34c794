//! Closest-triangle search over the deformed template: an obvhs `Bvh2` (PLOC) whose boxes are
//! refitted every frame, searched depth first with an upper bound.
//!
//! `trisplat_geometry::spatial::TriangleBvh` answers unbounded closest-point queries; hop
//! detection needs a query *seeded* with the Gaussian's current triangle (only boxes nearer than
//! it are opened, which is what makes a frame update cheap) and a tree that is refitted rather
//! than rebuilt. The answer is the same as `TriangleBvh`'s: the minimum of
//! [`closest_point_on_triangle`] over all triangles, ties to the smallest triangle id, because
//! boxes are padded (see [`BOX_PADDING_REL`]) so pruning never drops a triangle whose computed
//! distance could tie or beat the bound.

use glam::{DVec3, Vec3, Vec3A};
use obvhs::aabb::Aabb as BvhAabb;
use obvhs::bvh2::Bvh2;
use obvhs::ploc::{PlocBuilder, PlocSearchDistance, SortPrecision};
use obvhs::triangle::Triangle;
use rayon::prelude::*;
use trisplat_geometry::spatial::{box_distance_sq, closest_point_on_triangle};

use super::certify::is_flat;

/// Node boxes grow by this fraction of the template's bounding-box diagonal (plus the same
/// fraction of each coordinate's magnitude), far above the f64 rounding of a point-triangle
/// distance, so a box is only skipped when every triangle in it is certainly farther than the
/// bound.
pub const BOX_PADDING_REL: f32 = 1e-5;

/// A candidate: squared distance and triangle id, ordered lexicographically.
pub(crate) type Candidate = (f64, u32);

/// The BVH over the deformed triangles.
pub(crate) struct DeformedBvh {
    bvh: Bvh2,
    /// Deformed corners of every triangle (f32, as the mesh stores them).
    corners: Vec<[Vec3; 3]>,
    /// Leaf node of each triangle.
    leaf_of: Vec<u32>,
    /// Parent of each node (`u32::MAX` for the root).
    parent: Vec<u32>,
    /// Per triangle: flat in the sense of `certify::FLAT_RATIO`.
    flat: Vec<bool>,
}

impl DeformedBvh {
    /// Builds a tree over the triangles `tris` of `positions` (indices already checked).
    pub(crate) fn build(positions: &[Vec3], tris: &[[u32; 3]], diagonal: f32) -> Self {
        let (corners, flat) = gather_corners(positions, tris);
        let triangles: Vec<Triangle> = corners
            .par_iter()
            .map(|&[a, b, c]| Triangle {
                v0: a.into(),
                v1: b.into(),
                v2: c.into(),
            })
            .collect();
        let n = triangles.len();
        let bvh = if n == 0 {
            Bvh2::default()
        } else {
            PlocBuilder::with_capacity(n).build(
                PlocSearchDistance::Medium,
                &triangles,
                (0..n as u32).collect(),
                SortPrecision::U64,
                3,
            )
        };
        let mut leaf_of = vec![u32::MAX; n];
        for (index, node) in bvh.nodes.iter().enumerate() {
            if node.is_leaf() {
                for slot in node.first_index..node.first_index.saturating_add(node.prim_count) {
                    if let Some(&t) = bvh.primitive_indices.get(slot as usize)
                        && let Some(l) = leaf_of.get_mut(t as usize)
                    {
                        *l = index as u32;
                    }
                }
            }
        }
        let mut parent = vec![u32::MAX; bvh.nodes.len()];
        for (index, node) in bvh.nodes.iter().enumerate() {
            if !node.is_leaf() {
                for child in [node.first_index, node.first_index.saturating_add(1)] {
                    if let Some(p) = parent.get_mut(child as usize) {
                        *p = index as u32;
                    }
                }
            }
        }
        let mut out = Self {
            bvh,
            corners,
            leaf_of,
            parent,
            flat,
        };
        out.set_leaf_boxes(diagonal);
        out.bvh.refit_all();
        out
    }

    /// Moves the triangles to `positions` and refits the boxes (same tree).
    pub(crate) fn refit(&mut self, positions: &[Vec3], tris: &[[u32; 3]], diagonal: f32) {
        (self.corners, self.flat) = gather_corners(positions, tris);
        self.set_leaf_boxes(diagonal);
        self.bvh.refit_all();
    }

    /// Per triangle whether it is flat (`certify::FLAT_RATIO`), or `None` when none is.
    pub(crate) fn flat(&self) -> Option<&[bool]> {
        self.flat.contains(&true).then_some(self.flat.as_slice())
    }

    /// Sets every leaf's box to the union of its triangles' padded boxes (in parallel over
    /// the nodes; inner boxes are left to `refit_all`).
    fn set_leaf_boxes(&mut self, diagonal: f32) {
        let corners = &self.corners;
        let primitives = &self.bvh.primitive_indices;
        self.bvh
            .nodes
            .par_iter_mut()
            .with_min_len(1024)
            .filter(|node| node.is_leaf())
            .for_each(|node| {
                let first = node.first_index as usize;
                let slots = first..first.saturating_add(node.prim_count as usize);
                let mut aabb = BvhAabb::empty();
                for c in primitives
                    .get(slots)
                    .unwrap_or(&[])
                    .iter()
                    .filter_map(|&t| corners.get(t as usize))
                {
                    let lo = c[0].min(c[1]).min(c[2]);
                    let hi = c[0].max(c[1]).max(c[2]);
                    let pad = Vec3::splat(diagonal * BOX_PADDING_REL)
                        + lo.abs().max(hi.abs()) * BOX_PADDING_REL;
                    aabb = aabb.union(&BvhAabb::new(Vec3A::from(lo - pad), Vec3A::from(hi + pad)));
                }
                node.set_aabb(aabb);
            });
    }

    /// Squared distance from `q` to triangle `t` (as [`closest_point_on_triangle`]), and the
    /// barycentric weights of the closest point.
    pub(crate) fn distance_sq(&self, q: DVec3, t: u32) -> (f64, [f64; 3]) {
        match self.corners.get(t as usize) {
            Some(&[a, b, c]) => {
                let (p, bary) =
                    closest_point_on_triangle(q, a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
                ((p - q).length_squared(), bary)
            }
            None => (f64::INFINITY, [1.0 / 3.0; 3]),
        }
    }

    /// Deformed corners of triangle `t` in f64 (zeros past the end).
    pub(crate) fn corners(&self, t: u32) -> [DVec3; 3] {
        self.corners
            .get(t as usize)
            .map_or([DVec3::ZERO; 3], |c| c.map(Vec3::as_dvec3))
    }

    /// Appends to `out` every triangle whose padded leaf box is within squared distance `r2`
    /// of `q` (a superset of the triangles within distance `√r2`), with a caller-owned
    /// traversal stack (no allocation once it has grown). The boxes are tested in f32: their
    /// padding ([`BOX_PADDING_REL`]) is far above the f32 rounding of the test, so a triangle
    /// within `√r2` is never left out.
    pub(crate) fn triangles_within_using(
        &self,
        q: DVec3,
        r2: f64,
        out: &mut Vec<u32>,
        stack: &mut Vec<u32>,
    ) {
        let nodes = &self.bvh.nodes;
        stack.clear();
        if nodes.is_empty() {
            return;
        }
        let p = Vec3A::from(q.as_vec3());
        // Round the radius up (f32 keeps 24 bits; the padding covers the rest).
        let r2 = (r2 * (1.0 + 1e-6)) as f32;
        stack.push(0);
        while let Some(index) = stack.pop() {
            let Some(node) = nodes.get(index as usize) else {
                continue;
            };
            let b = node.aabb();
            let d = (b.min - p).max(p - b.max).max(Vec3A::ZERO);
            if d.length_squared() > r2 {
                continue;
            }
            if node.is_leaf() {
                for slot in node.first_index..node.first_index.saturating_add(node.prim_count) {
                    if let Some(&t) = self.bvh.primitive_indices.get(slot as usize) {
                        out.push(t);
                    }
                }
            } else {
                stack.push(node.first_index);
                stack.push(node.first_index.saturating_add(1));
            }
        }
    }

    /// Number of nodes.
    pub(crate) fn node_count(&self) -> usize {
        self.bvh.nodes.len()
    }

    /// Fills `out` with the *frontier* of the triangles `inside`: nodes whose subtrees hold no
    /// triangle of `inside` and together hold every other triangle (the children, off the
    /// paths from the root to `inside`'s leaves, of nodes on those paths). `marks` is a
    /// per-node scratch array (`token` marks this call; it must differ from every earlier
    /// token written to it).
    pub(crate) fn frontier(
        &self,
        inside: &[u32],
        marks: &mut [u32],
        token: u32,
        out: &mut Vec<u32>,
    ) {
        out.clear();
        let nodes = &self.bvh.nodes;
        if nodes.is_empty() {
            return;
        }
        for &t in inside {
            let mut n = self.leaf_of.get(t as usize).copied().unwrap_or(u32::MAX);
            while let Some(m) = marks.get_mut(n as usize) {
                if *m == token {
                    break;
                }
                *m = token;
                n = self.parent.get(n as usize).copied().unwrap_or(u32::MAX);
            }
        }
        if marks.first() != Some(&token) {
            out.push(0);
            return;
        }
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let Some(node) = nodes.get(n as usize) else {
                continue;
            };
            if node.is_leaf() {
                continue;
            }
            for child in [node.first_index, node.first_index.saturating_add(1)] {
                if marks.get(child as usize) == Some(&token) {
                    stack.push(child);
                } else {
                    out.push(child);
                }
            }
        }
    }

    /// Whether a triangle under one of the nodes `roots` has its padded leaf box within
    /// squared distance `r2` of `q` (tested in f32 as [`DeformedBvh::triangles_within_using`]).
    pub(crate) fn any_within(
        &self,
        roots: &[u32],
        q: DVec3,
        r2: f64,
        stack: &mut Vec<u32>,
    ) -> bool {
        let nodes = &self.bvh.nodes;
        let p = Vec3A::from(q.as_vec3());
        let r2 = (r2 * (1.0 + 1e-6)) as f32;
        let near = |node: &obvhs::bvh2::node::Bvh2Node| {
            let b = node.aabb();
            let d = (b.min - p).max(p - b.max).max(Vec3A::ZERO);
            d.length_squared() <= r2
        };
        // Every node is tested once, before it is pushed.
        stack.clear();
        stack.extend(
            roots
                .iter()
                .copied()
                .filter(|&r| nodes.get(r as usize).is_some_and(near)),
        );
        while let Some(index) = stack.pop() {
            let Some(node) = nodes.get(index as usize) else {
                continue;
            };
            if node.is_leaf() {
                return true;
            }
            for child in [node.first_index, node.first_index.saturating_add(1)] {
                if nodes.get(child as usize).is_some_and(near) {
                    stack.push(child);
                }
            }
        }
        false
    }

    /// The padded box of triangle `t`'s leaf as `(min, max)` in f64 (its squared distance
    /// from a point is a lower bound of the triangle's); an infinite box past the end.
    pub(crate) fn leaf_box(&self, t: u32) -> (DVec3, DVec3) {
        self.leaf_of
            .get(t as usize)
            .and_then(|&l| self.bvh.nodes.get(l as usize))
            .map_or((DVec3::NEG_INFINITY, DVec3::INFINITY), |n| {
                let b = n.aabb();
                (Vec3::from(b.min).as_dvec3(), Vec3::from(b.max).as_dvec3())
            })
    }

    /// The lexicographically smallest `(squared distance, triangle)` that is smaller than
    /// `bound`, or `None`. With `bound = (d², t)` for the current triangle `t`, a result means
    /// that another triangle is strictly nearer (or as near with a smaller id).
    pub(crate) fn nearest_below(&self, q: DVec3, bound: Candidate) -> Option<Candidate> {
        let nodes = &self.bvh.nodes;
        if nodes.is_empty() {
            return None;
        }
        let mut best = bound;
        let mut found = false;
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        stack.push((0, box_distance_sq(nodes[0].aabb(), q)));
        while let Some((index, lower)) = stack.pop() {
            if lower > best.0 {
                continue;
            }
            let Some(node) = nodes.get(index as usize) else {
                continue;
            };
            if node.is_leaf() {
                for slot in node.first_index..node.first_index.saturating_add(node.prim_count) {
                    let Some(&t) = self.bvh.primitive_indices.get(slot as usize) else {
                        continue;
                    };
                    let (d2, _) = self.distance_sq(q, t);
                    if (d2, t) < best {
                        best = (d2, t);
                        found = true;
                    }
                }
                continue;
            }
            let left = node.first_index;
            let right = left + 1;
            let (Some(ln), Some(rn)) = (nodes.get(left as usize), nodes.get(right as usize)) else {
                continue;
            };
            let dl = box_distance_sq(ln.aabb(), q);
            let dr = box_distance_sq(rn.aabb(), q);
            let (near, dn, far, df) = if dl <= dr {
                (left, dl, right, dr)
            } else {
                (right, dr, left, dl)
            };
            if df <= best.0 {
                stack.push((far, df));
            }
            if dn <= best.0 {
                stack.push((near, dn));
            }
        }
        found.then_some(best)
    }
}

/// The corners of every triangle and whether it is flat (`certify::is_flat`).
fn gather_corners(positions: &[Vec3], tris: &[[u32; 3]]) -> (Vec<[Vec3; 3]>, Vec<bool>) {
    tris.par_iter()
        .with_min_len(1024)
        .map(|t| {
            let c = t.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
            (c, is_flat(c.map(Vec3::as_dvec3)))
        })
        .unzip()
}
