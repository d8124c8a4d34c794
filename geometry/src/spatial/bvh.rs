//! A BVH over a mesh's triangles (obvhs 0.4) with exact closest-point and closest-hit queries,
//! refittable when the triangles move.
//!
//! One PLOC-built binary tree (`Bvh2`, one triangle per leaf) serves the closest-point queries,
//! which obvhs does not have: a depth-first search over its public nodes, nearer child first,
//! pruning boxes whose f64 distance exceeds the best squared distance found so far, with
//! Ericson's closest point on a triangle in f64 at the leaves. The same tree converted to a
//! compressed wide BVH (`CwBvh`, built on the first ray) serves ray casting: obvhs' `Bvh2` ray
//! traversal missed hits for rays with an exactly-zero direction component, the `CwBvh` one
//! does not (tested below).
//!
//! Leaf boxes are padded by [`BOX_PADDING`] times the mesh's bounding-box diagonal plus the same
//! fraction of each coordinate's magnitude, so that f32 rounding in obvhs' slab tests, and in
//! the f32 range tests below, can never cull a triangle that is within reach (rays along an
//! edge, through a vertex, or axis-aligned in the plane of a face; a query whose bound ties a
//! triangle's distance). The padding only makes the culling more conservative; the answers are
//! computed exactly (f64) from the triangles.
//!
//! A mesh that moves keeps its tree: [`TriangleBvh::refit`] moves the corners and recomputes the
//! boxes bottom-up, which is what an animated template needs per frame (the incremental Delaunay
//! mesher searches the deformed template this way). Besides the closest point, the tree answers
//! the queries such a mesher needs: the nearest triangle below a bound
//! ([`TriangleBvh::nearest_below`]), every triangle within a radius
//! ([`TriangleBvh::triangles_within`]), and the *frontier* of a set of triangles, the subtrees
//! holding every other triangle ([`TriangleBvh::frontier`], [`TriangleBvh::any_within`]).

use std::sync::OnceLock;

use glam::{DVec3, Vec3, Vec3A};
use obvhs::aabb::Aabb as BvhAabb;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::ploc::{PlocBuilder, PlocSearchDistance, SortPrecision};
use obvhs::ray::{Ray, RayHit as ObvhsRayHit};
use obvhs::triangle::Triangle;
use rayon::prelude::*;

use super::error::SpatialError;
use super::limits::{check_dpoints, check_points};
use super::morton::morton_order;
use crate::mesh::TriMesh;

/// Leaf boxes grow by this fraction of the mesh's bounding-box diagonal, plus this fraction of
/// each coordinate's magnitude (see the module docs). Rays whose origin lies within about 100
/// diagonals of the mesh keep f32 slab errors below it.
pub const BOX_PADDING: f32 = 1e-5;

/// A triangle is treated as degenerate (a segment or a point) when its squared doubled area
/// `|(b - a) x (c - a)|^2` is at most this fraction of the fourth power of its longest edge,
/// i.e. when it is flatter than about 1e-7 relative.
pub const DEGENERATE_TRIANGLE: f64 = 1e-14;

/// Ray hits within this barycentric distance outside a triangle still count, so that a ray
/// through a shared edge or vertex hits at least one of the triangles despite f64 rounding.
pub const RAY_EDGE_TOLERANCE: f64 = 1e-12;

/// obvhs' `CwBvh` ray traversal ignores node boxes that end before `t = 1e-4` along the ray
/// (its private `EPSILON`). Rays are handed to it with a unit direction, starting this many
/// world units behind their true origin, so that hits near `t = 0` are found; the hits
/// themselves are computed from the true origin.
const RAY_BACKOFF: f32 = 2e-4;

/// `parent` of the root node.
const NO_NODE: u32 = u32::MAX;

/// The closest point of a mesh's surface to a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosestPoint {
    /// Euclidean distance from the query (f64).
    pub distance: f64,
    /// The closest point on the surface.
    pub point: DVec3,
    /// The triangle it lies on (the smallest id among exactly equidistant triangles).
    pub triangle: u32,
    /// Barycentric weights of the triangle's corners `[a, b, c]` (non-negative, sum 1).
    pub barycentric: [f64; 3],
}

/// The first triangle a ray hits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Ray parameter of the hit: the point is `origin + t * direction` (in units of the given
    /// direction's length).
    pub t: f64,
    /// The triangle hit.
    pub triangle: u32,
    /// Barycentric weights of the triangle's corners `[a, b, c]`.
    pub barycentric: [f64; 3],
}

/// A candidate of [`TriangleBvh::nearest_below`]: squared distance and triangle id, ordered
/// lexicographically (ties go to the smaller id).
pub type Candidate = (f64, u32);

/// A BVH over the triangles of a mesh (it copies the triangle corners; the mesh is not
/// borrowed). An empty mesh gives an empty BVH whose queries return `None`.
pub struct TriangleBvh {
    bvh2: Bvh2,
    /// The ray-casting tree, converted from `bvh2` on the first ray (and again after a refit).
    cwbvh: OnceLock<CwBvh>,
    /// Vertex indices of every triangle (kept for [`TriangleBvh::refit`]).
    triangles: Vec<[u32; 3]>,
    /// Corners of every triangle, indexed by the mesh's triangle id.
    corners: Vec<[DVec3; 3]>,
    /// Leaf node of each triangle.
    leaf_of: Vec<u32>,
    /// Parent of each node ([`NO_NODE`] for the root).
    parent: Vec<u32>,
    /// Absolute part of the box padding: [`BOX_PADDING`] times the diagonal at build time.
    padding: f32,
    /// Ray back-off in world units (see [`RAY_BACKOFF`]).
    backoff: f32,
}

impl std::fmt::Debug for TriangleBvh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TriangleBvh")
            .field("triangles", &self.corners.len())
            .field("nodes", &self.bvh2.nodes.len())
            .finish_non_exhaustive()
    }
}

impl TriangleBvh {
    /// Builds the BVH over a mesh's triangles (PLOC with reinsertion optimisation, as obvhs'
    /// `medium_build`, without spatial splits).
    ///
    /// # Errors
    /// [`SpatialError::TooLarge`] when a vertex exceeds [`super::MAX_COORDINATE`] in
    /// magnitude ([`TriMesh`] positions are already finite), [`SpatialError::TooMany`] past
    /// `u32::MAX` triangles.
    pub fn new(mesh: &TriMesh) -> Result<Self, SpatialError> {
        Self::from_triangles(mesh.positions(), mesh.triangles())
    }

    /// Builds the BVH over `triangles` (vertex indices into `positions`).
    ///
    /// # Errors
    /// [`SpatialError::NonFinite`] or [`SpatialError::TooLarge`] naming the first bad vertex,
    /// [`SpatialError::BadIndex`] for a triangle naming a vertex past the end,
    /// [`SpatialError::TooMany`] past `u32::MAX` triangles.
    pub fn from_triangles(
        positions: &[DVec3],
        triangles: &[[u32; 3]],
    ) -> Result<Self, SpatialError> {
        check_dpoints(positions)?;
        check_indices(positions.len(), triangles)?;
        let n = triangles.len();
        if u32::try_from(n).is_err() {
            return Err(SpatialError::TooMany { count: n });
        }
        let corners = gather_corners(positions, triangles);
        let diagonal = crate::mesh::Aabb::from_dpoints(positions).map_or(0.0, |b| b.diagonal());
        let padding = (diagonal * f64::from(BOX_PADDING)) as f32;
        let mut bvh2 = if n == 0 {
            Bvh2::default()
        } else {
            let primitives: Vec<Triangle> = corners
                .par_iter()
                .map(|&[a, b, c]| Triangle {
                    v0: a.as_vec3().into(),
                    v1: b.as_vec3().into(),
                    v2: c.as_vec3().into(),
                })
                .collect();
            let mut bvh2 = PlocBuilder::with_capacity(n).build(
                PlocSearchDistance::Medium,
                &primitives,
                (0..n as u32).collect(),
                SortPrecision::U64,
                3,
            );
            ReinsertionOptimizer::default().run(&mut bvh2, 0.05, None);
            bvh2
        };
        let (leaf_of, parent) = links(&bvh2, n);
        set_leaf_boxes(&mut bvh2, &corners, padding);
        bvh2.refit_all();
        Ok(Self {
            bvh2,
            cwbvh: OnceLock::new(),
            triangles: triangles.to_vec(),
            corners,
            leaf_of,
            parent,
            padding,
            backoff: RAY_BACKOFF.max(2.0 * padding),
        })
    }

    /// Moves the triangles to new vertex `positions` (same vertex count and triangles) and
    /// refits the boxes bottom-up; the tree's shape is kept, so queries stay exact but may get
    /// slower when the mesh moves far from the pose it was built in.
    ///
    /// # Errors
    /// [`SpatialError::NonFinite`] or [`SpatialError::TooLarge`] naming the first bad vertex,
    /// [`SpatialError::BadIndex`] when `positions` is shorter than the triangles need; the tree
    /// is unchanged then.
    pub fn refit(&mut self, positions: &[DVec3]) -> Result<(), SpatialError> {
        check_dpoints(positions)?;
        check_indices(positions.len(), &self.triangles)?;
        self.corners = gather_corners(positions, &self.triangles);
        set_leaf_boxes(&mut self.bvh2, &self.corners, self.padding);
        self.bvh2.refit_all();
        self.cwbvh = OnceLock::new();
        Ok(())
    }

    /// Number of triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.corners.len()
    }

    /// Number of tree nodes (node ids of [`TriangleBvh::frontier`] are below it).
    #[must_use]
    pub fn node_count(&self) -> usize {
        self.bvh2.nodes.len()
    }

    /// The corners of triangle `t` as stored (mesh order), if it exists.
    #[must_use]
    pub fn corners(&self, t: usize) -> Option<[DVec3; 3]> {
        self.corners.get(t).copied()
    }

    /// Squared distance from `q` to triangle `t` (as [`closest_point_on_triangle`], f64) and the
    /// barycentric weights of the closest point; infinite for a triangle past the end.
    #[must_use]
    pub fn distance_sq(&self, q: DVec3, t: u32) -> (f64, [f64; 3]) {
        match self.corners.get(t as usize) {
            Some(&[a, b, c]) => {
                let (p, bary) = closest_point_on_triangle(q, a, b, c);
                ((p - q).length_squared(), bary)
            }
            None => (f64::INFINITY, [1.0 / 3.0; 3]),
        }
    }

    /// The padded box of triangle `t`'s leaf as `(min, max)` in f64 (its squared distance
    /// from a point is a lower bound of the triangle's); an infinite box past the end.
    #[must_use]
    pub fn leaf_box(&self, t: u32) -> (DVec3, DVec3) {
        self.leaf_of
            .get(t as usize)
            .and_then(|&l| self.bvh2.nodes.get(l as usize))
            .map_or((DVec3::NEG_INFINITY, DVec3::INFINITY), |n| {
                let b = n.aabb();
                (Vec3::from(b.min).as_dvec3(), Vec3::from(b.max).as_dvec3())
            })
    }

    /// The closest point of the surface to `query` (f32 or f64: an f64 query far from the
    /// origin is answered exactly too); `None` for an empty mesh or a query that is not
    /// finite. Exact up to f64 rounding: the answer equals the minimum over all triangles
    /// of [`closest_point_on_triangle`].
    #[must_use]
    pub fn closest_point(&self, query: impl Into<DVec3>) -> Option<ClosestPoint> {
        let q: DVec3 = query.into();
        if !q.is_finite() {
            return None;
        }
        let (d2, triangle) = self.nearest_below(q, (f64::INFINITY, u32::MAX))?;
        let [a, b, c] = *self.corners.get(triangle as usize)?;
        let (point, barycentric) = closest_point_on_triangle(q, a, b, c);
        Some(ClosestPoint {
            distance: d2.sqrt(),
            point,
            triangle,
            barycentric,
        })
    }

    /// The lexicographically smallest `(squared distance, triangle)` over all triangles that
    /// is smaller than `bound`, or `None`. With `bound = (d², t)` for a triangle `t` already
    /// known, a result means that another triangle is strictly nearer (or as near with a
    /// smaller id); only boxes nearer than the bound are opened, so a good bound makes the
    /// search cheap.
    #[must_use]
    pub fn nearest_below(&self, q: DVec3, bound: Candidate) -> Option<Candidate> {
        let nodes = &self.bvh2.nodes;
        let root = nodes.first()?;
        let mut best = bound;
        let mut found = false;
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        stack.push((0, box_distance_sq(root.aabb(), q)));
        while let Some((index, lower)) = stack.pop() {
            if lower > best.0 {
                continue;
            }
            let Some(node) = nodes.get(index as usize) else {
                continue;
            };
            if node.is_leaf() {
                for slot in node.first_index..node.first_index.saturating_add(node.prim_count) {
                    let Some(&t) = self.bvh2.primitive_indices.get(slot as usize) else {
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
            let right = left.saturating_add(1);
            let (Some(ln), Some(rn)) = (nodes.get(left as usize), nodes.get(right as usize)) else {
                continue;
            };
            let dl = box_distance_sq(ln.aabb(), q);
            let dr = box_distance_sq(rn.aabb(), q);
            // Push the farther child first so the nearer one is searched first.
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

    /// Appends to `out` every triangle whose padded leaf box is within squared distance `r2`
    /// of `q` (a superset of the triangles within distance `√r2`), with a caller-owned
    /// traversal stack (no allocation once it has grown). The boxes are tested in f32: their
    /// padding ([`BOX_PADDING`]) is far above the f32 rounding of the test, so a triangle
    /// within `√r2` is never left out.
    pub fn triangles_within(&self, q: DVec3, r2: f64, out: &mut Vec<u32>, stack: &mut Vec<u32>) {
        let nodes = &self.bvh2.nodes;
        stack.clear();
        if nodes.is_empty() {
            return;
        }
        let near = near_test(q, r2);
        stack.push(0);
        while let Some(index) = stack.pop() {
            let Some(node) = nodes.get(index as usize) else {
                continue;
            };
            if !near(node) {
                continue;
            }
            if node.is_leaf() {
                for slot in node.first_index..node.first_index.saturating_add(node.prim_count) {
                    if let Some(&t) = self.bvh2.primitive_indices.get(slot as usize) {
                        out.push(t);
                    }
                }
            } else {
                stack.push(node.first_index);
                stack.push(node.first_index.saturating_add(1));
            }
        }
    }

    /// Fills `out` with the *frontier* of the triangles `inside`: nodes whose subtrees hold no
    /// triangle of `inside` and together hold every other triangle (the children, off the
    /// paths from the root to `inside`'s leaves, of nodes on those paths). `marks` is a
    /// per-node scratch array of at least [`TriangleBvh::node_count`] entries; `token` marks
    /// this call and must differ from every earlier token written to it.
    pub fn frontier(&self, inside: &[u32], marks: &mut [u32], token: u32, out: &mut Vec<u32>) {
        out.clear();
        let nodes = &self.bvh2.nodes;
        if nodes.is_empty() {
            return;
        }
        for &t in inside {
            let mut n = self.leaf_of.get(t as usize).copied().unwrap_or(NO_NODE);
            while let Some(m) = marks.get_mut(n as usize) {
                if *m == token {
                    break;
                }
                *m = token;
                n = self.parent.get(n as usize).copied().unwrap_or(NO_NODE);
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

    /// Whether a triangle under one of the nodes `roots` (ids from
    /// [`TriangleBvh::frontier`]) has its padded leaf box within squared distance `r2` of `q`
    /// (tested in f32 as [`TriangleBvh::triangles_within`]).
    #[must_use]
    pub fn any_within(&self, roots: &[u32], q: DVec3, r2: f64, stack: &mut Vec<u32>) -> bool {
        let nodes = &self.bvh2.nodes;
        let near = near_test(q, r2);
        let near = |i: u32| nodes.get(i as usize).is_some_and(&near);
        // Every node is tested once, before it is pushed.
        stack.clear();
        stack.extend(roots.iter().copied().filter(|&r| near(r)));
        while let Some(index) = stack.pop() {
            let Some(node) = nodes.get(index as usize) else {
                continue;
            };
            if node.is_leaf() {
                return true;
            }
            for child in [node.first_index, node.first_index.saturating_add(1)] {
                if near(child) {
                    stack.push(child);
                }
            }
        }
        false
    }

    /// [`TriangleBvh::closest_point`] for every query, in parallel (Morton order for cache
    /// locality); `result[i]` answers `queries[i]`, independent of the thread count.
    ///
    /// # Errors
    /// [`SpatialError::Empty`] when the mesh has no triangles; [`SpatialError::NonFinite`] or
    /// [`SpatialError::TooLarge`] naming the first bad query.
    pub fn closest_points(&self, queries: &[Vec3]) -> Result<Vec<ClosestPoint>, SpatialError> {
        if self.corners.is_empty() {
            return Err(SpatialError::Empty);
        }
        check_points(queries)?;
        let order = morton_order(queries);
        let sorted: Vec<Option<ClosestPoint>> = order
            .par_iter()
            .with_min_len(128)
            .map(|&i| self.closest_point(queries[i as usize]))
            .collect();
        let mut out = vec![None; queries.len()];
        for (cp, &i) in sorted.into_iter().zip(&order) {
            out[i as usize] = cp;
        }
        // Every query is finite and the mesh is not empty, so every answer exists.
        out.into_iter()
            .enumerate()
            .map(|(index, cp)| cp.ok_or(SpatialError::NonFinite { index }))
            .collect()
    }

    /// The first triangle hit by the ray `origin + t * direction`, `t` in `[0, t_max]`
    /// (`f64::INFINITY` for no limit). Both faces count; triangles parallel to the ray and
    /// degenerate triangles are never hit. `None` for a miss, an empty mesh, a zero or
    /// non-finite direction or a non-finite origin. The direction need not be unit length:
    /// `t` is in units of its length.
    #[must_use]
    pub fn cast_ray(&self, origin: Vec3, direction: Vec3, t_max: f64) -> Option<RayHit> {
        if self.corners.is_empty()
            || !origin.is_finite()
            || !direction.is_finite()
            || direction == Vec3::ZERO
            || t_max.is_nan()
            || t_max < 0.0
        {
            return None;
        }
        let o = origin.as_dvec3();
        let d = direction.as_dvec3();
        let length = d.length();
        let unit = (d / length).as_vec3a();
        let backoff = self.backoff;
        // obvhs sees a unit-direction ray starting `backoff` behind the origin; its parameter
        // is `t * length + backoff`.
        let far = (t_max * length + f64::from(backoff)) as f32 * (1.0 + 4.0 * f32::EPSILON);
        let ray = Ray::new(
            Vec3A::from(origin) - unit * backoff,
            unit,
            0.0,
            if far.is_finite() { far } else { f32::INFINITY },
        );
        let mut best: Option<RayHit> = None;
        let mut hit = ObvhsRayHit::none();
        let cwbvh = self
            .cwbvh
            .get_or_init(|| bvh2_to_cwbvh(&self.bvh2, 3, true, false));
        cwbvh.ray_traverse(ray, &mut hit, |_, slot| {
            let Some(&tri) = cwbvh.primitive_indices.get(slot) else {
                return f32::INFINITY;
            };
            let Some(&[a, b, c]) = self.corners.get(tri as usize) else {
                return f32::INFINITY;
            };
            match ray_triangle(o, d, a, b, c) {
                Some((t, barycentric)) if t <= t_max => {
                    let better = match best {
                        None => true,
                        Some(h) => t < h.t || (t == h.t && tri < h.triangle),
                    };
                    if better {
                        best = Some(RayHit {
                            t,
                            triangle: tri,
                            barycentric,
                        });
                    }
                    // Report a parameter rounded up so that ties are not culled.
                    ((t * length + f64::from(backoff)) as f32) * (1.0 + 4.0 * f32::EPSILON)
                }
                _ => f32::INFINITY,
            }
        });
        best
    }

    /// [`TriangleBvh::cast_ray`] for many rays in parallel; `result[i]` answers ray `i`.
    /// Rays are given as `(origin, direction)` pairs, all with the same `t_max`.
    #[must_use]
    pub fn cast_rays(&self, rays: &[(Vec3, Vec3)], t_max: f64) -> Vec<Option<RayHit>> {
        rays.par_iter()
            .with_min_len(64)
            .map(|&(o, d)| self.cast_ray(o, d, t_max))
            .collect()
    }
}

/// Checks that every triangle names vertices below `vertex_count`.
pub(super) fn check_indices(
    vertex_count: usize,
    triangles: &[[u32; 3]],
) -> Result<(), SpatialError> {
    match triangles
        .par_iter()
        .with_min_len(4096)
        .position_first(|t| t.iter().any(|&v| v as usize >= vertex_count))
    {
        None => Ok(()),
        Some(triangle) => Err(SpatialError::BadIndex {
            triangle,
            vertex_count,
        }),
    }
}

/// The corners of every triangle (indices already checked).
fn gather_corners(positions: &[DVec3], triangles: &[[u32; 3]]) -> Vec<[DVec3; 3]> {
    triangles
        .par_iter()
        .with_min_len(4096)
        .map(|t| t.map(|i| positions.get(i as usize).copied().unwrap_or(DVec3::ZERO)))
        .collect()
}

/// The leaf of each of `n` triangles and the parent of each node.
fn links(bvh2: &Bvh2, n: usize) -> (Vec<u32>, Vec<u32>) {
    let mut leaf_of = vec![NO_NODE; n];
    let mut parent = vec![NO_NODE; bvh2.nodes.len()];
    for (index, node) in bvh2.nodes.iter().enumerate() {
        if node.is_leaf() {
            for slot in node.first_index..node.first_index.saturating_add(node.prim_count) {
                if let Some(&t) = bvh2.primitive_indices.get(slot as usize)
                    && let Some(l) = leaf_of.get_mut(t as usize)
                {
                    *l = index as u32;
                }
            }
        } else {
            for child in [node.first_index, node.first_index.saturating_add(1)] {
                if let Some(p) = parent.get_mut(child as usize) {
                    *p = index as u32;
                }
            }
        }
    }
    (leaf_of, parent)
}

/// Sets every leaf's box to the union of its triangles' padded boxes (in parallel over the
/// nodes; inner boxes are left to `refit_all`).
fn set_leaf_boxes(bvh2: &mut Bvh2, corners: &[[DVec3; 3]], padding: f32) {
    let primitives = &bvh2.primitive_indices;
    bvh2.nodes
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
                // In f64, then rounded to f32: the padding (1e-5 of the magnitude) is far above
                // the rounding (6e-8 of it).
                let pad = DVec3::splat(f64::from(padding))
                    + lo.abs().max(hi.abs()) * f64::from(BOX_PADDING);
                aabb = aabb.union(&BvhAabb::new(
                    Vec3A::from((lo - pad).as_vec3()),
                    Vec3A::from((hi + pad).as_vec3()),
                ));
            }
            node.set_aabb(aabb);
        });
}

/// Whether a node's box is within squared distance `r2` of `q`, tested in f32 with the radius
/// rounded up (f32 keeps 24 bits; the box padding covers the rest).
fn near_test(q: DVec3, r2: f64) -> impl Fn(&Bvh2Node) -> bool {
    let p = Vec3A::from(q.as_vec3());
    let r2 = (r2 * (1.0 + 1e-6)) as f32;
    move |node| {
        let b = node.aabb();
        let d = (b.min - p).max(p - b.max).max(Vec3A::ZERO);
        d.length_squared() <= r2
    }
}

/// Squared distance from `q` to an obvhs box (0 inside), in f64: a lower bound of the squared
/// distance to anything in the box.
#[inline]
#[must_use]
pub fn box_distance_sq(aabb: &BvhAabb, q: DVec3) -> f64 {
    let lo = Vec3::from(aabb.min).as_dvec3();
    let hi = Vec3::from(aabb.max).as_dvec3();
    let d = (lo - q).max(q - hi).max(DVec3::ZERO);
    d.length_squared()
}

/// Closest point to `p` on the segment `a b` and its parameter in `[0, 1]` (0 for a point).
#[inline]
fn closest_on_segment(p: DVec3, a: DVec3, b: DVec3) -> (DVec3, f64) {
    let ab = b - a;
    let len2 = ab.length_squared();
    if len2 <= 0.0 {
        return (a, 0.0);
    }
    let s = ((p - a).dot(ab) / len2).clamp(0.0, 1.0);
    (a + ab * s, s)
}

/// The closest point to `p` on the triangle `a b c` and its barycentric weights `[wa, wb, wc]`
/// (non-negative, summing to 1), in f64 (Ericson, *Real-Time Collision Detection*, 5.1.5).
///
/// Degenerate triangles (see [`DEGENERATE_TRIANGLE`]) are handled as the union of their three
/// edges, each edge possibly a single point, so the result is always the closest point of the
/// (possibly flat) set.
#[must_use]
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, [f64; 3]) {
    if triangle_is_flat(a, b, c) {
        return closest_on_degenerate(p, a, b, c);
    }
    closest_point_on_proper_triangle(p, a, b, c)
}

/// Whether [`closest_point_on_triangle`] treats `a b c` as degenerate (see
/// [`DEGENERATE_TRIANGLE`]): a property of the triangle alone, so an index can decide it once.
#[inline]
#[must_use]
pub(crate) fn triangle_is_flat(a: DVec3, b: DVec3, c: DVec3) -> bool {
    let ab = b - a;
    let ac = c - a;
    let longest = ab
        .length_squared()
        .max(ac.length_squared())
        .max((c - b).length_squared());
    let n2 = ab.cross(ac).length_squared();
    n2 <= DEGENERATE_TRIANGLE * longest * longest
}

/// [`closest_point_on_triangle`] of a triangle that is not [`triangle_is_flat`]: the same
/// arithmetic after that test, so the same bits.
#[inline]
#[must_use]
pub(crate) fn closest_point_on_proper_triangle(
    p: DVec3,
    a: DVec3,
    b: DVec3,
    c: DVec3,
) -> (DVec3, [f64; 3]) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let sum = va + vb + vc;
    let v = vb / sum;
    let w = vc / sum;
    if !(v.is_finite() && w.is_finite()) {
        return closest_on_degenerate(p, a, b, c);
    }
    // Rounding can leave the weights a hair outside [0, 1]; the region tests above guarantee
    // the point is inside in exact arithmetic, so clamp.
    let v = v.clamp(0.0, 1.0);
    let w = w.clamp(0.0, 1.0 - v);
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

/// Closest point on the three edges of a flat triangle.
fn closest_on_degenerate(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, [f64; 3]) {
    let (pab, s) = closest_on_segment(p, a, b);
    let (pbc, t) = closest_on_segment(p, b, c);
    let (pca, u) = closest_on_segment(p, c, a);
    let candidates = [
        (pab, [1.0 - s, s, 0.0]),
        (pbc, [0.0, 1.0 - t, t]),
        (pca, [u, 0.0, 1.0 - u]),
    ];
    let mut best = candidates[0];
    let mut best_d2 = (best.0 - p).length_squared();
    for cand in &candidates[1..] {
        let d2 = (cand.0 - p).length_squared();
        if d2 < best_d2 {
            best = *cand;
            best_d2 = d2;
        }
    }
    best
}

/// Möller-Trumbore in f64: the hit parameter `t >= 0` and barycentrics of the ray
/// `o + t d` with triangle `a b c`, both faces, with [`RAY_EDGE_TOLERANCE`] on the edges.
#[must_use]
fn ray_triangle(o: DVec3, d: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<(f64, [f64; 3])> {
    let e1 = b - a;
    let e2 = c - a;
    let pvec = d.cross(e2);
    let det = e1.dot(pvec);
    // A triangle parallel to the ray (or degenerate) has det 0 up to rounding; measure it
    // against the sizes involved.
    let scale = e1.length() * e2.length() * d.length();
    if det.abs() <= DEGENERATE_TRIANGLE.sqrt() * scale {
        return None;
    }
    let inv = 1.0 / det;
    let tvec = o - a;
    let u = tvec.dot(pvec) * inv;
    if !(-RAY_EDGE_TOLERANCE..=1.0 + RAY_EDGE_TOLERANCE).contains(&u) {
        return None;
    }
    let qvec = tvec.cross(e1);
    let v = d.dot(qvec) * inv;
    if v < -RAY_EDGE_TOLERANCE || u + v > 1.0 + RAY_EDGE_TOLERANCE {
        return None;
    }
    let t = e2.dot(qvec) * inv;
    // Inputs are finite (checked by the callers), so `t` is not NaN.
    if t < 0.0 {
        return None;
    }
    let u = u.clamp(0.0, 1.0);
    let v = v.clamp(0.0, 1.0 - u);
    Some((t, [1.0 - u - v, u, v]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn rand_vec(rng: &mut Rng, scale: f32) -> Vec3 {
        Vec3::new(
            rng.uniform_f32() - 0.5,
            rng.uniform_f32() - 0.5,
            rng.uniform_f32() - 0.5,
        ) * scale
    }

    /// Random triangle soup: small triangles scattered in a unit cube, some degenerate.
    fn random_mesh(n: usize, seed: u64) -> TriMesh {
        let mut rng = Rng::new(seed);
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for i in 0..n {
            let centre = rand_vec(&mut rng, 1.0);
            let a = centre + rand_vec(&mut rng, 0.2);
            let mut b = centre + rand_vec(&mut rng, 0.2);
            let mut c = centre + rand_vec(&mut rng, 0.2);
            match i % 17 {
                0 => c = a + (b - a) * 0.25, // collinear
                1 => {
                    b = a; // a segment a-c
                }
                2 => {
                    b = a;
                    c = a; // a point
                }
                _ => {}
            }
            let base = positions.len() as u32;
            positions.extend([a, b, c]);
            triangles.push([base, base + 1, base + 2]);
        }
        TriMesh::new(positions, triangles)
    }

    fn brute_closest(mesh: &TriMesh, q: Vec3) -> (f64, u32) {
        let mut best = (f64::INFINITY, u32::MAX);
        for t in 0..mesh.triangle_count() {
            let [a, b, c] = mesh.corners(t);
            let (p, _) = closest_point_on_triangle(q.as_dvec3(), a, b, c);
            let d = (p - q.as_dvec3()).length();
            if d < best.0 {
                best = (d, t as u32);
            }
        }
        best
    }

    fn brute_ray(mesh: &TriMesh, o: Vec3, d: Vec3) -> Option<f64> {
        let mut best: Option<f64> = None;
        for t in 0..mesh.triangle_count() {
            let [a, b, c] = mesh.corners(t);
            if let Some((hit, _)) = ray_triangle(o.as_dvec3(), d.as_dvec3(), a, b, c) {
                best = Some(best.map_or(hit, |b| b.min(hit)));
            }
        }
        best
    }

    #[test]
    fn closest_point_on_triangle_is_optimal() {
        let mut rng = Rng::new(11);
        for i in 0..2000 {
            let a = rand_vec(&mut rng, 1.0).as_dvec3();
            let b = rand_vec(&mut rng, 1.0).as_dvec3();
            let c = if i % 10 == 0 {
                a + (b - a) * 2.0
            } else {
                rand_vec(&mut rng, 1.0).as_dvec3()
            };
            let p = rand_vec(&mut rng, 3.0).as_dvec3();
            let (cp, w) = closest_point_on_triangle(p, a, b, c);
            assert!(w.iter().all(|&x| (0.0..=1.0).contains(&x)), "{w:?}");
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            assert!((a * w[0] + b * w[1] + c * w[2] - cp).length() < 1e-12);
            let d = (cp - p).length();
            // No point of a dense barycentric grid is closer.
            let steps = 60;
            for s in 0..=steps {
                for t in 0..=(steps - s) {
                    let (u, v) = (f64::from(s) / 60.0, f64::from(t) / 60.0);
                    let q = a + (b - a) * u + (c - a) * v;
                    assert!((q - p).length() >= d - 1e-12, "triangle {i}");
                }
            }
        }
    }

    #[test]
    fn closest_point_degenerate_cases() {
        let a = DVec3::ZERO;
        let b = DVec3::X;
        // A point triangle.
        let (p, w) = closest_point_on_triangle(DVec3::new(0.0, 2.0, 0.0), a, a, a);
        assert_eq!(p, a);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // A segment triangle (repeated vertex) and a collinear one.
        for c in [b, DVec3::new(0.5, 0.0, 0.0)] {
            let (p, _) = closest_point_on_triangle(DVec3::new(0.3, 1.0, 0.0), a, b, c);
            assert!((p - DVec3::new(0.3, 0.0, 0.0)).length() < 1e-15);
        }
    }

    #[test]
    fn closest_points_match_brute_force() {
        let mesh = random_mesh(600, 21);
        let bvh = TriangleBvh::new(&mesh).expect("valid mesh");
        let mut rng = Rng::new(22);
        let mut queries: Vec<Vec3> = (0..800).map(|_| rand_vec(&mut rng, 1.6)).collect();
        // Far away, and exactly on vertices.
        queries.push(Vec3::new(1e6, -3e5, 2e6));
        queries.push(Vec3::splat(-1e12));
        queries.extend(mesh.positions_f32().iter().step_by(13).copied());
        let got = bvh.closest_points(&queries).expect("valid queries");
        for (q, cp) in queries.iter().zip(&got) {
            let (want, _) = brute_closest(&mesh, *q);
            assert!(
                (cp.distance - want).abs() <= 1e-12 * want.max(1.0),
                "query {q}: {} vs {want}",
                cp.distance
            );
            let [a, b, c] = mesh.corners(cp.triangle as usize);
            let w = cp.barycentric;
            assert!((a * w[0] + b * w[1] + c * w[2] - cp.point).length() < 1e-9);
            assert_eq!(bvh.closest_point(*q), Some(*cp));
        }
    }

    #[test]
    fn closest_point_on_a_closed_mesh() {
        // A unit cube (12 triangles): inside, outside, on faces.
        let p = [
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [0., 0., 1.],
            [1., 0., 1.],
            [1., 1., 1.],
            [0., 1., 1.],
        ]
        .map(Vec3::from_array)
        .to_vec();
        let t = vec![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [2, 3, 7],
            [2, 7, 6],
            [1, 2, 6],
            [1, 6, 5],
            [0, 4, 7],
            [0, 7, 3],
        ];
        let mesh = TriMesh::new(p, t);
        let bvh = TriangleBvh::new(&mesh).expect("valid");
        let cp = bvh.closest_point(Vec3::new(0.5, 0.4, 0.3)).expect("hit");
        assert!((cp.distance - 0.3).abs() < 1e-7);
        let cp = bvh.closest_point(Vec3::new(2.0, 2.0, 2.0)).expect("hit");
        assert!((cp.distance - 3f64.sqrt()).abs() < 1e-12);
        assert_eq!(cp.point, DVec3::ONE);
    }

    #[test]
    fn rays_match_brute_force() {
        let mesh = random_mesh(500, 31);
        let bvh = TriangleBvh::new(&mesh).expect("valid mesh");
        let mut rng = Rng::new(32);
        let mut rays = Vec::new();
        for i in 0..3000 {
            let o = rand_vec(&mut rng, 3.0);
            let d = match i % 4 {
                // Axis-aligned rays: two exactly-zero direction components.
                0 => [Vec3::X, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_X][i / 4 % 4],
                // One zero component.
                1 => Vec3::new(rng.uniform_f32() - 0.5, 0.0, rng.uniform_f32() - 0.5),
                // Aimed at a vertex or an edge midpoint.
                2 => {
                    let v = mesh.positions()[i % mesh.vertex_count()].as_vec3();
                    let w = mesh.positions()[(i * 7 + 1) % mesh.vertex_count()].as_vec3();
                    if i % 8 == 2 { v - o } else { (v + w) * 0.5 - o }
                }
                _ => rand_vec(&mut rng, 1.0),
            };
            rays.push((o, d));
        }
        // Axis-aligned rays straight through vertices.
        for v in mesh.positions_f32().iter().step_by(5) {
            rays.push((*v - Vec3::new(0.0, 0.0, 5.0), Vec3::Z));
            rays.push((*v + Vec3::new(3.0, 0.0, 0.0), Vec3::NEG_X));
        }
        let got = bvh.cast_rays(&rays, f64::INFINITY);
        let mut hits = 0;
        for ((o, d), hit) in rays.iter().zip(&got) {
            let want = brute_ray(&mesh, *o, *d);
            match (hit, want) {
                (None, None) => {}
                (Some(h), Some(w)) => {
                    hits += 1;
                    assert!((h.t - w).abs() <= 1e-12 * w.max(1.0), "ray {o} {d}");
                }
                _ => panic!("ray {o} {d}: bvh {hit:?} brute {want:?}"),
            }
        }
        assert!(hits > 1000, "only {hits} hits");
    }

    #[test]
    fn rays_along_faces_of_a_grid() {
        // A planar grid at z = 0: axis-aligned rays in the plane z = 0 hit nothing (parallel),
        // vertical rays through every vertex and edge midpoint hit at t = 1.
        let n = 20;
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                positions.push(Vec3::new(i as f32 * 0.05, j as f32 * 0.05, 0.0));
            }
        }
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = (j * (n + 1) + i) as u32;
                let w = v + n as u32 + 1;
                triangles.push([v, v + 1, w + 1]);
                triangles.push([v, w + 1, w]);
            }
        }
        let mesh = TriMesh::new(positions.clone(), triangles);
        let bvh = TriangleBvh::new(&mesh).expect("valid");
        for p in &positions {
            for target in [
                *p,
                *p + Vec3::new(0.025, 0.0, 0.0),
                *p + Vec3::new(0.025, 0.025, 0.0),
            ] {
                let hit = bvh.cast_ray(target + Vec3::Z, Vec3::NEG_Z, f64::INFINITY);
                let inside = target.x <= 1.0 && target.y <= 1.0;
                assert_eq!(hit.is_some(), inside, "{target}");
                if let Some(h) = hit {
                    assert!((h.t - 1.0).abs() < 1e-7, "{target} {h:?}");
                }
            }
            assert!(bvh.cast_ray(*p, Vec3::X, f64::INFINITY).is_none());
        }
        // Origin on the surface: hit at t = 0.
        let h = bvh
            .cast_ray(Vec3::new(0.512, 0.5, 0.0), Vec3::Z, f64::INFINITY)
            .expect("hit at the origin");
        assert_eq!(h.t, 0.0);
        // t_max limits.
        assert!(
            bvh.cast_ray(Vec3::new(0.5, 0.5, 1.0), Vec3::NEG_Z, 0.5)
                .is_none()
        );
    }

    #[test]
    fn empty_and_bad_inputs() {
        let empty = TriMesh::default();
        let bvh = TriangleBvh::new(&empty).expect("empty is fine");
        assert_eq!(bvh.closest_point(Vec3::ZERO), None);
        assert!(bvh.closest_points(&[Vec3::ZERO]).is_err());
        assert_eq!(bvh.cast_ray(Vec3::ZERO, Vec3::X, f64::INFINITY), None);
        let one = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let bvh = TriangleBvh::new(&one).expect("valid");
        assert_eq!(bvh.closest_point(Vec3::NAN), None);
        assert!(bvh.closest_points(&[Vec3::NAN]).is_err());
        assert_eq!(bvh.cast_ray(Vec3::Z, Vec3::ZERO, f64::INFINITY), None);
        assert_eq!(bvh.cast_ray(Vec3::Z, Vec3::NAN, f64::INFINITY), None);
        let h = bvh
            .cast_ray(
                Vec3::new(0.25, 0.25, 1.0),
                Vec3::new(0.0, 0.0, -2.0),
                f64::INFINITY,
            )
            .expect("hit");
        assert!((h.t - 0.5).abs() < 1e-15);
        assert_eq!(h.barycentric, [0.5, 0.25, 0.25]);
        let huge = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::splat(1e20)],
            vec![[0, 1, 2]],
        );
        assert!(matches!(
            TriangleBvh::new(&huge),
            Err(SpatialError::TooLarge { index: 2 })
        ));
        // Only degenerate triangles: closest points still exact.
        let flat = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0], vec![[0, 1, 2]]);
        let bvh = TriangleBvh::new(&flat).expect("valid");
        let cp = bvh.closest_point(Vec3::new(1.5, 1.0, 0.0)).expect("hit");
        assert!((cp.distance - 1.0).abs() < 1e-15);
        assert_eq!(
            bvh.cast_ray(Vec3::new(1.0, 1.0, 0.0), Vec3::NEG_Y, 10.0),
            None
        );
    }

    /// Squared distance from `q` to triangle `t` of `mesh`, brute force in f64.
    fn brute_d2(mesh: &TriMesh, q: DVec3, t: usize) -> f64 {
        let [a, b, c] = mesh.corners(t);
        (closest_point_on_triangle(q, a, b, c).0 - q).length_squared()
    }

    /// The mesh moved far from its build pose: every vertex displaced, the whole mesh
    /// stretched and sent away from the origin.
    fn moved(mesh: &TriMesh, seed: u64) -> Vec<DVec3> {
        let mut rng = Rng::new(seed);
        mesh.positions()
            .iter()
            .map(|&p| {
                p * DVec3::new(3.0, 0.5, 1.0)
                    + rand_vec(&mut rng, 0.3).as_dvec3()
                    + DVec3::splat(50.0)
            })
            .collect()
    }

    #[test]
    fn refit_answers_as_a_fresh_build() {
        let mesh = random_mesh(600, 21);
        let mut bvh = TriangleBvh::new(&mesh).expect("valid");
        // Rays go through the converted tree: build it before the refit so the refit must
        // drop it.
        assert!(
            bvh.cast_ray(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 10.0)
                .is_some()
        );
        let positions = moved(&mesh, 22);
        bvh.refit(&positions).expect("same size");
        let moved_mesh = TriMesh::new(positions.clone(), mesh.triangles().to_vec());
        let fresh = TriangleBvh::new(&moved_mesh).expect("valid");
        let mut rng = Rng::new(23);
        for _ in 0..300 {
            let q = Vec3::splat(50.0) + rand_vec(&mut rng, 4.0);
            let (a, b) = (bvh.closest_point(q), fresh.closest_point(q));
            assert_eq!(a, b);
            let (d, t) = brute_closest(&moved_mesh, q);
            let a = a.expect("not empty");
            assert_eq!(a.triangle, t);
            assert!((a.distance - d).abs() <= 1e-12 * d.max(1.0));
            let (o, dir) = (q + Vec3::Z * 10.0, Vec3::NEG_Z);
            assert_eq!(
                bvh.cast_ray(o, dir, 20.0).map(|h| h.triangle),
                fresh.cast_ray(o, dir, 20.0).map(|h| h.triangle)
            );
        }
        // Wrong vertex count or a bad coordinate: refused, tree unchanged.
        let before = bvh.closest_point(Vec3::splat(50.0));
        assert!(matches!(
            bvh.refit(&positions[..10]),
            Err(SpatialError::BadIndex { .. })
        ));
        let mut bad = positions.clone();
        bad[7] = DVec3::NAN;
        assert_eq!(bvh.refit(&bad), Err(SpatialError::NonFinite { index: 7 }));
        assert_eq!(bvh.closest_point(Vec3::splat(50.0)), before);
        assert!(matches!(
            TriangleBvh::from_triangles(&positions[..2], &[[0, 1, 2]]),
            Err(SpatialError::BadIndex {
                triangle: 0,
                vertex_count: 2
            })
        ));
    }

    #[test]
    fn nearest_below_and_range_queries_match_brute_force() {
        let mesh = random_mesh(500, 31);
        let mut bvh = TriangleBvh::new(&mesh).expect("valid");
        let positions = moved(&mesh, 32);
        bvh.refit(&positions).expect("same size");
        let moved_mesh = TriMesh::new(positions, mesh.triangles().to_vec());
        let n = moved_mesh.triangle_count();
        let mut rng = Rng::new(33);
        let (mut found, mut stack) = (Vec::new(), Vec::new());
        for _ in 0..200 {
            let q = (Vec3::splat(50.0) + rand_vec(&mut rng, 4.0)).as_dvec3();
            let all: Vec<(f64, u32)> = (0..n)
                .map(|t| (brute_d2(&moved_mesh, q, t), t as u32))
                .collect();
            let best = all
                .iter()
                .copied()
                .fold((f64::INFINITY, u32::MAX), |a, b| if b < a { b } else { a });
            // Seeded with a triangle: the answer is the best one when it is below the seed.
            let seed = rng.below(n as u32);
            let bound = all[seed as usize];
            assert_eq!(bvh.nearest_below(q, bound), (best < bound).then_some(best));
            assert_eq!(bvh.nearest_below(q, best), None);
            // Every triangle within the radius is listed (a superset is allowed).
            let r2 = all[seed as usize].0;
            found.clear();
            bvh.triangles_within(q, r2, &mut found, &mut stack);
            for &(d2, t) in &all {
                if d2 <= r2 {
                    assert!(found.contains(&t), "triangle {t} at {d2} <= {r2} missing");
                }
            }
        }
    }

    #[test]
    fn the_frontier_holds_every_other_triangle() {
        let mesh = random_mesh(400, 41);
        let bvh = TriangleBvh::new(&mesh).expect("valid");
        let n = mesh.triangle_count() as u32;
        let mut marks = vec![0u32; bvh.node_count()];
        let (mut frontier, mut stack) = (Vec::new(), Vec::new());
        let mut rng = Rng::new(42);
        for token in 1..=40u32 {
            let inside: Vec<u32> = (0..rng.below(6)).map(|_| rng.below(n)).collect();
            bvh.frontier(&inside, &mut marks, token, &mut frontier);
            // The triangles under the frontier, each once: exactly those not inside.
            let mut under: Vec<u32> = Vec::new();
            let mut todo = frontier.clone();
            while let Some(i) = todo.pop() {
                let node = &bvh.bvh2.nodes[i as usize];
                if node.is_leaf() {
                    let first = node.first_index as usize;
                    under.extend(
                        &bvh.bvh2.primitive_indices[first..first + node.prim_count as usize],
                    );
                } else {
                    todo.extend([node.first_index, node.first_index + 1]);
                }
            }
            under.sort_unstable();
            let want: Vec<u32> = (0..n).filter(|t| !inside.contains(t)).collect();
            assert_eq!(under, want);
            // `any_within` over the frontier sees exactly the outside triangles' boxes.
            let q = rand_vec(&mut rng, 1.5).as_dvec3();
            let r2 = 0.01;
            let near_outside = want.iter().any(|&t| {
                let (lo, hi) = bvh.leaf_box(t);
                (lo - q).max(q - hi).max(DVec3::ZERO).length_squared() <= r2
            });
            assert_eq!(bvh.any_within(&frontier, q, r2, &mut stack), near_outside);
        }
    }
}
