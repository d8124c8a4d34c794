//! The report's model: the whole run (report.json) with one entry per method, its per-frame
//! records and their means, built from the run's records.

use std::collections::BTreeMap;
use std::path::Path;

use trisplat_geometry::io::{IoError, write_atomically};
use trisplat_geometry::mesh_stats::MeshStats;
use trisplat_geometry::metrics::Relation;

use crate::config::Method;
use crate::records::{
    DelaunayFrame, FailedFrame, FrameMetrics, FrameRecord, GaussiansUsed, RenderConsistency,
    Resolved, ShardRecord,
};

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
    /// Frames with render consistency (non-empty mesh, `--consistency-views` > 0).
    #[serde(default)]
    pub consistency_frames: usize,
    /// Mean silhouette IoU against the frame's Gaussians over those frames.
    #[serde(default)]
    pub render_iou: Option<f64>,
    /// Mean of the frames' median depth errors against the Gaussians.
    #[serde(default)]
    pub render_depth_error_median: Option<f64>,
    /// Mean of the frames' 90th-percentile depth errors against the Gaussians.
    #[serde(default)]
    pub render_depth_error_p90: Option<f64>,
    /// Mean of the frames' median normal angles against the Gaussians, degrees.
    #[serde(default)]
    pub render_normal_angle_deg: Option<f64>,
    /// The frames that started a key mesh (`--topology fixed|adaptive`; empty per frame).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keys: Vec<usize>,
    /// The largest share of probe Gaussians that hopped off a carried mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_hops: Option<f64>,
    /// The largest mean change (scene units) of the probe Gaussians' distances to a carried
    /// mesh since its key.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_offset: Option<f64>,
}

pub(super) fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

pub(super) fn median(values: &[f64]) -> f64 {
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
        let consistency: Vec<&RenderConsistency> = records
            .iter()
            .filter_map(|r| r.consistency.as_ref())
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
            consistency_frames: consistency.len(),
            render_iou: mean(consistency.iter().map(|c| c.iou)),
            render_depth_error_median: mean(
                consistency.iter().filter_map(|c| c.depth_error_median),
            ),
            render_depth_error_p90: mean(consistency.iter().filter_map(|c| c.depth_error_p90)),
            render_normal_angle_deg: mean(consistency.iter().filter_map(|c| c.normal_angle_deg)),
            keys: records
                .iter()
                .filter_map(|r| r.topology.filter(|t| t.key == r.frame).map(|_| r.frame))
                .collect(),
            max_hops: records
                .iter()
                .filter_map(|r| r.topology.map(|t| t.hops))
                .reduce(f64::max),
            max_offset: records
                .iter()
                .filter_map(|r| r.topology.map(|t| t.offset))
                .reduce(f64::max),
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
    /// The rig moved onto its first key mesh (`--targets rig`).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub rig: Option<RigRecord>,
}

/// How a method's animated glTF stores its frames: each run of frames of one topology (one
/// per key frame) holds a morph basis (a few basis shapes, a weight per shape and frame) or
/// one morph target per frame; distances in the template's units.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GlbStorage {
    /// Runs of frames of one topology.
    pub runs: usize,
    /// Runs stored as a morph basis.
    pub basis_runs: usize,
    /// Basis vectors (morph targets) over all basis runs.
    pub basis_vectors: usize,
    /// The most basis vectors of one run.
    pub largest_basis: usize,
    /// Morph targets of runs stored one per frame.
    pub frame_targets: usize,
    /// The tolerance asked: the largest distance of a vertex from its place, as a fraction of
    /// its run's smallest frame diagonal (0: no basis asked).
    pub tolerance: f64,
    /// The largest distance of a vertex of any frame from its place as the frame was made:
    /// measured for basis runs (the weights as stored), the grid's bound (half a step per
    /// axis) for quantised per-frame targets, 0 for plain `f32`.
    pub max_error: f64,
    /// `max_error` as a fraction of the run's smallest frame diagonal (the largest over runs).
    pub max_error_relative: f64,
    /// The median over frames of each frame's largest distance.
    pub median_frame_error: f64,
}

/// `<method>_rig.glb` (`--targets rig`): the template's skin and morph targets moved onto the
/// method's first key mesh, and how far the rig played by geometry's glTF evaluator is from
/// the carried key mesh at each frame (distances in the template's units).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RigRecord {
    /// The file, relative to the output folder.
    pub file: String,
    /// Its size in bytes.
    pub bytes: u64,
    /// Vertices of the rigged mesh (the key mesh's).
    pub vertices: usize,
    /// Its triangles.
    pub triangles: usize,
    /// Joints of its skin.
    pub joints: usize,
    /// Morph targets.
    pub targets: usize,
    /// Non-zero vertex deltas over all targets (what the sparse accessors store).
    pub deltas: usize,
    /// Frames its animation keys.
    pub frames: usize,
    /// Largest distance of a rig vertex from the carried vertex, over all frames.
    pub max_error: f64,
    /// Median over the frames of each frame's median distance.
    pub median_error: f64,
    /// The frame of the largest distance.
    pub worst_frame: usize,
    /// Milliseconds to transfer and write it.
    pub write_ms: f64,
    /// Milliseconds to read it back and measure it at every frame.
    pub measure_ms: f64,
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
    pub failed_frames: Vec<FailedFrame>,
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
    /// Which Gaussians the point methods (delaunay, alpha) meshed ([`crate::Visibility`]);
    /// absent when neither ran and in reports of older versions, which used them all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaussians_used: Option<GaussiansUsed>,
    /// Whether the methods of a frame ran one after another (`--serial-methods`: each
    /// method's ms is its time alone) rather than side by side (the default: each method's ms
    /// includes waiting for the cores the others held).
    #[serde(default)]
    pub serial_methods: bool,
    /// The shard of a track this run was (`--shard`); absent for a whole run and a merged one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<ShardRecord>,
    /// One entry per method, by name.
    pub methods: BTreeMap<String, MethodReport>,
    /// How each method's animated glTF stores its frames (morph basis, error), by method name;
    /// empty without the `glb` target and in reports of older versions.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub glb_storage: BTreeMap<String, GlbStorage>,
    /// Thumbnails of one frame's meshes, shown in report.html (absent when that frame
    /// failed or the report was written by an older version).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thumbnails: Option<Thumbnails>,
}

/// Thumbnails of one frame's meshes: each method's mesh and the ground truth seen from the
/// same camera, coloured by the distance of each visible point to the ground truth's surface
/// (module [`crate::report::thumbnail`]).
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::tests::tetra;
    use crate::report::table::significant;
    use trisplat_extract::incremental_delaunay::FrameStats;

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
            consistency: None,
            topology: None,
            simplify: None,
        }
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
            rig: None,
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
            glb_storage: BTreeMap::new(),
            serial_methods: false,
            shard: None,
            methods: BTreeMap::from([
                ("delaunay".to_owned(), method(Method::Delaunay, Some(d))),
                ("alpha".to_owned(), method(Method::Alpha, None)),
            ]),
            thumbnails: None,
        };
        let md = report.markdown();
        assert!(
            md.contains("| depth p90 | hopped | charts redone | rebuilt |"),
            "{md}"
        );
        assert!(md.contains("| - | - | - | - | 0 | 10 | yes |\n"), "{md}");
        assert!(md.contains("| - | - | - | - | 6 | 3 | no |\n"), "{md}");
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
}
