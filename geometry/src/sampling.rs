//! Surface sampling: area-uniform (Open3D's `sample_points_uniformly`), weighted by any
//! per-triangle density (curvature-weighted sampling builds on it), and Poisson disk by Yuksel's
//! weighted sample elimination (Open3D's `sample_points_poisson_disk`).
//!
//! # Area-uniform sampling
//! A triangle is drawn with probability proportional to its area (binary search in the f64
//! cumulative areas), then a point in it with Open3D's barycentrics
//! `(1 - sqrt r1, sqrt r1 (1 - r2), sqrt r1 r2)` for uniform `r1, r2` in `[0, 1)`, which is
//! uniform over the triangle. Each point carries its triangle's unit face normal.
//!
//! # Seeds and threads
//! Samples are produced in fixed chunks of [`SAMPLE_CHUNK`] points; chunk `i` draws from
//! [`Rng::stream`]`(seed, i)`. The output therefore depends only on the mesh, `n` and the seed,
//! never on the number of threads.
//!
//! # Degenerate input
//! A mesh whose total area is zero (no triangles, or only degenerate ones) has no surface to
//! sample: the `sample_*` functions return an empty set (no NaN, no panic). Callers that need
//! points (the CLI) check [`SurfaceSamples::is_empty`] and report an error.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::TriId;
use crate::mesh::TriMesh;
use crate::points::PointCloud;
use crate::rng::Rng;

/// Number of samples drawn from one random stream. Fixed so that the output does not depend on
/// the thread count.
pub const SAMPLE_CHUNK: usize = 4096;

/// Errors of weighted sampling.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum SamplingError {
    /// The weight array does not have one entry per triangle.
    #[error("{len} triangle weights given, but the mesh has {triangle_count} triangles")]
    WeightCount {
        /// Entries given.
        len: usize,
        /// Number of triangles.
        triangle_count: usize,
    },
    /// A triangle weight is negative, NaN or infinite.
    #[error("triangle {triangle} has weight {weight}, expected a finite value >= 0")]
    BadWeight {
        /// Triangle index.
        triangle: usize,
        /// The offending weight.
        weight: f64,
    },
}

/// Points sampled on a mesh surface, each with the triangle it lies on.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceSamples {
    /// The points, with their triangles' unit face normals.
    pub points: PointCloud,
    /// The triangle of every point.
    pub triangles: Vec<TriId>,
}

impl SurfaceSamples {
    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// True when there are no samples (also the result for a zero-area mesh).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }
}

/// A discrete distribution over triangles: f64 cumulative weights searched by bisection.
#[derive(Clone, Debug)]
pub struct TriangleDistribution {
    cumulative: Vec<f64>,
    /// Last triangle with positive weight: the clamp target when rounding lands on the total.
    last_positive: usize,
}

impl TriangleDistribution {
    /// Distribution proportional to `weights`; `Ok(None)` when they sum to zero.
    ///
    /// # Errors
    /// [`SamplingError::BadWeight`] for a negative or non-finite weight, or when the sum
    /// overflows to infinity.
    pub fn new(weights: &[f64]) -> Result<Option<Self>, SamplingError> {
        let mut cumulative = Vec::with_capacity(weights.len());
        let mut sum = 0.0f64;
        let mut last_positive = None;
        for (t, &w) in weights.iter().enumerate() {
            if !(w.is_finite() && w >= 0.0) {
                return Err(SamplingError::BadWeight {
                    triangle: t,
                    weight: w,
                });
            }
            sum += w;
            if !sum.is_finite() {
                return Err(SamplingError::BadWeight {
                    triangle: t,
                    weight: w,
                });
            }
            if w > 0.0 {
                last_positive = Some(t);
            }
            cumulative.push(sum);
        }
        Ok(last_positive
            .filter(|_| sum > 0.0)
            .map(|last_positive| Self {
                cumulative,
                last_positive,
            }))
    }

    /// Sum of the weights.
    #[must_use]
    pub fn total(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    /// The triangle whose cumulative interval holds `u * total` for `u` in `[0, 1)`. Zero-weight
    /// triangles are never returned.
    #[inline]
    #[must_use]
    pub fn pick(&self, u: f64) -> usize {
        let r = u * self.total();
        self.cumulative
            .partition_point(|&c| c <= r)
            .min(self.last_positive)
    }
}

/// Open3D's barycentric coordinates `(1 - sqrt r1, sqrt r1 (1 - r2), sqrt r1 r2)`.
#[inline]
#[must_use]
pub fn open3d_barycentrics(r1: f64, r2: f64) -> [f64; 3] {
    let s = r1.sqrt();
    [1.0 - s, s * (1.0 - r2), s * r2]
}

/// `n` points distributed over the surface with density proportional to per-triangle `weights`
/// times uniform within each triangle. With `weights` = triangle areas this is area-uniform.
/// Returns an empty set when the weights sum to zero.
///
/// # Errors
/// [`SamplingError`] when `weights` has the wrong length or a negative or non-finite entry.
pub fn sample_weighted(
    mesh: &TriMesh,
    weights: &[f64],
    n: usize,
    seed: u64,
) -> Result<SurfaceSamples, SamplingError> {
    if weights.len() != mesh.triangle_count() {
        return Err(SamplingError::WeightCount {
            len: weights.len(),
            triangle_count: mesh.triangle_count(),
        });
    }
    let Some(dist) = TriangleDistribution::new(weights)? else {
        return Ok(SurfaceSamples::default());
    };
    Ok(sample_distribution(mesh, &dist, n, seed))
}

/// Area-uniform samples with their triangles. Empty for a zero-area mesh.
#[must_use]
pub fn sample_uniform_with_triangles(mesh: &TriMesh, n: usize, seed: u64) -> SurfaceSamples {
    let areas = mesh.triangle_areas();
    // Areas of a valid mesh are finite and >= 0 (f64 products of finite f32 coordinates).
    match TriangleDistribution::new(&areas) {
        Ok(Some(dist)) => sample_distribution(mesh, &dist, n, seed),
        Ok(None) | Err(_) => SurfaceSamples::default(),
    }
}

/// `n` area-uniform points on the surface of `mesh` with their triangles' unit face normals, as
/// Open3D's `sample_points_uniformly` (same barycentrics, different random numbers). The result
/// depends only on `mesh`, `n` and `seed`, not on the thread count. Empty for a zero-area mesh.
#[must_use]
pub fn sample_uniform(mesh: &TriMesh, n: usize, seed: u64) -> PointCloud {
    sample_uniform_with_triangles(mesh, n, seed).points
}

/// Draws `n` samples from `dist` in parallel, one random stream per [`SAMPLE_CHUNK`].
fn sample_distribution(
    mesh: &TriMesh,
    dist: &TriangleDistribution,
    n: usize,
    seed: u64,
) -> SurfaceSamples {
    let face_normals = mesh.face_normals();
    let mut positions = vec![Vec3::ZERO; n];
    let mut normals = vec![Vec3::ZERO; n];
    let mut triangles = vec![TriId(0); n];
    positions
        .par_chunks_mut(SAMPLE_CHUNK)
        .zip(normals.par_chunks_mut(SAMPLE_CHUNK))
        .zip(triangles.par_chunks_mut(SAMPLE_CHUNK))
        .enumerate()
        .for_each(|(chunk, ((pos, nor), tri))| {
            let mut rng = Rng::stream(seed, chunk as u64);
            for ((p, nrm), t_out) in pos.iter_mut().zip(nor.iter_mut()).zip(tri.iter_mut()) {
                let t = dist.pick(rng.uniform_f64());
                let r1 = rng.uniform_f64();
                let r2 = rng.uniform_f64();
                let [wa, wb, wc] = open3d_barycentrics(r1, r2);
                let [a, b, c] = mesh.corners(t).map(Vec3::as_dvec3);
                let q: DVec3 = a * wa + b * wb + c * wc;
                *p = q.as_vec3();
                *nrm = face_normals[t];
                // A TriMesh has at most u32::MAX + 1 vertices; triangle counts beyond u32 are
                // not addressable by TriId and cannot come from our readers.
                *t_out = TriId(t as u32);
            }
        });
    let points = PointCloud::new_unchecked(positions)
        .with_normals(normals)
        .expect("one normal per point by construction");
    SurfaceSamples { points, triangles }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> TriMesh {
        TriMesh::new(
            vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(5.0, 5.0, 5.0),
            ],
            // The last triangle is degenerate and must never be picked.
            vec![[0, 1, 2], [0, 2, 3], [4, 4, 4]],
        )
    }

    #[test]
    fn points_lie_on_their_triangle_with_face_normal() {
        let m = square();
        let s = sample_uniform_with_triangles(&m, 10_000, 3);
        assert_eq!(s.len(), 10_000);
        let normals = s.points.normals().unwrap();
        for ((p, n), t) in s.points.positions().iter().zip(normals).zip(&s.triangles) {
            assert!(t.0 < 2);
            assert_eq!(p.z, 0.0);
            assert!((0.0..=1.0).contains(&p.x) && (0.0..=1.0).contains(&p.y));
            // Triangle 0 is below the diagonal x = y, triangle 1 above.
            if t.0 == 0 {
                assert!(p.x >= p.y - 1e-6);
            } else {
                assert!(p.y >= p.x - 1e-6);
            }
            assert_eq!(*n, Vec3::Z);
        }
    }

    #[test]
    fn zero_area_and_zero_count_give_empty() {
        let flat = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0], vec![[0, 1, 2]]);
        assert!(sample_uniform(&flat, 100, 1).is_empty());
        assert!(sample_uniform(&TriMesh::default(), 100, 1).is_empty());
        assert!(sample_uniform(&square(), 0, 1).is_empty());
    }

    #[test]
    fn bad_weights_are_errors() {
        let m = square();
        assert!(matches!(
            sample_weighted(&m, &[1.0], 10, 0),
            Err(SamplingError::WeightCount { .. })
        ));
        assert!(matches!(
            sample_weighted(&m, &[1.0, f64::NAN, 0.0], 10, 0),
            Err(SamplingError::BadWeight { triangle: 1, .. })
        ));
        assert!(matches!(
            sample_weighted(&m, &[1.0, -1.0, 0.0], 10, 0),
            Err(SamplingError::BadWeight { triangle: 1, .. })
        ));
        let only_second = sample_weighted(&m, &[0.0, 1.0, 0.0], 500, 0).unwrap();
        assert!(only_second.triangles.iter().all(|t| t.0 == 1));
    }

    #[test]
    fn distribution_clamps_to_last_positive() {
        let d = TriangleDistribution::new(&[0.0, 2.0, 0.0])
            .unwrap()
            .unwrap();
        assert_eq!(d.pick(0.0), 1);
        assert_eq!(d.pick(0.999_999_999), 1);
        assert_eq!(d.pick(1.0), 1);
        assert!(TriangleDistribution::new(&[0.0, 0.0]).unwrap().is_none());
    }
}
