//! A BVH over a mesh's triangles (obvhs 0.4) with exact closest-point and closest-hit queries.
//!
//! One PLOC-built binary tree (`Bvh2`, one triangle per leaf) serves the closest-point query,
//! which obvhs does not have: a depth-first search over its public nodes, nearer child first,
//! pruning boxes whose f64 distance exceeds the best squared distance found so far, with
//! Ericson's closest point on a triangle in f64 at the leaves. The same tree converted to a
//! compressed wide BVH (`CwBvh`) serves ray casting: obvhs' `Bvh2` ray traversal missed hits
//! for rays with an exactly-zero direction component, the `CwBvh` one does not (tested below).
//!
//! Node boxes are padded by [`BOX_PADDING`] times the mesh's bounding-box diagonal, so that
//! f32 rounding in obvhs' slab tests cannot cull a ray that grazes a box face (rays along an
//! edge, through a vertex, or axis-aligned in the plane of a face). The padding only makes
//! the culling more conservative; the answers are computed exactly (f64) from the triangles.

use glam::{DVec3, Vec3, Vec3A};
use obvhs::aabb::Aabb as BvhAabb;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::ploc::{PlocBuilder, PlocSearchDistance, SortPrecision};
use obvhs::ray::{Ray, RayHit as ObvhsRayHit};
use obvhs::triangle::Triangle;
use rayon::prelude::*;

use super::{SpatialError, check_points, morton_order};
use crate::mesh::TriMesh;

/// Node boxes grow by this fraction of the mesh's bounding-box diagonal (see the module docs).
/// Rays whose origin lies within about 100 diagonals of the mesh keep f32 slab errors below it.
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

/// A BVH over the triangles of a [`TriMesh`] (it copies the triangle corners; the mesh is not
/// borrowed). An empty mesh gives an empty BVH whose queries return `None`.
pub struct TriangleBvh {
    bvh2: Bvh2,
    cwbvh: CwBvh,
    /// Corners of every triangle, indexed by the mesh's triangle id.
    corners: Vec<[Vec3; 3]>,
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
    /// Builds the BVH (PLOC with reinsertion optimisation, as obvhs' `medium_build`, without
    /// spatial splits).
    ///
    /// # Errors
    /// [`SpatialError::TooLarge`] when a vertex exceeds [`super::MAX_COORDINATE`] in
    /// magnitude ([`TriMesh`] positions are already finite), [`SpatialError::TooMany`] past
    /// `u32::MAX` triangles.
    pub fn new(mesh: &TriMesh) -> Result<Self, SpatialError> {
        check_points(mesh.positions())?;
        let n = mesh.triangle_count();
        if u32::try_from(n).is_err() {
            return Err(SpatialError::TooMany { count: n });
        }
        let corners: Vec<[Vec3; 3]> = (0..n).into_par_iter().map(|t| mesh.corners(t)).collect();
        let diagonal = mesh.bounds().map_or(0.0, |b| b.diagonal());
        let padding = diagonal * BOX_PADDING;
        let backoff = RAY_BACKOFF.max(2.0 * padding);
        if n == 0 {
            return Ok(Self {
                bvh2: Bvh2::default(),
                cwbvh: CwBvh::default(),
                corners,
                backoff,
            });
        }
        let triangles: Vec<Triangle> = corners
            .par_iter()
            .map(|&[a, b, c]| Triangle {
                v0: a.into(),
                v1: b.into(),
                v2: c.into(),
            })
            .collect();
        let indices: Vec<u32> = (0..n as u32).collect();
        let mut bvh2 = PlocBuilder::with_capacity(n).build(
            PlocSearchDistance::Medium,
            &triangles,
            indices,
            SortPrecision::U64,
            3,
        );
        ReinsertionOptimizer::default().run(&mut bvh2, 0.05, None);
        let pad = Vec3A::splat(padding);
        for node in &mut bvh2.nodes {
            let aabb = *node.aabb();
            node.set_aabb(BvhAabb::new(aabb.min - pad, aabb.max + pad));
        }
        let cwbvh = bvh2_to_cwbvh(&bvh2, 3, true, false);
        Ok(Self {
            bvh2,
            cwbvh,
            corners,
            backoff,
        })
    }

    /// Number of triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.corners.len()
    }

    /// The corners of triangle `t` as stored (mesh order), if it exists.
    #[must_use]
    pub fn corners(&self, t: usize) -> Option<[Vec3; 3]> {
        self.corners.get(t).copied()
    }

    /// The closest point of the surface to `query`; `None` for an empty mesh or a query that is
    /// not finite. Exact up to f64 rounding: the answer equals the minimum over all triangles
    /// of [`closest_point_on_triangle`].
    #[must_use]
    pub fn closest_point(&self, query: Vec3) -> Option<ClosestPoint> {
        if self.bvh2.nodes.is_empty() || !query.is_finite() {
            return None;
        }
        let q = query.as_dvec3();
        let nodes = &self.bvh2.nodes;
        let mut best: Option<(f64, ClosestPoint)> = None;
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        stack.push((0, box_distance_sq(nodes[0].aabb(), q)));
        while let Some((index, lower)) = stack.pop() {
            if best.is_some_and(|(d2, _)| lower > d2) {
                continue;
            }
            let Some(node) = nodes.get(index as usize) else {
                continue;
            };
            if node.is_leaf() {
                for slot in node.first_index..node.first_index.saturating_add(node.prim_count) {
                    let Some(&tri) = self.bvh2.primitive_indices.get(slot as usize) else {
                        continue;
                    };
                    let Some(&[a, b, c]) = self.corners.get(tri as usize) else {
                        continue;
                    };
                    let (point, barycentric) =
                        closest_point_on_triangle(q, a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
                    let d2 = (point - q).length_squared();
                    let better = match best {
                        None => true,
                        Some((b2, ref cp)) => d2 < b2 || (d2 == b2 && tri < cp.triangle),
                    };
                    if better {
                        best = Some((
                            d2,
                            ClosestPoint {
                                distance: d2.sqrt(),
                                point,
                                triangle: tri,
                                barycentric,
                            },
                        ));
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
            let bound = best.map_or(f64::INFINITY, |(d2, _)| d2);
            // Push the farther child first so the nearer one is searched first.
            let (near, dn, far, df) = if dl <= dr {
                (left, dl, right, dr)
            } else {
                (right, dr, left, dl)
            };
            if df <= bound {
                stack.push((far, df));
            }
            if dn <= bound {
                stack.push((near, dn));
            }
        }
        best.map(|(_, cp)| cp)
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
        if self.cwbvh.nodes.is_empty()
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
        self.cwbvh.ray_traverse(ray, &mut hit, |_, slot| {
            let Some(&tri) = self.cwbvh.primitive_indices.get(slot) else {
                return f32::INFINITY;
            };
            let Some(&[a, b, c]) = self.corners.get(tri as usize) else {
                return f32::INFINITY;
            };
            match ray_triangle(o, d, a.as_dvec3(), b.as_dvec3(), c.as_dvec3()) {
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

/// Squared distance from `q` to the box (0 inside), in f64.
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
    let ab = b - a;
    let ac = c - a;
    let longest = ab
        .length_squared()
        .max(ac.length_squared())
        .max((c - b).length_squared());
    let n2 = ab.cross(ac).length_squared();
    if n2 <= DEGENERATE_TRIANGLE * longest * longest {
        return closest_on_degenerate(p, a, b, c);
    }
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
            let [a, b, c] = mesh.corners(t).map(Vec3::as_dvec3);
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
            let [a, b, c] = mesh.corners(t).map(Vec3::as_dvec3);
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
        queries.extend(mesh.positions().iter().step_by(13).copied());
        let got = bvh.closest_points(&queries).expect("valid queries");
        for (q, cp) in queries.iter().zip(&got) {
            let (want, _) = brute_closest(&mesh, *q);
            assert!(
                (cp.distance - want).abs() <= 1e-12 * want.max(1.0),
                "query {q}: {} vs {want}",
                cp.distance
            );
            let [a, b, c] = mesh.corners(cp.triangle as usize).map(Vec3::as_dvec3);
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
                    let v = mesh.positions()[i % mesh.vertex_count()];
                    let w = mesh.positions()[(i * 7 + 1) % mesh.vertex_count()];
                    if i % 8 == 2 { v - o } else { (v + w) * 0.5 - o }
                }
                _ => rand_vec(&mut rng, 1.0),
            };
            rays.push((o, d));
        }
        // Axis-aligned rays straight through vertices.
        for v in mesh.positions().iter().step_by(5) {
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
        let empty = TriMesh::new(Vec::new(), Vec::new());
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
}
