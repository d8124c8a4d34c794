//! Nearest-neighbour queries over a fixed point set: a kiddo 6 `ImmutableKdTree<f32, 3>`.
//!
//! The tree searches with f32 squared distances (kiddo's `SquaredEuclidean<f32>`); every
//! distance this module returns is recomputed in f64 from the f32 coordinates of the point the
//! tree found, so a distance agrees with scipy's float64 `cKDTree` to rounding (about 1e-16
//! relative) whenever both pick the same point.
//!
//! # Ties
//! When several points are (nearly) equidistant from a query, any of them may be returned:
//! the distance is the same, but the index (and so, in the metrics, the neighbour's normal) may
//! differ from scipy's choice. "Nearly" means within the f32 rounding of the tree's squared
//! distances, about 3e-7 relative. Distance-only metrics are unaffected beyond that rounding.
//!
//! The mutable kiddo tree is never used: it fails once more than a bucket of points share a
//! coordinate (planes, grids). The immutable tree handles duplicates correctly but searches
//! them in quadratic time (200k copies of one point: 29 s for `eval` of the set against
//! itself), so points at the same position are indexed once: the tree holds the distinct
//! positions, each standing for its copies (the smallest index answers `nearest`; `k_nearest`
//! lists the copies). Only sets with copies pay for finding them: a set of more than 2,048
//! points whose evenly spaced sample of 1,024 holds no copy is indexed as it is (the slow case
//! needs thousands of copies of one position, which the sample sees).
//!
//! Likewise a set flat along a coordinate axis (a line along x, a plane z = 0) makes every
//! query search both sides of the splits on that axis; it is indexed turned by a fixed
//! rotation, queries turned alike. Distances are still those of the original coordinates;
//! only which of two points tied within f32 rounding answers may change.

use std::cmp::Ordering;
use std::num::NonZeroUsize;

use glam::Vec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use super::error::SpatialError;
use super::limits::{MAX_COORDINATE, check_points};
use super::morton::morton_order;

/// A nearest point: its index in the indexed set and its Euclidean distance (f64).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nearest {
    /// Index of the point in the slice the index was built from.
    pub index: u32,
    /// Euclidean distance from the query, computed in f64 from the f32 coordinates.
    pub distance: f64,
}

/// A k-d tree over a fixed set of points (at least one, all finite and bounded).
pub struct PointIndex {
    /// Over the distinct positions (all points when there are no copies), rotated by `turn`
    /// when there is one.
    tree: ImmutableKdTree<f32, 3>,
    /// For a set flat along an axis ([`flat_along_an_axis`]): the rotation its coordinates
    /// (and every query) take in the tree.
    turn: Option<glam::DMat3>,
    points: Vec<Vec3>,
    /// Copies, when there are any: the points of tree item `u` are
    /// `members[offsets[u]..offsets[u + 1]]`, ascending.
    copies: Option<Copies>,
}

/// Points looked at to decide whether a large set has copies (see [`Copies::of`]).
const COPY_SAMPLE: usize = 1024;

/// The points of each distinct position (see [`PointIndex`]).
struct Copies {
    offsets: Vec<u32>,
    members: Vec<u32>,
}

impl Copies {
    /// Groups equal positions (`-0.0` equals `0.0`); `None` when all are distinct. Returns the
    /// distinct positions in tree order with the groups.
    fn of(points: &[Vec3]) -> Option<(Vec<[f32; 3]>, Self)> {
        let key = |p: Vec3| (p + Vec3::ZERO).to_array().map(f32::to_bits);
        // The search is slow only with thousands of copies of one position, which an evenly
        // spaced sample sees: a set whose sample holds no copy is indexed as it is (sorting
        // every point cost 13% of `eval` on 1M distinct points).
        if points.len() > 2 * COPY_SAMPLE {
            let mut sample: Vec<[u32; 3]> = points
                .iter()
                .step_by(points.len() / COPY_SAMPLE)
                .map(|&p| key(p))
                .collect();
            sample.sort_unstable();
            if sample.windows(2).all(|w| w[0] != w[1]) {
                return None;
            }
        }
        let mut order: Vec<([u32; 3], u32)> = points
            .par_iter()
            .enumerate()
            .map(|(i, &p)| (key(p), i as u32))
            .collect();
        order.par_sort_unstable();
        if order.windows(2).all(|w| w[0].0 != w[1].0) {
            return None;
        }
        let mut distinct = Vec::new();
        let mut offsets = Vec::new();
        for (k, &(bits, i)) in order.iter().enumerate() {
            if k == 0 || order[k - 1].0 != bits {
                offsets.push(k as u32);
                distinct.push(points[i as usize].to_array());
            }
        }
        offsets.push(order.len() as u32);
        let members = order.into_iter().map(|(_, i)| i).collect();
        Some((distinct, Self { offsets, members }))
    }

    /// The points at tree item `u`, ascending.
    fn of_item(&self, u: u32) -> &[u32] {
        let u = u as usize;
        &self.members[self.offsets[u] as usize..self.offsets[u + 1] as usize]
    }
}

impl std::fmt::Debug for PointIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointIndex")
            .field("len", &self.points.len())
            .finish_non_exhaustive()
    }
}

/// An axis whose extent is at most this fraction of the largest makes a set flat
/// ([`flat_along_an_axis`]).
const FLAT_AXIS_REL: f64 = 1e-3;

/// Whether the points are collinear or coplanar along a coordinate axis (some axis's extent
/// at most [`FLAT_AXIS_REL`] of the largest, e.g. a line along x or a plane z = 0). The tree
/// splits every axis in turn; along a flat one every query is near the split and searches
/// both sides, so queries grow linear in the set (500k points on a line: `eval` 21 s). Such
/// sets are indexed turned by [`generic_rotation`], where no axis is flat.
fn flat_along_an_axis(points: &[Vec3]) -> bool {
    let (lo, hi) = points.iter().fold(
        (glam::DVec3::INFINITY, glam::DVec3::NEG_INFINITY),
        |(lo, hi), p| (lo.min(p.as_dvec3()), hi.max(p.as_dvec3())),
    );
    let extent = hi - lo;
    points.len() > 1 && extent.min_element() <= FLAT_AXIS_REL * extent.max_element()
}

/// A fixed rotation that leaves no coordinate axis parallel to another axis, line or plane of
/// small rational direction (the unit quaternion (3, 5, 7, 11) normalised).
fn generic_rotation() -> glam::DMat3 {
    glam::DMat3::from_quat(glam::DQuat::from_xyzw(5.0, 7.0, 11.0, 3.0).normalize())
}

/// `p` rotated by `r`, in f64, stored as f32.
#[inline]
fn turned(r: glam::DMat3, p: Vec3) -> [f32; 3] {
    (r * p.as_dvec3()).as_vec3().to_array()
}

/// Exact f64 Euclidean distance between two f32 points.
#[inline]
#[must_use]
pub fn distance_f64(a: Vec3, b: Vec3) -> f64 {
    (a.as_dvec3() - b.as_dvec3()).length()
}

impl PointIndex {
    /// Builds the tree (in parallel for large sets).
    ///
    /// # Errors
    /// [`SpatialError::Empty`] for no points, [`SpatialError::NonFinite`] or
    /// [`SpatialError::TooLarge`] for a coordinate that is not finite or exceeds
    /// [`MAX_COORDINATE`] in magnitude, [`SpatialError::TooMany`] past `u32::MAX` points.
    pub fn new(points: &[Vec3]) -> Result<Self, SpatialError> {
        if points.is_empty() {
            return Err(SpatialError::Empty);
        }
        check_points(points)?;
        if u32::try_from(points.len()).is_err() {
            return Err(SpatialError::TooMany {
                count: points.len(),
            });
        }
        let (mut coords, copies) = match Copies::of(points) {
            Some((distinct, copies)) => (distinct, Some(copies)),
            None => (points.iter().map(|p| p.to_array()).collect(), None),
        };
        let turn = flat_along_an_axis(points).then(generic_rotation);
        if let Some(r) = turn {
            for c in &mut coords {
                *c = turned(r, Vec3::from(*c));
            }
        }
        let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&coords).map_err(|e| {
            SpatialError::Build {
                message: e.to_string(),
            }
        })?;
        Ok(Self {
            tree,
            turn,
            points: points.to_vec(),
            copies,
        })
    }

    /// The point a tree item stands for: the smallest index at its position.
    #[inline]
    fn representative(&self, item: u32) -> u32 {
        match &self.copies {
            Some(c) => c.of_item(item)[0],
            None => item,
        }
    }

    /// The indexed points, in their original order.
    #[must_use]
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }

    /// Number of indexed points (at least one).
    #[must_use]
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Always false: an index holds at least one point.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The nearest indexed point to `query`, or `None` when `query` is not finite or exceeds
    /// [`MAX_COORDINATE`].
    #[must_use]
    pub fn nearest(&self, query: Vec3) -> Option<Nearest> {
        if !query_ok(query) {
            return None;
        }
        Some(self.nearest_unchecked(query))
    }

    /// `query` as the tree holds it.
    #[inline]
    fn tree_query(&self, query: Vec3) -> [f32; 3] {
        match self.turn {
            Some(r) => turned(r, query),
            None => query.to_array(),
        }
    }

    #[inline]
    fn nearest_unchecked(&self, query: Vec3) -> Nearest {
        let q = self.tree_query(query);
        let found = self
            .tree
            .query(&q)
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute();
        let index = self.representative(found.item);
        let p = self.points.get(index as usize).copied().unwrap_or(query);
        Nearest {
            index,
            distance: distance_f64(query, p),
        }
    }

    /// The `k` nearest indexed points (fewer when the set is smaller), closest first, sorted by
    /// f64 distance then index. Empty when `k` is 0 or the query is not usable (see
    /// [`PointIndex::nearest`]).
    #[must_use]
    pub fn k_nearest(&self, query: Vec3, k: usize) -> Vec<Nearest> {
        let Some(k) = NonZeroUsize::new(k.min(self.points.len())) else {
            return Vec::new();
        };
        if !query_ok(query) {
            return Vec::new();
        }
        let q = self.tree_query(query);
        let found = self
            .tree
            .query(&q)
            .nearest_n::<SquaredEuclidean<f32>>(k)
            .execute();
        // Each distinct position found stands for all its copies (at one distance): the `k`
        // nearest points are among them.
        let mut out: Vec<Nearest> = found
            .into_iter()
            .flat_map(|r| {
                let (copies, single): (&[u32], Option<u32>) = match &self.copies {
                    Some(c) => (c.of_item(r.item), None),
                    None => (&[], Some(r.item)),
                };
                copies.iter().copied().chain(single)
            })
            .filter_map(|index| {
                let p = self.points.get(index as usize)?;
                Some(Nearest {
                    index,
                    distance: distance_f64(query, *p),
                })
            })
            .collect();
        out.sort_by(|a, b| {
            a.distance
                .partial_cmp(&b.distance)
                .unwrap_or(Ordering::Equal)
                .then(a.index.cmp(&b.index))
        });
        out.truncate(k.get());
        out
    }

    /// [`PointIndex::nearest`] for every query, in parallel; `result[i]` answers `queries[i]`.
    /// Queries are processed in Morton (Z-curve) order for cache locality; the result does not
    /// depend on the thread count.
    ///
    /// # Errors
    /// [`SpatialError::NonFinite`] or [`SpatialError::TooLarge`] naming the first bad query.
    pub fn nearest_batch(&self, queries: &[Vec3]) -> Result<Vec<Nearest>, SpatialError> {
        check_points(queries)?;
        let order = morton_order(queries);
        let coords: Vec<[f32; 3]> = order
            .par_iter()
            .map(|&i| self.tree_query(queries[i as usize]))
            .collect();
        // kiddo's batch query (parallel, results indexed like `coords`) was 25-35% faster than
        // one `query` per point on 1M Morton-sorted queries.
        let found = self
            .tree
            .query_batch(&coords)
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute();
        let sorted: Vec<Nearest> = found
            .par_iter()
            .zip(order.par_iter())
            .map(|(f, &i)| {
                let q = queries[i as usize];
                let index = self.representative(f.item);
                let p = self.points.get(index as usize).copied().unwrap_or(q);
                Nearest {
                    index,
                    distance: distance_f64(q, p),
                }
            })
            .collect();
        let mut out = vec![
            Nearest {
                index: 0,
                distance: 0.0
            };
            queries.len()
        ];
        for (n, &i) in sorted.iter().zip(&order) {
            out[i as usize] = *n;
        }
        Ok(out)
    }

    /// [`PointIndex::k_nearest`] for every query, in parallel.
    ///
    /// # Errors
    /// As [`PointIndex::nearest_batch`].
    pub fn k_nearest_batch(
        &self,
        queries: &[Vec3],
        k: usize,
    ) -> Result<Vec<Vec<Nearest>>, SpatialError> {
        check_points(queries)?;
        Ok(queries
            .par_iter()
            .with_min_len(64)
            .map(|&q| self.k_nearest(q, k))
            .collect())
    }
}

#[inline]
fn query_ok(q: Vec3) -> bool {
    q.is_finite() && q.abs().max_element() <= MAX_COORDINATE
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn random_points(n: usize, seed: u64) -> Vec<Vec3> {
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()))
            .collect()
    }

    fn brute(points: &[Vec3], q: Vec3) -> f64 {
        points
            .iter()
            .map(|&p| distance_f64(q, p))
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn nearest_matches_brute_force() {
        let points = random_points(2000, 1);
        let queries = random_points(500, 2);
        let index = PointIndex::new(&points).expect("valid points");
        let batch = index.nearest_batch(&queries).expect("valid queries");
        for (q, got) in queries.iter().zip(&batch) {
            let want = brute(&points, *q);
            assert_eq!(got.distance, want, "query {q}");
            assert_eq!(distance_f64(*q, points[got.index as usize]), got.distance);
            assert_eq!(index.nearest(*q), Some(*got));
        }
    }

    #[test]
    fn flat_sets_are_turned_and_still_exact() {
        let mut rng = Rng::new(11);
        // A line along x, a plane z = 0 (a grid: many ties) and a thin slab: turned; a cube:
        // not.
        let line: Vec<Vec3> = (0..3000)
            .map(|i| Vec3::new(i as f32 * 1e-3, 0.0, 0.0))
            .collect();
        let plane: Vec<Vec3> = (0..3000)
            .map(|i| Vec3::new((i % 60) as f32 * 0.01, (i / 60) as f32 * 0.01, 0.0))
            .collect();
        let slab: Vec<Vec3> = (0..3000)
            .map(|_| {
                Vec3::new(
                    rng.uniform_f32(),
                    rng.uniform_f32(),
                    1e-5 * rng.uniform_f32(),
                )
            })
            .collect();
        for (name, points, flat) in [
            ("line", &line, true),
            ("plane", &plane, true),
            ("slab", &slab, true),
            ("cube", &random_points(3000, 12), false),
        ] {
            let index = PointIndex::new(points).expect("valid points");
            assert_eq!(index.turn.is_some(), flat, "{name}");
            let queries: Vec<Vec3> = (0..200)
                .map(|_| {
                    Vec3::new(
                        rng.uniform_f32(),
                        rng.uniform_f32(),
                        0.01 * rng.uniform_f32(),
                    )
                })
                .collect();
            let batch = index.nearest_batch(&queries).expect("valid queries");
            for (q, got) in queries.iter().zip(&batch) {
                // The distance is the true nearest one (to f32 tie rounding: 3e-7 relative).
                let want = brute(points, *q);
                assert!(
                    (got.distance - want).abs() <= 3e-7 * want.max(1e-30),
                    "{name}: {} vs {want}",
                    got.distance
                );
                assert_eq!(distance_f64(*q, points[got.index as usize]), got.distance);
                assert_eq!(index.nearest(*q).map(|n| n.distance), Some(got.distance));
                let k = index.k_nearest(*q, 3);
                assert_eq!(k.len(), 3);
                assert!((k[0].distance - want).abs() <= 3e-7 * want.max(1e-30));
            }
        }
    }

    #[test]
    fn k_nearest_matches_brute_force() {
        let points = random_points(500, 3);
        let index = PointIndex::new(&points).expect("valid points");
        for q in random_points(50, 4) {
            let mut all: Vec<f64> = points.iter().map(|&p| distance_f64(q, p)).collect();
            all.sort_by(f64::total_cmp);
            let got = index.k_nearest(q, 8);
            assert_eq!(got.len(), 8);
            for (g, w) in got.iter().zip(&all) {
                assert_eq!(g.distance, *w);
            }
        }
        assert_eq!(index.k_nearest(Vec3::ZERO, 10_000).len(), 500);
        assert!(index.k_nearest(Vec3::ZERO, 0).is_empty());
    }

    #[test]
    fn duplicates_grids_and_all_equal_points() {
        // All equal: 1000 copies of one point.
        let same = vec![Vec3::new(0.5, -1.0, 2.0); 1000];
        let index = PointIndex::new(&same).expect("valid points");
        let got = index.nearest(Vec3::new(0.5, -1.0, 3.0)).expect("finite");
        assert!((got.distance - 1.0).abs() < 1e-12);
        assert_eq!(index.k_nearest(Vec3::ZERO, 40).len(), 40);
        // A planar grid (z = 0 for all, many shared x and y) with duplicates of every point.
        let mut grid = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                let p = Vec3::new(i as f32 * 0.1, j as f32 * 0.1, 0.0);
                grid.push(p);
                grid.push(p);
            }
        }
        let index = PointIndex::new(&grid).expect("valid points");
        let queries = random_points(400, 5)
            .into_iter()
            .map(|p| Vec3::new(p.x * 6.0, p.y * 6.0, p.z - 0.5))
            .collect::<Vec<_>>();
        for (q, got) in queries
            .iter()
            .zip(index.nearest_batch(&queries).expect("valid"))
        {
            assert_eq!(got.distance, brute(&grid, *q));
        }
        // Queries exactly on grid points find distance 0.
        for p in grid.iter().step_by(37) {
            assert_eq!(index.nearest(*p).map(|n| n.distance), Some(0.0));
        }
    }

    #[test]
    fn copies_are_indexed_once_and_all_listed() {
        // 200k copies of one point took 29 s to search before they were indexed once.
        let mut points = vec![Vec3::new(0.25, 0.5, -1.0); 200_000];
        points[7] = Vec3::new(3.0, 0.0, 0.0);
        points.push(Vec3::new(-0.0, 0.0, 0.0));
        points.push(Vec3::new(0.0, -0.0, 0.0));
        let index = PointIndex::new(&points).expect("valid points");
        let queries = vec![Vec3::new(0.25, 0.5, -0.9); 200_000];
        let found = index.nearest_batch(&queries).expect("valid");
        // The smallest index of the copies answers.
        assert!(
            found
                .iter()
                .all(|n| n.index == 0 && (n.distance - 0.1).abs() < 1e-6)
        );
        assert_eq!(
            index.nearest(Vec3::new(3.0, 0.1, 0.0)).map(|n| n.index),
            Some(7)
        );
        // -0.0 and 0.0 are one position: both copies listed, in index order.
        let near: Vec<u32> = index
            .k_nearest(Vec3::new(0.0, 0.0, 0.01), 2)
            .iter()
            .map(|n| n.index)
            .collect();
        assert_eq!(near, vec![200_000, 200_001]);
        // k nearest lists copies by index and stops at k.
        let k = index.k_nearest(Vec3::new(0.25, 0.5, -1.0), 5);
        assert_eq!(
            k.iter().map(|n| n.index).collect::<Vec<_>>(),
            vec![0, 1, 2, 3, 4]
        );
        assert_eq!(index.k_nearest(Vec3::ZERO, 1_000_000).len(), points.len());
    }

    #[test]
    fn k_nearest_with_copies_matches_brute_force() {
        let mut rng = Rng::new(9);
        let base = random_points(300, 8);
        let points: Vec<Vec3> = (0..1200).map(|_| base[rng.below(300) as usize]).collect();
        let index = PointIndex::new(&points).expect("valid points");
        for q in random_points(40, 10) {
            let mut all: Vec<(f64, u32)> = points
                .iter()
                .enumerate()
                .map(|(i, &p)| (distance_f64(q, p), i as u32))
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let got: Vec<(f64, u32)> = index
                .k_nearest(q, 9)
                .iter()
                .map(|n| (n.distance, n.index))
                .collect();
            assert_eq!(got, all[..9].to_vec(), "query {q}");
            let nearest = index.nearest(q).expect("finite");
            assert_eq!((nearest.distance, nearest.index), all[0]);
        }
    }

    #[test]
    fn bad_inputs_are_errors_not_panics() {
        assert!(matches!(PointIndex::new(&[]), Err(SpatialError::Empty)));
        assert!(matches!(
            PointIndex::new(&[Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0)]),
            Err(SpatialError::NonFinite { index: 1 })
        ));
        assert!(matches!(
            PointIndex::new(&[Vec3::new(0.0, f32::MAX, 0.0)]),
            Err(SpatialError::TooLarge { index: 0 })
        ));
        let index = PointIndex::new(&[Vec3::ZERO]).expect("one point");
        assert_eq!(index.nearest(Vec3::splat(f32::INFINITY)), None);
        assert!(index.k_nearest(Vec3::NAN, 3).is_empty());
        assert!(index.nearest_batch(&[Vec3::ZERO, Vec3::NAN]).is_err());
        let far = index.nearest(Vec3::splat(1e17)).expect("bounded");
        assert_eq!(far.distance, Vec3::splat(1e17).as_dvec3().length());
    }

    #[test]
    fn batch_does_not_depend_on_threads() {
        let points = random_points(3000, 6);
        let queries = random_points(3000, 7);
        let index = PointIndex::new(&points).expect("valid points");
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| index.nearest_batch(&queries).expect("valid"));
        let many = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .expect("pool")
            .install(|| index.nearest_batch(&queries).expect("valid"));
        assert_eq!(one, many);
    }
}
