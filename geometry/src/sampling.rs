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
//! # Poisson disk
//! [`sample_poisson_disk`] is Yuksel's weighted sample elimination (Eurographics 2015), as Open3D's
//! `sample_points_poisson_disk` with `init_factor` 5: draw `5 N` area-uniform candidates, give
//! each the weight `Σ_j (1 − max(d_ij, d_min) / d_max)^α` over the other candidates within
//! `d_max`, and repeatedly remove the heaviest candidate (subtracting its contribution from its
//! neighbours) until `N` remain. `d_max = 2 sqrt(A / (2 sqrt 3 N))` is twice the largest disk
//! radius `N` points can have on area `A` (hexagonal packing) and
//! `d_min = d_max β (1 − (N / M)^γ)` for `M` candidates. Constants from the paper: α = 8,
//! β = 0.65, γ = 1.5 (Open3D's source uses β = 0.5). Distances are Euclidean in 3D, as in Open3D.
//! Degenerate sets stay near-linear: when the candidates are at least 4x denser than `A`
//! says (overlapping or coincident triangles count their area several times), `d_max`
//! follows their measured density instead (the median distance to the 32nd neighbour of 256
//! of them, scaled to the ~18 neighbours a candidate has within `d_max` on a surface); when
//! they lie within `d_max` of an axis-parallel line, neighbours are found through cells of side
//! `d_max` rather than the k-d tree. Ordinary meshes take neither path.
//!
//! # Curvature-weighted sampling
//! [`sample_curvature`] draws triangles with probability proportional to
//! `A_t (1 + c |H_t| / H̄)`, where `|H_t|` is the mean of the absolute discrete mean curvature
//! of the triangle's corners ([`vertex_mean_curvature`]), `H̄` its area-weighted mean over the
//! mesh (so `c` is dimensionless and the density does not depend on the mesh's scale), and `c`
//! the strength (0 gives area-uniform sampling).
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
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::ids::TriId;
use crate::mesh::TriMesh;
use crate::points::PointCloud;
use crate::rng::Rng;

/// Number of samples drawn from one random stream. Fixed so that the output does not depend on
/// the thread count.
pub const SAMPLE_CHUNK: usize = 4096;

/// Yuksel's weight exponent α.
pub const POISSON_ALPHA: f64 = 8.0;
/// Yuksel's β: the weight is flat below `d_min = d_max β (1 − (N/M)^γ)`.
pub const POISSON_BETA: f64 = 0.65;
/// Yuksel's γ.
pub const POISSON_GAMMA: f64 = 1.5;
/// Candidates per output point (Open3D's `init_factor` default).
pub const POISSON_INIT_FACTOR: usize = 5;
/// Default strength `c` of curvature-weighted sampling.
pub const DEFAULT_CURVATURE_STRENGTH: f64 = 1.0;

/// How to place points on a surface.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum SampleMethod {
    /// Area-uniform random points (Open3D `sample_points_uniformly`).
    #[default]
    Uniform,
    /// Poisson disk by weighted sample elimination (Open3D `sample_points_poisson_disk`).
    Poisson,
    /// Density `area x (1 + c |H| / mean |H|)`: more points where the surface bends.
    Curvature,
}

/// Options of [`sample`].
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SampleOptions {
    /// Sampling method: uniform (area-uniform), poisson (Yuksel sample elimination from 5N
    /// uniform candidates) or curvature (density grows with |mean curvature|).
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = SampleMethod::Uniform))]
    pub method: SampleMethod,
    /// Random seed: the same seed gives the same points on any number of threads.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0))]
    pub seed: u64,
    /// Strength c of curvature weighting (dimensionless; 0 = uniform).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = DEFAULT_CURVATURE_STRENGTH))]
    pub curvature_strength: f64,
}

impl Default for SampleOptions {
    fn default() -> Self {
        Self {
            method: SampleMethod::Uniform,
            seed: 0,
            curvature_strength: DEFAULT_CURVATURE_STRENGTH,
        }
    }
}

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
    /// A parameter is out of its range.
    #[error("{name} = {value} is out of range ({expected})")]
    BadParameter {
        /// Parameter name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What is accepted.
        expected: &'static str,
    },
    /// The candidate set could not be indexed (coordinates too large for the k-d tree).
    #[error("cannot index the candidate points: {message}")]
    Index {
        /// kiddo's message.
        message: String,
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
    /// Guide table (Chen and Asau 1974): `guide[k]` is the first triangle whose cumulative
    /// weight exceeds `k / K` of the total, so a search starts next to its answer and takes
    /// O(1) expected steps instead of a cache-missing bisection over all triangles. The result
    /// is exactly the bisection's.
    guide: Vec<u32>,
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
        let Some(last_positive) = last_positive.filter(|_| sum > 0.0) else {
            return Ok(None);
        };
        let buckets = cumulative.len().max(1);
        let mut guide = Vec::with_capacity(buckets);
        let mut i = 0usize;
        for k in 0..buckets {
            let threshold = k as f64 / buckets as f64 * sum;
            while i < cumulative.len() && cumulative[i] <= threshold {
                i += 1;
            }
            guide.push(i.min(cumulative.len() - 1) as u32);
        }
        Ok(Some(Self {
            cumulative,
            last_positive,
            guide,
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
        let k = ((u * self.guide.len() as f64) as usize).min(self.guide.len() - 1);
        let mut i = self.guide[k] as usize;
        // The guide's threshold and `r` are rounded differently: step back if needed, then
        // forward to the first cumulative weight above `r` (the bisection's answer).
        while i > 0 && self.cumulative[i - 1] > r {
            i -= 1;
        }
        while i < self.cumulative.len() && self.cumulative[i] <= r {
            i += 1;
        }
        i.min(self.last_positive)
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

/// `n` points on `mesh` by the method of `options` (see the module docs). Empty for a zero-area
/// mesh or `n` = 0.
///
/// # Errors
/// [`SamplingError`] for a negative or non-finite curvature strength, or when the candidates
/// cannot be indexed.
pub fn sample(
    mesh: &TriMesh,
    n: usize,
    options: &SampleOptions,
) -> Result<SurfaceSamples, SamplingError> {
    match options.method {
        SampleMethod::Uniform => Ok(sample_uniform_with_triangles(mesh, n, options.seed)),
        SampleMethod::Poisson => sample_poisson_disk(mesh, n, options.seed),
        SampleMethod::Curvature => {
            sample_curvature(mesh, n, options.seed, options.curvature_strength)
        }
    }
}

/// Poisson-disk samples by Yuksel's weighted sample elimination from
/// [`POISSON_INIT_FACTOR`]` * n` area-uniform candidates (see the module docs). Returns exactly
/// `n` points (a subset of the candidates, in candidate order), or none for a zero-area mesh.
///
/// # Errors
/// [`SamplingError::Index`] when the candidates cannot be put in a k-d tree (coordinates beyond
/// what kiddo's f32 tree accepts).
pub fn sample_poisson_disk(
    mesh: &TriMesh,
    n: usize,
    seed: u64,
) -> Result<SurfaceSamples, SamplingError> {
    let Some(m) = n.checked_mul(POISSON_INIT_FACTOR) else {
        return Err(SamplingError::BadParameter {
            name: "n",
            value: n as f64,
            expected: "small enough that 5 n candidates fit in memory",
        });
    };
    let candidates = sample_uniform_with_triangles(mesh, m, seed);
    if n == 0 || candidates.len() <= n {
        return Ok(candidates);
    }
    let keep = eliminate(candidates.points.positions(), n, mesh.area())?;
    let normals = candidates.points.normals().unwrap_or_default();
    let mut positions = Vec::with_capacity(n);
    let mut kept_normals = Vec::with_capacity(n);
    let mut triangles = Vec::with_capacity(n);
    for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
        positions.push(candidates.points.positions()[i]);
        kept_normals.push(normals.get(i).copied().unwrap_or(Vec3::ZERO));
        triangles.push(candidates.triangles[i]);
    }
    let points = PointCloud::new_unchecked(positions)
        .with_normals(kept_normals)
        .expect("one normal per kept point by construction");
    Ok(SurfaceSamples { points, triangles })
}

/// Weighted sample elimination: which of `points` to keep so that `n` remain.
fn eliminate(points: &[Vec3], n: usize, area: f64) -> Result<Vec<bool>, SamplingError> {
    let m = points.len();
    let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
    let tree =
        ImmutableKdTree::<f32, 3>::new_from_slice(&coords).map_err(|e| SamplingError::Index {
            message: e.to_string(),
        })?;
    let d_max = 2.0 * (area / (2.0 * 3f64.sqrt() * n as f64)).sqrt();
    // Overlapping or coincident triangles count their area several times: the candidates are
    // then far denser than `area` says, every one would have thousands of neighbours within
    // d_max and the lists would grow quadratically (100k copies of one triangle did not end
    // in 2 minutes). The radius then follows the density the candidates really have.
    let d_max = match crowded_radius(&tree, &coords) {
        Some(r) if r < CROWDED_RATIO * d_max => r,
        _ => d_max,
    };
    let d_min = d_max * POISSON_BETA * (1.0 - (n as f64 / m as f64).powf(POISSON_GAMMA));
    // Each candidate's neighbours within d_max and their weights, sorted by index so sums do
    // not depend on the visiting order.
    let weighted = |p: Vec3, i: usize, j: u32, list: &mut Vec<(u32, f32)>| {
        if j as usize == i {
            return;
        }
        let d = (p.as_dvec3() - points[j as usize].as_dvec3()).length();
        if d < d_max {
            let w = (1.0 - d.max(d_min) / d_max).powf(POISSON_ALPHA);
            list.push((j, w as f32));
        }
    };
    // The k-d tree's radius queries degrade when the candidates lie within d_max of an
    // axis-parallel line (every split along the two thin axes is crossed: 100k slivers along
    // a line took 17 s); such sets go through cells of side d_max instead (1.6 s), others
    // through the tree (1.2-1.5x faster than the cells on planes and ordinary surfaces).
    let (lo, hi) = points.iter().fold(
        (glam::DVec3::INFINITY, glam::DVec3::NEG_INFINITY),
        |(lo, hi), p| (lo.min(p.as_dvec3()), hi.max(p.as_dvec3())),
    );
    let extent = hi - lo;
    let thin_axes = [extent.x, extent.y, extent.z]
        .iter()
        .filter(|&&e| e < d_max)
        .count();
    let grid = (thin_axes >= 2).then(|| CellGrid::new(points, d_max));
    // kiddo's SquaredEuclidean radius is a squared distance.
    let radius_sq = (d_max * d_max) as f32;
    let lists: Vec<Vec<(u32, f32)>> = (0..m)
        .into_par_iter()
        .map(|i| {
            let p = points[i];
            let mut list = Vec::new();
            match &grid {
                Some(grid) => grid.visit_near(p, |j| weighted(p, i, j, &mut list)),
                None => tree
                    .query(&coords[i])
                    .within::<SquaredEuclidean<f32>>(radius_sq)
                    .unsorted()
                    .visit(|r| weighted(p, i, r.item, &mut list)),
            }
            list.sort_unstable_by_key(|&(j, _)| j);
            list
        })
        .collect();
    let mut offsets = Vec::with_capacity(m + 1);
    offsets.push(0usize);
    for l in &lists {
        offsets.push(offsets.last().copied().unwrap_or(0) + l.len());
    }
    let weights: Vec<f64> = lists
        .iter()
        .map(|l| l.iter().map(|&(_, w)| f64::from(w)).sum())
        .collect();
    let neighbors: Vec<(u32, f32)> = lists.into_iter().flatten().collect();

    let mut heap = IndexedMaxHeap::new(weights);
    let mut keep = vec![true; m];
    let mut remaining = m;
    while remaining > n {
        let Some(i) = heap.pop() else { break };
        keep[i] = false;
        remaining -= 1;
        for &(j, w) in &neighbors[offsets[i]..offsets[i + 1]] {
            let j = j as usize;
            if keep[j] {
                heap.decrease(j, f64::from(w));
            }
        }
    }
    Ok(keep)
}

/// Points bucketed in cubic cells of a given side: any two points closer than the side lie
/// in the same or in adjacent cells, however the points are laid out.
struct CellGrid {
    /// Corner the cells start from.
    lo: glam::DVec3,
    /// Cell side.
    side: f64,
    /// Occupied cells, sorted.
    keys: Vec<[i64; 3]>,
    /// Points of cell `c`: `order[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    order: Vec<u32>,
}

impl CellGrid {
    fn new(points: &[Vec3], side: f64) -> Self {
        let lo = points
            .iter()
            .fold(glam::DVec3::INFINITY, |lo, p| lo.min(p.as_dvec3()));
        let side = side.max(f64::MIN_POSITIVE);
        let mut grid = Self {
            lo,
            side,
            keys: Vec::new(),
            starts: Vec::new(),
            order: Vec::with_capacity(points.len()),
        };
        let mut keyed: Vec<([i64; 3], u32)> = points
            .par_iter()
            .enumerate()
            .map(|(i, &p)| (grid.key(p), i as u32))
            .collect();
        keyed.par_sort_unstable();
        for (k, &(key, i)) in keyed.iter().enumerate() {
            if grid.keys.last() != Some(&key) {
                grid.keys.push(key);
                grid.starts.push(k as u32);
            }
            grid.order.push(i);
        }
        grid.starts.push(keyed.len() as u32);
        grid
    }

    /// The cell of `p` (coordinates saturate: far cells merge, which costs time, not pairs).
    fn key(&self, p: Vec3) -> [i64; 3] {
        let c = (p.as_dvec3() - self.lo) / self.side;
        [c.x, c.y, c.z].map(|v| v.floor() as i64)
    }

    /// Calls `visit` with every point in the cell of `p` and the 26 around it, each once.
    fn visit_near(&self, p: Vec3, mut visit: impl FnMut(u32)) {
        let [x, y, z] = self.key(p);
        let mut cells = [[0i64; 3]; 27];
        let mut n = 0;
        for dz in -1..=1i64 {
            for dy in -1..=1i64 {
                for dx in -1..=1i64 {
                    cells[n] = [
                        x.saturating_add(dx),
                        y.saturating_add(dy),
                        z.saturating_add(dz),
                    ];
                    n += 1;
                }
            }
        }
        cells.sort_unstable();
        let mut previous = None;
        for cell in cells {
            if previous == Some(cell) {
                continue;
            }
            previous = Some(cell);
            if let Ok(c) = self.keys.binary_search(&cell) {
                for &i in &self.order[self.starts[c] as usize..self.starts[c + 1] as usize] {
                    visit(i);
                }
            }
        }
    }
}

/// Neighbours a candidate has within `d_max` on average when the candidates cover the area
/// they were drawn on: `5 N / A · π d_max²` with `d_max² = 4 A / (2 √3 N)`, i.e. `10 π / √3`.
const EXPECTED_NEIGHBOURS: f64 = 18.137_993_642_342_18;
/// The neighbour rank [`crowded_radius`] measures.
const PROBE_RANK: usize = 32;
/// [`PROBE_RANK`] others and the candidate itself.
const PROBE_NEIGHBOURS: std::num::NonZeroUsize = match std::num::NonZeroUsize::new(PROBE_RANK + 1) {
    Some(k) => k,
    None => unreachable!(),
};
/// Candidates [`crowded_radius`] looks at, evenly spaced.
const PROBE_POINTS: usize = 256;
/// The measured radius replaces the area's only below this fraction of it (candidates at least
/// 4x denser than the area says): ordinary meshes keep the radius of Yuksel's method.
const CROWDED_RATIO: f64 = 0.5;

/// The elimination radius the candidates' own density gives: the median distance to the
/// [`PROBE_RANK`]-th nearest other candidate over [`PROBE_POINTS`] evenly spaced ones, scaled
/// to [`EXPECTED_NEIGHBOURS`] (neighbour counts grow as the radius squared on a surface);
/// `None` for too few candidates.
fn crowded_radius(tree: &ImmutableKdTree<f32, 3>, coords: &[[f32; 3]]) -> Option<f64> {
    if coords.len() <= 4 * PROBE_RANK {
        return None;
    }
    let step = (coords.len() / PROBE_POINTS).max(1);
    let mut radii: Vec<f64> = coords
        .iter()
        .step_by(step)
        .map(|c| {
            tree.query(c)
                .nearest_n::<SquaredEuclidean<f32>>(PROBE_NEIGHBOURS)
                .execute()
                .last()
                .map_or(0.0, |nn| f64::from(nn.distance).sqrt())
        })
        .collect();
    radii.sort_unstable_by(f64::total_cmp);
    let median = radii[radii.len() / 2];
    (median > 0.0).then(|| median * (EXPECTED_NEIGHBOURS / PROBE_RANK as f64).sqrt())
}

/// A binary max-heap over item weights with in-place decrease-key; ties go to the larger index
/// (any fixed rule keeps the result deterministic).
struct IndexedMaxHeap {
    weights: Vec<f64>,
    heap: Vec<u32>,
    /// Position of each item in `heap`, `u32::MAX` once popped.
    pos: Vec<u32>,
}

impl IndexedMaxHeap {
    fn new(weights: Vec<f64>) -> Self {
        let n = weights.len();
        let mut h = Self {
            weights,
            heap: (0..n as u32).collect(),
            pos: (0..n as u32).collect(),
        };
        for i in (0..n / 2).rev() {
            h.sift_down(i);
        }
        h
    }

    #[inline]
    fn above(&self, a: u32, b: u32) -> bool {
        let (wa, wb) = (self.weights[a as usize], self.weights[b as usize]);
        wa > wb || (wa == wb && a > b)
    }

    fn swap(&mut self, i: usize, j: usize) {
        self.heap.swap(i, j);
        self.pos[self.heap[i] as usize] = i as u32;
        self.pos[self.heap[j] as usize] = j as u32;
    }

    fn sift_down(&mut self, mut i: usize) {
        let n = self.heap.len();
        loop {
            let (l, r) = (2 * i + 1, 2 * i + 2);
            let mut top = i;
            if l < n && self.above(self.heap[l], self.heap[top]) {
                top = l;
            }
            if r < n && self.above(self.heap[r], self.heap[top]) {
                top = r;
            }
            if top == i {
                return;
            }
            self.swap(i, top);
            i = top;
        }
    }

    fn pop(&mut self) -> Option<usize> {
        let last = self.heap.len().checked_sub(1)?;
        self.swap(0, last);
        let item = self.heap.pop()? as usize;
        self.pos[item] = u32::MAX;
        if !self.heap.is_empty() {
            self.sift_down(0);
        }
        Some(item)
    }

    /// Lowers item's weight by `amount` (>= 0) if it is still in the heap.
    fn decrease(&mut self, item: usize, amount: f64) {
        let p = self.pos[item];
        if p == u32::MAX {
            return;
        }
        self.weights[item] -= amount;
        self.sift_down(p as usize);
    }
}

/// Absolute discrete mean curvature `|H_v|` of every vertex.
///
/// With the cotangent Laplace-Beltrami operator (Meyer, Desbrun, Schröder and Barr 2003, with
/// barycentric vertex areas), `Δx_v = 1 / (2 A_v) Σ_j (cot α_ij + cot β_ij) (x_j − x_v)`, where
/// `α_ij, β_ij` are the angles opposite edge `ij` and `A_v` is a third of the area of the
/// triangles around `v`; then `|H_v| = ‖Δx_v‖ / 2` (1/R on a sphere of radius R). Vertices on a
/// boundary edge, isolated vertices and vertices with zero area get 0, as do non-finite results
/// (degenerate triangles contribute nothing).
#[must_use]
pub fn vertex_mean_curvature(mesh: &TriMesh) -> Vec<f64> {
    let nv = mesh.vertex_count();
    let mut laplace = vec![DVec3::ZERO; nv];
    let mut area = vec![0.0f64; nv];
    for t in 0..mesh.triangle_count() {
        let tri = mesh.triangles()[t];
        let [a, b, c] = tri;
        if a == b || b == c || a == c {
            continue;
        }
        let x = mesh.corners(t);
        let twice_area = (x[1] - x[0]).cross(x[2] - x[0]).length();
        if twice_area <= 0.0 {
            continue;
        }
        for k in 0..3 {
            let (i, j, o) = (k, (k + 1) % 3, (k + 2) % 3);
            // Angle at corner o is opposite edge (i, j).
            let (u, w) = (x[i] - x[o], x[j] - x[o]);
            let cot = u.dot(w) / u.cross(w).length();
            laplace[tri[i] as usize] += cot * (x[j] - x[i]);
            laplace[tri[j] as usize] += cot * (x[i] - x[j]);
            area[tri[k] as usize] += twice_area / 6.0;
        }
    }
    let mut on_boundary = vec![false; nv];
    for (p, q) in crate::topology::boundary_edges(mesh.triangles()) {
        on_boundary[p as usize] = true;
        on_boundary[q as usize] = true;
    }
    (0..nv)
        .map(|v| {
            if on_boundary[v] || area[v] <= 0.0 {
                return 0.0;
            }
            let h = (laplace[v] / (2.0 * area[v])).length() / 2.0;
            if h.is_finite() { h } else { 0.0 }
        })
        .collect()
}

/// Samples with density `A_t (1 + strength |H_t| / H̄)` (see the module docs). Empty for a
/// zero-area mesh.
///
/// # Errors
/// [`SamplingError::BadParameter`] when `strength` is negative or not finite.
pub fn sample_curvature(
    mesh: &TriMesh,
    n: usize,
    seed: u64,
    strength: f64,
) -> Result<SurfaceSamples, SamplingError> {
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(SamplingError::BadParameter {
            name: "curvature strength",
            value: strength,
            expected: "finite and >= 0",
        });
    }
    let curvature = vertex_mean_curvature(mesh);
    let areas = mesh.triangle_areas();
    let per_triangle: Vec<f64> = mesh
        .triangles()
        .iter()
        .map(|t| t.iter().map(|&v| curvature[v as usize]).sum::<f64>() / 3.0)
        .collect();
    let total_area: f64 = areas.iter().sum();
    let mean = areas
        .iter()
        .zip(&per_triangle)
        .map(|(a, h)| a * h)
        .sum::<f64>()
        / total_area;
    let weights: Vec<f64> = if mean > 0.0 && mean.is_finite() {
        areas
            .iter()
            .zip(&per_triangle)
            .map(|(a, h)| a * (1.0 + strength * h / mean))
            .collect()
    } else {
        areas
    };
    sample_weighted(mesh, &weights, n, seed)
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
                let [a, b, c] = mesh.corners(t);
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
    fn guide_table_search_equals_bisection() {
        let mut rng = Rng::new(5);
        let weights: Vec<f64> = (0..1000)
            .map(|i| {
                if i % 7 == 0 {
                    0.0
                } else {
                    rng.uniform_f64().powi(4)
                }
            })
            .collect();
        let d = TriangleDistribution::new(&weights).unwrap().unwrap();
        for _ in 0..100_000 {
            let u = rng.uniform_f64();
            let r = u * d.total();
            let expected = d
                .cumulative
                .partition_point(|&c| c <= r)
                .min(d.last_positive);
            assert_eq!(d.pick(u), expected);
            assert!(weights[expected] > 0.0);
        }
        assert_eq!(d.pick(0.0), 1);
        assert_eq!(d.pick(1.0 - f64::EPSILON / 2.0), 999);
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

    fn sphere(radius: f32, levels: usize) -> TriMesh {
        let octa = TriMesh::new(
            vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z],
            crate::test_meshes::OCTAHEDRON_TRIANGLES.to_vec(),
        );
        let fine = crate::subdivide::midpoint(&octa, levels).unwrap();
        let positions = fine
            .positions()
            .iter()
            .map(|p| p.normalize() * f64::from(radius))
            .collect();
        TriMesh::new(positions, fine.triangles().to_vec())
    }

    #[test]
    fn mean_curvature_of_a_sphere_is_one_over_radius() {
        let m = sphere(2.0, 4);
        let h = vertex_mean_curvature(&m);
        let mean = h.iter().sum::<f64>() / h.len() as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        // An open patch: boundary vertices get zero.
        let open = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        assert_eq!(vertex_mean_curvature(&open), vec![0.0; 3]);
    }

    #[test]
    fn heap_pops_in_weight_order_with_decrease() {
        let mut h = IndexedMaxHeap::new(vec![3.0, 1.0, 4.0, 1.0, 5.0]);
        h.decrease(4, 4.5); // 0.5
        let order: Vec<usize> = std::iter::from_fn(|| h.pop()).collect();
        assert_eq!(order, vec![2, 0, 3, 1, 4]);
    }

    #[test]
    fn poisson_returns_n_spread_points() {
        let m = sphere(1.0, 3);
        let s = sample_poisson_disk(&m, 300, 9).unwrap();
        assert_eq!(s.len(), 300);
        let p = s.points.positions();
        let mut min_d = f64::INFINITY;
        for i in 0..p.len() {
            for j in 0..i {
                min_d = min_d.min((p[i].as_dvec3() - p[j].as_dvec3()).length());
            }
        }
        let d_max = 2.0 * (m.area() / (2.0 * 3f64.sqrt() * 300.0)).sqrt();
        assert!(min_d > 0.5 * d_max, "{min_d} vs d_max {d_max}");
        assert!(sample_poisson_disk(&m, 0, 1).unwrap().is_empty());
    }

    /// The smallest distance between two of `p` (brute force).
    fn min_distance(p: &[Vec3]) -> f64 {
        let mut min_d = f64::INFINITY;
        for i in 0..p.len() {
            for j in 0..i {
                min_d = min_d.min((p[i].as_dvec3() - p[j].as_dvec3()).length());
            }
        }
        min_d
    }

    #[test]
    fn poisson_on_coincident_triangles_spreads_over_the_one_surface() {
        // 20,000 copies of one unit right triangle: the summed area (10,000) is 20,000 times
        // the surface's, which made every candidate a neighbour of every other (quadratic).
        let triangles = vec![[0, 1, 2]; 20_000];
        let m = TriMesh::try_new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], triangles).unwrap();
        let s = sample_poisson_disk(&m, 500, 3).unwrap();
        assert_eq!(s.len(), 500);
        // Spread as 500 Poisson samples of the real area (0.5) would be.
        let d_max = 2.0 * (0.5 / (2.0 * 3f64.sqrt() * 500.0)).sqrt();
        let min_d = min_distance(s.points.positions());
        assert!(min_d > 0.3 * d_max, "{min_d} vs {d_max}");
    }

    #[test]
    fn poisson_on_slivers_along_a_line_and_cells_find_every_pair() {
        // Slivers along the x axis (heights 1e-9): the candidates lie within d_max of a line.
        let n = 2_000;
        let positions: Vec<Vec3> = (0..=n)
            .map(|i| Vec3::new(i as f32 * 1e-3, 1e-9 * (i % 2) as f32, 0.0))
            .collect();
        let triangles: Vec<[u32; 3]> = (0..n - 1).map(|i| [i, i + 1, i + 2]).collect();
        let m = TriMesh::try_new(positions, triangles).unwrap();
        let s = sample_poisson_disk(&m, 400, 5).unwrap();
        assert_eq!(s.len(), 400);
        // The cells see every pair within their side, as a brute-force search does.
        let mut rng = crate::rng::Rng::stream(7, 0);
        let mut points: Vec<Vec3> = (0..300)
            .map(|_| Vec3::new(rng.uniform_f32(), 1e-7 * rng.uniform_f32(), 0.0))
            .collect();
        points.extend([Vec3::splat(1e18), Vec3::splat(-1e18), Vec3::splat(1e18)]);
        let side = 0.01;
        let grid = CellGrid::new(&points, side);
        for (i, p) in points.iter().enumerate() {
            let mut found = Vec::new();
            grid.visit_near(*p, |j| found.push(j as usize));
            found.sort_unstable();
            assert!(found.windows(2).all(|w| w[0] != w[1]), "each point once");
            for (j, q) in points.iter().enumerate() {
                if (p.as_dvec3() - q.as_dvec3()).length() < side {
                    assert!(found.binary_search(&j).is_ok(), "{i} misses {j}");
                }
            }
        }
    }

    #[test]
    fn curvature_sampling_prefers_curved_parts_and_checks_strength() {
        let m = square();
        assert!(sample_curvature(&m, 10, 0, -1.0).is_err());
        assert!(sample_curvature(&m, 10, 0, f64::NAN).is_err());
        // A flat mesh has no curvature: uniform.
        assert_eq!(sample_curvature(&m, 10, 0, 3.0).unwrap().len(), 10);
    }
}
