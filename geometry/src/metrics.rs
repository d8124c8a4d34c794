//! Geometry metrics between a prediction P and a ground truth G (docs/conventions.md §8).
//!
//! With `d(x, S)` the Euclidean distance from `x` to the nearest point of `S`:
//! - accuracy = mean over p of d(p, G); completeness = mean over g of d(g, P);
//! - chamfer_l1 = (accuracy + completeness) / 2;
//!   chamfer_l2 = (mean d(p, G)^2 + mean d(g, P)^2) / 2 (squared distances, halved sum);
//! - normal_consistency = (mean |n_p . n_nn(p)| + mean |n_g . n_nn(g)|) / 2, where nn(x) is the
//!   neighbour that realised d(x, .); normal_angle_deg = the same with acos |n . n'| in degrees;
//! - per threshold tau: precision = fraction of p with d(p, G) < tau, recall = fraction of g
//!   with d(g, P) < tau, fscore = 2PR / (P + R), 0 when both are 0.
//!
//! Point mode: S is a point set (a mesh is first sampled area-uniformly with face normals by the
//! caller) and d is found with a k-d tree. Surface mode: where S is a mesh, d is the exact
//! distance to the closest point of its triangles (BVH), which removes the sampling floor of
//! about 0.5 sqrt(area / N) of point-to-point distances; n_nn is then the unit normal of the
//! closest triangle. Other tools differ: PyTorch3D's chamfer sums the two squared means
//! without halving, DTU's script drops distances above 20 mm.
//!
//! Distances are computed in f64 from the f32 coordinates and accumulated in f64 over fixed
//! chunks, so the result does not depend on the thread count. Normals are normalised in f64
//! before the dot product; a zero normal counts as perpendicular (|n . n'| = 0). When either
//! side has no normals the normal metrics are `None` (JSON `null`). Empty inputs are errors,
//! so no metric is ever NaN.
//!
//! Ties: when several neighbours are equally near, distances are the same whichever is taken,
//! but the normal metrics may differ from another tool's (scipy, trimesh) choice.

use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use serde::Serialize;

use crate::mesh::{Aabb, TriMesh};
use crate::points::PointCloud;
use crate::spatial::bvh::TriangleBvh;
use crate::spatial::error::SpatialError;
use crate::spatial::kdtree::{Nearest, PointIndex};
use crate::spatial::surface::SurfaceIndex;

/// Default F-score thresholds, in the input's length unit: 1, 2.5, 5 and 10 mm for inputs in
/// metres (2.5 mm gives the common "Recall@2.5mm").
pub const DEFAULT_TAUS: [f64; 4] = [0.001, 0.0025, 0.005, 0.01];

/// Default F-score thresholds as fractions of the ground truth's bounding-box diagonal
/// (`trisplat eval` without `--tau`): 0.1%, 0.25%, 0.5% and 1% of it, so that a threshold
/// means the same on a 2 m body and a 20 cm head.
pub const DEFAULT_TAU_FRACTIONS: [f64; 4] = [0.001, 0.0025, 0.005, 0.01];

/// Shared-vertex fraction from which scores are labelled [`Relation::SelfConsistency`]: at
/// least half of the ground truth's vertices are, bit for bit, vertices of the prediction.
pub const SELF_CONSISTENCY_MIN_SHARED: f64 = 0.5;

/// Points per chunk of the fixed-order f64 accumulation.
const SUM_CHUNK: usize = 4096;

/// Which side of the comparison an error concerns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The prediction P.
    Prediction,
    /// The ground truth G.
    GroundTruth,
}

impl std::fmt::Display for Side {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Prediction => "prediction",
            Self::GroundTruth => "ground truth",
        })
    }
}

/// Why metrics could not be computed.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum MetricsError {
    /// A side has no points (metrics would be NaN).
    #[error("the {0} has no points")]
    Empty(Side),
    /// A threshold is not a finite positive number.
    #[error("threshold {tau} is not a finite positive number")]
    BadThreshold {
        /// The threshold.
        tau: f64,
    },
    /// A spatial index could not be built or queried (e.g. coordinates beyond 1e18).
    #[error("{side}: {source}")]
    Spatial {
        /// The side whose points are at fault.
        side: Side,
        /// The index error.
        source: SpatialError,
    },
}

/// Precision, recall and F-score at one threshold.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ThresholdScore {
    /// The distance threshold (absolute, in the input's unit).
    pub tau: f64,
    /// The threshold as a fraction of the ground truth's bounding-box diagonal when it was
    /// asked for that way ([`Tau::Fraction`]); `None` (JSON `null`) when given absolutely.
    pub tau_fraction: Option<f64>,
    /// Fraction of prediction points with d(p, G) < tau.
    pub precision: f64,
    /// Fraction of ground-truth points with d(g, P) < tau.
    pub recall: f64,
    /// 2PR / (P + R), 0 when both are 0.
    pub fscore: f64,
}

/// The metrics of docs/conventions.md §8; serialises to the `trisplat eval --json` object of docs/conventions.md §10.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Metrics {
    /// Mean d(p, G).
    pub accuracy: f64,
    /// Mean d(g, P).
    pub completeness: f64,
    /// (accuracy + completeness) / 2.
    pub chamfer_l1: f64,
    /// (mean d(p, G)^2 + mean d(g, P)^2) / 2.
    pub chamfer_l2: f64,
    /// (mean |n_p . n_nn(p)| + mean |n_g . n_nn(g)|) / 2; `None` without normals.
    pub normal_consistency: Option<f64>,
    /// (mean acos |n_p . n_nn(p)| + mean acos |n_g . n_nn(g)|) / 2 in degrees; `None` without
    /// normals.
    pub normal_angle_deg: Option<f64>,
    /// Number of prediction points.
    pub n_pred: usize,
    /// Number of ground-truth points.
    pub n_gt: usize,
    /// Wall time of the computation (index builds and queries; not file loading or sampling).
    pub seconds: f64,
    /// One entry per threshold, in the order given.
    pub thresholds: Vec<ThresholdScore>,
}

impl Metrics {
    /// Records on each threshold score the fraction it was asked as (`taus` in the order
    /// the thresholds were given, as resolved by [`resolve_taus`]).
    #[must_use]
    pub fn with_tau_fractions(mut self, taus: &[Tau]) -> Self {
        for (score, tau) in self.thresholds.iter_mut().zip(taus) {
            score.tau_fraction = tau.fraction();
        }
        self
    }
}

/// An F-score threshold as asked for: a distance, or a fraction of the ground truth's
/// bounding-box diagonal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tau {
    /// A distance in the input's unit.
    Absolute(f64),
    /// A fraction of the ground truth's bounding-box diagonal.
    Fraction(f64),
}

impl Tau {
    /// The distance this threshold stands for when the ground truth's bounding-box diagonal
    /// is `diagonal`.
    #[must_use]
    pub fn resolve(self, diagonal: f64) -> f64 {
        match self {
            Self::Absolute(t) => t,
            Self::Fraction(f) => f * diagonal,
        }
    }

    /// The fraction, for [`Tau::Fraction`].
    #[must_use]
    pub fn fraction(self) -> Option<f64> {
        match self {
            Self::Absolute(_) => None,
            Self::Fraction(f) => Some(f),
        }
    }
}

/// The distances of `taus` for a ground truth of bounding-box diagonal `diagonal`.
///
/// # Errors
/// [`MetricsError::BadThreshold`] when a threshold is not a finite positive distance (a
/// fraction of a zero diagonal among them: a ground truth without extent).
pub fn resolve_taus(taus: &[Tau], diagonal: f64) -> Result<Vec<f64>, MetricsError> {
    taus.iter()
        .map(|t| {
            let tau = t.resolve(diagonal);
            if tau.is_finite() && tau > 0.0 {
                Ok(tau)
            } else {
                Err(MetricsError::BadThreshold { tau })
            }
        })
        .collect()
}

/// Length of the diagonal of the axis-aligned box around `points`, in f64 (0 for no points).
#[must_use]
pub fn bbox_diagonal(points: &[Vec3]) -> f64 {
    Aabb::from_points(points).map_or(0.0, |b| b.diagonal())
}

/// What the scores of a prediction against a ground truth measure.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
pub enum Relation {
    /// The prediction was made without the ground truth: the scores are its accuracy.
    #[default]
    #[serde(rename = "accuracy")]
    Accuracy,
    /// The prediction contains the ground truth's vertices (at least
    /// [`SELF_CONSISTENCY_MIN_SHARED`] of them, bit for bit): it consumed the mesh it is
    /// scored against, and the scores say how well it reproduces its own input, not how
    /// accurate it is.
    #[serde(rename = "self-consistency")]
    SelfConsistency,
}

impl Relation {
    /// The relation implied by a [`shared_vertex_fraction`] (`None`: not known, accuracy).
    #[must_use]
    pub fn from_shared_fraction(shared: Option<f64>) -> Self {
        match shared {
            Some(f) if f >= SELF_CONSISTENCY_MIN_SHARED => Self::SelfConsistency,
            _ => Self::Accuracy,
        }
    }

    /// `accuracy` or `self-consistency`, as in JSON.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Accuracy => "accuracy",
            Self::SelfConsistency => "self-consistency",
        }
    }
}

impl std::fmt::Display for Relation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Fraction of the ground truth's vertices `gt` whose position rounded to f32 (bit for bit, with
/// -0 taken as +0) is also one of `pred`'s (a prediction's vertices or points, rounded alike);
/// `None` when `gt` is empty. A prediction that copied the ground truth's vertices scores ~1, one
/// that re-meshed the surface ~0 (its vertices land on the surface, not on these points).
///
/// Sorts the smaller side's positions and looks the other side's up by binary search
/// (parallel), so the cost is `O((G + P) log min(G, P))`.
#[must_use]
pub fn shared_vertex_fraction(gt: &[DVec3], pred: &[DVec3]) -> Option<f64> {
    use std::sync::atomic::{AtomicBool, Ordering};
    if gt.is_empty() {
        return None;
    }
    // At f32 precision: a prediction that carried the vertices through f32 storage (points,
    // Gaussian means) copied them all the same.
    let key = |p: &DVec3| {
        let p = p.as_vec3();
        [p.x + 0.0, p.y + 0.0, p.z + 0.0].map(f32::to_bits)
    };
    let shared = if pred.len() <= gt.len() {
        let mut keys: Vec<[u32; 3]> = pred.par_iter().map(key).collect();
        keys.par_sort_unstable();
        keys.dedup();
        gt.par_iter()
            .filter(|&p| keys.binary_search(&key(p)).is_ok())
            .count()
    } else {
        // Distinct ground-truth positions with their multiplicity, marked when seen in pred.
        let mut keys: Vec<[u32; 3]> = gt.par_iter().map(key).collect();
        keys.par_sort_unstable();
        let runs: Vec<(&[u32; 3], usize)> = keys
            .chunk_by(|a, b| a == b)
            .map(|run| (&run[0], run.len()))
            .collect();
        let seen: Vec<AtomicBool> = runs.iter().map(|_| AtomicBool::new(false)).collect();
        pred.par_iter().for_each(|p| {
            let k = key(p);
            if let Ok(i) = runs.binary_search_by(|(r, _)| (*r).cmp(&k)) {
                seen[i].store(true, Ordering::Relaxed);
            }
        });
        runs.iter()
            .zip(&seen)
            .filter(|(_, s)| s.load(Ordering::Relaxed))
            .map(|((_, n), _)| n)
            .sum()
    };
    Some(shared as f64 / gt.len() as f64)
}

/// One side of a comparison: points (with optional normals), and for surface mode the mesh
/// they were sampled from.
#[derive(Clone, Copy, Debug)]
pub struct Shape<'a> {
    /// The points used as queries, and as the target in point mode.
    pub points: &'a PointCloud,
    /// The mesh, when the side is one: the target of surface-mode distances.
    pub mesh: Option<&'a TriMesh>,
    /// A BVH already built over `mesh` (see [`Shape::indexed_mesh`]).
    pub bvh: Option<&'a TriangleBvh>,
    /// A [`SurfaceIndex`] already built over `mesh` (see [`Shape::surface_indexed`]); with
    /// neither index, surface mode builds a [`SurfaceIndex`] per call.
    pub surface: Option<&'a SurfaceIndex>,
}

impl<'a> Shape<'a> {
    /// A point set.
    #[must_use]
    pub fn points(points: &'a PointCloud) -> Self {
        Self {
            points,
            mesh: None,
            bvh: None,
            surface: None,
        }
    }

    /// A mesh and points sampled on it (e.g. by [`crate::sampling::sample_uniform`]).
    #[must_use]
    pub fn mesh(mesh: &'a TriMesh, samples: &'a PointCloud) -> Self {
        Self {
            points: samples,
            mesh: Some(mesh),
            bvh: None,
            surface: None,
        }
    }

    /// A mesh, points sampled on it, and a BVH built over it (`TriangleBvh::new(mesh)`):
    /// a side measured against several others builds its index once.
    #[must_use]
    pub fn indexed_mesh(mesh: &'a TriMesh, samples: &'a PointCloud, bvh: &'a TriangleBvh) -> Self {
        Self {
            points: samples,
            mesh: Some(mesh),
            bvh: Some(bvh),
            surface: None,
        }
    }

    /// A mesh, points sampled on it, and a [`SurfaceIndex`] over its triangles (built from
    /// `mesh.positions()` and `mesh.triangles()`): a side measured against several others
    /// builds its index once.
    #[must_use]
    pub fn surface_indexed(
        mesh: &'a TriMesh,
        samples: &'a PointCloud,
        index: &'a SurfaceIndex,
    ) -> Self {
        Self {
            points: samples,
            mesh: Some(mesh),
            bvh: None,
            surface: Some(index),
        }
    }
}

/// What to compute.
#[derive(Clone, Debug, PartialEq)]
pub struct MetricsOptions {
    /// F-score thresholds (finite, positive), in the input's unit.
    pub taus: Vec<f64>,
    /// Surface mode: distances to the other side's triangles when it is a mesh.
    pub surface: bool,
}

impl Default for MetricsOptions {
    fn default() -> Self {
        Self {
            taus: DEFAULT_TAUS.to_vec(),
            surface: false,
        }
    }
}

/// Point-mode metrics between two point sets (k-d tree both ways).
///
/// # Errors
/// As [`evaluate`].
pub fn point_metrics(
    pred: &PointCloud,
    gt: &PointCloud,
    taus: &[f64],
) -> Result<Metrics, MetricsError> {
    evaluate(
        Shape::points(pred),
        Shape::points(gt),
        &MetricsOptions {
            taus: taus.to_vec(),
            surface: false,
        },
    )
}

/// Computes the metrics of P = `pred` against G = `gt` (see the module docs).
///
/// # Errors
/// [`MetricsError::Empty`] when a side has no points, [`MetricsError::BadThreshold`],
/// [`MetricsError::Spatial`] when coordinates exceed the indexes' range.
pub fn evaluate(
    pred: Shape<'_>,
    gt: Shape<'_>,
    options: &MetricsOptions,
) -> Result<Metrics, MetricsError> {
    let start = Instant::now();
    if let Some(&tau) = options.taus.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        return Err(MetricsError::BadThreshold { tau });
    }
    if pred.points.is_empty() {
        return Err(MetricsError::Empty(Side::Prediction));
    }
    if gt.points.is_empty() {
        return Err(MetricsError::Empty(Side::GroundTruth));
    }
    let with_normals = pred.points.normals().is_some() && gt.points.normals().is_some();
    let (forward, backward) = if point_to_point(gt, options) && point_to_point(pred, options) {
        point_sums(pred, gt, options, with_normals)?
    } else {
        let (forward, backward) = rayon::join(
            || one_way(pred, gt, Side::GroundTruth, options, with_normals),
            || one_way(gt, pred, Side::Prediction, options, with_normals),
        );
        (forward?, backward?)
    };
    let n_p = pred.points.len() as f64;
    let n_g = gt.points.len() as f64;
    let accuracy = forward.sum_d / n_p;
    let completeness = backward.sum_d / n_g;
    let thresholds = options
        .taus
        .iter()
        .zip(forward.below.iter().zip(&backward.below))
        .map(|(&tau, (&bp, &bg))| {
            let precision = bp as f64 / n_p;
            let recall = bg as f64 / n_g;
            let fscore = if precision + recall > 0.0 {
                2.0 * precision * recall / (precision + recall)
            } else {
                0.0
            };
            ThresholdScore {
                tau,
                tau_fraction: None,
                precision,
                recall,
                fscore,
            }
        })
        .collect();
    let normals = forward.normals.zip(backward.normals);
    Ok(Metrics {
        accuracy,
        completeness,
        chamfer_l1: 0.5 * (accuracy + completeness),
        chamfer_l2: 0.5 * (forward.sum_d2 / n_p + backward.sum_d2 / n_g),
        normal_consistency: normals.map(|((cp, _), (cg, _))| 0.5 * (cp / n_p + cg / n_g)),
        normal_angle_deg: normals
            .map(|((_, ap), (_, ag))| 0.5 * (ap / n_p + ag / n_g).to_degrees()),
        n_pred: pred.points.len(),
        n_gt: gt.points.len(),
        seconds: start.elapsed().as_secs_f64(),
        thresholds,
    })
}

/// Sums over the queries of one direction.
#[derive(Clone, Debug, Default)]
struct Sums {
    sum_d: f64,
    sum_d2: f64,
    /// Count of distances below each threshold.
    below: Vec<u64>,
    /// Sum of |cos| and of the angle in radians, when normals are used.
    normals: Option<(f64, f64)>,
}

/// Whether distances to `to` are to its points (point mode, or a side without triangles).
fn point_to_point(to: Shape<'_>, options: &MetricsOptions) -> bool {
    !(options.surface && to.mesh.is_some_and(|m| m.triangle_count() > 0))
}

/// Both directions in point mode: one k-d tree per side, built side by side, and each
/// side's points asked of the other's tree in that side's own tree order (spatially coherent,
/// so no sort of the queries).
fn point_sums(
    pred: Shape<'_>,
    gt: Shape<'_>,
    options: &MetricsOptions,
    with_normals: bool,
) -> Result<(Sums, Sums), MetricsError> {
    let index = |side: Side, shape: Shape<'_>| {
        PointIndex::new(shape.points.positions())
            .map_err(|source| MetricsError::Spatial { side, source })
    };
    let (pred_index, gt_index) = rayon::join(
        || index(Side::Prediction, pred),
        || index(Side::GroundTruth, gt),
    );
    let (pred_index, gt_index) = (pred_index?, gt_index?);
    let sums = |from: Shape<'_>, to: Shape<'_>, found: &[Nearest]| {
        let normals = if with_normals {
            from.points.normals().zip(to.points.normals())
        } else {
            None
        };
        // Each neighbour's normal, gathered first in a loop of loads alone: the neighbours lie
        // anywhere in `to`'s normals, and inside the sums' loop (a normalisation and an `acos`
        // per item) those cache misses were taken one at a time (18% of `eval`'s CPU time on
        // 1M <-> 1M points). The sums are then those of the same terms in the same order.
        let gathered = normals.map(|(qn, tn)| (qn, neighbour_normals(found, tn)));
        let gathered = gathered.as_ref();
        accumulate(
            found.len(),
            |i| found[i].distance,
            gathered.map(|(qn, nn)| move |i: usize| (qn[i], nn[i])),
            &options.taus,
        )
    };
    Ok(rayon::join(
        || sums(pred, gt, &gt_index.nearest_to_points_of(&pred_index)),
        || sums(gt, pred, &pred_index.nearest_to_points_of(&gt_index)),
    ))
}

/// The normal of each query's neighbour, `normals[found[i].index]`, gathered in parallel.
fn neighbour_normals(found: &[Nearest], normals: &[Vec3]) -> Vec<Vec3> {
    found
        .par_iter()
        .with_min_len(SUM_CHUNK)
        .map(|n| normals[n.index as usize])
        .collect()
}

/// Distances (and neighbour normals) from `from`'s points to `to`, summed.
fn one_way(
    from: Shape<'_>,
    to: Shape<'_>,
    to_side: Side,
    options: &MetricsOptions,
    with_normals: bool,
) -> Result<Sums, MetricsError> {
    let from_side = match to_side {
        Side::Prediction => Side::GroundTruth,
        Side::GroundTruth => Side::Prediction,
    };
    let queries = from.points.positions();
    let query_normals = if with_normals {
        from.points.normals()
    } else {
        None
    };
    let spatial = |side: Side| move |source: SpatialError| MetricsError::Spatial { side, source };
    match (options.surface, to.mesh) {
        (true, Some(mesh)) if mesh.triangle_count() > 0 => {
            // (distance, triangle) of every query: from the index given, else a fresh
            // SurfaceIndex (cheaper to build than a TriangleBvh for one batch of queries).
            let found: Vec<(f64, u32)> = match (to.surface, to.bvh) {
                (Some(index), _) => surface_hits(index, queries, from_side)?,
                (None, Some(bvh)) => bvh
                    .closest_points(queries)
                    .map_err(spatial(from_side))?
                    .into_iter()
                    .map(|c| (c.distance, c.triangle))
                    .collect(),
                (None, None) => {
                    let index = SurfaceIndex::new(mesh.positions(), mesh.triangles())
                        .map_err(spatial(to_side))?;
                    surface_hits(&index, queries, from_side)?
                }
            };
            let found = &found;
            // The unit normal of each triangle found, as `TriMesh::face_normals` has it.
            let face_normal = move |t: u32| {
                mesh.triangle_cross(t as usize)
                    .normalize_or_zero()
                    .as_vec3()
            };
            Ok(accumulate(
                found.len(),
                |i| found[i].0,
                query_normals.map(|qn| move |i: usize| (qn[i], face_normal(found[i].1))),
                &options.taus,
            ))
        }
        _ => {
            let index = PointIndex::new(to.points.positions()).map_err(spatial(to_side))?;
            let found = &index.nearest_batch(queries).map_err(spatial(from_side))?;
            let target_normals = if with_normals {
                to.points.normals()
            } else {
                None
            };
            Ok(accumulate(
                found.len(),
                |i| found[i].distance,
                query_normals
                    .zip(target_normals)
                    .map(|(qn, tn)| move |i: usize| (qn[i], tn[found[i].index as usize])),
                &options.taus,
            ))
        }
    }
}

/// [`SurfaceIndex::closest_batch`] as `(distance, triangle)`, errors naming `side`.
fn surface_hits(
    index: &SurfaceIndex,
    queries: &[Vec3],
    side: Side,
) -> Result<Vec<(f64, u32)>, MetricsError> {
    Ok(index
        .closest_batch(queries)
        .map_err(|source| MetricsError::Spatial { side, source })?
        .into_iter()
        .map(|h| (h.distance, h.triangle))
        .collect())
}

/// |cos| of the angle between two normals, normalised in f64 (0 when either is zero).
#[inline]
fn abs_cos(a: Vec3, b: Vec3) -> f64 {
    let a = a.as_dvec3().normalize_or_zero();
    let b = b.as_dvec3().normalize_or_zero();
    DVec3::dot(a, b).abs().min(1.0)
}

/// Sums distance terms (and normal terms) over `n` items in fixed chunks, in parallel, then
/// adds the chunk sums in order: the result is independent of the thread count.
fn accumulate<D, N>(n: usize, distance: D, normals: Option<N>, taus: &[f64]) -> Sums
where
    D: Fn(usize) -> f64 + Sync,
    N: Fn(usize) -> (Vec3, Vec3) + Sync,
{
    let chunks: Vec<Sums> = (0..n.div_ceil(SUM_CHUNK))
        .into_par_iter()
        .map(|c| {
            let range = c * SUM_CHUNK..((c + 1) * SUM_CHUNK).min(n);
            let mut s = Sums {
                below: vec![0; taus.len()],
                normals: normals.as_ref().map(|_| (0.0, 0.0)),
                ..Sums::default()
            };
            for i in range {
                let d = distance(i);
                s.sum_d += d;
                s.sum_d2 += d * d;
                for (count, &tau) in s.below.iter_mut().zip(taus) {
                    *count += u64::from(d < tau);
                }
                if let (Some(f), Some((cos_sum, angle_sum))) = (normals.as_ref(), &mut s.normals) {
                    let (a, b) = f(i);
                    let cos = abs_cos(a, b);
                    *cos_sum += cos;
                    *angle_sum += cos.acos();
                }
            }
            s
        })
        .collect();
    let mut total = Sums {
        below: vec![0; taus.len()],
        normals: normals.as_ref().map(|_| (0.0, 0.0)),
        ..Sums::default()
    };
    for c in chunks {
        total.sum_d += c.sum_d;
        total.sum_d2 += c.sum_d2;
        for (t, b) in total.below.iter_mut().zip(&c.below) {
            *t += b;
        }
        if let (Some((tc, ta)), Some((cc, ca))) = (&mut total.normals, c.normals) {
            *tc += cc;
            *ta += ca;
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use crate::spatial::kdtree::distance_f64;

    fn cloud(n: usize, seed: u64, normals: bool) -> PointCloud {
        let mut rng = Rng::new(seed);
        let p: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()))
            .collect();
        let cloud = PointCloud::try_new(p).expect("finite");
        if normals {
            let nrm = (0..n)
                .map(|_| {
                    Vec3::new(
                        rng.uniform_f32() - 0.5,
                        rng.uniform_f32() - 0.5,
                        rng.uniform_f32() - 0.5,
                    )
                })
                .collect();
            cloud.with_normals(nrm).expect("same length")
        } else {
            cloud
        }
    }

    /// Brute-force nearest (index, distance).
    fn brute(to: &[Vec3], q: Vec3) -> (usize, f64) {
        to.iter()
            .enumerate()
            .map(|(i, &p)| (i, distance_f64(q, p)))
            .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a })
    }

    #[test]
    fn point_metrics_match_a_direct_computation() {
        let p = cloud(700, 1, true);
        let g = cloud(900, 2, true);
        let taus = [0.01, 0.05, 0.1];
        let m = point_metrics(&p, &g, &taus).expect("valid");
        let dir = |a: &PointCloud, b: &PointCloud| {
            let (mut sd, mut sd2, mut sc, mut sa) = (0.0, 0.0, 0.0, 0.0);
            let mut below = [0usize; 3];
            for (i, &q) in a.positions().iter().enumerate() {
                let (j, d) = brute(b.positions(), q);
                sd += d;
                sd2 += d * d;
                for (k, tau) in taus.iter().enumerate() {
                    below[k] += usize::from(d < *tau);
                }
                let c = abs_cos(a.normals().unwrap()[i], b.normals().unwrap()[j]);
                sc += c;
                sa += c.acos();
            }
            let n = a.len() as f64;
            (sd / n, sd2 / n, sc / n, sa / n, below.map(|b| b as f64 / n))
        };
        let (acc, acc2, cp, ap, prec) = dir(&p, &g);
        let (comp, comp2, cg, ag, rec) = dir(&g, &p);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1e-300);
        assert!(close(m.accuracy, acc));
        assert!(close(m.completeness, comp));
        assert!(close(m.chamfer_l1, 0.5 * (acc + comp)));
        assert!(close(m.chamfer_l2, 0.5 * (acc2 + comp2)));
        assert!(close(m.normal_consistency.unwrap(), 0.5 * (cp + cg)));
        assert!(close(
            m.normal_angle_deg.unwrap(),
            0.5 * (ap + ag).to_degrees()
        ));
        for (k, t) in m.thresholds.iter().enumerate() {
            assert_eq!(t.precision, prec[k]);
            assert_eq!(t.recall, rec[k]);
            let f = if prec[k] + rec[k] > 0.0 {
                2.0 * prec[k] * rec[k] / (prec[k] + rec[k])
            } else {
                0.0
            };
            assert!(close(t.fscore, f) || f == 0.0 && t.fscore == 0.0);
        }
        assert_eq!((m.n_pred, m.n_gt), (700, 900));
    }

    #[test]
    fn identical_sets_are_perfect_and_fscore_zero_case() {
        let p = cloud(300, 3, true);
        let m = point_metrics(&p, &p.clone(), &[1e-9]).expect("valid");
        assert_eq!(m.chamfer_l1, 0.0);
        assert_eq!(m.chamfer_l2, 0.0);
        assert_eq!(m.normal_consistency, Some(1.0));
        assert_eq!(m.thresholds[0].fscore, 1.0);
        // Far apart: every threshold fails, fscore 0 (not NaN).
        let far = PointCloud::try_new(vec![Vec3::splat(100.0)]).expect("finite");
        let m = point_metrics(&p, &far, &[0.5]).expect("valid");
        assert_eq!(m.thresholds[0].fscore, 0.0);
        assert_eq!(m.normal_consistency, None);
        assert_eq!(m.normal_angle_deg, None);
    }

    #[test]
    fn errors_instead_of_nan() {
        let p = cloud(10, 4, false);
        let empty = PointCloud::default();
        assert_eq!(
            point_metrics(&empty, &p, &[0.1]),
            Err(MetricsError::Empty(Side::Prediction))
        );
        assert_eq!(
            point_metrics(&p, &empty, &[0.1]),
            Err(MetricsError::Empty(Side::GroundTruth))
        );
        for tau in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                point_metrics(&p, &p, &[tau]),
                Err(MetricsError::BadThreshold { .. })
            ));
        }
        let huge = PointCloud::try_new(vec![Vec3::splat(1e30)]).expect("finite");
        assert!(matches!(
            point_metrics(&p, &huge, &[0.1]),
            Err(MetricsError::Spatial {
                side: Side::GroundTruth,
                ..
            })
        ));
    }

    #[test]
    fn surface_mode_uses_exact_triangle_distances() {
        // G: the unit square at z = 0 (two triangles); P: points above it at height h.
        let mesh = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let mut rng = Rng::new(5);
        let h = 0.01f32;
        let pts: Vec<Vec3> = (0..500)
            .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), h))
            .collect();
        let pred = PointCloud::try_new(pts.clone())
            .expect("finite")
            .with_normals(vec![Vec3::Z; 500])
            .expect("same length");
        let samples = crate::sampling::sample_uniform(&mesh, 2000, 7);
        let options = MetricsOptions {
            taus: vec![0.02],
            surface: true,
        };
        let m =
            evaluate(Shape::points(&pred), Shape::mesh(&mesh, &samples), &options).expect("valid");
        assert!((m.accuracy - f64::from(h)).abs() < 1e-9, "{}", m.accuracy);
        assert_eq!(m.thresholds[0].precision, 1.0);
        assert!(m.normal_consistency.expect("normals") > 0.999_999);
        // Point mode has the sampling floor: accuracy is larger.
        let point = evaluate(
            Shape::points(&pred),
            Shape::mesh(&mesh, &samples),
            &MetricsOptions {
                surface: false,
                ..options
            },
        )
        .expect("valid");
        assert!(point.accuracy > m.accuracy + 1e-3);
    }

    #[test]
    fn independent_of_thread_count() {
        let p = cloud(20_000, 8, true);
        let g = cloud(15_000, 9, true);
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| point_metrics(&p, &g, &DEFAULT_TAUS).expect("valid"))
        };
        let (mut a, mut b) = (run(1), run(3));
        a.seconds = 0.0;
        b.seconds = 0.0;
        assert_eq!(a, b);
    }

    #[test]
    fn json_keys_follow_the_cli_contract() {
        let p = cloud(50, 10, false);
        let m = point_metrics(&p, &p, &[0.1]).expect("valid");
        let v = serde_json::to_value(&m).expect("serialises");
        for key in [
            "accuracy",
            "completeness",
            "chamfer_l1",
            "chamfer_l2",
            "normal_consistency",
            "normal_angle_deg",
            "n_pred",
            "n_gt",
            "seconds",
            "thresholds",
        ] {
            assert!(v.get(key).is_some(), "{key}");
        }
        assert!(v["normal_consistency"].is_null());
        let t = &v["thresholds"][0];
        for key in ["tau", "tau_fraction", "precision", "recall", "fscore"] {
            assert!(t.get(key).is_some(), "{key}");
        }
        assert!(t["tau_fraction"].is_null());
        let m = m.with_tau_fractions(&[Tau::Fraction(0.01)]);
        assert_eq!(m.thresholds[0].tau_fraction, Some(0.01));
    }

    #[test]
    fn relative_thresholds_resolve_against_the_diagonal() {
        let diag = bbox_diagonal(&[Vec3::ZERO, Vec3::new(3.0, 4.0, 0.0), Vec3::X]);
        assert_eq!(diag, 5.0);
        assert_eq!(
            resolve_taus(&[Tau::Fraction(0.01), Tau::Absolute(0.2)], diag),
            Ok(vec![0.05, 0.2])
        );
        // A ground truth without extent has no relative threshold.
        assert_eq!(bbox_diagonal(&[]), 0.0);
        assert_eq!(
            resolve_taus(&[Tau::Fraction(0.01)], 0.0),
            Err(MetricsError::BadThreshold { tau: 0.0 })
        );
        assert!(resolve_taus(&[Tau::Absolute(f64::NAN)], 1.0).is_err());
    }

    /// The definition: each ground-truth vertex looked for among all prediction vertices.
    fn shared_by_scan(gt: &[DVec3], pred: &[DVec3]) -> Option<f64> {
        let same = |a: DVec3, b: DVec3| a.x == b.x && a.y == b.y && a.z == b.z;
        (!gt.is_empty()).then(|| {
            gt.iter()
                .filter(|&&g| pred.iter().any(|&p| same(g, p)))
                .count() as f64
                / gt.len() as f64
        })
    }

    #[test]
    fn shared_vertices_by_bits_on_both_search_paths() {
        let mut rng = Rng::new(12);
        let grid = |rng: &mut Rng| DVec3::new(rng.below(4) as f64, rng.below(4) as f64, 0.0);
        for case in 0..200 {
            let g: Vec<DVec3> = (0..case % 30).map(|_| grid(&mut rng)).collect();
            let p: Vec<DVec3> = (0..(case * 7) % 45).map(|_| grid(&mut rng)).collect();
            assert_eq!(
                shared_vertex_fraction(&g, &p),
                shared_by_scan(&g, &p),
                "{case}"
            );
        }
        // -0 and +0 are one position; a one-ulp difference is another.
        let g = [DVec3::new(-0.0, 1.0, 2.0), DVec3::new(1.0, 1.0, 1.0)];
        let p = [
            DVec3::new(0.0, 1.0, 2.0),
            DVec3::new(1.0, 1.0, f64::from(f32::from_bits(1.0f32.to_bits() + 1))),
        ];
        assert_eq!(shared_vertex_fraction(&g, &p), Some(0.5));
        assert_eq!(shared_vertex_fraction(&[], &p), None);
        assert_eq!(shared_vertex_fraction(&g, &[]), Some(0.0));
        assert_eq!(
            Relation::from_shared_fraction(Some(0.5)),
            Relation::SelfConsistency
        );
        assert_eq!(
            Relation::from_shared_fraction(Some(0.49)),
            Relation::Accuracy
        );
        assert_eq!(Relation::from_shared_fraction(None), Relation::Accuracy);
        assert_eq!(
            serde_json::to_value(Relation::SelfConsistency).expect("json"),
            "self-consistency"
        );
    }
}
