//! The metrics of one mesh against a ground truth, per frame: docs/conventions.md §8 as
//! `trisplat eval --surface` computes them, the mesh's structure and whether it is watertight.
//!
//! Metrics follow docs/conventions.md §8 as `trisplat eval --surface` computes them: both meshes sampled
//! area-uniformly (`samples` points each, seed 0 for the prediction and `splitmix64(0)` for the
//! ground truth, as `eval`'s defaults), distances exact to the other side's triangles, the
//! threshold a fraction of the ground truth's bounding-box diagonal (or absolute). So a frame's
//! numbers equal `trisplat eval DIR/<method>/frame_NNNNNN.ply GT --surface --samples N
//! --tau-fraction F` (or `--tau T`) for a static ground truth, structure, area ratio and the
//! self-consistency label included.
//!
//! Self-consistency: a method whose mesh contains the ground truth's vertices (at least half
//! of them, bit for bit: the incremental Delaunay's output holds the deformed template's
//! vertices, so with `--gt template` it is scored against its own input) gets its scores
//! labelled [`Relation::SelfConsistency`], per frame and per method, in report.json,
//! report.md and the plot.

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::mesh_stats::{MeshStats, StatsTopology};
use trisplat_geometry::metrics::{
    MetricsError, MetricsOptions, Relation, Shape, Side, Tau, evaluate, shared_vertex_fraction,
};
use trisplat_geometry::rng::splitmix64;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::spatial::SurfaceIndex;
use trisplat_geometry::topology::triangles_around_vertices;
use trisplat_geometry::{PointCloud, TriMesh};

use crate::records::FrameMetrics;

/// Seed of the prediction's surface samples (the ground truth uses `splitmix64` of it), as
/// `trisplat eval`'s default.
pub const SAMPLE_SEED: u64 = 0;

/// A ground-truth mesh with its samples and its surface index (made once per frame, shared
/// by the methods).
#[derive(Debug)]
pub struct GtSamples {
    /// The mesh.
    pub mesh: TriMesh,
    /// The mesh moved by `-origin`: what is sampled and indexed (in f32) and what the
    /// predictions, moved the same way, are measured against.
    local: TriMesh,
    /// Centre of the mesh's bounding box: both sides of a comparison are moved to it in f64
    /// first, so the scores do not depend on how far from the origin the meshes are.
    origin: DVec3,
    /// Area-uniform samples of `local` with face normals.
    pub samples: PointCloud,
    /// The index the predictions' samples are measured against; `None` when the mesh cannot
    /// be indexed (then [`measure`] reports the reason).
    index: Option<SurfaceIndex>,
    /// Diagonal of the bounding box of its vertices (relative thresholds scale with it).
    diagonal: f64,
    /// Its surface area (f64).
    area: f64,
}

impl GtSamples {
    /// Samples and indexes `mesh`; `None` when it has no area.
    #[must_use]
    pub fn new(mesh: TriMesh, samples: usize) -> Option<Self> {
        Self::reusing(mesh, samples, None)
    }

    /// [`GtSamples::new`], refitting the index of `previous` (the last frame's ground truth)
    /// when it indexes the same triangles ([`SurfaceIndex::reuse`]): the same samples and
    /// the same answers, without a new tree.
    #[must_use]
    pub fn reusing(mesh: TriMesh, samples: usize, previous: Option<Self>) -> Option<Self> {
        let bounds = mesh.bounds()?;
        let origin = bounds.center();
        let mut local = mesh.clone();
        local.translate(-origin);
        let points = sample_uniform(&local, samples, splitmix64(SAMPLE_SEED));
        if points.is_empty() {
            return None;
        }
        let previous = previous.and_then(|p| p.index);
        let index = SurfaceIndex::reuse(previous, local.positions(), local.triangles()).ok();
        let diagonal = bounds.diagonal();
        let area = mesh.area();
        Some(Self {
            mesh,
            local,
            origin,
            samples: points,
            index,
            diagonal,
            area,
        })
    }

    /// Diagonal of the bounding box of the ground truth's vertices.
    #[must_use]
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }

    /// Euclidean distance from `point` (world space, f64) to the ground truth's surface, exact
    /// up to f64 rounding (the closest point on its triangles); `None` when the mesh could not
    /// be indexed or `point` is not finite.
    #[must_use]
    pub fn distance(&self, point: DVec3) -> Option<f64> {
        let index = self.index.as_ref()?;
        index.closest(point - self.origin).map(|c| c.distance)
    }

    /// [`GtSamples::distance`] of every point, in parallel; `None` when the mesh could not be
    /// indexed or a point is not finite.
    #[must_use]
    pub fn distances(&self, points: &[DVec3]) -> Option<Vec<f64>> {
        points
            .par_iter()
            .with_min_len(256)
            .map(|&p| self.distance(p))
            .collect()
    }

    /// The ground truth as one side of a comparison.
    fn shape(&self) -> Shape<'_> {
        match &self.index {
            Some(index) => Shape::surface_indexed(&self.local, &self.samples, index),
            None => Shape::mesh(&self.local, &self.samples),
        }
    }
}

/// Metrics of `pred` against `gt` at the absolute threshold `tau` (see [`measure_with`]).
///
/// # Errors
/// As [`measure_with`].
pub fn measure(
    pred: &TriMesh,
    gt: &GtSamples,
    samples: usize,
    tau: f64,
) -> Result<Option<FrameMetrics>, MetricsError> {
    measure_with(pred, gt, samples, Tau::Absolute(tau))
}

/// Metrics of `pred` against `gt` (surface mode, see the module docs) at threshold `tau`
/// (a fraction is of `gt`'s bounding-box diagonal), with the structure of `pred`, its area
/// ratio to `gt` and the self-consistency label; `Ok(None)` when `pred` has no surface (an
/// empty mesh is not measured).
///
/// # Errors
/// [`MetricsError`] for coordinates beyond the spatial indexes' range or a threshold that is
/// not a positive distance.
pub fn measure_with(
    pred: &TriMesh,
    gt: &GtSamples,
    samples: usize,
    tau: Tau,
) -> Result<Option<FrameMetrics>, MetricsError> {
    measure_cached(pred, gt, samples, tau, &mut ScoreCache::default())
}

/// What scoring one method's mesh leaves for its next frame: its surface index and the
/// topological part of its structure, reused (refitted) when the next mesh has the same
/// triangles, as a carried mesh (`--topology fixed|adaptive`) has between keys.
#[derive(Debug, Default)]
pub struct ScoreCache {
    index: Option<SurfaceIndex>,
    stats: Option<StatsTopology>,
}

/// [`measure_with`], reusing `cache` (see [`ScoreCache`]) and leaving this mesh's in it; the
/// metrics are bit for bit [`measure_with`]'s.
///
/// # Errors
/// As [`measure_with`].
pub fn measure_cached(
    pred: &TriMesh,
    gt: &GtSamples,
    samples: usize,
    tau: Tau,
    cache: &mut ScoreCache,
) -> Result<Option<FrameMetrics>, MetricsError> {
    // Positions and triangles only (`translate`'s arithmetic, without copying the vertex
    // attributes a clone would carry).
    let offset = -gt.origin;
    let local = TriMesh::new_unchecked(
        pred.positions()
            .par_iter()
            .with_min_len(1 << 14)
            .map(|&p| p + offset)
            .collect::<Vec<DVec3>>(),
        pred.triangles().to_vec(),
    );
    let points = sample_uniform(&local, samples, SAMPLE_SEED);
    if points.is_empty() {
        return Ok(None);
    }
    let options = MetricsOptions {
        taus: trisplat_geometry::metrics::resolve_taus(&[tau], gt.diagonal)?,
        surface: true,
    };
    let ScoreCache { index, stats } = cache;
    let (m, (structure, shared)) = rayon::join(
        || -> Result<_, MetricsError> {
            let built = SurfaceIndex::reuse(index.take(), local.positions(), local.triangles())
                .map_err(|source| MetricsError::Spatial {
                    side: Side::Prediction,
                    source,
                })?;
            let shape = Shape::surface_indexed(&local, &points, index.insert(built));
            evaluate(shape, gt.shape(), &options)
        },
        || {
            rayon::join(
                || MeshStats::of_cached(pred, stats),
                || shared_vertex_fraction(gt.mesh.positions(), pred.positions()),
            )
        },
    );
    let m = m?;
    let t = m.thresholds.first().copied();
    Ok(Some(FrameMetrics {
        chamfer_l1: m.chamfer_l1,
        chamfer_l2: m.chamfer_l2,
        normal_consistency: m.normal_consistency,
        normal_angle_deg: m.normal_angle_deg,
        accuracy: m.accuracy,
        completeness: m.completeness,
        precision: t.map_or(0.0, |t| t.precision),
        recall: t.map_or(0.0, |t| t.recall),
        fscore: t.map_or(0.0, |t| t.fscore),
        tau: options.taus[0],
        tau_fraction: tau.fraction(),
        gt_diagonal: gt.diagonal,
        gt_area: gt.area,
        area_ratio: (gt.area > 0.0).then(|| structure.area / gt.area),
        shared_vertex_fraction: shared,
        relation: Relation::from_shared_fraction(shared),
        structure: Some(structure),
    }))
}

/// Whether `mesh` is a closed, consistently oriented surface: it has triangles, none with a
/// repeated vertex index, and every edge is shared by exactly two triangles that traverse it
/// in opposite directions (each directed edge `a -> b` occurs once and so does `b -> a`).
/// This is trimesh's `is_watertight and is_winding_consistent`.
#[must_use]
pub fn is_watertight(mesh: &TriMesh) -> bool {
    let t = mesh.triangles();
    if t.is_empty() || t.iter().any(|&[a, b, c]| a == b || b == c || a == c) {
        return false;
    }
    // Each directed edge x -> y must be in exactly one triangle and its reverse in exactly one:
    // look among the triangles around x (no sort or hash of the 3n edges; the first open edge
    // ends the search, and TSDF meshes have many).
    let (offsets, around) = triangles_around_vertices(mesh.vertex_count(), t);
    let has = |tri: [u32; 3], x: u32, y: u32| (0..3).any(|k| tri[k] == x && tri[(k + 1) % 3] == y);
    // In parallel: a run with one method checks its mesh while nothing else runs.
    t.par_iter().with_min_len(1 << 12).all(|&[a, b, c]| {
        [(a, b), (b, c), (c, a)].into_iter().all(|(x, y)| {
            let ring = &around[offsets[x as usize] as usize..offsets[x as usize + 1] as usize];
            let (mut forward, mut backward) = (0, 0);
            for &u in ring {
                let tri = t[u as usize];
                forward += usize::from(has(tri, x, y));
                backward += usize::from(has(tri, y, x));
            }
            forward == 1 && backward == 1
        })
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use glam::Vec3;
    use trisplat_geometry::metrics::DEFAULT_TAUS;

    use super::*;

    /// A tetrahedron with three edges of length `scale` along the axes, outward faces.
    pub(crate) fn tetra(scale: f32) -> TriMesh {
        let p = vec![
            Vec3::ZERO,
            Vec3::X * scale,
            Vec3::Y * scale,
            Vec3::Z * scale,
        ];
        TriMesh::new(p, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    }

    #[test]
    fn measure_equals_a_direct_evaluation() {
        let pred = tetra(1.0);
        let gt_mesh = tetra(1.1);
        let gt = GtSamples::new(gt_mesh.clone(), 2000).expect("area");
        let tau = DEFAULT_TAUS[3] * 10.0;
        let got = measure(&pred, &gt, 2000, tau)
            .expect("ok")
            .expect("non-empty");
        // Both sides at the ground truth's centre, as `measure` puts them.
        let centre = gt_mesh.bounds().expect("bounds").center();
        let (mut pred_local, mut gt_local) = (pred.clone(), gt_mesh.clone());
        pred_local.translate(-centre);
        gt_local.translate(-centre);
        let p = sample_uniform(&pred_local, 2000, SAMPLE_SEED);
        let g = sample_uniform(&gt_local, 2000, splitmix64(SAMPLE_SEED));
        let m = evaluate(
            Shape::mesh(&pred_local, &p),
            Shape::mesh(&gt_local, &g),
            &MetricsOptions {
                taus: vec![tau],
                surface: true,
            },
        )
        .expect("ok");
        assert_eq!(got.chamfer_l1, m.chamfer_l1);
        assert_eq!(got.chamfer_l2, m.chamfer_l2);
        assert_eq!(got.normal_consistency, m.normal_consistency);
        assert_eq!(got.fscore, m.thresholds[0].fscore);
        assert!(got.chamfer_l1 > 0.0);
        // Same mesh: zero distance.
        let same = measure(&gt_mesh, &gt, 2000, tau)
            .expect("ok")
            .expect("non-empty");
        assert!(same.chamfer_l1 < 1e-6, "{}", same.chamfer_l1);
        // An empty prediction is not measured.
        assert_eq!(measure(&TriMesh::default(), &gt, 100, tau), Ok(None));
    }

    #[test]
    fn measure_labels_a_mesh_that_contains_the_ground_truth() {
        let gt_mesh = tetra(1.0);
        let gt = GtSamples::new(gt_mesh.clone(), 500).expect("area");
        let own = measure_with(&gt_mesh, &gt, 500, Tau::Fraction(0.01))
            .expect("ok")
            .expect("non-empty");
        assert_eq!(own.relation, Relation::SelfConsistency);
        assert_eq!(own.shared_vertex_fraction, Some(1.0));
        assert_eq!(own.area_ratio, Some(1.0));
        assert_eq!(own.tau, 0.01 * gt.diagonal());
        assert_eq!(own.tau_fraction, Some(0.01));
        assert_eq!(gt.diagonal(), 3f64.sqrt());
        let st = own.structure.expect("structure");
        assert!(st.watertight && st.components == 1);
        // Scaled by 1.1 about a shared corner: one vertex in four is shared, accuracy.
        let other = measure_with(&tetra(1.1), &gt, 500, Tau::Absolute(0.05))
            .expect("ok")
            .expect("non-empty");
        assert_eq!(other.relation, Relation::Accuracy);
        assert_eq!(other.shared_vertex_fraction, Some(0.25));
        assert!((other.area_ratio.expect("area") - 1.21).abs() < 1e-6);
        assert_eq!((other.tau, other.tau_fraction), (0.05, None));
        assert!(other.normal_angle_deg.is_some());
    }

    /// The Spot fixture with its vertices moved by a smooth field of phase `s` and size
    /// `amount` (the same triangles always).
    fn spot_moved(s: f64, amount: f64) -> TriMesh {
        let spot = trisplat_fixtures::spot().expect("the Spot fixture");
        let moved = spot
            .positions()
            .iter()
            .map(|p| {
                *p + DVec3::new((3.0 * p.y + s).sin(), (2.0 * p.x).cos(), (p.z - s).sin()) * amount
            })
            .collect();
        TriMesh::new_unchecked(moved, spot.triangles().to_vec())
    }

    #[test]
    fn carried_scores_equal_fresh_ones_over_frames() {
        // A prediction and a ground truth that keep their triangles while their vertices
        // move, frame after frame: scored through one cache (the prediction's index refitted,
        // its structure's topology kept; the ground truth's index refitted) they score as
        // fresh, bit for bit.
        let mut cache = ScoreCache::default();
        let mut previous: Option<GtSamples> = None;
        for frame in 0..6 {
            let s = f64::from(frame) * 0.07;
            let gt_mesh = spot_moved(s, 0.02);
            let pred = spot_moved(1.3 * s + 0.5, 0.03);
            let gt = GtSamples::reusing(gt_mesh.clone(), 3000, previous.take()).expect("area");
            let carried = measure_cached(&pred, &gt, 3000, Tau::Fraction(0.01), &mut cache)
                .expect("ok")
                .expect("non-empty");
            let fresh_gt = GtSamples::new(gt_mesh, 3000).expect("area");
            let fresh = measure_with(&pred, &fresh_gt, 3000, Tau::Fraction(0.01))
                .expect("ok")
                .expect("non-empty");
            assert_eq!(carried, fresh, "frame {frame}");
            assert!(carried.chamfer_l1 > 0.0);
            assert!(cache.index.is_some() && cache.stats.is_some());
            previous = Some(gt);
        }
        // Another mesh (other triangles) through the same cache: still the fresh scores.
        let other = tetra(1.0);
        let gt = GtSamples::new(tetra(1.1), 3000).expect("area");
        assert_eq!(
            measure_cached(&other, &gt, 3000, Tau::Fraction(0.01), &mut cache),
            measure_with(&other, &gt, 3000, Tau::Fraction(0.01))
        );
    }

    #[test]
    fn watertight_flags() {
        let closed = tetra(1.0);
        assert!(is_watertight(&closed));
        let p = closed.positions().to_vec();
        let open = TriMesh::new(p.clone(), vec![[0, 2, 1], [0, 1, 3]]);
        assert!(!is_watertight(&open));
        assert!(!is_watertight(&TriMesh::default()));
        // Closed but one face flipped: every edge has two triangles, the winding disagrees.
        let flipped = TriMesh::new(p.clone(), vec![[0, 1, 2], [0, 1, 3], [0, 3, 2], [1, 2, 3]]);
        assert!(!is_watertight(&flipped));
        // Every edge of a face shared by three triangles (the tetrahedron plus a copy of one
        // face, reversed): non-manifold.
        let extra = TriMesh::new(
            p.clone(),
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [0, 1, 2]],
        );
        assert!(!is_watertight(&extra));
        // A repeated index.
        let degenerate =
            TriMesh::new_unchecked(p.clone(), vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 2]]);
        assert!(!is_watertight(&degenerate));
        // A closed sheet of two triangles with opposite windings is closed and oriented.
        let sheet = TriMesh::new(p, vec![[0, 1, 2], [0, 2, 1]]);
        assert!(is_watertight(&sheet));
        // Two tetrahedra sharing one vertex: every edge fine (vertex non-manifold is allowed,
        // as in trimesh).
        let mut q = tetra(1.0).positions().to_vec();
        q.extend([
            DVec3::new(-1.0, 0.0, 0.0),
            DVec3::new(0.0, -1.0, 0.0),
            DVec3::new(0.0, 0.0, -1.0),
        ]);
        let two = TriMesh::new(
            q,
            vec![
                [0, 2, 1],
                [0, 1, 3],
                [0, 3, 2],
                [1, 2, 3],
                [0, 4, 5],
                [0, 6, 4],
                [0, 5, 6],
                [4, 6, 5],
            ],
        );
        assert!(is_watertight(&two));
    }

    /// The definition, by sorting every edge use.
    fn watertight_by_sorting(t: &[[u32; 3]]) -> bool {
        if t.is_empty() || t.iter().any(|&[a, b, c]| a == b || b == c || a == c) {
            return false;
        }
        let mut edges: Vec<(u32, u32, bool)> = t
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(x, y)| (x.min(y), x.max(y), x < y))
            .collect();
        edges.sort_unstable();
        edges
            .chunk_by(|p, q| (p.0, p.1) == (q.0, q.1))
            .all(|g| matches!(g, [(_, _, f), (_, _, s)] if f != s))
    }

    #[test]
    fn watertight_matches_the_definition_on_edited_closed_meshes() {
        // An octahedron (closed), then random edits: a face removed, flipped, duplicated (as
        // is or reversed), a vertex renamed; and pairs of closed pieces.
        let octahedron: Vec<[u32; 3]> = vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        let mut rng = trisplat_geometry::rng::Rng::new(5);
        let positions: Vec<Vec3> = (0..12).map(|k| Vec3::splat(k as f32)).collect();
        let (mut closed, mut open) = (0, 0);
        for case in 0..2000 {
            let mut t = octahedron.clone();
            if case % 3 == 0 {
                t.extend(octahedron.iter().map(|f| f.map(|v| v + 6)));
            }
            for _ in 0..rng.below(3) {
                let k = rng.below(t.len() as u32) as usize;
                match rng.below(5) {
                    0 => {
                        t.remove(k);
                    }
                    1 => t[k].swap(0, 1),
                    2 => t.push(t[k]),
                    3 => t.push([t[k][1], t[k][0], t[k][2]]),
                    _ => t[k][rng.below(3) as usize] = rng.below(12),
                }
                if t.is_empty() {
                    break;
                }
            }
            let mesh = TriMesh::new_unchecked(positions.clone(), t.clone());
            let want = watertight_by_sorting(&t);
            assert_eq!(is_watertight(&mesh), want, "case {case}: {t:?}");
            if want {
                closed += 1;
            } else {
                open += 1;
            }
        }
        assert!(closed > 100 && open > 100, "{closed} closed, {open} open");
    }
}
