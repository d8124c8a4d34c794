//! Statistical outlier removal with Open3D's rule: `PointCloud::remove_statistical_outlier(
//! nb_neighbors, std_ratio)` (Open3D 0.20.0, `cpp/open3d/geometry/PointCloud.cpp`,
//! `PointCloud::RemoveStatisticalOutliers`), with the same f64 arithmetic in the same order.
//!
//! # Definition
//! For `n` points `p_i` and `k = min(nb_neighbors, n)`:
//!
//! - `N_i` are the `k` points nearest `p_i`, **`p_i` itself included** (at distance 0): Open3D
//!   queries the cloud's own k-d tree with each of its points. Copies of `p_i` are neighbours at
//!   distance 0 too. Which of several points tied at the `k`-th distance is taken does not
//!   matter: only the distances enter.
//! - `a_i = (1/k) Σ_{j ∈ N_i} ‖p_i − p_j‖`, the mean of the Euclidean (not squared) distances.
//! - `μ = (Σ_{i : a_i > 0} a_i) / n` and `σ = √(Σ_{i : a_i > 0} (a_i − μ)² / (n − 1))`
//!   (Bessel's correction). Points with `a_i = 0` — all `k` nearest coincide with them, e.g. a
//!   point with `k − 1` or more copies — are left out of both sums but still counted in `n`
//!   (Open3D's `valid_distances` counts every point that has a neighbour, which is every point).
//! - `t = μ + std_ratio · σ`.
//! - `p_i` is kept iff `0 < a_i < t`, both strict; otherwise it is an outlier (Open3D removes
//!   it). So coincident points (`a_i = 0`) are always outliers, and a cloud whose means are all
//!   equal (σ = 0: two points, say) loses every point. One point is an outlier (`a_0 = 0`;
//!   Open3D's `σ` is `0 / 0`).
//!
//! Distances are computed in f64 from the f32 coordinates, `√((dx² + dy²) + dz²)` as
//! nanoflann's L2 metric does over Open3D's f64 copy of the points; each `a_i` sums its
//! distances in ascending order from 0 (nanoflann returns them sorted); `μ` and the squared
//! deviations are summed sequentially in index order (`std::accumulate`,
//! `std::inner_product`). The values are therefore Open3D's to the bit whenever both
//! compilers evaluate the same expressions in the same order; a point can only be classified
//! differently when its `a_i` lies within rounding of `t`.
//!
//! The neighbours are exact: [`PointIndex`] ranks candidates by f32 distances, so each point
//! asks it for one more than `k` and checks in f64 that no point left out can be nearer than
//! the `k`-th; when one could (near-ties), it asks for twice as many, up to every point.
//!
//! # Differences from Open3D
//! - `std_ratio = 0` is accepted (`t = μ`); Open3D refuses `std_ratio <= 0`.
//! - Bad parameters and non-finite points are [`OutlierError`]s, not exceptions.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::mesh::Aabb;
use crate::spatial::error::SpatialError;
use crate::spatial::kdtree::{PointIndex, distance_f64};

/// Why outliers could not be found.
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum OutlierError {
    /// `neighbors` is 0 (Open3D: "the number of neighbors ... must be positive").
    #[error("the number of neighbours must be at least 1")]
    NoNeighbors,
    /// `std_ratio` is negative, NaN or infinite.
    #[error("std_ratio {std_ratio} is not a finite non-negative number")]
    BadStdRatio {
        /// The ratio given.
        std_ratio: f64,
    },
    /// A coordinate is NaN or infinite.
    #[error("point {index} has a non-finite coordinate")]
    NonFinite {
        /// Index of the first such point.
        index: usize,
    },
    /// The points could not be indexed: more than `u32::MAX` of them, or coordinates (relative
    /// to the cloud's local origin) beyond [`crate::spatial::MAX_COORDINATE`].
    #[error(transparent)]
    Spatial(#[from] SpatialError),
}

/// Bound, relative to the distance, on how far a distance as [`PointIndex`]'s f32 search sees
/// it can be from the f64 one (f32 rounding of the differences, squares and sums and of
/// kiddo's pruning bounds: about ten f32 units in the last place, 6e-7). 2e-6 leaves a margin.
const SEARCH_REL: f64 = 2e-6;

/// Bound, relative to the largest coordinate magnitude the index holds, on the same error for
/// a set the index stores rotated (a set flat along an axis): rotated coordinates rounded to
/// f32 move a distance by at most about 6 units in the last place of that magnitude, 3.6e-7.
/// 2e-6 leaves a margin.
const SEARCH_ABS: f64 = 2e-6;

/// Open3D's `PointCloud::remove_statistical_outlier(nb_neighbors, std_ratio)` rule (see the
/// [module docs](self) for the exact definition): `result[i]` is `true` when Open3D would
/// remove `points[i]`, an outlier.
///
/// With `k = min(neighbors, n)`, `a_i` the mean Euclidean distance from `p_i` to its `k`
/// nearest points (itself included, at distance 0), `μ = Σ_{a_i > 0} a_i / n` and
/// `σ = √(Σ_{a_i > 0} (a_i − μ)² / (n − 1))`, a point is kept iff `0 < a_i < μ + std_ratio · σ`.
/// Distances are computed in f64 from the f32 coordinates and every sum is accumulated in f64
/// in Open3D's order. `neighbors` larger than the cloud uses every point. An empty cloud gives
/// an empty mask.
///
/// The neighbour searches run in parallel (rayon); the result does not depend on the thread
/// count.
///
/// # Errors
/// [`OutlierError::NoNeighbors`] for `neighbors == 0`, [`OutlierError::BadStdRatio`] for a
/// negative or non-finite `std_ratio`, [`OutlierError::NonFinite`] naming the first point with
/// a NaN or infinite coordinate, [`OutlierError::Spatial`] when the points cannot be indexed.
pub fn statistical_outliers(
    points: &[Vec3],
    neighbors: usize,
    std_ratio: f64,
) -> Result<Vec<bool>, OutlierError> {
    if neighbors == 0 {
        return Err(OutlierError::NoNeighbors);
    }
    if !(std_ratio.is_finite() && std_ratio >= 0.0) {
        return Err(OutlierError::BadStdRatio { std_ratio });
    }
    if let Some(index) = points
        .par_iter()
        .with_min_len(4096)
        .position_first(|p| !p.is_finite())
    {
        return Err(OutlierError::NonFinite { index });
    }
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let means = mean_distances(points, neighbors.min(points.len()))?;
    Ok(outlier_mask(&means, std_ratio))
}

/// `a_i` for every point: the mean f64 distance to its `k` nearest points (`1 <= k <= n`).
fn mean_distances(points: &[Vec3], k: usize) -> Result<Vec<f64>, OutlierError> {
    // The index holds the points relative to the cloud's local origin (zero near the world
    // origin), so the f32 search keeps its relative precision far from it; distances are
    // recomputed from `points` themselves.
    let origin = Aabb::from_points(points).map_or(DVec3::ZERO, |b| b.local_origin());
    let local: Option<Vec<Vec3>> = (origin != DVec3::ZERO).then(|| {
        points
            .par_iter()
            .map(|p| (p.as_dvec3() - origin).as_vec3())
            .collect()
    });
    let index = PointIndex::new(local.as_deref().unwrap_or(points))?;
    let scale = index
        .points()
        .par_iter()
        .map(|p| f64::from(p.abs().max_element()))
        .reduce(|| 0.0, f64::max);
    let slack = SEARCH_ABS * scale;
    Ok((0..points.len())
        .into_par_iter()
        .with_min_len(256)
        .map(|i| mean_distance(&index, points, i, k, slack))
        .collect())
}

/// `a_i`: the mean of the f64 distances from `points[i]` to its `k` nearest points, summed in
/// ascending order from 0.
///
/// [`PointIndex::k_nearest`] ranks candidates by f32 distances, so its `k`-th may not be the
/// f64 `k`-th when distances nearly tie. It is asked for more than `k` points (`k + 1` first)
/// and the f64 distances to them are sorted: every point it left out is at least as far as
/// the farthest one it returned, less the search's rounding (`2 · (SEARCH_REL · d + slack)`,
/// both sides' errors). When the `k`-th distance is below that bound the first `k` are the
/// exact `k` nearest; otherwise the request doubles, up to every point.
///
/// One `Vec` per request is allocated inside [`PointIndex::k_nearest`]; its API offers no
/// caller-owned buffer. The distances are recomputed in that same `Vec`.
fn mean_distance(index: &PointIndex, points: &[Vec3], i: usize, k: usize, slack: f64) -> f64 {
    let n = points.len();
    let query = index.points()[i];
    let p = points[i];
    let mut want = if k < n { k + 1 } else { n };
    loop {
        let mut found = index.k_nearest(query, want);
        for f in &mut found {
            f.distance = distance_f64(p, points[f.index as usize]);
        }
        found.sort_unstable_by(|a, b| a.distance.total_cmp(&b.distance));
        let certified = match (found.get(k - 1), found.last()) {
            (Some(kth), Some(last)) if want < n => {
                kth.distance < last.distance - 2.0 * (SEARCH_REL * last.distance + slack)
            }
            // Every point was returned (or, defensively, fewer than asked for).
            _ => true,
        };
        if certified || want >= n {
            let taken = found.len().min(k);
            let sum = found[..taken].iter().fold(0.0, |s, f| s + f.distance);
            return if taken == 0 { 0.0 } else { sum / taken as f64 };
        }
        want = want.saturating_mul(2).min(n);
    }
}

/// The outlier mask from the means `a_i` (at least one), with Open3D's sums in its order.
fn outlier_mask(means: &[f64], std_ratio: f64) -> Vec<bool> {
    let n = means.len();
    if n < 2 {
        // `a_0 = 0`: the only neighbour is the point itself (Open3D's σ would be 0 / 0).
        return vec![true; n];
    }
    let mean = means
        .iter()
        .fold(0.0, |s, &a| if a > 0.0 { s + a } else { s })
        / n as f64;
    let sq_sum = means.iter().fold(0.0, |s, &a| {
        if a > 0.0 {
            s + (a - mean) * (a - mean)
        } else {
            s
        }
    });
    let std_dev = (sq_sum / (n - 1) as f64).sqrt();
    let threshold = mean + std_ratio * std_dev;
    means
        .par_iter()
        .with_min_len(4096)
        .map(|&a| {
            let kept = a > 0.0 && a < threshold;
            !kept
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// The definition by brute force: f64 distances to every point, sorted.
    fn brute_means(points: &[Vec3], neighbors: usize) -> Vec<f64> {
        let k = neighbors.min(points.len());
        points
            .iter()
            .map(|&p| {
                let mut d: Vec<f64> = points.iter().map(|&q| distance_f64(p, q)).collect();
                d.sort_by(f64::total_cmp);
                d[..k].iter().fold(0.0, |s, x| s + x) / k as f64
            })
            .collect()
    }

    fn cluster(n: usize, seed: u64) -> Vec<Vec3> {
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()))
            .collect()
    }

    #[test]
    fn a_far_point_is_an_outlier() {
        let mut points = cluster(500, 1);
        points.push(Vec3::new(10.0, 10.0, 10.0));
        let mask = statistical_outliers(&points, 10, 2.0).expect("valid input");
        assert_eq!(mask.len(), 501);
        assert!(mask[500]);
        // A uniform cluster keeps most of its points.
        assert!(mask[..500].iter().filter(|&&m| m).count() < 25);
        assert_eq!(mask, outlier_mask(&brute_means(&points, 10), 2.0));
    }

    #[test]
    fn means_match_brute_force_exactly() {
        // Random, on a grid (ties at the k-th distance), with copies, flat (indexed rotated),
        // and far from the origin (indexed relative to a local origin).
        let mut rng = Rng::new(3);
        let random = cluster(400, 2);
        let grid: Vec<Vec3> = (0..343)
            .map(|i| Vec3::new((i % 7) as f32, (i / 7 % 7) as f32, (i / 49) as f32))
            .collect();
        let copies: Vec<Vec3> = (0..400).map(|_| random[rng.below(50) as usize]).collect();
        let flat: Vec<Vec3> = (0..400)
            .map(|i| Vec3::new((i % 20) as f32 * 0.1, (i / 20) as f32 * 0.1, 0.0))
            .collect();
        // f32 spacing 1.2e-4 at 2e3: many near-ties.
        let far: Vec<Vec3> = random
            .iter()
            .map(|p| *p * 0.1 + Vec3::new(1e3, -2e3, 500.0))
            .collect();
        for (name, points) in [
            ("random", random),
            ("grid", grid),
            ("copies", copies),
            ("flat", flat),
            ("far", far),
        ] {
            let origin = Aabb::from_points(&points).map(|b| b.local_origin());
            assert_eq!(
                origin.is_some_and(|o| o != DVec3::ZERO),
                name == "far",
                "{name}"
            );
            for k in [1, 2, 5, 6, 7, 20, 1000] {
                let want = brute_means(&points, k);
                let got = mean_distances(&points, k.min(points.len())).expect("valid");
                let first = got.iter().zip(&want).position(|(g, w)| g != w);
                assert_eq!(first, None, "{name}, k = {k}: first differing point");
            }
        }
    }

    #[test]
    fn all_duplicates_are_outliers() {
        let points = vec![Vec3::new(0.5, -1.0, 2.0); 50];
        for k in [1, 3, 50, 80] {
            let mask = statistical_outliers(&points, k, 2.0).expect("valid input");
            assert_eq!(mask, vec![true; 50], "k = {k}");
        }
        // Copies are neighbours at distance 0: six copies of one point with k <= 6 have a
        // mean of 0 and go, though they sit in the cluster; with k = 7 they stay.
        let mut points = cluster(300, 4);
        let copy = points[17];
        points.extend([copy; 5]);
        let mask = statistical_outliers(&points, 6, 3.0).expect("valid input");
        assert!(mask[17] && mask[300..].iter().all(|&m| m));
        let mask = statistical_outliers(&points, 7, 3.0).expect("valid input");
        assert!(!mask[17] && mask[300..].iter().all(|&m| !m));
    }

    #[test]
    fn more_neighbours_than_points() {
        // Every point is used: (0,0,0), (1,0,0), (0,2,0) have means 1, (1 + √5)/3, (2 + √5)/3.
        let points = [Vec3::ZERO, Vec3::X, Vec3::new(0.0, 2.0, 0.0)];
        let means = mean_distances(&points, 3).expect("valid");
        let root5 = 5f64.sqrt();
        assert_eq!(means, vec![1.0, (1.0 + root5) / 3.0, (2.0 + root5) / 3.0]);
        assert_eq!(
            statistical_outliers(&points, 20, 2.0),
            Ok(vec![false, false, false])
        );
        // σ ≈ 0.219 with the n − 1 denominator: the third point stays at 1.25 and goes at 0.5.
        assert_eq!(
            statistical_outliers(&points, 20, 1.25),
            Ok(vec![false, false, false])
        );
        assert_eq!(
            statistical_outliers(&points, 20, 0.5),
            Ok(vec![false, false, true])
        );
        // Two points: equal means, σ = 0, the strict comparison removes both; one point goes.
        assert_eq!(
            statistical_outliers(&[Vec3::ZERO, Vec3::ONE], 20, 2.0),
            Ok(vec![true, true])
        );
        assert_eq!(statistical_outliers(&[Vec3::ONE], 1, 2.0), Ok(vec![true]));
    }

    #[test]
    fn errors_and_empty_input() {
        let points = [Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::NAN, 0.0)];
        assert_eq!(
            statistical_outliers(&points[..2], 0, 2.0),
            Err(OutlierError::NoNeighbors)
        );
        for std_ratio in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                statistical_outliers(&points[..2], 3, std_ratio),
                Err(OutlierError::BadStdRatio { .. })
            ));
        }
        assert_eq!(
            statistical_outliers(&points, 3, 2.0),
            Err(OutlierError::NonFinite { index: 2 })
        );
        assert_eq!(
            statistical_outliers(&[Vec3::ZERO, Vec3::new(0.0, 0.0, f32::INFINITY)], 3, 2.0),
            Err(OutlierError::NonFinite { index: 1 })
        );
        assert!(matches!(
            statistical_outliers(&[Vec3::ZERO, Vec3::splat(f32::MAX)], 3, 2.0),
            Err(OutlierError::Spatial(_))
        ));
        assert_eq!(statistical_outliers(&[], 3, 2.0), Ok(Vec::new()));
        // std_ratio 0 (refused by Open3D) is the threshold μ.
        assert!(statistical_outliers(&points[..2], 3, 0.0).is_ok());
    }

    #[test]
    fn result_does_not_depend_on_threads() {
        let mut points = cluster(3000, 5);
        points.extend(cluster(30, 6).iter().map(|p| *p * 4.0 - 1.5));
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| statistical_outliers(&points, 16, 1.5).expect("valid"))
        };
        assert_eq!(run(1), run(4));
    }
}
