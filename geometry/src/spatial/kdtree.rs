//! Nearest-neighbour queries over a fixed point set: an exact k-d tree ([`super::point_tree`]).
//!
//! The tree ranks candidates by their f64 squared distance computed from the f32 coordinates
//! (`dx * dx + dy * dy + dz * dz`, the expression of [`distance_f64`]) and then by index, so
//! `nearest` returns what a brute-force scan returns, ties included: the smallest index among
//! the points at the least distance, and its distance to the bit. `k_nearest` likewise returns
//! the first `k` of the points sorted by distance then index. A distance agrees with scipy's
//! float64 `cKDTree` to rounding (about 1e-16 relative); with ties the index (and so, in the
//! metrics, the neighbour's normal) may differ from scipy's choice.
//!
//! Points at the same position are indexed once: the tree holds the distinct positions, each
//! standing for its copies (the smallest index answers `nearest`; `k_nearest` lists the
//! copies), so 200k copies of one point are one tree item. Only sets with copies pay for
//! finding them: a set of more than 2,048 points whose evenly spaced sample of 1,024 holds no
//! copy is indexed as it is (a set with a few copies then has a few equal leaf entries, which
//! costs nothing measurable).
//!
//! The tree splits along the widest axis of each node's points, so sets flat along an axis (a
//! line along x, a plane z = 0) are split along the axes they extend in: no rotation is needed
//! (kiddo's tree, used before, cycled through the axes and searched both sides of every split
//! on a flat one).

use std::cmp::Ordering;

use glam::Vec3;
use rayon::prelude::*;

use super::error::SpatialError;
use super::limits::{MAX_COORDINATE, check_points};
use super::morton::morton_order;
use super::point_tree::{Cursor, PointTree};

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
    /// Over the distinct positions (all points when there are no copies); a tree item's id is
    /// the smallest index of the points at its position.
    tree: PointTree,
    points: Vec<Vec3>,
    /// Copies, when there are any.
    copies: Option<Copies>,
}

/// Points looked at to decide whether a large set has copies (see [`Copies::of`]).
const COPY_SAMPLE: usize = 1024;

/// Queries answered one after the other, each starting from the previous one's answer, in a
/// batch (consecutive queries in a spatially coherent order).
const QUERY_CHUNK: usize = 1024;

/// The points of each distinct position (see [`PointIndex`]).
struct Copies {
    /// The points of group `g` are `members[offsets[g]..offsets[g + 1]]`, ascending.
    offsets: Vec<u32>,
    members: Vec<u32>,
    /// The group of each point.
    group: Vec<u32>,
}

impl Copies {
    /// Groups equal positions (`-0.0` equals `0.0`); `None` when all are distinct. Returns the
    /// distinct positions with their smallest indices, and the groups.
    fn of(points: &[Vec3]) -> Option<(Vec<Vec3>, Vec<u32>, Self)> {
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
        let mut ids = Vec::new();
        let mut offsets = Vec::new();
        let mut group = vec![0u32; points.len()];
        for (k, &(bits, i)) in order.iter().enumerate() {
            if k == 0 || order[k - 1].0 != bits {
                offsets.push(k as u32);
                distinct.push(points[i as usize]);
                ids.push(i);
            }
            group[i as usize] = (offsets.len() - 1) as u32;
        }
        offsets.push(order.len() as u32);
        let members = order.into_iter().map(|(_, i)| i).collect();
        Some((
            distinct,
            ids,
            Self {
                offsets,
                members,
                group,
            },
        ))
    }

    /// The points at the position of point `index`, ascending.
    fn of_point(&self, index: u32) -> &[u32] {
        let g = self.group[index as usize] as usize;
        &self.members[self.offsets[g] as usize..self.offsets[g + 1] as usize]
    }
}

impl std::fmt::Debug for PointIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointIndex")
            .field("len", &self.points.len())
            .finish_non_exhaustive()
    }
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
        let (tree, copies) = match Copies::of(points) {
            Some((distinct, ids, copies)) => (PointTree::new(&distinct, Some(&ids)), Some(copies)),
            None => (PointTree::new(points, None), None),
        };
        Ok(Self {
            tree,
            points: points.to_vec(),
            copies,
        })
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

    /// The nearest indexed point to `query` (the smallest index among the nearest), or `None`
    /// when `query` is not finite or exceeds [`MAX_COORDINATE`].
    #[must_use]
    pub fn nearest(&self, query: Vec3) -> Option<Nearest> {
        if !query_ok(query) {
            return None;
        }
        let best = self.tree.nearest(query.as_dvec3());
        Some(Nearest {
            index: best.id,
            distance: best.dist_sq.sqrt(),
        })
    }

    /// The `k` nearest indexed points (fewer when the set is smaller), closest first, sorted by
    /// f64 distance then index. Empty when `k` is 0 or the query is not usable (see
    /// [`PointIndex::nearest`]).
    #[must_use]
    pub fn k_nearest(&self, query: Vec3, k: usize) -> Vec<Nearest> {
        let k = k.min(self.points.len());
        if k == 0 || !query_ok(query) {
            return Vec::new();
        }
        let found = self.tree.k_nearest(query.as_dvec3(), k);
        // Each distinct position found stands for all its copies (at one distance): the `k`
        // nearest points are among them.
        let mut out: Vec<Nearest> = found
            .into_iter()
            .flat_map(|(dist_sq, id, _)| {
                let distance = dist_sq.sqrt();
                let copies: &[u32] = match &self.copies {
                    Some(c) => c.of_point(id),
                    None => &[],
                };
                let single = self.copies.is_none().then_some(id);
                copies
                    .iter()
                    .copied()
                    .chain(single)
                    .map(move |index| Nearest { index, distance })
            })
            .collect();
        out.sort_by(|a, b| {
            a.distance
                .partial_cmp(&b.distance)
                .unwrap_or(Ordering::Equal)
                .then(a.index.cmp(&b.index))
        });
        out.truncate(k);
        out
    }

    /// [`PointIndex::nearest`] for every query, in parallel; `result[i]` answers `queries[i]`.
    /// Queries are processed in Morton (Z-curve) order, each starting from the previous
    /// answer; the result does not depend on the thread count (every answer is exact).
    ///
    /// # Errors
    /// [`SpatialError::NonFinite`] or [`SpatialError::TooLarge`] naming the first bad query.
    pub fn nearest_batch(&self, queries: &[Vec3]) -> Result<Vec<Nearest>, SpatialError> {
        check_points(queries)?;
        let order = morton_order(queries);
        let mut sorted = vec![
            Nearest {
                index: 0,
                distance: 0.0
            };
            queries.len()
        ];
        sorted
            .par_chunks_mut(QUERY_CHUNK)
            .zip(order.par_chunks(QUERY_CHUNK))
            .for_each(|(out, ids)| {
                let mut cursor = Cursor::default();
                for (o, &i) in out.iter_mut().zip(ids) {
                    let best = self
                        .tree
                        .nearest_after(queries[i as usize].as_dvec3(), &mut cursor);
                    *o = Nearest {
                        index: best.id,
                        distance: best.dist_sq.sqrt(),
                    };
                }
            });
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

    /// [`PointIndex::nearest`] for every point of `other`, the set another index was built
    /// over: `result[i]` answers `other.points()[i]`. The queries go a leaf of `other`'s tree
    /// at a time (at most 16 nearby points in a tight box, no sorting needed), the leaves of
    /// this tree within reach listed once per leaf of queries (see `PointTree::nearest_to_tree`),
    /// and each distinct position of `other` is searched once for all its copies. Equal to
    /// `self.nearest_batch(other.points())`, ties included.
    #[must_use]
    pub fn nearest_to_points_of(&self, other: &Self) -> Vec<Nearest> {
        let by_slot: Vec<Nearest> = self
            .tree
            .nearest_to_tree(&other.tree)
            .into_par_iter()
            .map(|best| Nearest {
                index: best.id,
                distance: best.dist_sq.sqrt(),
            })
            .collect();
        let mut out = vec![
            Nearest {
                index: 0,
                distance: 0.0
            };
            other.len()
        ];
        for (slot, n) in by_slot.iter().enumerate() {
            let id = other.tree.id(slot);
            match &other.copies {
                Some(c) => {
                    for &i in c.of_point(id) {
                        out[i as usize] = *n;
                    }
                }
                None => out[id as usize] = *n,
            }
        }
        out
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

    /// The least (distance, index) over `points`, as a scan finds it.
    fn brute_with_index(points: &[Vec3], q: Vec3) -> (f64, u32) {
        points
            .iter()
            .enumerate()
            .map(|(i, &p)| (distance_f64(q, p), i as u32))
            .fold((f64::INFINITY, u32::MAX), |a, b| {
                if b.0 < a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            })
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
    fn flat_sets_are_exact() {
        let mut rng = Rng::new(11);
        // A line along x, a plane z = 0 (a grid: many ties), a thin slab and a cube.
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
        for (name, points) in [
            ("line", &line),
            ("plane", &plane),
            ("slab", &slab),
            ("cube", &random_points(3000, 12)),
        ] {
            let index = PointIndex::new(points).expect("valid points");
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
                let (want, at) = brute_with_index(points, *q);
                assert_eq!((got.distance, got.index), (want, at), "{name}");
                assert_eq!(index.nearest(*q), Some(*got));
                let k = index.k_nearest(*q, 3);
                assert_eq!(k.len(), 3);
                assert_eq!((k[0].distance, k[0].index), (want, at), "{name}");
            }
        }
    }

    /// Awkward sets against a brute-force scan: every answer (distance and index, ties
    /// included) of `nearest`, `nearest_batch`, `nearest_to_points_of` and the first of
    /// `k_nearest` must be the scan's.
    #[test]
    fn awkward_sets_match_brute_force_exactly() {
        let mut rng = Rng::new(21);
        let mut u = || rng.uniform_f32();
        let cube: Vec<Vec3> = (0..3000).map(|_| Vec3::new(u(), u(), u())).collect();
        // Copies: few (not seen by the sample), many of a few positions, all coincident.
        let mut few_copies = cube.clone();
        for i in 0..50 {
            few_copies[2000 + i] = few_copies[i];
        }
        let many_copies: Vec<Vec3> = (0..5000).map(|i| cube[i % 7]).collect();
        let coincident = vec![Vec3::new(0.3, -0.2, 0.9); 2500];
        // A line along x (ties between the two neighbours of a query), a diagonal line, a
        // grid plane (four-way ties), integer lattice points (exact ties everywhere).
        let line: Vec<Vec3> = (0..3000)
            .map(|i| Vec3::new(i as f32 * 1e-3, 0.0, 0.0))
            .collect();
        let diagonal: Vec<Vec3> = (0..3000).map(|i| Vec3::splat(i as f32 * 1e-3)).collect();
        let grid: Vec<Vec3> = (0..3600)
            .map(|i| Vec3::new((i % 60) as f32 * 0.25, (i / 60) as f32 * 0.25, 0.0))
            .collect();
        let lattice: Vec<Vec3> = (0..4096)
            .map(|i| Vec3::new((i % 16) as f32, (i / 16 % 16) as f32, (i / 256) as f32))
            .collect();
        // Clusters: tight blobs far apart, and one far outlier.
        let mut clustered: Vec<Vec3> = (0..4000)
            .map(|i| {
                let centre = Vec3::new((i % 5) as f32 * 10.0, (i % 3) as f32 * -7.0, 0.0);
                centre + 1e-3 * Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5)
            })
            .collect();
        clustered.push(Vec3::new(1e6, 1e6, -1e6));
        let sets: [(&str, &Vec<Vec3>); 9] = [
            ("cube", &cube),
            ("few copies", &few_copies),
            ("many copies", &many_copies),
            ("coincident", &coincident),
            ("line", &line),
            ("diagonal", &diagonal),
            ("grid", &grid),
            ("lattice", &lattice),
            ("clustered", &clustered),
        ];
        for (name, points) in sets {
            let index = PointIndex::new(points).expect("valid points");
            // Queries: the set's own points (distance 0, ties among copies), points between
            // them (ties), random points around them, and the points of every other set.
            let mut queries: Vec<Vec3> = points.iter().step_by(7).copied().collect();
            queries.extend(points.windows(2).step_by(11).map(|w| (w[0] + w[1]) * 0.5));
            queries.extend((0..300).map(|_| Vec3::new(u() * 16.0, u() * 16.0, u() * 2.0 - 1.0)));
            for (_, other) in sets {
                queries.extend(other.iter().step_by(97));
            }
            let want: Vec<(f64, u32)> = queries
                .iter()
                .map(|&q| brute_with_index(points, q))
                .collect();
            let batch = index.nearest_batch(&queries).expect("valid queries");
            for ((q, got), w) in queries.iter().zip(&batch).zip(&want) {
                assert_eq!((got.distance, got.index), *w, "{name}: batch, query {q}");
                assert_eq!(index.nearest(*q), Some(*got), "{name}: one, query {q}");
                let k = index.k_nearest(*q, 4);
                assert_eq!((k[0].distance, k[0].index), *w, "{name}: k, query {q}");
            }
            let as_index = PointIndex::new(&queries).expect("valid queries");
            assert_eq!(index.nearest_to_points_of(&as_index), batch, "{name}");
        }
    }

    /// `nearest_to_points_of` against a scan on a surface-like set: queries sampled on the
    /// same sphere (each leaf of them answered from one list of nearby leaves), on spheres
    /// 1.5 and 4 times as large (far: more leaves within reach than a list holds, so query
    /// by query), and lattice points with exact ties, with the set queried holding copies.
    #[test]
    fn sweeps_near_and_far_match_brute_force() {
        let mut rng = Rng::new(31);
        let mut sphere = |n: usize, radius: f32| -> Vec<Vec3> {
            (0..n)
                .map(|_| {
                    let v = Vec3::new(
                        rng.uniform_f32() - 0.5,
                        rng.uniform_f32() - 0.5,
                        rng.uniform_f32() - 0.5,
                    );
                    radius * v.normalize_or(Vec3::X)
                })
                .collect()
        };
        let mut points = sphere(6000, 1.0);
        points.extend_from_within(..300);
        let index = PointIndex::new(&points).expect("valid points");
        let mut near = sphere(3000, 1.0);
        near.extend(sphere(1500, 1.5));
        near.extend(sphere(1500, 4.0));
        near.extend(
            (0..512).map(|i| {
                Vec3::new((i % 8) as f32, (i / 8 % 8) as f32, (i / 64) as f32) * 0.25 - 1.0
            }),
        );
        near.extend_from_slice(&points[..200]);
        let queries = PointIndex::new(&near).expect("valid queries");
        let got = index.nearest_to_points_of(&queries);
        for (q, g) in near.iter().zip(&got) {
            assert_eq!(
                (g.distance, g.index),
                brute_with_index(&points, *q),
                "query {q}"
            );
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
