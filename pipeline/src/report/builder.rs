//! The report assembled from a run's events: the facts told when it starts, every frame done
//! (by this run or the one it resumes) and every frame that failed.

use std::collections::BTreeMap;

use super::model::{DelaunayStats, MethodReport, Report, Summary};
use crate::config::Method;
use crate::event::Event;
use crate::records::{DelaunayFrame, FailedFrame, FrameEntry, FrameRecord, RunFacts};

/// Reads a run's events and makes its report (report.json's model) when the run is done.
#[derive(Clone, Debug, Default)]
pub struct ReportBuilder {
    /// What the run is (from [`Event::Started`]).
    facts: Option<RunFacts>,
    /// The frames done, by frame index.
    done: BTreeMap<usize, FrameEntry>,
    /// The frames that failed, in the order they did.
    failed: Vec<FailedFrame>,
}

impl ReportBuilder {
    /// Takes what the report needs of `event`.
    pub fn consume(&mut self, event: &Event) {
        match event {
            Event::Started { facts, .. } => self.facts = Some((**facts).clone()),
            Event::FrameDone { entry, .. } => {
                self.done.insert(entry.frame, entry.clone());
            }
            Event::FrameFailed { failure, .. } => {
                self.done.remove(&failure.frame);
                self.failed.push(failure.clone());
            }
            Event::Notice(_) | Event::MethodDone { .. } | Event::Finishing => {}
        }
    }

    /// The report of the frames done, in frame order; `None` when the run never started.
    /// Thumbnails and the glTF parts are filled in by whoever writes them.
    #[must_use]
    pub fn finish(self) -> Option<Report> {
        let facts = self.facts?;
        let entries: Vec<&FrameEntry> = self.done.values().collect();
        let mut records: BTreeMap<Method, Vec<FrameRecord>> = BTreeMap::new();
        let mut delaunay_frames: Vec<DelaunayFrame> = Vec::new();
        for e in &entries {
            for m in facts.parameters.keys() {
                if let Some(r) = e.methods.get(m.name()) {
                    records.entry(*m).or_default().push(r.clone());
                }
            }
            delaunay_frames.extend(e.delaunay);
        }
        let mut methods = BTreeMap::new();
        for (m, frames) in records {
            let mean = Summary::of(&frames);
            methods.insert(
                m.name().to_owned(),
                MethodReport {
                    method: m,
                    parameters: facts.parameters.get(&m).cloned().unwrap_or_default(),
                    frames,
                    relation: mean.relation(),
                    mean,
                    ply_dir: m.name().to_owned(),
                    glb: format!("{}.glb", m.name()),
                    glb_parts: Vec::new(),
                    delaunay: (m == Method::Delaunay).then(|| {
                        DelaunayStats::new(
                            facts.charts,
                            facts.gaussian_count,
                            std::mem::take(&mut delaunay_frames),
                        )
                    }),
                },
            );
        }
        Some(Report {
            version: env!("CARGO_PKG_VERSION").to_owned(),
            template: facts.template,
            template_vertices: facts.template_vertices,
            welded_vertices: facts.welded_vertices,
            animation: facts.animation,
            gaussians: facts.gaussians,
            gaussian_count: facts.gaussian_count,
            mode: facts.mode,
            frames: entries.iter().map(|e| e.frame).collect(),
            frame_times: entries.iter().map(|e| e.time).collect(),
            deform_ms: entries.iter().map(|e| e.deform_ms).collect(),
            collapsed_triangles: entries.iter().map(|e| e.collapsed_triangles).collect(),
            failed_frames: self.failed,
            unused_channels: facts.unused_channels,
            ground_truth: facts.ground_truth,
            samples: facts.samples,
            tau: facts.tau,
            tau_fraction: facts.tau_fraction,
            resolved: facts.resolved,
            gaussians_used: facts.gaussians_used,
            serial_methods: facts.serial_methods,
            methods,
            thumbnails: None,
        })
    }
}
