//! report.md: the facts of the run, the table of means and one table per method, with the
//! notes that say what the scores measure.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use trisplat_geometry::io::{IoError, write_atomically};
use trisplat_geometry::metrics::Relation;

use super::files::{PLOT_PNG, PLOT_SVG, REPORT_HTML};
use super::model::{GlbStorage, MethodReport, Report, mean};
use super::table::{Cell, Table, fixed, opt, optf, pct, scored_as, significant};
use crate::records::DelaunayFrame;

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

/// The sentence on what decimation cost a method (`--faces`, `--simplify-error`), if it
/// decimated.
fn simplify_note(m: &MethodReport) -> Option<String> {
    let d: Vec<_> = m.frames.iter().filter_map(|r| r.simplify).collect();
    if d.is_empty() {
        return None;
    }
    let n = d.len() as f64;
    let before = d.iter().map(|d| d.faces_before as f64).sum::<f64>() / n;
    let after = d.iter().map(|d| d.faces_after as f64).sum::<f64>() / n;
    let worst = |f: fn(&crate::records::SimplifyFrame) -> f64| d.iter().map(f).fold(0.0, f64::max);
    Some(format!(
        "decimated {} mesh(es) (meshoptimizer): {before:.0} → {after:.0} faces on average; \
         meshoptimizer's error estimate at most {}, measured from the undecimated mesh \
         (vertices and triangle centroids, exact point-to-surface): Hausdorff at most {}, \
         mean distance at most {} (scene units)",
        d.len(),
        opt(Some(worst(|d| d.meshopt_error)), 3),
        opt(Some(worst(|d| d.hausdorff)), 3),
        opt(Some(worst(|d| d.mean_distance)), 3),
    ))
}

impl Report {
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
            ("render IoU", true),
            ("depth error", true),
            ("depth p90", true),
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
                    optf(a.render_iou),
                    opt(a.render_depth_error_median, 3),
                    opt(a.render_depth_error_p90, 3),
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
            ("render IoU", true),
            ("depth error", true),
            ("depth p90", true),
        ];
        // A carried mesh adds its key and drift.
        let carried = m.frames.iter().any(|r| r.topology.is_some());
        if carried {
            columns.extend([("key", true), ("hops", true), ("stretched", true)]);
        }
        // A decimated mesh adds what decimation cost.
        let decimated = m.frames.iter().any(|r| r.simplify.is_some());
        if decimated {
            columns.extend([
                ("faces before", true),
                ("meshopt error", true),
                ("Hausdorff", true),
                ("mean distance", true),
            ]);
        }
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
                    optf(r.consistency.map(|c| c.iou)),
                    opt(r.consistency.and_then(|c| c.depth_error_median), 3),
                    opt(r.consistency.and_then(|c| c.depth_error_p90), 3),
                ]
                .map(Cell::plain),
            );
            if carried {
                row.extend(
                    [
                        r.topology
                            .map_or_else(|| "-".to_owned(), |t| t.key.to_string()),
                        pct(r.topology.map(|t| t.hops)),
                        pct(r.topology.map(|t| t.stretched)),
                    ]
                    .map(Cell::plain),
                );
            }
            if decimated {
                let d = r.simplify;
                row.extend(
                    [
                        d.map_or_else(|| "-".to_owned(), |d| d.faces_before.to_string()),
                        opt(d.map(|d| d.meshopt_error), 4),
                        opt(d.map(|d| d.hausdorff), 4),
                        opt(d.map(|d| d.mean_distance), 4),
                    ]
                    .map(Cell::plain),
                );
            }
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
        if !m.mean.keys.is_empty() {
            v.push(format!(
                "topology: one mesh carried from {} key frame(s) ({}); most probe Gaussians \
                 hopping off a carried mesh: {}; largest mean change of their distances to it: \
                 {}",
                m.mean.keys.len(),
                m.mean
                    .keys
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", "),
                pct(m.mean.max_hops),
                m.mean
                    .max_offset
                    .map_or_else(|| "-".to_owned(), |o| format!("{o:.3e}"))
            ));
        }
        if let Some(note) = simplify_note(m) {
            v.push(note);
        }
        if let Some(r) = &m.rig {
            v.push(format!(
                "rig: `{}` ({:.1} MB: {} vertices, {} joints, {} morph targets with {} non-zero \
                 deltas, {} frames keyed); played against the carried key mesh, largest \
                 distance {} (frame {}), median {}",
                r.file,
                r.bytes as f64 / 1e6,
                r.vertices,
                r.joints,
                r.targets,
                r.deltas,
                r.frames,
                significant(r.max_error),
                r.worst_frame,
                significant(r.median_error)
            ));
        }
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
            if let Some(g) = self.glb_storage.get(m.method.name()) {
                let _ = writeln!(s, "{}\n", Self::glb_note(g));
            }
            s.push_str(&Self::frame_table(m).markdown());
        }
        s
    }

    /// How a method's glTF stores its frames, one sentence.
    fn glb_note(g: &GlbStorage) -> String {
        let basis = if g.basis_runs > 0 {
            format!(
                "{} of {} run(s) between keys as a morph basis, {} vectors in all (at most {} \
                 in one run)",
                g.basis_runs, g.runs, g.basis_vectors, g.largest_basis
            )
        } else {
            format!("{} run(s) between keys, no morph basis", g.runs)
        };
        format!(
            "glb: {basis}; {} per-frame morph targets; largest vertex error {} ({} of the \
             frame's diagonal; tolerance {}), median frame {}",
            g.frame_targets,
            significant(g.max_error),
            significant(g.max_error_relative),
            significant(g.tolerance),
            significant(g.median_frame_error),
        )
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
