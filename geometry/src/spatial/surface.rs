//! Exact closest-point queries on a mesh's surface for the metrics (docs/conventions.md §8):
//! a BVH built in one Morton sort, for meshes indexed once and queried a few thousand times.
//!
//! [`super::TriangleBvh`] (PLOC with reinsertion) builds a better tree, but the build costs more
//! than the queries the metrics make of it: a 340k-triangle TSDF mesh took 0.29 s to index
//! and 0.17 s to answer 20k queries. Here the triangles are sorted along a Morton curve of
//! their centroids and grouped [`LEAF`] to a leaf; the tree halves the sorted leaves at every
//! level, boxes bottom-up (f64, padded). The build is one parallel sort and a linear pass.
//! Queries walk that tree with its levels collapsed in pairs (a 4-wide tree, each node
//! holding its four children's boxes in f32 rounded outwards, tested in one SIMD pass; a
//! leaf's triangles' boxes likewise, four at a time): about a quarter fewer instructions
//! than the binary walk in f64 on LAM's scoring sweeps (docs/benchmarks.md, "Scoring at
//! speed, part 6").
//!
//! Queries answer what [`super::TriangleBvh::closest_point`] answers, bit for bit: the
//! lexicographically smallest `(squared distance, triangle id)` over all triangles, each
//! squared distance from [`closest_point_on_triangle`] in f64. The tree only decides which
//! triangles are looked at, and a box is skipped only when its (padded) distance exceeds the
//! best squared distance so far, so its shape cannot change an answer. Batches are answered
//! in Morton order, each query starting from the previous one's triangle as its bound
//! (neighbouring queries have neighbouring answers, so most boxes are skipped at once); the
//! traversal stack is a fixed array (the tree is at most 32 levels deep).

use glam::{DVec3, Vec3, Vec4};
use rayon::prelude::*;

use super::bvh::{closest_point_on_proper_triangle, closest_point_on_triangle, triangle_is_flat};
use super::error::SpatialError;
use super::limits::{check_dpoints, check_points};
use super::morton::{morton_order, morton_sorted};

/// Triangles per leaf.
pub const LEAF: usize = 8;

/// Boxes grow by this fraction of the mesh's bounding-box diagonal plus the same fraction of
/// each coordinate's magnitude: far above the f64 rounding of a closest point (1e-16
/// relative), so no box is ever nearer than its rounded triangles' distances allow.
const PADDING: f64 = 1e-9;

/// A child of a [`Wide`] node that is a leaf (the rest of the word: its index in
/// [`SurfaceIndex::leaves`]).
const LEAF_BIT: u32 = 1 << 31;

/// An unused child of a [`Wide`] node (its box is empty: never within reach).
const NO_CHILD: u32 = u32::MAX;

/// Squared f32 box distances are compared with the best squared distance grown by this
/// fraction: far above their rounding (a few f32 ulps), so a box within reach in exact
/// arithmetic is never skipped.
const F32_SLACK: f32 = 1e-5;

/// Queries answered one after another, each bounded by the previous answer.
const RUN: usize = 256;

/// Initial capacity of a traversal stack (it grows if ever needed): a split on a Morton bit
/// leaves at most 63 levels, then halving at most 32 (`u32::MAX` triangles), and a 4-wide
/// search holds at most three entries per wide level, i.e. per two binary levels.
const STACK: usize = 160;

/// A node: its padded box, and either its children (`left` is the next node, `right` given)
/// or its triangles (`count > 0`: slots `first..first + count`).
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first slot; inner: index of the right child.
    first_or_right: u32,
    /// Leaf: number of triangles; inner: 0.
    count: u32,
}

/// The closest point of the surface to a query, as the metrics use it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Euclidean distance from the query (f64).
    pub distance: f64,
    /// The triangle it lies on (the smallest id among exactly equidistant triangles).
    pub triangle: u32,
}

/// A triangle in leaf order: what a query reads of it, in one place (two cache lines).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Slot {
    /// Padded box: the triangle is looked at only when its box is within reach.
    lo: DVec3,
    hi: DVec3,
    /// Corners.
    corners: [DVec3; 3],
    /// Mesh triangle id.
    id: u32,
    /// Whether [`triangle_is_flat`] (decided once here, not at every query).
    flat: bool,
}

/// Four boxes in f32, one per lane (rounded outwards from the f64 boxes, so each contains
/// its f64 box), tested against a query at once.
#[derive(Clone, Copy, Debug)]
struct Boxes4 {
    lo: [Vec4; 3],
    hi: [Vec4; 3],
}

impl Boxes4 {
    /// Every lane empty (never within reach).
    const EMPTY: Self = Self {
        lo: [Vec4::INFINITY; 3],
        hi: [Vec4::NEG_INFINITY; 3],
    };

    /// Sets lane `k` to the f64 box `lo..hi`, rounded outwards.
    fn set(&mut self, k: usize, lo: DVec3, hi: DVec3) {
        for a in 0..3 {
            self.lo[a][k] = down(lo[a]);
            self.hi[a][k] = up(hi[a]);
        }
    }

    /// Squared distances from the query box `qlo..=qhi` (one f32 point, or the two f32
    /// neighbours of an f64 one) to the four boxes: never above the exact distances.
    #[inline]
    fn distances(&self, qlo: &[Vec4; 3], qhi: &[Vec4; 3]) -> Vec4 {
        let d = |a: usize| {
            (self.lo[a] - qhi[a])
                .max(qlo[a] - self.hi[a])
                .max(Vec4::ZERO)
        };
        let (x, y, z) = (d(0), d(1), d(2));
        x * x + y * y + z * z
    }
}

/// The largest f32 not above `x`.
fn down(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) > x { f.next_down() } else { f }
}

/// The smallest f32 not below `x`.
fn up(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x { f.next_up() } else { f }
}

/// A node of the 4-wide tree the queries walk (the binary tree's levels collapsed in pairs):
/// its children's boxes, tested in one go, and the children (a [`Wide`] node, a leaf with
/// [`LEAF_BIT`], or [`NO_CHILD`]).
#[derive(Clone, Copy, Debug)]
struct Wide {
    boxes: Boxes4,
    child: [u32; 4],
    /// The binary node of each child (what its box is refitted from).
    source: [u32; 4],
}

/// A leaf of the binary tree as the queries read it: its slots and their boxes in f32.
#[derive(Clone, Copy, Debug)]
struct LeafBlock {
    boxes: [Boxes4; 2],
    first: u32,
    count: u32,
    /// Its binary node (what a refit writes the leaf's f64 box to).
    node: u32,
}

/// A BVH over a mesh's triangles for exact closest-point queries (see the module docs).
pub struct SurfaceIndex {
    nodes: Vec<Node>,
    /// The 4-wide tree over `nodes` the queries walk (root first).
    wide: Vec<Wide>,
    /// The leaves of `nodes`, in the order [`Wide`] children name them.
    leaves: Vec<LeafBlock>,
    /// What the root is: a [`Wide`] node or, for one leaf, `LEAF_BIT | 0`.
    root: u32,
    /// The triangles in leaf order.
    slots: Vec<Slot>,
    /// The triangles indexed (mesh order): what [`SurfaceIndex::refit`] checks a mesh against.
    triangles: Vec<[u32; 3]>,
}

impl std::fmt::Debug for SurfaceIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SurfaceIndex")
            .field("triangles", &self.slots.len())
            .field("nodes", &self.nodes.len())
            .finish_non_exhaustive()
    }
}

impl SurfaceIndex {
    /// Indexes `triangles` (vertex indices into `positions`).
    ///
    /// # Errors
    /// [`SpatialError::Empty`] without triangles, [`SpatialError::NonFinite`] or
    /// [`SpatialError::TooLarge`] naming the first bad vertex, [`SpatialError::BadIndex`] for
    /// a triangle naming a vertex past the end, [`SpatialError::TooMany`] past `u32::MAX`
    /// triangles.
    pub fn new(positions: &[DVec3], triangles: &[[u32; 3]]) -> Result<Self, SpatialError> {
        check_dpoints(positions)?;
        super::bvh::check_indices(positions.len(), triangles)?;
        if triangles.is_empty() {
            return Err(SpatialError::Empty);
        }
        if u32::try_from(triangles.len()).is_err() {
            return Err(SpatialError::TooMany {
                count: triangles.len(),
            });
        }
        let corner = |t: [u32; 3]| t.map(|i| positions[i as usize]);
        let centroids: Vec<Vec3> = triangles
            .par_iter()
            .with_min_len(4096)
            .map(|&t| {
                let [a, b, c] = corner(t);
                ((a + b + c) / 3.0).as_vec3()
            })
            .collect();
        let (codes, ids): (Vec<u64>, Vec<u32>) = morton_sorted(&centroids).into_iter().unzip();
        let pad = padding(positions);
        let slots: Vec<Slot> = ids
            .par_iter()
            .with_min_len(4096)
            .map(|&id| slot(corner(triangles[id as usize]), id, pad))
            .collect();
        drop(ids);
        let mut nodes = Vec::with_capacity(2 * triangles.len().div_ceil(LEAF));
        build(&mut nodes, &slots, &codes, 0, slots.len());
        let mut index = Self {
            nodes,
            wide: Vec::new(),
            leaves: Vec::new(),
            root: 0,
            slots,
            triangles: triangles.to_vec(),
        };
        index.root = index.widen(0);
        index.refit_wide();
        Ok(index)
    }

    /// Appends the 4-wide subtree over binary node `n` (its boxes are filled by
    /// [`SurfaceIndex::refit_wide`]) and returns what names it.
    fn widen(&mut self, n: u32) -> u32 {
        let node = self.nodes[n as usize];
        if node.count > 0 {
            self.leaves.push(LeafBlock {
                boxes: [Boxes4::EMPTY; 2],
                first: node.first_or_right,
                count: node.count,
                node: n,
            });
            return LEAF_BIT | (self.leaves.len() - 1) as u32;
        }
        // Up to four binary nodes under `n`: open the inner one with the largest box until
        // there are four (or only leaves).
        let mut kids: Vec<u32> = vec![n + 1, node.first_or_right];
        while kids.len() < 4 {
            let open = kids
                .iter()
                .enumerate()
                .filter(|&(_, &k)| self.nodes[k as usize].count == 0)
                .map(|(i, &k)| (i, half_area(&self.nodes[k as usize])))
                .fold(None, |b: Option<(usize, f64)>, x| match b {
                    Some(b) if b.1 >= x.1 => Some(b),
                    _ => Some(x),
                });
            let Some((i, _)) = open else { break };
            let k = kids[i];
            kids[i] = k + 1;
            kids.insert(i + 1, self.nodes[k as usize].first_or_right);
        }
        let at = self.wide.len();
        self.wide.push(Wide {
            boxes: Boxes4::EMPTY,
            child: [NO_CHILD; 4],
            source: [NO_CHILD; 4],
        });
        for (lane, &k) in kids.iter().enumerate() {
            let child = self.widen(k);
            self.wide[at].child[lane] = child;
            self.wide[at].source[lane] = k;
        }
        at as u32
    }

    /// The f32 boxes of the 4-wide tree and of the leaves' slots, from the binary tree's and
    /// the slots' f64 boxes.
    fn refit_wide(&mut self) {
        self.refit_wide_nodes();
        let slots = &self.slots;
        self.leaves
            .par_iter_mut()
            .with_min_len(1024)
            .for_each(|leaf| {
                for k in 0..leaf.count as usize {
                    let s = &slots[leaf.first as usize + k];
                    leaf.boxes[k / 4].set(k % 4, s.lo, s.hi);
                }
            });
    }

    /// The f32 boxes of the 4-wide tree's nodes from the binary tree's f64 boxes.
    fn refit_wide_nodes(&mut self) {
        let nodes = &self.nodes;
        self.wide.par_iter_mut().with_min_len(1024).for_each(|w| {
            for lane in 0..4 {
                if w.source[lane] != NO_CHILD {
                    let n = &nodes[w.source[lane] as usize];
                    w.boxes.set(lane, n.lo, n.hi);
                }
            }
        });
    }

    /// Indexes `triangles` over `positions`, refitting `previous` when it indexes the same
    /// triangles (a mesh carried from frame to frame: same triangles, moved vertices), else
    /// building anew ([`SurfaceIndex::new`]). Answers are the same either way: the tree only
    /// decides what is skipped.
    ///
    /// # Errors
    /// As [`SurfaceIndex::new`].
    pub fn reuse(
        previous: Option<Self>,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
    ) -> Result<Self, SpatialError> {
        match previous {
            Some(mut index) if index.triangles == triangles => {
                index.refit(positions)?;
                Ok(index)
            }
            _ => Self::new(positions, triangles),
        }
    }

    /// Moves the indexed triangles' corners to `positions` and recomputes every box bottom-up,
    /// keeping the tree (its order is the build's Morton order: still a valid tree, a looser
    /// one the farther the vertices moved).
    ///
    /// One parallel pass over the leaves makes each leaf's slots, its f64 box and its f32
    /// lane boxes together (the slots are read once, while in cache); then the inner nodes
    /// bottom-up and the 4-wide nodes. The boxes are those [`SurfaceIndex::new`] makes of
    /// the same corners, bit for bit.
    fn refit(&mut self, positions: &[DVec3]) -> Result<(), SpatialError> {
        check_dpoints(positions)?;
        super::bvh::check_indices(positions.len(), &self.triangles)?;
        let pad = padding(positions);
        let triangles = &self.triangles;
        // The leaves hold consecutive runs of slots, in slot order (both are the binary
        // tree's depth-first order): hand each leaf its own run.
        let mut runs: Vec<(&mut LeafBlock, &mut [Slot])> = Vec::with_capacity(self.leaves.len());
        let mut rest: &mut [Slot] = &mut self.slots;
        let mut at = 0;
        for leaf in &mut self.leaves {
            let (skip, tail) = std::mem::take(&mut rest).split_at_mut(leaf.first as usize - at);
            debug_assert!(skip.is_empty(), "leaves cover the slots in order");
            let (own, tail) = tail.split_at_mut(leaf.count as usize);
            at = (leaf.first + leaf.count) as usize;
            rest = tail;
            runs.push((leaf, own));
        }
        let leaf_boxes: Vec<(u32, DVec3, DVec3)> = runs
            .into_par_iter()
            .with_min_len(256)
            .map(|(leaf, own)| {
                for (k, s) in own.iter_mut().enumerate() {
                    *s = slot(
                        triangles[s.id as usize].map(|i| positions[i as usize]),
                        s.id,
                        pad,
                    );
                    leaf.boxes[k / 4].set(k % 4, s.lo, s.hi);
                }
                let (lo, hi) = leaf_box(own);
                (leaf.node, lo, hi)
            })
            .collect();
        for (node, lo, hi) in leaf_boxes {
            let n = &mut self.nodes[node as usize];
            n.lo = lo;
            n.hi = hi;
        }
        // Children follow their parent (depth first), so a reverse pass meets them first.
        for i in (0..self.nodes.len()).rev() {
            let n = self.nodes[i];
            if n.count == 0 {
                let (l, r) = (&self.nodes[i + 1], &self.nodes[n.first_or_right as usize]);
                let (lo, hi) = (l.lo.min(r.lo), l.hi.max(r.hi));
                self.nodes[i].lo = lo;
                self.nodes[i].hi = hi;
            }
        }
        self.refit_wide_nodes();
        Ok(())
    }

    /// Number of triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.slots.len()
    }

    /// The closest point of the surface to `query` (f64), or `None` when it is not finite.
    #[must_use]
    pub fn closest(&self, query: DVec3) -> Option<SurfaceHit> {
        if !query.is_finite() {
            return None;
        }
        // One traversal stack per thread, kept between calls (no allocation per query).
        thread_local! {
            static STACK_OF_THREAD: std::cell::RefCell<Vec<(u32, f32)>> =
                std::cell::RefCell::new(Vec::with_capacity(STACK));
        }
        let (d2, slot) = STACK_OF_THREAD.with(|stack| match stack.try_borrow_mut() {
            Ok(mut stack) => self.search(query, None, &mut stack),
            // Re-entered on this thread (not done by this module): a stack of its own.
            Err(_) => self.search(query, None, &mut Vec::with_capacity(STACK)),
        });
        Some(SurfaceHit {
            distance: d2.sqrt(),
            triangle: self.slots[slot as usize].id,
        })
    }

    /// [`SurfaceIndex::closest`] of every query, in parallel; `result[i]` answers
    /// `queries[i]`, independent of the thread count.
    ///
    /// # Errors
    /// [`SpatialError::NonFinite`] or [`SpatialError::TooLarge`] naming the first bad query.
    pub fn closest_batch(&self, queries: &[Vec3]) -> Result<Vec<SurfaceHit>, SpatialError> {
        check_points(queries)?;
        let order = morton_order(queries);
        let runs: Vec<Vec<SurfaceHit>> = order
            .par_chunks(RUN)
            .map(|run| {
                let mut previous = None;
                let mut stack = Vec::with_capacity(STACK);
                run.iter()
                    .map(|&i| {
                        let (d2, slot) =
                            self.search(queries[i as usize].as_dvec3(), previous, &mut stack);
                        previous = Some(slot);
                        SurfaceHit {
                            distance: d2.sqrt(),
                            triangle: self.slots[slot as usize].id,
                        }
                    })
                    .collect()
            })
            .collect();
        let mut out = vec![
            SurfaceHit {
                distance: 0.0,
                triangle: 0
            };
            queries.len()
        ];
        for (hit, &i) in runs.into_iter().flatten().zip(&order) {
            out[i as usize] = hit;
        }
        Ok(out)
    }

    /// Squared distance from `q` to the triangle in `slot` and its mesh id.
    #[inline]
    fn candidate(&self, q: DVec3, slot: u32) -> (f64, u32) {
        let s = &self.slots[slot as usize];
        let [a, b, c] = s.corners;
        let (p, _) = if s.flat {
            closest_point_on_triangle(q, a, b, c)
        } else {
            closest_point_on_proper_triangle(q, a, b, c)
        };
        ((p - q).length_squared(), s.id)
    }

    /// The slot of the lexicographically smallest `(squared distance, id)`, with that squared
    /// distance; `start` (a slot) bounds the search from the outset.
    fn search(&self, q: DVec3, start: Option<u32>, stack: &mut Vec<(u32, f32)>) -> (f64, u32) {
        let (mut best, mut best_slot) = match start {
            Some(slot) => (self.candidate(q, slot), slot),
            None => ((f64::INFINITY, u32::MAX), 0),
        };
        // The query as the f32 box of its two nearest f32 neighbours (one point when it is
        // an f32 query), so f32 box distances never exceed the exact ones.
        let (qlo, qhi) = (q.to_array().map(down), q.to_array().map(up));
        let qlo = qlo.map(Vec4::splat);
        let qhi = qhi.map(Vec4::splat);
        let reach = |best: f64| (best as f32) * (1.0 + F32_SLACK);
        stack.clear();
        let mut node = self.root;
        loop {
            if node & LEAF_BIT != 0 {
                let leaf = &self.leaves[(node & !LEAF_BIT) as usize];
                for (half, boxes) in leaf.boxes.iter().enumerate() {
                    if half * 4 >= leaf.count as usize {
                        break;
                    }
                    let d = boxes.distances(&qlo, &qhi);
                    let mut mask = d.cmple(Vec4::splat(reach(best.0))).bitmask();
                    while mask != 0 {
                        let lane = mask.trailing_zeros();
                        mask &= mask - 1;
                        // The best may have tightened since the four were tested.
                        if d[lane as usize] > reach(best.0) {
                            continue;
                        }
                        let slot = leaf.first + (half * 4) as u32 + lane;
                        let c = self.candidate(q, slot);
                        if c < best {
                            best = c;
                            best_slot = slot;
                        }
                    }
                }
            } else {
                let w = &self.wide[node as usize];
                let d = w.boxes.distances(&qlo, &qhi);
                let limit = reach(best.0);
                let mut mask = d.cmple(Vec4::splat(limit)).bitmask();
                if mask != 0 {
                    // The children within reach, nearest first: the nearest is next, the
                    // others wait on the stack (farthest deepest).
                    let mut near = [(0f32, 0u32); 4];
                    let mut n = 0;
                    while mask != 0 {
                        let lane = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let e = (d[lane], w.child[lane]);
                        let mut j = n;
                        while j > 0 && near[j - 1].0 > e.0 {
                            near[j] = near[j - 1];
                            j -= 1;
                        }
                        near[j] = e;
                        n += 1;
                    }
                    for &(dist, child) in near[1..n].iter().rev() {
                        stack.push((child, dist));
                    }
                    node = near[0].1;
                    continue;
                }
            }
            // Next: the nearest pending box still within reach.
            loop {
                let Some((pending, lower)) = stack.pop() else {
                    return (best.0, best_slot);
                };
                if lower <= reach(best.0) {
                    node = pending;
                    break;
                }
            }
        }
    }
}

/// Half the surface area of a node's box (which inner node a [`Wide`] node opens first).
fn half_area(n: &Node) -> f64 {
    let e = (n.hi - n.lo).max(DVec3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// The absolute part of the boxes' padding: [`PADDING`] of the bounding-box diagonal.
fn padding(positions: &[DVec3]) -> f64 {
    crate::mesh::Aabb::from_dpoints(positions).map_or(0.0, |b| b.diagonal()) * PADDING
}

/// A triangle's slot: its corners, padded box and flatness.
fn slot(corners: [DVec3; 3], id: u32, pad: f64) -> Slot {
    let [lo, hi] = padded_box(&corners, pad);
    let [a, b, c] = corners;
    Slot {
        lo,
        hi,
        corners,
        id,
        flat: triangle_is_flat(a, b, c),
    }
}

/// The union of the slots' boxes.
fn leaf_box(slots: &[Slot]) -> (DVec3, DVec3) {
    slots
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), s| {
            (lo.min(s.lo), hi.max(s.hi))
        })
}

/// The box of a triangle's corners grown by `pad` plus [`PADDING`] of its coordinates'
/// magnitude.
fn padded_box(c: &[DVec3; 3], pad: f64) -> [DVec3; 2] {
    let lo = c[0].min(c[1]).min(c[2]);
    let hi = c[0].max(c[1]).max(c[2]);
    let margin = DVec3::splat(pad) + lo.abs().max(hi.abs()) * PADDING;
    [lo - margin, hi + margin]
}

/// Appends the subtree over slots `first..end` (depth first, left child next), boxes from the
/// slots' boxes: split where the highest Morton bit that differs in the range flips
/// (so a child is one cell of the Z-curve's octree, a tight box), else halved.
fn build(nodes: &mut Vec<Node>, slots: &[Slot], codes: &[u64], first: usize, end: usize) {
    let index = nodes.len();
    if end - first <= LEAF {
        let (lo, hi) = leaf_box(&slots[first..end]);
        nodes.push(Node {
            lo,
            hi,
            first_or_right: first as u32,
            count: (end - first) as u32,
        });
        return;
    }
    nodes.push(Node {
        lo: DVec3::INFINITY,
        hi: DVec3::NEG_INFINITY,
        first_or_right: 0,
        count: 0,
    });
    let differ = codes[first] ^ codes[end - 1];
    let mid = if differ == 0 {
        // One cell: halve the leaves (a multiple of LEAF on the left keeps them full).
        first + (end - first).div_ceil(LEAF).div_ceil(2) * LEAF
    } else {
        // The first code with the highest differing bit set (codes are sorted).
        let bit = 63 - differ.leading_zeros();
        let prefix = codes[first] >> bit;
        first + codes[first..end].partition_point(|&c| c >> bit == prefix)
    };
    build(nodes, slots, codes, first, mid);
    let right = nodes.len();
    build(nodes, slots, codes, mid, end);
    let (l, r) = (nodes[index + 1], nodes[right]);
    nodes[index] = Node {
        lo: l.lo.min(r.lo),
        hi: l.hi.max(r.hi),
        first_or_right: right as u32,
        count: 0,
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::rng::Rng;
    use crate::spatial::TriangleBvh;

    fn soup(n: usize, seed: u64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let mut rng = Rng::new(seed);
        let mut p = Vec::new();
        let mut t = Vec::new();
        for k in 0..n {
            let c = DVec3::new(
                f64::from(rng.uniform_f32()),
                f64::from(rng.uniform_f32()),
                f64::from(rng.uniform_f32()),
            );
            for _ in 0..3 {
                let d = DVec3::new(
                    f64::from(rng.uniform_f32()),
                    f64::from(rng.uniform_f32()),
                    f64::from(rng.uniform_f32()),
                ) - 0.5;
                p.push(c + d * 0.1);
            }
            let b = 3 * k as u32;
            t.push([b, b + 1, b + 2]);
        }
        // A triangle repeated past a leaf (one Morton cell: ties go to the smaller id) and a
        // degenerate one.
        for _ in 0..2 * LEAF {
            t.push(t[0]);
        }
        t.push([0, 0, 1]);
        (p, t)
    }

    #[test]
    fn answers_as_the_bvh_bit_for_bit() {
        for (n, seed) in [(1, 1), (7, 2), (300, 3), (5000, 4)] {
            let (p, t) = soup(n, seed);
            let index = SurfaceIndex::new(&p, &t).expect("valid");
            let bvh = TriangleBvh::from_triangles(&p, &t).expect("valid");
            let mut rng = Rng::new(seed + 10);
            let queries: Vec<Vec3> = (0..2000)
                .map(|_| {
                    Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()) * 1.4 - 0.2
                })
                .chain(p.iter().take(50).map(|v| v.as_vec3()))
                .collect();
            let got = index.closest_batch(&queries).expect("finite");
            let want = bvh.closest_points(&queries).expect("finite");
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert_eq!(
                    (g.distance, g.triangle),
                    (w.distance, w.triangle),
                    "{n} {i}"
                );
                let one = index.closest(queries[i].as_dvec3()).expect("finite");
                assert_eq!(one, *g);
            }
        }
    }

    #[test]
    fn answers_as_the_bvh_on_a_grid_with_ties() {
        // A flat 30 x 30 grid of unit squares (two triangles each, every diagonal the same
        // way), a slanted copy of part of it, a sliver and a triangle repeated: queries on
        // grid points and edge midpoints are equidistant from several triangles.
        let n = 30u32;
        let mut p: Vec<DVec3> = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| DVec3::new(f64::from(i), f64::from(j), 0.0)))
            .collect();
        let mut t = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = j * (n + 1) + i;
                t.push([v, v + 1, v + n + 2]);
                t.push([v, v + n + 2, v + n + 1]);
            }
        }
        let base = p.len() as u32;
        p.extend([
            DVec3::new(3.0, 3.0, 1.0),
            DVec3::new(9.0, 3.0, 2.0),
            DVec3::new(3.0, 9.0, 1.0),
            DVec3::new(5.0, 5.0, 0.5),
            DVec3::new(5.0 + 1e-9, 5.0, 0.5),
            DVec3::new(5.0 + 2e-9, 5.0, 0.5),
        ]);
        t.extend([
            [base, base + 1, base + 2],
            [base + 3, base + 4, base + 5],
            t[7],
        ]);
        let index = SurfaceIndex::new(&p, &t).expect("valid");
        let bvh = TriangleBvh::from_triangles(&p, &t).expect("valid");
        let queries: Vec<Vec3> = (0..=2 * n)
            .flat_map(|j| (0..=2 * n).map(move |i| (i, j)))
            .flat_map(|(i, j)| {
                let (x, y) = (i as f32 * 0.5, j as f32 * 0.5);
                [
                    Vec3::new(x, y, 0.0),
                    Vec3::new(x, y, 0.75),
                    Vec3::new(x, y, -2.0),
                ]
            })
            .collect();
        let got = index.closest_batch(&queries).expect("finite");
        let want = bvh.closest_points(&queries).expect("finite");
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!((g.distance, g.triangle), (w.distance, w.triangle), "{i}");
        }
        // And against brute force: the least (squared distance, id) over every triangle.
        for (i, q) in queries.iter().enumerate().step_by(5) {
            let q = q.as_dvec3();
            let (d2, id) = t
                .iter()
                .enumerate()
                .map(|(k, tri)| {
                    let [a, b, c] = tri.map(|v| p[v as usize]);
                    (
                        (closest_point_on_triangle(q, a, b, c).0 - q).length_squared(),
                        k as u32,
                    )
                })
                .fold((f64::INFINITY, u32::MAX), |x, y| if y < x { y } else { x });
            assert_eq!((got[i].distance, got[i].triangle), (d2.sqrt(), id), "{i}");
        }
        // One triangle, queried everywhere.
        let one = SurfaceIndex::new(&p, &t[..1]).expect("valid");
        let hits = one.closest_batch(&queries).expect("finite");
        assert!(hits.iter().all(|h| h.triangle == 0));
    }

    /// Every box of `index` recomputed from its slots (brute force): what a refit must give.
    fn assert_boxes_fit_the_slots(index: &SurfaceIndex) {
        // The leaves cover the slots in order, each run once (what the refit relies on).
        let mut at = 0;
        for leaf in &index.leaves {
            assert_eq!(leaf.first as usize, at);
            at += leaf.count as usize;
            let n = index.nodes[leaf.node as usize];
            assert_eq!((n.first_or_right, n.count), (leaf.first, leaf.count));
        }
        assert_eq!(at, index.slots.len());
        for (i, n) in index.nodes.iter().enumerate() {
            let (lo, hi) = if n.count > 0 {
                leaf_box(&index.slots[n.first_or_right as usize..][..n.count as usize])
            } else {
                let (l, r) = (index.nodes[i + 1], index.nodes[n.first_or_right as usize]);
                (l.lo.min(r.lo), l.hi.max(r.hi))
            };
            assert_eq!((n.lo, n.hi), (lo, hi), "node {i}");
        }
        for leaf in &index.leaves {
            for k in 0..leaf.count as usize {
                let s = &index.slots[leaf.first as usize + k];
                let b = &leaf.boxes[k / 4];
                for a in 0..3 {
                    assert_eq!(b.lo[a][k % 4], down(s.lo[a]));
                    assert_eq!(b.hi[a][k % 4], up(s.hi[a]));
                }
            }
        }
    }

    #[test]
    fn a_refit_gives_the_boxes_of_its_slots() {
        let (p, t) = soup(700, 11);
        let mut index = SurfaceIndex::new(&p, &t).expect("valid");
        assert_boxes_fit_the_slots(&index);
        for step in 1..4 {
            let moved: Vec<DVec3> = p
                .iter()
                .enumerate()
                .map(|(i, &x)| {
                    x + DVec3::new((i % 7) as f64, (i % 3) as f64, 1.0) * 0.01 * f64::from(step)
                })
                .collect();
            index = SurfaceIndex::reuse(Some(index), &moved, &t).expect("valid");
            assert_boxes_fit_the_slots(&index);
            for s in &index.slots {
                let c = t[s.id as usize].map(|i| moved[i as usize]);
                assert_eq!(s.corners, c);
            }
        }
    }

    #[test]
    fn a_refitted_index_answers_as_a_new_one() {
        let (p, t) = soup(3000, 5);
        let mut index = SurfaceIndex::new(&p, &t).expect("valid");
        let mut rng = Rng::new(6);
        let queries: Vec<Vec3> = (0..3000)
            .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()) * 1.4 - 0.2)
            .collect();
        // The vertices move further each step (a looser and looser tree), once far off.
        let mut moved = p.clone();
        for step in 1..=4 {
            for (k, v) in moved.iter_mut().enumerate() {
                let w = (k as f64 * 0.37 + f64::from(step)).sin();
                *v += DVec3::new(w, -w * 0.5, w * 0.25) * 0.02 * f64::from(step * step);
            }
            index = SurfaceIndex::reuse(Some(index), &moved, &t).expect("valid");
            let fresh = SurfaceIndex::new(&moved, &t).expect("valid");
            let bvh = TriangleBvh::from_triangles(&moved, &t).expect("valid");
            let got = index.closest_batch(&queries).expect("finite");
            assert_eq!(
                got,
                fresh.closest_batch(&queries).expect("finite"),
                "{step}"
            );
            let want = bvh.closest_points(&queries).expect("finite");
            for (g, w) in got.iter().zip(&want) {
                assert_eq!((g.distance, g.triangle), (w.distance, w.triangle), "{step}");
            }
        }
        // Other triangles: built anew, not refitted.
        let fewer = &t[..t.len() / 2];
        let other = SurfaceIndex::reuse(Some(index), &moved, fewer).expect("valid");
        assert_eq!(other.triangle_count(), fewer.len());
        let fresh = SurfaceIndex::new(&moved, fewer).expect("valid");
        assert_eq!(
            other.closest_batch(&queries).expect("finite"),
            fresh.closest_batch(&queries).expect("finite")
        );
        // A bad position is an error on a refit too.
        let mut bad = moved.clone();
        bad[4] = DVec3::NAN;
        let fresh = SurfaceIndex::new(&moved, &t).expect("valid");
        assert!(SurfaceIndex::reuse(Some(fresh), &bad, &t).is_err());
        assert!(SurfaceIndex::reuse(None, &moved[..10], &t).is_err());
    }

    #[test]
    fn f64_queries_far_from_the_origin_answer_as_brute_force() {
        // Coordinates whose f32 rounding is coarse next to the triangles (1e5 with triangles
        // of 1e-2), queries between f32 values: the f32 boxes must still never skip a
        // triangle the exact f64 answer needs.
        let (p, t) = soup(400, 9);
        let offset = DVec3::new(1.0e5, -3.0e4, 7.0e3);
        let p: Vec<DVec3> = p.iter().map(|v| offset + *v * 0.1).collect();
        let index = SurfaceIndex::new(&p, &t).expect("valid");
        let mut rng = Rng::new(10);
        for k in 0..300 {
            let u = DVec3::new(
                f64::from(rng.uniform_f32()),
                f64::from(rng.uniform_f32()),
                f64::from(rng.uniform_f32()),
            );
            let q = offset + (u * 1.4 - 0.2) * 0.1 + DVec3::splat(1.0e-7 * f64::from(k % 7));
            let (d2, id) = t
                .iter()
                .enumerate()
                .map(|(i, tri)| {
                    let [a, b, c] = tri.map(|v| p[v as usize]);
                    (
                        (closest_point_on_triangle(q, a, b, c).0 - q).length_squared(),
                        i as u32,
                    )
                })
                .fold((f64::INFINITY, u32::MAX), |x, y| if y < x { y } else { x });
            let hit = index.closest(q).expect("finite");
            assert_eq!((hit.distance, hit.triangle), (d2.sqrt(), id), "{k}");
        }
        // f32 queries there too, through the batch (each bounded by the previous answer).
        let queries: Vec<Vec3> = p.iter().step_by(3).map(|v| v.as_vec3()).collect();
        let bvh = TriangleBvh::from_triangles(&p, &t).expect("valid");
        let got = index.closest_batch(&queries).expect("finite");
        let want = bvh.closest_points(&queries).expect("finite");
        for (g, w) in got.iter().zip(&want) {
            assert_eq!((g.distance, g.triangle), (w.distance, w.triangle));
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let p = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
        assert!(matches!(
            SurfaceIndex::new(&p, &[]),
            Err(SpatialError::Empty)
        ));
        assert!(matches!(
            SurfaceIndex::new(&p, &[[0, 1, 3]]),
            Err(SpatialError::BadIndex { triangle: 0, .. })
        ));
        let index = SurfaceIndex::new(&p, &[[0, 1, 2]]).expect("valid");
        assert_eq!(index.closest(DVec3::NAN), None);
        assert!(index.closest_batch(&[Vec3::ZERO, Vec3::NAN]).is_err());
        let mesh = TriMesh::new(p, vec![[0, 1, 2]]);
        let hit = index.closest(DVec3::new(0.25, 0.25, 2.0)).expect("finite");
        assert_eq!((hit.distance, hit.triangle), (2.0, 0));
        assert_eq!(mesh.triangle_count(), index.triangle_count());
    }
}
