//! The k-d tree behind [`super::PointIndex`]: exact nearest and k-nearest neighbours of f32
//! points, ranked by f64 squared distance and then by id, as brute force ranks them.
//!
//! # Layout
//! A complete binary tree of `depth` levels over `n` points: every node halves its range of
//! points (`mid = lo + (hi - lo) / 2`) at the median along the widest axis of its points'
//! bounding box (`select_nth_unstable`), so a node's range follows from its parent's and is not
//! stored. Each node keeps its points' tight bounding box (f32); the nodes are kept in
//! pre-order, so a subtree's nodes are one contiguous slice (built in parallel with
//! `rayon::join`). The points of the leaves (at most [`LEAF`] each) are stored in tree order as
//! a structure of arrays of f32 coordinates and ids.
//!
//! # Exactness
//! A candidate's squared distance is `dx * dx + dy * dy + dz * dz` in f64 from the f32
//! coordinates, `d = q - p` per axis: the expression of [`super::distance_f64`], so the
//! distance reported is that of a brute-force scan to the bit. A subtree is skipped only when
//! the squared distance from the query to its bounding box, `ox² + oy² + oz²` with `o` the f64
//! differences to the box's faces, is *greater* than the best so far. Rounding is monotone, so that bound never
//! exceeds the computed squared distance of a point in the cell, and equality is searched: the
//! answer is the minimum of `(squared distance, id)` over all points, ties included.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// Most points in a leaf.
pub(crate) const LEAF: usize = 16;
const _: () = assert!(
    LEAF.is_multiple_of(4),
    "leaf scans take the minimum four lanes at a time"
);

/// Subtrees of more points than this are built in parallel.
const PARALLEL_BUILD: usize = 1 << 15;

/// Queries answered in one task by [`PointTree::nearest_to_tree`] (more are split in two).
const PARALLEL_SWEEP: usize = 1 << 12;

/// Most leaves listed for one group of queries by [`PointTree::nearest_to_tree`]; a group
/// that would need more (its points far apart, around a gap) searches query by query.
const MAX_GROUP_LEAVES: usize = 64;

/// What one task of [`PointTree::nearest_to_tree`] reuses from group to group: the list of
/// leaves, and the cursor of the groups searched query by query.
#[derive(Debug, Default)]
struct Scratch {
    leaves: Vec<LeafRef>,
    cursor: Cursor,
}

/// A leaf of the tree listed for a group of queries: its squared distance to the group's box
/// ([`Node::gap_sq`]), its node and its slots `lo..hi`.
#[derive(Clone, Copy, Debug)]
struct LeafRef {
    gap_sq: f64,
    node: u32,
    lo: u32,
    hi: u32,
}

/// A node: the bounding box of its points.
#[derive(Clone, Copy, Debug, Default)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
}

impl Node {
    /// Squared distance from `q` to the box, rounded no higher than that of any point in it.
    #[inline(always)]
    fn dist_sq(&self, q: DVec3) -> f64 {
        let o = |a: usize, q: f64| {
            let below = f64::from(self.lo[a]) - q;
            let above = q - f64::from(self.hi[a]);
            let out = if below > above { below } else { above };
            if out > 0.0 { out } else { 0.0 }
        };
        let (x, y, z) = (o(0, q.x), o(1, q.y), o(2, q.z));
        x * x + y * y + z * z
    }

    /// Squared distance between this box and `other`, rounded no higher than that of any
    /// point of one to any point of the other (each gap is the difference of two f32 bounds
    /// in f64, and rounding is monotone).
    #[inline(always)]
    fn gap_sq(&self, other: &Node) -> f64 {
        let o = |a: usize| {
            let below = f64::from(self.lo[a]) - f64::from(other.hi[a]);
            let above = f64::from(other.lo[a]) - f64::from(self.hi[a]);
            let out = if below > above { below } else { above };
            if out > 0.0 { out } else { 0.0 }
        };
        let (x, y, z) = (o(0), o(1), o(2));
        x * x + y * y + z * z
    }
}

/// How an internal node splits its points: those of the left half have
/// `coordinate[axis] <= value`, those of the right half `>= value`.
#[derive(Clone, Copy, Debug, Default)]
struct Split {
    value: f32,
    axis: u32,
}

/// A node on the way from the root to a query, with its cell (the region its splits bound:
/// every point of the tree inside it, strictly, is in the node's subtree).
#[derive(Clone, Copy, Debug)]
struct Frame {
    node: u32,
    height: u32,
    lo: u32,
    hi: u32,
    cell_lo: [f32; 3],
    cell_hi: [f32; 3],
}

impl Frame {
    /// Whether every point outside this node's subtree is farther from `q` than
    /// `sqrt(dist_sq)`: `q` is in the cell and each face's squared distance, rounded as a
    /// point's would be (monotone), exceeds `dist_sq`.
    #[inline]
    fn holds_ball(&self, q: DVec3, dist_sq: f64) -> bool {
        (0..3).all(|a| {
            let below = q[a] - f64::from(self.cell_lo[a]);
            let above = f64::from(self.cell_hi[a]) - q[a];
            below >= 0.0 && above >= 0.0 && below * below > dist_sq && above * above > dist_sq
        })
    }
}

/// Where the previous query of a run of nearby queries ended: its answer's slot and the nodes
/// from the root down to the subtree it was searched in (see [`PointTree::nearest_after`]).
#[derive(Clone, Debug, Default)]
pub(crate) struct Cursor {
    stack: Vec<Frame>,
    answer: Option<u32>,
}

/// One point during the build.
#[derive(Clone, Copy, Debug)]
struct Record {
    p: [f32; 3],
    id: u32,
}

/// The best candidate so far: squared distance, id, and slot (position in tree order).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Best {
    pub(crate) dist_sq: f64,
    pub(crate) id: u32,
    pub(crate) slot: u32,
}

impl Best {
    /// No candidate yet.
    pub(crate) const NONE: Self = Self {
        dist_sq: f64::INFINITY,
        id: u32::MAX,
        slot: u32::MAX,
    };

    #[inline]
    fn beaten_by(&self, dist_sq: f64, id: u32) -> bool {
        dist_sq < self.dist_sq || (dist_sq == self.dist_sq && id < self.id)
    }
}

/// A static k-d tree over at least one point.
#[derive(Clone, Debug)]
pub(crate) struct PointTree {
    /// All nodes in pre-order (`2^(depth + 1) - 1` of them).
    nodes: Vec<Node>,
    /// The split of each internal node (same indices; unused for leaves).
    splits: Vec<Split>,
    depth: u32,
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
    ids: Vec<u32>,
}

/// Squared distance as [`super::distance_f64`] computes it (before the square root).
#[inline(always)]
fn dist_sq(q: DVec3, x: f32, y: f32, z: f32) -> f64 {
    let dx = q.x - f64::from(x);
    let dy = q.y - f64::from(y);
    let dz = q.z - f64::from(z);
    dx * dx + dy * dy + dz * dz
}

impl PointTree {
    /// Builds the tree over `points` (finite, at least one) with the given ids (one per point),
    /// or with ids `0, 1, 2, ...` when `ids` is `None`.
    pub(crate) fn new(points: &[Vec3], ids: Option<&[u32]>) -> Self {
        debug_assert!(ids.is_none_or(|ids| ids.len() == points.len()));
        let n = points.len();
        let mut depth = 0u32;
        while n.div_ceil(1 << depth) > LEAF {
            depth += 1;
        }
        let mut records: Vec<Record> = points
            .par_iter()
            .enumerate()
            .map(|(i, p)| Record {
                p: p.to_array(),
                id: ids.map_or(i as u32, |ids| ids[i]),
            })
            .collect();
        let mut nodes = vec![Node::default(); (2usize << depth) - 1];
        let mut splits = vec![Split::default(); nodes.len()];
        let room = bounds(&records);
        build(&mut records, &mut nodes, &mut splits, depth, room);
        let column = |f: fn(&Record) -> f32| records.par_iter().map(f).collect::<Vec<f32>>();
        let (xs, ys, zs) = (column(|r| r.p[0]), column(|r| r.p[1]), column(|r| r.p[2]));
        let ids = records.par_iter().map(|r| r.id).collect();
        Self {
            nodes,
            splits,
            depth,
            xs,
            ys,
            zs,
            ids,
        }
    }

    /// Number of points.
    pub(crate) fn len(&self) -> usize {
        self.ids.len()
    }

    /// The point in tree slot `slot`.
    #[inline]
    pub(crate) fn point(&self, slot: usize) -> Vec3 {
        Vec3::new(self.xs[slot], self.ys[slot], self.zs[slot])
    }

    /// The id of tree slot `slot`.
    #[inline]
    pub(crate) fn id(&self, slot: usize) -> u32 {
        self.ids[slot]
    }

    /// The nearest point to `q`: the least `(squared distance, id)`, searched from the root.
    pub(crate) fn nearest(&self, q: DVec3) -> Best {
        let mut best = Best::NONE;
        self.search_nearest(0, self.depth, 0, self.len(), q, &mut best);
        best
    }

    /// [`PointTree::nearest`] for a query near the previous one of `cursor`: the previous
    /// answer is the first candidate, and the search starts at the deepest node on the way to
    /// `q` whose cell holds the ball around `q` through that candidate (every point outside
    /// is farther), reached by going up from where the previous query's search started and
    /// down again. The answer is the same as from the root.
    pub(crate) fn nearest_after(&self, q: DVec3, cursor: &mut Cursor) -> Best {
        let mut best = Best::NONE;
        if let Some(slot) = cursor.answer {
            let s = slot as usize;
            best = Best {
                dist_sq: dist_sq(q, self.xs[s], self.ys[s], self.zs[s]),
                id: self.ids[s],
                slot,
            };
        }
        let stack = &mut cursor.stack;
        if stack.is_empty() {
            stack.push(Frame {
                node: 0,
                height: self.depth,
                lo: 0,
                hi: self.len() as u32,
                cell_lo: [f32::NEG_INFINITY; 3],
                cell_hi: [f32::INFINITY; 3],
            });
        }
        while stack.len() > 1 && !stack[stack.len() - 1].holds_ball(q, best.dist_sq) {
            stack.pop();
        }
        loop {
            let top = stack[stack.len() - 1];
            if top.height == 0 {
                break;
            }
            let split = self.splits[top.node as usize];
            let axis = split.axis as usize;
            let mid = top.lo + (top.hi - top.lo) / 2;
            let mut child = top;
            child.height -= 1;
            if q[axis] <= f64::from(split.value) {
                child.node += 1;
                child.hi = mid;
                child.cell_hi[axis] = split.value;
            } else {
                child.node += 1 << top.height;
                child.lo = mid;
                child.cell_lo[axis] = split.value;
            }
            if !child.holds_ball(q, best.dist_sq) {
                break;
            }
            stack.push(child);
        }
        let top = stack[stack.len() - 1];
        self.search_nearest(
            top.node as usize,
            top.height,
            top.lo as usize,
            top.hi as usize,
            q,
            &mut best,
        );
        cursor.answer = Some(best.slot);
        best
    }

    fn search_nearest(
        &self,
        node: usize,
        height: u32,
        lo: usize,
        hi: usize,
        q: DVec3,
        best: &mut Best,
    ) {
        if height == 0 {
            self.scan_leaf(lo, hi, q, best);
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let left = node + 1;
        let right = node + (1 << height);
        let dl = self.nodes[left].dist_sq(q);
        let dr = self.nodes[right].dist_sq(q);
        if dl <= dr {
            if dl <= best.dist_sq {
                self.search_nearest(left, height - 1, lo, mid, q, best);
                if dr <= best.dist_sq {
                    self.search_nearest(right, height - 1, mid, hi, q, best);
                }
            }
        } else if dr <= best.dist_sq {
            self.search_nearest(right, height - 1, mid, hi, q, best);
            if dl <= best.dist_sq {
                self.search_nearest(left, height - 1, lo, mid, q, best);
            }
        }
    }

    /// Offers the points of slots `lo..hi` (one leaf, at most [`LEAF`]) to `best`. The
    /// squared distances are computed first, all of them, without a branch (two f64 lanes at
    /// a time), and the leaf is passed over when none is within `best`; only then are they
    /// compared one by one, with the ids of ties.
    #[inline]
    fn scan_leaf(&self, lo: usize, hi: usize, q: DVec3, best: &mut Best) {
        let (xs, ys, zs) = (&self.xs[lo..hi], &self.ys[lo..hi], &self.zs[lo..hi]);
        let mut dists = [f64::INFINITY; LEAF];
        for (((d, &x), &y), &z) in dists.iter_mut().zip(xs).zip(ys).zip(zs) {
            *d = dist_sq(q, x, y, z);
        }
        // Four running minima (no chain of dependent comparisons), then the least of them.
        let mut low = [f64::INFINITY; 4];
        for four in dists.chunks_exact(4) {
            for (m, &d) in low.iter_mut().zip(four) {
                *m = if d < *m { d } else { *m };
            }
        }
        let least = low
            .iter()
            .fold(f64::INFINITY, |m, &d| if d < m { d } else { m });
        if least > best.dist_sq {
            return;
        }
        for (j, &d) in dists[..xs.len()].iter().enumerate() {
            if d <= best.dist_sq {
                let slot = lo + j;
                let id = self.ids[slot];
                if best.beaten_by(d, id) {
                    *best = Best {
                        dist_sq: d,
                        id,
                        slot: slot as u32,
                    };
                }
            }
        }
    }

    /// The nearest point of `self` to every point of `queries` (another tree), by the
    /// queries' slots: `result[s]` answers `queries.point(s)`. The queries go a leaf of
    /// `queries` at a time (at most [`LEAF`] points in a tight box): the leaf of `self` holding
    /// the box's centre is scanned for each, which bounds every answer by the largest `bound`
    /// of those distances; the other leaves of `self` within `sqrt(bound)` of the box are
    /// listed once, nearest to the box first, and each query scans those of them whose box is
    /// within its best so far, stopping at the first listed leaf farther from the group's box
    /// than that. Every point nearer than a query's answer lies in a listed leaf (the box
    /// distances are rounded no higher than a point's), so the answer is
    /// [`PointTree::nearest`]'s, ties included. A group whose list would pass
    /// [`MAX_GROUP_LEAVES`] searches query by query instead ([`PointTree::nearest_after`],
    /// one cursor per task).
    pub(crate) fn nearest_to_tree(&self, queries: &PointTree) -> Vec<Best> {
        let mut out = vec![Best::NONE; queries.len()];
        self.sweep(
            queries,
            0,
            queries.depth,
            0,
            &mut out,
            &mut Scratch::default(),
        );
        out
    }

    /// [`PointTree::nearest_to_tree`] for the subtree of `queries` at `node` (of `height`
    /// levels, slots from `lo`), answers into `out` (its slots' length); in parallel above
    /// [`PARALLEL_SWEEP`] queries. `leaves` is the scratch list of one group's leaves.
    fn sweep(
        &self,
        queries: &PointTree,
        node: usize,
        height: u32,
        lo: usize,
        out: &mut [Best],
        scratch: &mut Scratch,
    ) {
        if height == 0 {
            self.answer_group(queries, node, lo, out, scratch);
            return;
        }
        let half = out.len() / 2;
        let (left, right) = out.split_at_mut(half);
        let (l, r) = (node + 1, node + (1 << height));
        if left.len() + right.len() > PARALLEL_SWEEP {
            rayon::join(
                || self.sweep(queries, l, height - 1, lo, left, &mut Scratch::default()),
                || {
                    let mut scratch = Scratch::default();
                    self.sweep(queries, r, height - 1, lo + half, right, &mut scratch);
                },
            );
        } else {
            self.sweep(queries, l, height - 1, lo, left, scratch);
            self.sweep(queries, r, height - 1, lo + half, right, scratch);
        }
    }

    /// Answers the queries of one leaf of `queries` (`node`, slots `lo..lo + out.len()`).
    fn answer_group(
        &self,
        queries: &PointTree,
        node: usize,
        lo: usize,
        out: &mut [Best],
        scratch: &mut Scratch,
    ) {
        let leaves = &mut scratch.leaves;
        let group = queries.nodes[node];
        let centre = DVec3::from_array(
            [0, 1, 2].map(|a| 0.5 * (f64::from(group.lo[a]) + f64::from(group.hi[a]))),
        );
        // The leaf of `self` whose cell holds the centre.
        let (mut at, mut height, mut a, mut b) = (0usize, self.depth, 0usize, self.len());
        while height > 0 {
            let split = self.splits[at];
            let mid = a + (b - a) / 2;
            if centre[split.axis as usize] <= f64::from(split.value) {
                at += 1;
                b = mid;
            } else {
                at += 1 << height;
                a = mid;
            }
            height -= 1;
        }
        let home = at;
        let mut bound = 0.0f64;
        for (k, best) in out.iter_mut().enumerate() {
            *best = Best::NONE;
            self.scan_leaf(a, b, queries.point(lo + k).as_dvec3(), best);
            bound = bound.max(best.dist_sq);
        }
        leaves.clear();
        let listed = self.collect_leaves(0, self.depth, 0, self.len(), &group, bound, home, leaves);
        // Nearest to the group first: a query stops at the first leaf farther from the group
        // than its best so far (no point of it or of the rest can be nearer).
        leaves.sort_unstable_by(|x, y| x.gap_sq.total_cmp(&y.gap_sq).then(x.node.cmp(&y.node)));
        for (k, best) in out.iter_mut().enumerate() {
            let q = queries.point(lo + k).as_dvec3();
            if listed {
                for leaf in leaves.iter() {
                    if leaf.gap_sq > best.dist_sq {
                        break;
                    }
                    if self.nodes[leaf.node as usize].dist_sq(q) <= best.dist_sq {
                        self.scan_leaf(leaf.lo as usize, leaf.hi as usize, q, best);
                    }
                }
            } else {
                *best = self.nearest_after(q, &mut scratch.cursor);
            }
        }
    }

    /// Lists into `leaves` the leaves under `node` (of `height` levels, slots `lo..hi`) other
    /// than `home` whose box's squared distance to `group`'s box is at most `bound`; false
    /// (the list abandoned) when there are more than [`MAX_GROUP_LEAVES`].
    #[expect(
        clippy::too_many_arguments,
        reason = "the recursion's state: node, height, range, group box, bound, home, list"
    )]
    fn collect_leaves(
        &self,
        node: usize,
        height: u32,
        lo: usize,
        hi: usize,
        group: &Node,
        bound: f64,
        home: usize,
        leaves: &mut Vec<LeafRef>,
    ) -> bool {
        let gap_sq = self.nodes[node].gap_sq(group);
        if gap_sq > bound {
            return true;
        }
        if height == 0 {
            if node != home {
                if leaves.len() == MAX_GROUP_LEAVES {
                    return false;
                }
                leaves.push(LeafRef {
                    gap_sq,
                    node: node as u32,
                    lo: lo as u32,
                    hi: hi as u32,
                });
            }
            return true;
        }
        let mid = lo + (hi - lo) / 2;
        self.collect_leaves(node + 1, height - 1, lo, mid, group, bound, home, leaves)
            && self.collect_leaves(
                node + (1 << height),
                height - 1,
                mid,
                hi,
                group,
                bound,
                home,
                leaves,
            )
    }

    /// The `k` nearest points to `q` (fewer when the tree has fewer), ascending by
    /// `(squared distance, id)`, as `(squared distance, slot)`.
    pub(crate) fn k_nearest(&self, q: DVec3, k: usize) -> Vec<(f64, u32, u32)> {
        let mut found: Vec<(f64, u32, u32)> = Vec::with_capacity(k.min(self.len()) + 1);
        if k == 0 {
            return found;
        }
        self.search_k(0, self.depth, 0, self.len(), q, k, &mut found);
        found
    }

    #[expect(
        clippy::too_many_arguments,
        reason = "the recursion's state: node, height, range, query, k, found"
    )]
    fn search_k(
        &self,
        node: usize,
        height: u32,
        lo: usize,
        hi: usize,
        q: DVec3,
        k: usize,
        found: &mut Vec<(f64, u32, u32)>,
    ) {
        if height == 0 {
            for slot in lo..hi {
                let d = dist_sq(q, self.xs[slot], self.ys[slot], self.zs[slot]);
                let id = self.ids[slot];
                if found.len() == k {
                    let &(wd, wid, _) = found.last().unwrap_or(&(f64::INFINITY, u32::MAX, 0));
                    if !(d < wd || (d == wd && id < wid)) {
                        continue;
                    }
                    found.pop();
                }
                let at = found.partition_point(|&(fd, fid, _)| fd < d || (fd == d && fid < id));
                found.insert(at, (d, id, slot as u32));
            }
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let left = (node + 1, lo, mid, self.nodes[node + 1].dist_sq(q));
        let right = (
            node + (1 << height),
            mid,
            hi,
            self.nodes[node + (1 << height)].dist_sq(q),
        );
        let (near, far) = if left.3 <= right.3 {
            (left, right)
        } else {
            (right, left)
        };
        for (child, child_lo, child_hi, bound) in [near, far] {
            if found.len() < k || found.last().is_some_and(|&(wd, _, _)| bound <= wd) {
                self.search_k(child, height - 1, child_lo, child_hi, q, k, found);
            }
        }
    }
}

/// Builds the subtree of `height` levels over `records` into `nodes` and `splits` (its
/// pre-order slices): unless `height` is 0, splits the records at their median along the
/// widest axis of `room` (a box around them: the parent's room cut at its split, so no pass
/// over the records is needed to choose) and builds both halves; then records the subtree's
/// tight bounding box, a leaf's from its points, a node's as the union of its children's.
fn build(
    records: &mut [Record],
    nodes: &mut [Node],
    splits: &mut [Split],
    height: u32,
    room: Node,
) {
    if height == 0 {
        nodes[0] = bounds(records);
        return;
    }
    let extent = [0, 1, 2].map(|a| f64::from(room.hi[a]) - f64::from(room.lo[a]));
    let mut axis = 0;
    for a in 1..3 {
        if extent[a] > extent[axis] {
            axis = a;
        }
    }
    let mid = records.len() / 2;
    let value = match axis {
        0 => select_median::<0>(records, mid),
        1 => select_median::<1>(records, mid),
        _ => select_median::<2>(records, mid),
    };
    splits[0] = Split {
        value,
        axis: axis as u32,
    };
    let (mut left_room, mut right_room) = (room, room);
    left_room.hi[axis] = value;
    right_room.lo[axis] = value;
    let (left_nodes, right_nodes) = nodes[1..].split_at_mut((1 << height) - 1);
    let (left_splits, right_splits) = splits[1..].split_at_mut((1 << height) - 1);
    let (left, right) = records.split_at_mut(mid);
    if left.len() + right.len() > PARALLEL_BUILD {
        rayon::join(
            || build(left, left_nodes, left_splits, height - 1, left_room),
            || build(right, right_nodes, right_splits, height - 1, right_room),
        );
    } else {
        build(left, left_nodes, left_splits, height - 1, left_room);
        build(right, right_nodes, right_splits, height - 1, right_room);
    }
    let (l, r) = (left_nodes[0], right_nodes[0]);
    nodes[0] = Node {
        lo: [0, 1, 2].map(|a| if r.lo[a] < l.lo[a] { r.lo[a] } else { l.lo[a] }),
        hi: [0, 1, 2].map(|a| if r.hi[a] > l.hi[a] { r.hi[a] } else { l.hi[a] }),
    };
}

/// Puts the record of rank `mid` along axis `A` at `mid` (the less before, the greater after)
/// and returns its coordinate; one copy per axis, so the comparison reads a fixed field.
fn select_median<const A: usize>(records: &mut [Record], mid: usize) -> f32 {
    let (_, median, _) = records.select_nth_unstable_by(mid, |a, b| {
        a.p[A]
            .partial_cmp(&b.p[A])
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    median.p[A]
}

/// The bounding box of the records.
fn bounds(records: &[Record]) -> Node {
    let mut node = Node {
        lo: [f32::INFINITY; 3],
        hi: [f32::NEG_INFINITY; 3],
    };
    for r in records {
        for a in 0..3 {
            if r.p[a] < node.lo[a] {
                node.lo[a] = r.p[a];
            }
            if r.p[a] > node.hi[a] {
                node.hi[a] = r.p[a];
            }
        }
    }
    node
}
