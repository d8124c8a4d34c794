//! Per-frame records, per-method means, and the two report files (report.json, report.md).
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

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;
use trisplat_extract::incremental_delaunay::FrameStats;
use trisplat_geometry::io::{IoError, write_atomically};
use trisplat_geometry::mesh_stats::MeshStats;
use trisplat_geometry::metrics::{
    MetricsError, MetricsOptions, Relation, Shape, Tau, evaluate, shared_vertex_fraction,
};
use trisplat_geometry::rng::splitmix64;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::spatial::TriangleBvh;
use trisplat_geometry::topology::triangles_around_vertices;
use trisplat_geometry::{PointCloud, TriMesh};

use crate::config::Method;
use crate::methods::Resolved;
use crate::run::{PLOT_PNG, PLOT_SVG, REPORT_HTML};
use crate::visibility::GaussiansUsed;

/// Seed of the prediction's surface samples (the ground truth uses `splitmix64` of it), as
/// `trisplat eval`'s default.
pub const SAMPLE_SEED: u64 = 0;

/// A ground-truth mesh with its samples and its BVH (made once per frame, shared by the
/// methods).
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
    /// The BVH the predictions' samples are measured against; `None` when the mesh cannot
    /// be indexed (then [`measure`] reports the reason).
    bvh: Option<TriangleBvh>,
    /// Diagonal of the bounding box of its vertices (relative thresholds scale with it).
    diagonal: f64,
    /// Its surface area (f64).
    area: f64,
}

impl GtSamples {
    /// Samples and indexes `mesh`; `None` when it has no area.
    #[must_use]
    pub fn new(mesh: TriMesh, samples: usize) -> Option<Self> {
        let bounds = mesh.bounds()?;
        let origin = bounds.center();
        let mut local = mesh.clone();
        local.translate(-origin);
        let points = sample_uniform(&local, samples, splitmix64(SAMPLE_SEED));
        if points.is_empty() {
            return None;
        }
        let bvh = TriangleBvh::new(&local).ok();
        let diagonal = bounds.diagonal();
        let area = mesh.area();
        Some(Self {
            mesh,
            local,
            origin,
            samples: points,
            bvh,
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
        let bvh = self.bvh.as_ref()?;
        bvh.closest_point(point - self.origin).map(|c| c.distance)
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
        match &self.bvh {
            Some(bvh) => Shape::indexed_mesh(&self.local, &self.samples, bvh),
            None => Shape::mesh(&self.local, &self.samples),
        }
    }
}

/// The metrics of one method on one frame (docs/conventions.md §8).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameMetrics {
    /// (accuracy + completeness) / 2.
    pub chamfer_l1: f64,
    /// (mean d(p,G)^2 + mean d(g,P)^2) / 2.
    pub chamfer_l2: f64,
    /// Mean |n . n'| both ways (`None` when a side has no normals).
    pub normal_consistency: Option<f64>,
    /// Mean angle between the normals both ways, degrees (`None` when a side has none).
    #[serde(default)]
    pub normal_angle_deg: Option<f64>,
    /// Mean distance from the prediction to the ground truth.
    pub accuracy: f64,
    /// Mean distance from the ground truth to the prediction.
    pub completeness: f64,
    /// Precision at `tau`.
    pub precision: f64,
    /// Recall at `tau`.
    pub recall: f64,
    /// F-score at `tau`.
    pub fscore: f64,
    /// The F-score threshold (absolute, scene units): `tau_fraction` x `gt_diagonal` when
    /// relative.
    pub tau: f64,
    /// The threshold as a fraction of the ground truth's bounding-box diagonal; `None` when
    /// it was given absolutely.
    #[serde(default)]
    pub tau_fraction: Option<f64>,
    /// Diagonal of the ground truth's bounding box.
    #[serde(default)]
    pub gt_diagonal: f64,
    /// Surface area of the ground truth.
    #[serde(default)]
    pub gt_area: f64,
    /// The prediction's area over the ground truth's (`None` when the latter is 0).
    #[serde(default)]
    pub area_ratio: Option<f64>,
    /// Fraction of the ground truth's vertices that are (bit for bit) vertices of the mesh.
    #[serde(default)]
    pub shared_vertex_fraction: Option<f64>,
    /// What the scores measure: `accuracy`, or `self-consistency` when the mesh contains
    /// the ground truth's vertices.
    #[serde(default)]
    pub relation: Relation,
    /// The structure of the mesh: area, components, holes, watertightness.
    #[serde(default)]
    pub structure: Option<MeshStats>,
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
    let mut local = pred.clone();
    local.translate(-gt.origin);
    let points = sample_uniform(&local, samples, SAMPLE_SEED);
    if points.is_empty() {
        return Ok(None);
    }
    let options = MetricsOptions {
        taus: trisplat_geometry::metrics::resolve_taus(&[tau], gt.diagonal)?,
        surface: true,
    };
    let (m, (structure, shared)) = rayon::join(
        || evaluate(Shape::mesh(&local, &points), gt.shape(), &options),
        || {
            rayon::join(
                || MeshStats::of(pred),
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

/// One method on one frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameRecord {
    /// Animation frame index.
    pub frame: usize,
    /// Its time in seconds.
    pub time: f64,
    /// Wall time of the method, milliseconds.
    pub ms: f64,
    /// Of which rendering (tsdf only).
    pub render_ms: Option<f64>,
    /// Mesh vertices.
    pub vertices: usize,
    /// Mesh triangles.
    pub faces: usize,
    /// Every edge shared by exactly two triangles.
    pub watertight: bool,
    /// Against the ground truth (`None` without --gt or for an empty mesh).
    pub metrics: Option<FrameMetrics>,
}

/// What the incremental Delaunay update did on one frame (its `FrameStats`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DelaunayFrame {
    /// Animation frame index.
    pub frame: usize,
    /// Whether every chart was triangulated from scratch (the first frame, and every
    /// `--rebuild-every` frames).
    pub rebuilt: bool,
    /// Gaussians that changed chart (0 on a rebuild, which reassigns them all).
    pub hopped: usize,
    /// Charts (template triangles) triangulated again.
    pub charts_redone: usize,
    /// Gaussians whose full nearest-triangle search ran (the others were settled by their
    /// motion certificate).
    pub searches: usize,
    /// Gaussians that are not vertices of the mesh (duplicates, degenerate charts).
    pub unmeshed: usize,
    /// Wall time of the update alone, milliseconds (the frame's `ms` adds the mesh assembly).
    pub update_ms: f64,
}

impl DelaunayFrame {
    /// The record of frame `frame` from the mesher's statistics.
    #[must_use]
    pub fn new(frame: usize, stats: &FrameStats) -> Self {
        Self {
            frame,
            rebuilt: stats.rebuilt,
            hopped: stats.hopped,
            charts_redone: stats.charts_redone,
            searches: stats.searches,
            unmeshed: stats.unmeshed,
            update_ms: stats.millis,
        }
    }
}

/// The incremental Delaunay's work over the frames (delaunay only).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DelaunayStats {
    /// Charts: one per template triangle.
    pub charts: usize,
    /// Gaussians meshed.
    pub gaussians: usize,
    /// Per frame, in frame order.
    pub frames: Vec<DelaunayFrame>,
    /// Frames rebuilt from scratch (the first frame included).
    pub rebuilt_frames: usize,
    /// Mean fraction of the Gaussians that hopped per incremental (not rebuilt) frame;
    /// `None` when every frame was rebuilt.
    pub hopped_fraction: Option<f64>,
    /// Mean fraction of the charts redone per incremental frame; `None` when every frame was
    /// rebuilt.
    pub charts_redone_fraction: Option<f64>,
}

impl DelaunayStats {
    /// The statistics of `frames` for `charts` charts and `gaussians` Gaussians.
    #[must_use]
    pub fn new(charts: usize, gaussians: usize, frames: Vec<DelaunayFrame>) -> Self {
        let incremental: Vec<&DelaunayFrame> = frames.iter().filter(|f| !f.rebuilt).collect();
        let fraction = |count: fn(&DelaunayFrame) -> usize, of: usize| {
            mean(
                incremental
                    .iter()
                    .map(|f| count(f) as f64 / of.max(1) as f64),
            )
        };
        Self {
            charts,
            gaussians,
            rebuilt_frames: frames.len() - incremental.len(),
            hopped_fraction: fraction(|f| f.hopped, gaussians),
            charts_redone_fraction: fraction(|f| f.charts_redone, charts),
            frames,
        }
    }
}

/// Means of one method over the frames.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    /// Frames meshed.
    pub frames: usize,
    /// Mean milliseconds per frame.
    pub ms: f64,
    /// Median milliseconds per frame.
    pub median_ms: f64,
    /// Mean vertices.
    pub vertices: f64,
    /// Mean triangles.
    pub faces: f64,
    /// Frames whose mesh is watertight.
    pub watertight_frames: usize,
    /// Frames with metrics (non-empty mesh, --gt given).
    pub measured_frames: usize,
    /// Mean Chamfer L1 over the measured frames.
    pub chamfer_l1: Option<f64>,
    /// Mean Chamfer L2 over the measured frames.
    pub chamfer_l2: Option<f64>,
    /// Mean normal consistency over the measured frames that have it.
    pub normal_consistency: Option<f64>,
    /// Mean normal angle error (degrees) over the measured frames that have it.
    #[serde(default)]
    pub normal_angle_deg: Option<f64>,
    /// Mean precision at each frame's tau over the measured frames.
    #[serde(default)]
    pub precision: Option<f64>,
    /// Mean recall at each frame's tau over the measured frames.
    #[serde(default)]
    pub recall: Option<f64>,
    /// Mean F-score over the measured frames.
    pub fscore: Option<f64>,
    /// Mean area ratio to the ground truth over the measured frames that have it.
    #[serde(default)]
    pub area_ratio: Option<f64>,
    /// Mean number of connected components over the measured frames.
    #[serde(default)]
    pub components: Option<f64>,
    /// Mean share of the area in the largest component over the measured frames that have
    /// area.
    #[serde(default)]
    pub largest_component_area_fraction: Option<f64>,
    /// Mean number of boundary edges over the measured frames.
    #[serde(default)]
    pub boundary_edges: Option<f64>,
    /// Mean shared-vertex fraction over the measured frames.
    #[serde(default)]
    pub shared_vertex_fraction: Option<f64>,
    /// Measured frames whose scores are self-consistency (the mesh contains the ground
    /// truth's vertices).
    #[serde(default)]
    pub self_consistency_frames: usize,
}

/// The "scored as" cell: what a method's or frame's scores measure (self-consistency in
/// bold).
fn scored_as(relation: Option<Relation>) -> Cell {
    match relation {
        Some(Relation::Accuracy) => Cell::plain("accuracy".to_owned()),
        Some(Relation::SelfConsistency) => Cell {
            text: "self-consistency".to_owned(),
            strong: true,
        },
        None => Cell::plain("-".to_owned()),
    }
}

/// `v` in scientific notation with `digits` decimals, `-` when absent.
fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{x:.digits$e}"))
}

/// `v` with 4 decimals, `-` when absent.
fn optf(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{x:.4}"))
}

/// `v` with `digits` decimals, `-` when absent.
fn fixed(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{x:.digits$}"))
}

/// The fraction `v` as a percentage with 2 decimals, `-` when absent.
fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{:.2}%", 100.0 * x))
}

/// `v` with at most 6 significant digits, without trailing zeros (`24`, `0.00603532`; the
/// exact value is in report.json).
fn significant(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let decimals = (5 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    }
}

/// One cell of a report table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cell {
    /// Its text (plain, not escaped).
    pub text: String,
    /// Shown in bold (report.md `**…**`, report.html `<strong>`).
    pub strong: bool,
}

impl Cell {
    /// A cell in normal weight.
    #[must_use]
    pub fn plain(text: String) -> Self {
        Self {
            text,
            strong: false,
        }
    }
}

/// A table of the report, as report.md and report.html print it (the same cells in both).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Table {
    /// Column titles.
    pub header: Vec<String>,
    /// Per column: aligned right (numbers) rather than left.
    pub right: Vec<bool>,
    /// The rows, each with one cell per column.
    pub rows: Vec<Vec<Cell>>,
}

impl Table {
    /// An empty table with these columns (title, aligned right).
    fn new(columns: &[(&str, bool)]) -> Self {
        Self {
            header: columns.iter().map(|c| c.0.to_owned()).collect(),
            right: columns.iter().map(|c| c.1).collect(),
            rows: Vec::new(),
        }
    }

    /// The table in Markdown (GitHub's pipe tables), one line per row.
    #[must_use]
    pub fn markdown(&self) -> String {
        let mut s = format!("| {} |\n|", self.header.join(" | "));
        for &right in &self.right {
            s.push_str(if right { "---:|" } else { "---|" });
        }
        s.push('\n');
        for row in &self.rows {
            let cells: Vec<String> = row
                .iter()
                .map(|c| {
                    if c.strong {
                        format!("**{}**", c.text)
                    } else {
                        c.text.clone()
                    }
                })
                .collect();
            let _ = writeln!(s, "| {} |", cells.join(" | "));
        }
        s
    }
}

/// The sentence that tells a method's scores are self-consistency, not accuracy.
fn self_consistency_note(m: &MethodReport) -> String {
    format!(
        "**{}: self-consistency, not accuracy.** Its meshes contain the ground truth's vertices \
         (mean shared-vertex fraction {:.1}%; {} of {} measured frames at or above {:.0}%): it is \
         scored against the mesh it was made from, so these scores say how well it reproduces \
         its own input, not how accurate it is. Score it against a ground truth it did not \
         consume (`--gt MESH`, `--gt-sequence`) for accuracy.",
        m.method,
        100.0 * m.mean.shared_vertex_fraction.unwrap_or(0.0),
        m.mean.self_consistency_frames,
        m.mean.measured_frames,
        100.0 * trisplat_geometry::metrics::SELF_CONSISTENCY_MIN_SHARED,
    )
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

impl Summary {
    /// The means of `records`.
    #[must_use]
    pub fn of(records: &[FrameRecord]) -> Self {
        let ms: Vec<f64> = records.iter().map(|r| r.ms).collect();
        let metrics: Vec<&FrameMetrics> =
            records.iter().filter_map(|r| r.metrics.as_ref()).collect();
        let structures: Vec<&MeshStats> = metrics
            .iter()
            .filter_map(|m| m.structure.as_ref())
            .collect();
        Self {
            frames: records.len(),
            ms: mean(ms.iter().copied()).unwrap_or(0.0),
            median_ms: median(&ms),
            vertices: mean(records.iter().map(|r| r.vertices as f64)).unwrap_or(0.0),
            faces: mean(records.iter().map(|r| r.faces as f64)).unwrap_or(0.0),
            watertight_frames: records.iter().filter(|r| r.watertight).count(),
            measured_frames: metrics.len(),
            chamfer_l1: mean(metrics.iter().map(|m| m.chamfer_l1)),
            chamfer_l2: mean(metrics.iter().map(|m| m.chamfer_l2)),
            normal_consistency: mean(metrics.iter().filter_map(|m| m.normal_consistency)),
            normal_angle_deg: mean(metrics.iter().filter_map(|m| m.normal_angle_deg)),
            precision: mean(metrics.iter().map(|m| m.precision)),
            recall: mean(metrics.iter().map(|m| m.recall)),
            fscore: mean(metrics.iter().map(|m| m.fscore)),
            area_ratio: mean(metrics.iter().filter_map(|m| m.area_ratio)),
            components: mean(structures.iter().map(|s| s.components as f64)),
            largest_component_area_fraction: mean(
                structures
                    .iter()
                    .filter_map(|s| s.largest_component_area_fraction),
            ),
            boundary_edges: mean(structures.iter().map(|s| s.boundary_edges as f64)),
            shared_vertex_fraction: mean(metrics.iter().filter_map(|m| m.shared_vertex_fraction)),
            self_consistency_frames: metrics
                .iter()
                .filter(|m| m.relation == Relation::SelfConsistency)
                .count(),
        }
    }

    /// What the method's scores measure: self-consistency when any measured frame's mesh
    /// contains the ground truth's vertices, else accuracy; `None` without measured frames.
    #[must_use]
    pub fn relation(&self) -> Option<Relation> {
        (self.measured_frames > 0).then_some(if self.self_consistency_frames > 0 {
            Relation::SelfConsistency
        } else {
            Relation::Accuracy
        })
    }
}

/// Everything about one method.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MethodReport {
    /// The method.
    pub method: Method,
    /// Its parameters, for the record (e.g. `voxel`, `alpha`, `views`).
    pub parameters: BTreeMap<String, f64>,
    /// Per-frame records, in frame order.
    pub frames: Vec<FrameRecord>,
    /// Means over the frames.
    pub mean: Summary,
    /// What its scores measure: `accuracy`, or `self-consistency` when its meshes contain
    /// the ground truth's vertices ([`Summary::relation`]); `None` without metrics.
    #[serde(default)]
    pub relation: Option<Relation>,
    /// Folder of its per-frame PLY files, relative to the output folder.
    pub ply_dir: String,
    /// Its animated glTF, relative to the output folder.
    pub glb: String,
    /// When the sequence is over glTF's 4 GiB limit: the `.glb` parts that hold it instead of
    /// `glb`, in frame order (`<method>_part001.glb`, ...); empty otherwise.
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub glb_parts: Vec<String>,
    /// What the incremental update did per frame (delaunay only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delaunay: Option<DelaunayStats>,
}

/// The whole run (report.json).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Report {
    /// trisplat version.
    pub version: String,
    /// Template file.
    pub template: String,
    /// Vertices of the template as stored.
    pub template_vertices: usize,
    /// Vertices of the template after welding its seams (the template every stage uses).
    pub welded_vertices: usize,
    /// Animation source (the template itself when it carries its clip).
    pub animation: String,
    /// Channels of a weights track that match no morph target and move nothing (empty for
    /// other animations).
    pub unused_channels: Vec<String>,
    /// Gaussian file, or `bound here: N per triangle`.
    pub gaussians: String,
    /// Number of Gaussians.
    pub gaussian_count: usize,
    /// Deform mode.
    pub mode: String,
    /// Animation frame indices meshed.
    pub frames: Vec<usize>,
    /// Their times in seconds.
    pub frame_times: Vec<f64>,
    /// Deformation wall time per frame, milliseconds (shared by the methods).
    pub deform_ms: Vec<f64>,
    /// Template triangles degenerate in each frame: each kept its last valid frame (or the
    /// fallback frame when it had none; docs/numerics.md, "The degenerate-triangle policy").
    #[serde(default)]
    pub collapsed_triangles: Vec<usize>,
    /// Frames that failed (not in `frames`), with the error; the run went on without them.
    pub failed_frames: Vec<crate::journal::FailedFrame>,
    /// `template`, the ground-truth file, or `None`.
    pub ground_truth: Option<String>,
    /// Samples per mesh for the metrics.
    pub samples: usize,
    /// Absolute F-score threshold when one was asked for (`--tau`); `None` when relative.
    pub tau: Option<f64>,
    /// F-score threshold as a fraction of each frame's ground-truth bounding-box diagonal
    /// (`--tau-fraction`, the default); each frame's absolute `tau` is in its metrics.
    #[serde(default)]
    pub tau_fraction: Option<f64>,
    /// Scale-derived parameters.
    pub resolved: Resolved,
    /// Which Gaussians the point methods (delaunay, alpha) meshed ([`crate::visibility`]);
    /// absent when neither ran and in reports of older versions, which used them all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaussians_used: Option<GaussiansUsed>,
    /// Whether the methods of a frame ran one after another (`--serial-methods`: each
    /// method's ms is its time alone) rather than side by side (the default: each method's ms
    /// includes waiting for the cores the others held).
    #[serde(default)]
    pub serial_methods: bool,
    /// One entry per method, by name.
    pub methods: BTreeMap<String, MethodReport>,
    /// Thumbnails of one frame's meshes, shown in report.html (absent when that frame
    /// failed or the report was written by an older version).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thumbnails: Option<Thumbnails>,
}

/// Thumbnails of one frame's meshes: each method's mesh and the ground truth seen from the
/// same camera, coloured by the distance of each visible point to the ground truth's surface
/// (module [`crate::thumbnail`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Thumbnails {
    /// The animation frame shown.
    pub frame: usize,
    /// The distance at the top of the colour scale (2 x the frame's F-score threshold tau,
    /// scene units; farther points take the top colour); `None` without a ground truth (the
    /// meshes are shaded grey).
    pub scale: Option<f64>,
    /// The ground truth's picture, relative to the output folder, when there is one.
    pub ground_truth: Option<String>,
    /// Each method's picture, by method name, relative to the output folder.
    pub methods: BTreeMap<String, String>,
}

impl Report {
    /// The methods in report order (tsdf, delaunay, alpha).
    #[must_use]
    pub fn ordered(&self) -> Vec<&MethodReport> {
        let mut v: Vec<&MethodReport> = self.methods.values().collect();
        v.sort_by_key(|m| m.method);
        v
    }

    /// Whether there are errors to plot: a ground truth and at least one measured frame
    /// (else the plot shows the time per frame).
    #[must_use]
    pub fn has_errors(&self) -> bool {
        self.ground_truth.is_some() && self.methods.values().any(|m| m.mean.chamfer_l1.is_some())
    }

    /// Writes report.json atomically.
    ///
    /// # Errors
    /// [`IoError`] when the file cannot be written.
    pub fn write_json(&self, path: &Path) -> Result<(), IoError> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| IoError::os(path, std::io::Error::other(e)))?;
        write_atomically(path, |w| {
            w.write_all(text.as_bytes())
                .and_then(|()| w.write_all(b"\n"))
                .map_err(|e| IoError::os(path, e))
        })
    }

    /// The lines above the tables (template, animation, Gaussians, frames, timing, ground
    /// truth, failures, deformation), as Markdown list items without the leading `- `.
    #[must_use]
    pub fn facts(&self) -> Vec<String> {
        let mut v = Vec::new();
        v.push(format!(
            "template: `{}` ({} vertices, {} after welding seams by position)",
            self.template, self.template_vertices, self.welded_vertices
        ));
        v.push(format!("animation: `{}`", self.animation));
        v.push(format!(
            "Gaussians: {} ({} Gaussians), mode {}",
            self.gaussians, self.gaussian_count, self.mode
        ));
        let (first, last) = (
            self.frames.first().copied().unwrap_or(0),
            self.frames.last().copied().unwrap_or(0),
        );
        v.push(format!("frames: {} ({first}..={last})", self.frames.len()));
        v.push(format!(
            "template radius {:.6}, mean Gaussian spacing {:.6}",
            self.resolved.template_radius, self.resolved.mean_spacing
        ));
        if let Some(u) = &self.gaussians_used {
            let floaters = match u.floater_std_ratio {
                Some(r) => format!(
                    "{} floaters (mean distance to the {} nearest above the mean + {r} std)",
                    u.floaters, u.floater_neighbors
                ),
                None => "floaters kept".to_owned(),
            };
            v.push(format!(
                "Gaussians meshed by delaunay and alpha: {} of {}; left out {} hidden (largest weight \
                 in the views of {} poses below {:.4}), {floaters}",
                u.kept, u.total, u.hidden, u.poses, u.min_contribution
            ));
        }
        v.push(format!(
            "timing: {}",
            if self.serial_methods {
                "the methods ran one after another (--serial-methods): each method's ms/frame \
                 is its time alone"
            } else {
                "the methods ran side by side: each method's ms/frame includes waiting for the \
                 cores the others held (--serial-methods times each alone)"
            }
        ));
        match &self.ground_truth {
            Some(gt) => v.push(format!(
                "ground truth: `{gt}`; {} samples per mesh, exact point-to-triangle \
                 distances (docs/conventions.md §8), precision, recall and F-score at {}",
                self.samples,
                self.tau_description()
            )),
            None => v.push("ground truth: none (no metrics)".to_owned()),
        }
        if !self.failed_frames.is_empty() {
            let mut line = format!(
                "**failed frames** ({}; not in the tables below):",
                self.failed_frames.len()
            );
            for f in &self.failed_frames {
                let _ = write!(line, "\n  - frame {}: {}", f.frame, f.error);
            }
            v.push(line);
        }
        if !self.unused_channels.is_empty() {
            v.push(format!(
                "channels of the animation that drive no morph target (ignored): {}",
                self.unused_channels.join(", ")
            ));
        }
        let collapsed: Vec<String> = self
            .frames
            .iter()
            .zip(&self.collapsed_triangles)
            .filter(|(_, n)| **n > 0)
            .map(|(f, n)| format!("{f} ({n})"))
            .collect();
        if !collapsed.is_empty() {
            v.push(format!(
                "**collapsed triangles** (zero area; each kept its last valid frame) in {} \
                 frame(s): {}",
                collapsed.len(),
                collapsed.join(", ")
            ));
        }
        let deform = mean(self.deform_ms.iter().copied()).unwrap_or(0.0);
        v.push(format!(
            "deformation: {deform:.2} ms/frame (not included below)"
        ));
        v
    }

    /// The table of means over the frames, one row per method (report.md's and
    /// report.html's "Means over frames").
    #[must_use]
    pub fn summary_table(&self) -> Table {
        let mut t = Table::new(&[
            ("method", false),
            ("scored as", false),
            ("ms/frame", true),
            ("median ms", true),
            ("vertices", true),
            ("faces", true),
            ("watertight", true),
            ("components", true),
            ("largest piece", true),
            ("boundary edges", true),
            ("area ratio", true),
            ("Chamfer L1", true),
            ("Chamfer L2", true),
            ("normal consistency", true),
            ("normal angle °", true),
            ("recall", true),
            ("F-score", true),
        ]);
        for m in self.ordered() {
            let a = &m.mean;
            let mut row = vec![Cell::plain(m.method.to_string()), scored_as(m.relation)];
            row.extend(
                [
                    format!("{:.2}", a.ms),
                    format!("{:.2}", a.median_ms),
                    format!("{:.0}", a.vertices),
                    format!("{:.0}", a.faces),
                    format!("{}/{}", a.watertight_frames, a.frames),
                    fixed(a.components, 1),
                    pct(a.largest_component_area_fraction),
                    fixed(a.boundary_edges, 1),
                    optf(a.area_ratio),
                    opt(a.chamfer_l1, 4),
                    opt(a.chamfer_l2, 4),
                    optf(a.normal_consistency),
                    fixed(a.normal_angle_deg, 2),
                    optf(a.recall),
                    optf(a.fscore),
                ]
                .map(Cell::plain),
            );
            t.rows.push(row);
        }
        t
    }

    /// The per-frame table of method `m` (with the incremental update's columns for
    /// delaunay).
    #[must_use]
    pub fn frame_table(m: &MethodReport) -> Table {
        let mut columns = vec![
            ("frame", true),
            ("time s", true),
            ("ms", true),
            ("vertices", true),
            ("faces", true),
            ("watertight", false),
            ("components", true),
            ("largest piece", true),
            ("boundary edges", true),
            ("area ratio", true),
            ("scored as", false),
            ("Chamfer L1", true),
            ("Chamfer L2", true),
            ("normal consistency", true),
            ("normal angle °", true),
            ("tau", true),
            ("recall", true),
            ("F-score", true),
        ];
        // Delaunay adds what its update did.
        if m.delaunay.is_some() {
            columns.extend([
                ("hopped", true),
                ("charts redone", true),
                ("rebuilt", false),
            ]);
        }
        let mut t = Table::new(&columns);
        let stats: BTreeMap<usize, &DelaunayFrame> = m
            .delaunay
            .iter()
            .flat_map(|d| d.frames.iter().map(|f| (f.frame, f)))
            .collect();
        for r in &m.frames {
            let mm = r.metrics.as_ref();
            let st = mm.and_then(|m| m.structure.as_ref());
            let mut row: Vec<Cell> = [
                r.frame.to_string(),
                format!("{:.3}", r.time),
                format!("{:.2}", r.ms),
                r.vertices.to_string(),
                r.faces.to_string(),
                (if r.watertight { "yes" } else { "no" }).to_owned(),
                st.map_or_else(|| "-".to_owned(), |s| s.components.to_string()),
                pct(st.and_then(|s| s.largest_component_area_fraction)),
                st.map_or_else(|| "-".to_owned(), |s| s.boundary_edges.to_string()),
                optf(mm.and_then(|m| m.area_ratio)),
            ]
            .map(Cell::plain)
            .into();
            row.push(scored_as(mm.map(|m| m.relation)));
            row.extend(
                [
                    opt(mm.map(|m| m.chamfer_l1), 4),
                    opt(mm.map(|m| m.chamfer_l2), 4),
                    optf(mm.and_then(|m| m.normal_consistency)),
                    fixed(mm.and_then(|m| m.normal_angle_deg), 2),
                    opt(mm.map(|m| m.tau), 3),
                    optf(mm.map(|m| m.recall)),
                    optf(mm.map(|m| m.fscore)),
                ]
                .map(Cell::plain),
            );
            match (&m.delaunay, stats.get(&r.frame)) {
                (Some(_), Some(d)) => row.extend(
                    [
                        d.hopped.to_string(),
                        d.charts_redone.to_string(),
                        (if d.rebuilt { "yes" } else { "no" }).to_owned(),
                    ]
                    .map(Cell::plain),
                ),
                (Some(_), None) => row.extend(["-", "-", "-"].map(|s| Cell::plain(s.to_owned()))),
                (None, _) => {}
            }
            t.rows.push(row);
        }
        t
    }

    /// The sentences under a method's heading: its parameters and files, what its scores
    /// measure, what its incremental updates did (delaunay); Markdown.
    #[must_use]
    pub fn method_notes(m: &MethodReport) -> Vec<String> {
        let mut v = Vec::new();
        let params: Vec<String> = m
            .parameters
            .iter()
            .map(|(k, v)| format!("{k} {}", significant(*v)))
            .collect();
        let glb = if m.glb_parts.is_empty() {
            m.glb.clone()
        } else {
            m.glb_parts.join("`, `")
        };
        v.push(format!(
            "parameters: {}; files: `{}/`, `{glb}`",
            params.join(", "),
            m.ply_dir,
        ));
        match m.relation {
            Some(Relation::SelfConsistency) => v.push(self_consistency_note(m)),
            Some(Relation::Accuracy) => v.push(format!(
                "scores: accuracy (the meshes do not contain the ground truth's \
                 vertices: mean shared-vertex fraction {})",
                pct(m.mean.shared_vertex_fraction)
            )),
            None => {}
        }
        if let Some(d) = &m.delaunay {
            let pct =
                |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |x| format!("{:.3}%", 100.0 * x));
            v.push(format!(
                "incremental updates: {} of {} frames rebuilt from scratch; per other frame, \
                 Gaussians hopped {} (of {}), charts redone {} (of {})",
                d.rebuilt_frames,
                d.frames.len(),
                pct(d.hopped_fraction),
                d.gaussians,
                pct(d.charts_redone_fraction),
                d.charts
            ));
        }
        v
    }

    /// The self-consistency notes of the methods whose scores are self-consistency
    /// (Markdown), in report order.
    #[must_use]
    pub fn self_consistency_notes(&self) -> Vec<String> {
        self.ordered()
            .into_iter()
            .filter(|m| m.relation == Some(Relation::SelfConsistency))
            .map(self_consistency_note)
            .collect()
    }

    /// The Markdown report.
    #[must_use]
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# trisplat extract report\n");
        for line in self.facts() {
            let _ = writeln!(s, "- {line}");
        }
        let _ = writeln!(s);
        let alt = if self.has_errors() {
            "Chamfer L1 against time per frame"
        } else {
            "time per frame (no ground truth)"
        };
        let _ = writeln!(
            s,
            "![{alt}]({PLOT_SVG})\n\nthe plot also as \
             [`{PLOT_PNG}`]({PLOT_PNG}); these tables with a thumbnail of each method's mesh, \
             coloured by its distance to the ground truth: [`{REPORT_HTML}`]({REPORT_HTML})\n"
        );
        let _ = writeln!(s, "## Means over frames\n");
        s.push_str(&self.summary_table().markdown());
        for note in self.self_consistency_notes() {
            let _ = writeln!(s, "\n{note}");
        }
        for m in self.ordered() {
            let _ = writeln!(s, "\n## {}\n", m.method);
            for note in Self::method_notes(m) {
                let _ = writeln!(s, "{note}\n");
            }
            s.push_str(&Self::frame_table(m).markdown());
        }
        s
    }

    /// The threshold as report.md states it.
    fn tau_description(&self) -> String {
        match (self.tau_fraction, self.tau) {
            (Some(f), _) => {
                let taus: Vec<f64> = self
                    .methods
                    .values()
                    .flat_map(|m| m.frames.iter().filter_map(|r| r.metrics.map(|x| x.tau)))
                    .collect();
                let range = match (
                    taus.iter().copied().reduce(f64::min),
                    taus.iter().copied().reduce(f64::max),
                ) {
                    (Some(lo), Some(hi)) if lo == hi => format!(" ({lo:.4e})"),
                    (Some(lo), Some(hi)) => format!(" ({lo:.4e} to {hi:.4e} over the frames)"),
                    _ => String::new(),
                };
                format!("tau = {f} x each frame's ground-truth bounding-box diagonal{range}")
            }
            (None, Some(t)) => format!("tau {t} (absolute)"),
            (None, None) => "-".to_owned(),
        }
    }

    /// Writes report.md atomically.
    ///
    /// # Errors
    /// [`IoError`] when the file cannot be written.
    pub fn write_markdown(&self, path: &Path) -> Result<(), IoError> {
        let text = self.markdown();
        write_atomically(path, |w| {
            w.write_all(text.as_bytes())
                .map_err(|e| IoError::os(path, e))
        })
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use trisplat_geometry::metrics::DEFAULT_TAUS;

    use glam::DVec3;

    use super::*;

    fn tetra(scale: f32) -> TriMesh {
        let p = vec![
            Vec3::ZERO,
            Vec3::X * scale,
            Vec3::Y * scale,
            Vec3::Z * scale,
        ];
        TriMesh::new(p, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    }

    fn record(frame: usize, ms: f64, metrics: Option<FrameMetrics>) -> FrameRecord {
        FrameRecord {
            frame,
            time: frame as f64 / 30.0,
            ms,
            render_ms: None,
            vertices: 4,
            faces: 4,
            watertight: frame.is_multiple_of(2),
            metrics,
        }
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

    #[test]
    fn summary_means_equal_direct_means() {
        let m = |c: f64| FrameMetrics {
            chamfer_l1: c,
            chamfer_l2: c * c,
            normal_consistency: Some(0.9),
            normal_angle_deg: Some(10.0 * c),
            accuracy: c,
            completeness: c,
            precision: 1.0,
            recall: 0.5,
            fscore: 2.0 / 3.0,
            tau: 0.01,
            tau_fraction: Some(0.005),
            gt_diagonal: 2.0,
            gt_area: 1.0,
            area_ratio: Some(1.0 + c),
            shared_vertex_fraction: Some(0.0),
            relation: Relation::Accuracy,
            structure: Some(MeshStats::of(&tetra(1.0))),
        };
        let records = vec![
            record(0, 10.0, Some(m(0.1))),
            record(1, 30.0, None),
            record(2, 20.0, Some(m(0.3))),
        ];
        let s = Summary::of(&records);
        assert_eq!(s.frames, 3);
        assert!((s.ms - 20.0).abs() < 1e-12);
        assert_eq!(s.median_ms, 20.0);
        assert_eq!(s.measured_frames, 2);
        assert!((s.chamfer_l1.expect("measured") - 0.2).abs() < 1e-12);
        assert!((s.chamfer_l2.expect("measured") - 0.05).abs() < 1e-12);
        assert_eq!(s.watertight_frames, 2);
        assert!((s.normal_angle_deg.expect("measured") - 2.0).abs() < 1e-12);
        assert!((s.area_ratio.expect("measured") - 1.2).abs() < 1e-12);
        assert_eq!(s.recall, Some(0.5));
        assert_eq!(s.components, Some(1.0));
        assert_eq!(s.boundary_edges, Some(0.0));
        assert_eq!(s.relation(), Some(Relation::Accuracy));
        let none = Summary::of(&[record(0, 1.0, None)]);
        assert_eq!(none.chamfer_l1, None);
        assert_eq!(none.relation(), None);
        // One self-consistent frame makes the method's scores self-consistency.
        let mut own = m(0.0);
        own.shared_vertex_fraction = Some(1.0);
        own.relation = Relation::SelfConsistency;
        let mixed = Summary::of(&[record(0, 1.0, Some(m(0.1))), record(1, 1.0, Some(own))]);
        assert_eq!(mixed.self_consistency_frames, 1);
        assert_eq!(mixed.relation(), Some(Relation::SelfConsistency));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
    }

    #[test]
    fn delaunay_statistics_and_their_columns() {
        let frame = |f: usize, rebuilt: bool, hopped: usize, charts: usize| DelaunayFrame {
            frame: f,
            rebuilt,
            hopped,
            charts_redone: charts,
            searches: 0,
            unmeshed: 0,
            update_ms: 1.0,
        };
        let frames = vec![
            frame(4, true, 0, 10),
            frame(5, false, 2, 1),
            frame(6, false, 6, 3),
        ];
        let d = DelaunayStats::new(10, 40, frames.clone());
        assert_eq!(d.rebuilt_frames, 1);
        // Means over the incremental frames only: (2 + 6) / 2 of 40, (1 + 3) / 2 of 10.
        assert!((d.hopped_fraction.expect("incremental") - 0.1).abs() < 1e-12);
        assert!((d.charts_redone_fraction.expect("incremental") - 0.2).abs() < 1e-12);
        let all_rebuilt = DelaunayStats::new(10, 40, vec![frame(0, true, 0, 10)]);
        assert_eq!(all_rebuilt.hopped_fraction, None);
        let stats = FrameStats {
            frame: 2,
            rebuilt: false,
            hopped: 7,
            charts_redone: 5,
            searches: 3,
            unmeshed: 1,
            millis: 2.5,
        };
        assert_eq!(
            DelaunayFrame::new(6, &stats),
            DelaunayFrame {
                frame: 6,
                rebuilt: false,
                hopped: 7,
                charts_redone: 5,
                searches: 3,
                unmeshed: 1,
                update_ms: 2.5,
            }
        );
        let records: Vec<FrameRecord> = (4..7).map(|f| record(f, 1.0, None)).collect();
        let method = |m: Method, delaunay: Option<DelaunayStats>| MethodReport {
            method: m,
            parameters: BTreeMap::new(),
            mean: Summary::of(&records),
            relation: None,
            frames: records.clone(),
            ply_dir: m.name().to_owned(),
            glb: format!("{}.glb", m.name()),
            glb_parts: Vec::new(),
            delaunay,
        };
        let report = Report {
            version: "0".to_owned(),
            template: "t.glb".to_owned(),
            template_vertices: 4,
            welded_vertices: 4,
            animation: "t.glb".to_owned(),
            unused_channels: Vec::new(),
            failed_frames: Vec::new(),
            gaussians: "bound here: 4 per triangle".to_owned(),
            gaussian_count: 40,
            mode: "binding".to_owned(),
            frames: vec![4, 5, 6],
            frame_times: vec![0.0; 3],
            deform_ms: vec![0.0; 3],
            collapsed_triangles: vec![0; 3],
            ground_truth: None,
            samples: 10,
            tau: Some(0.01),
            tau_fraction: None,
            resolved: Resolved {
                template_radius: 1.0,
                mean_spacing: 0.1,
                voxel: 0.01,
                alpha: 0.6,
            },
            gaussians_used: None,
            serial_methods: false,
            methods: BTreeMap::from([
                ("delaunay".to_owned(), method(Method::Delaunay, Some(d))),
                ("alpha".to_owned(), method(Method::Alpha, None)),
            ]),
            thumbnails: None,
        };
        let md = report.markdown();
        assert!(
            md.contains("| F-score | hopped | charts redone | rebuilt |"),
            "{md}"
        );
        assert!(md.contains("| - | 0 | 10 | yes |\n"), "{md}");
        assert!(md.contains("| - | 6 | 3 | no |\n"), "{md}");
        assert!(md.contains("Gaussians hopped 10.000% (of 40), charts redone 20.000% (of 10)"));
        assert_eq!(significant(0.006_035_319_638_385_869), "0.00603532");
        assert_eq!(significant(24.0), "24");
        assert_eq!(significant(123_456_789.0), "123456789");
        assert_eq!(significant(0.5), "0.5");
        // Only the delaunay table has the columns.
        assert_eq!(md.matches("| hopped |").count(), 1);
        let json = serde_json::to_value(&report).expect("json");
        assert_eq!(
            json["methods"]["delaunay"]["delaunay"]["frames"][1]["hopped"],
            2
        );
        assert!(json["methods"]["alpha"].get("delaunay").is_none());
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
