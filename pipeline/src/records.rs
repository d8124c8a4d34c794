//! The records of a run: what each frame and method produced, as the journal stores them,
//! the run's events carry them and the report reads them. Plain data (serialised as in
//! report.json and journal.jsonl); a leaf of the crate.

use std::collections::BTreeMap;

use trisplat_extract::incremental_delaunay::FrameStats;
use trisplat_geometry::mesh_stats::MeshStats;
use trisplat_geometry::metrics::Relation;

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

/// Render consistency of one mesh against the Gaussians it came from
/// ([`crate::consistency`], docs/conventions.md §8).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RenderConsistency {
    /// Silhouette IoU of the mesh against the Gaussians' alpha > 0.5 (1 when neither covers a
    /// pixel).
    pub iou: f64,
    /// Median |mesh depth − Gaussians' median depth| over pixels both cover (model units;
    /// `None` when no pixel is covered by both).
    pub depth_error_median: Option<f64>,
    /// Its 90th percentile.
    pub depth_error_p90: Option<f64>,
    /// Median angle between the mesh's and the Gaussians' normals over pixels both cover,
    /// degrees.
    pub normal_angle_deg: Option<f64>,
    /// Views rendered.
    pub views: usize,
    /// Pixels the Gaussians cover, over all views.
    pub gaussian_pixels: usize,
    /// Pixels the mesh covers, over all views.
    pub mesh_pixels: usize,
    /// Pixels both cover.
    pub both_pixels: usize,
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
    /// Of which rendering (tsdf, and the opacity method's median-depth field).
    pub render_ms: Option<f64>,
    /// Mesh vertices.
    pub vertices: usize,
    /// Mesh triangles.
    pub faces: usize,
    /// Every edge shared by exactly two triangles.
    pub watertight: bool,
    /// Against the ground truth (`None` without --gt or for an empty mesh).
    pub metrics: Option<FrameMetrics>,
    /// Against the frame's Gaussians from held-out views (`None` when not measured:
    /// `--consistency-views 0`, or reports of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub consistency: Option<RenderConsistency>,
    /// The carried mesh's key and drift (`None` with `--topology per-frame`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub topology: Option<TopologyFrame>,
    /// What decimation cost where this frame's mesh was simplified (`--faces`,
    /// `--simplify-error`: every frame per frame, key frames when carried).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simplify: Option<SimplifyFrame>,
}

/// What decimating one mesh cost (docs/conventions.md §10); lengths in scene units.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimplifyFrame {
    /// Triangles the method made.
    pub faces_before: usize,
    /// Triangles after decimation.
    pub faces_after: usize,
    /// meshoptimizer's own error estimate (its relative error times its scale).
    pub meshopt_error: f64,
    /// The largest exact distance from the method's mesh (its vertices and triangle
    /// centroids) to the decimated surface: a one-sided Hausdorff distance.
    pub hausdorff: f64,
    /// The mean of those distances: a one-sided Chamfer-L1.
    pub mean_distance: f64,
    /// Milliseconds decimating and measuring.
    pub ms: f64,
}

/// One frame of a carried mesh (`--topology fixed|adaptive`): the key it was carried from
/// and how far it had drifted from the frame's Gaussians (docs/conventions.md §10).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TopologyFrame {
    /// The key frame whose mesh this frame is (this frame itself where a key starts).
    pub key: usize,
    /// Share of the probe Gaussians that hopped off the carried mesh (measured before a new
    /// key replaced it; 0 on the track's first key).
    pub hops: f64,
    /// Share of the key mesh's area in triangles stretched or shrunk more than twofold.
    pub stretched: f64,
    /// Mean change (scene units) of the probe Gaussians' distances to the carried mesh since
    /// the key (measured before a new key replaced it; 0 on the track's first key).
    #[serde(default)]
    pub offset: f64,
    /// Mean distance (scene units) the probe Gaussians moved since the key (measured before
    /// a new key replaced it; 0 on the track's first key).
    #[serde(default)]
    pub moved: f64,
    /// Where a key starts: the largest distance from a key-mesh vertex to the Gaussian whose
    /// triangle it was bound to (a vertex far from every Gaussian follows the template
    /// loosely).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub farthest: Option<f64>,
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

/// One frame done: what the report needs of it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameEntry {
    /// Animation frame index.
    pub frame: usize,
    /// Its time in seconds.
    pub time: f64,
    /// Milliseconds spent deforming the Gaussians.
    pub deform_ms: f64,
    /// Template triangles degenerate in this frame (docs/numerics.md, "The
    /// degenerate-triangle policy"); 0 in journals written before it was recorded.
    #[serde(default)]
    pub collapsed_triangles: usize,
    /// Each method's record, by method name.
    pub methods: BTreeMap<String, FrameRecord>,
    /// The incremental Delaunay statistics (with the delaunay method).
    pub delaunay: Option<DelaunayFrame>,
}

/// The shard of a track a run was (`--shard I/N`), as its report records it; `merge` checks
/// that its shards are the parts of one selection, each once.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ShardRecord {
    /// This shard's position, `0..count`.
    pub index: usize,
    /// How many shards split the job's frames.
    pub count: usize,
    /// The frames the shards split (`--frames`, or the whole track): `[start, end)`.
    pub job_frames: [usize; 2],
}

/// A frame that failed, and why.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FailedFrame {
    /// Animation frame index.
    pub frame: usize,
    /// The error, as printed.
    pub error: String,
}

/// Scale-derived parameters of the methods, resolved once for the run.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Resolved {
    /// Bounding radius of the rest template (about its box centre).
    pub template_radius: f64,
    /// Mean nearest-neighbour spacing of the rest-pose Gaussian means.
    pub mean_spacing: f64,
    /// TSDF voxel.
    pub voxel: f64,
    /// Alpha radius: the fixed `--alpha` (or `--alpha-rule open3d`'s default), else the
    /// smallest α of the per-frame search.
    pub alpha: f64,
}

/// How many Gaussians the point methods use, why the others are left out, and the rule (in
/// the report).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GaussiansUsed {
    /// The rule's contribution threshold (0: no Gaussian hidden).
    pub min_contribution: f32,
    /// The floater rule's standard deviations (`None`: no floater rule).
    pub floater_std_ratio: Option<f64>,
    /// The floater rule's neighbours.
    pub floater_neighbors: usize,
    /// Gaussians in the set.
    pub total: usize,
    /// Gaussians the point methods use.
    pub kept: usize,
    /// Left out as hidden (below the contribution threshold in every view).
    pub hidden: usize,
    /// Left out as floaters (statistical outliers among the rest).
    pub floaters: usize,
    /// Poses rendered to decide: the rest pose and frames sampled over the track (0: not decided).
    #[serde(default)]
    pub poses: usize,
}
