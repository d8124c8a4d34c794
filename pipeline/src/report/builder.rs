//! The report assembled from a run's events: the facts told when it starts, every frame done
//! (by this run or the one it resumes) and every frame that failed.

use std::collections::BTreeMap;

use super::model::{DelaunayStats, MethodReport, Report, Summary};
use crate::config::Method;
use crate::event::Event;
use crate::records::{DelaunayFrame, FailedFrame, FrameEntry, FrameRecord};

/// What [`Event::Started`] tells of the run.
#[derive(Clone, Debug)]
struct Start {
    /// The report without frames or methods.
    report: Report,
    /// Each method's parameters.
    parameters: BTreeMap<Method, BTreeMap<String, f64>>,
    /// The incremental Delaunay's charts.
    charts: usize,
}

/// Reads a run's events and makes its report (report.json's model) when the run is done.
#[derive(Clone, Debug, Default)]
pub struct ReportBuilder {
    /// What the run is (from [`Event::Started`]).
    start: Option<Start>,
    /// The frames done, by frame index.
    done: BTreeMap<usize, FrameEntry>,
    /// The frames that failed, in the order they did.
    failed: Vec<FailedFrame>,
}

impl ReportBuilder {
    /// Takes what the report needs of `event`.
    pub fn consume(&mut self, event: &Event) {
        match event {
            Event::Started {
                report,
                parameters,
                charts,
                ..
            } => {
                self.start = Some(Start {
                    report: (**report).clone(),
                    parameters: parameters.clone(),
                    charts: *charts,
                });
            }
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
        let Start {
            mut report,
            parameters,
            charts,
        } = self.start?;
        let entries: Vec<&FrameEntry> = self.done.values().collect();
        let mut records: BTreeMap<Method, Vec<FrameRecord>> = BTreeMap::new();
        let mut delaunay_frames: Vec<DelaunayFrame> = Vec::new();
        for e in &entries {
            for m in parameters.keys() {
                if let Some(r) = e.methods.get(m.name()) {
                    records.entry(*m).or_default().push(r.clone());
                }
            }
            delaunay_frames.extend(e.delaunay);
        }
        for (m, frames) in records {
            let mean = Summary::of(&frames);
            report.methods.insert(
                m.name().to_owned(),
                MethodReport {
                    method: m,
                    parameters: parameters.get(&m).cloned().unwrap_or_default(),
                    frames,
                    relation: mean.relation(),
                    mean,
                    ply_dir: m.name().to_owned(),
                    glb: format!("{}.glb", m.name()),
                    glb_parts: Vec::new(),
                    delaunay: (m == Method::Delaunay).then(|| {
                        DelaunayStats::new(
                            charts,
                            report.gaussian_count,
                            std::mem::take(&mut delaunay_frames),
                        )
                    }),
                    rig: None,
                },
            );
        }
        report.frames = entries.iter().map(|e| e.frame).collect();
        report.frame_times = entries.iter().map(|e| e.time).collect();
        report.deform_ms = entries.iter().map(|e| e.deform_ms).collect();
        report.collapsed_triangles = entries.iter().map(|e| e.collapsed_triangles).collect();
        report.failed_frames = self.failed;
        Some(report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::DelaunayFrame;
    use crate::report::plot::tests::report;

    /// The report as a run of tsdf and delaunay starts: no frames, no methods.
    fn started() -> Event {
        let mut header = report(false, true);
        header.methods.clear();
        let parameters = [Method::Tsdf, Method::Delaunay]
            .into_iter()
            .map(|m| (m, BTreeMap::from([(format!("{m}_knob"), 1.0)])))
            .collect();
        Event::Started {
            frames: 3,
            report: Box::new(header),
            parameters,
            charts: 10,
        }
    }

    fn entry(frame: usize) -> FrameEntry {
        let finished = report(false, true);
        let record = |m: &str| {
            let mut r = finished.methods[m].frames[0].clone();
            r.frame = frame;
            r.ms = 10.0 * (frame + 1) as f64;
            r
        };
        FrameEntry {
            frame,
            time: frame as f64 / 30.0,
            deform_ms: 1.0,
            collapsed_triangles: frame,
            methods: BTreeMap::from([
                ("tsdf".to_owned(), record("tsdf")),
                ("delaunay".to_owned(), record("delaunay")),
            ]),
            delaunay: Some(DelaunayFrame {
                frame,
                rebuilt: frame == 0,
                hopped: 2,
                charts_redone: 1,
                searches: 0,
                unmeshed: 0,
                update_ms: 1.0,
            }),
        }
    }

    #[test]
    fn the_report_is_made_of_the_events_in_frame_order() {
        let mut builder = ReportBuilder::default();
        assert!(
            builder.clone().finish().is_none(),
            "no report before the run starts"
        );
        builder.consume(&Event::Notice("a notice".to_owned()));
        builder.consume(&started());
        // Frame 2 was done by the run being resumed; frame 1 fails; frame 0 is run.
        builder.consume(&Event::FrameDone {
            done: 1,
            total: 3,
            entry: entry(2),
            resumed: true,
        });
        builder.consume(&Event::FrameFailed {
            done: 2,
            total: 3,
            failure: FailedFrame {
                frame: 1,
                error: "bad frame".to_owned(),
            },
        });
        let first = entry(0);
        builder.consume(&Event::MethodDone {
            method: Method::Tsdf,
            record: Box::new(first.methods["tsdf"].clone()),
        });
        builder.consume(&Event::FrameDone {
            done: 3,
            total: 3,
            entry: first,
            resumed: false,
        });
        builder.consume(&Event::Finishing);
        let r = builder.finish().expect("started");
        assert_eq!(r.frames, [0, 2]);
        assert_eq!(r.collapsed_triangles, [0, 2]);
        assert_eq!(r.frame_times, [0.0, 2.0 / 30.0]);
        assert_eq!(r.failed_frames.len(), 1);
        assert_eq!(r.failed_frames[0].frame, 1);
        let tsdf = &r.methods["tsdf"];
        assert_eq!(
            tsdf.frames.iter().map(|f| f.frame).collect::<Vec<_>>(),
            [0, 2]
        );
        assert_eq!(tsdf.mean, Summary::of(&tsdf.frames));
        assert_eq!(tsdf.parameters["tsdf_knob"], 1.0);
        assert!(tsdf.delaunay.is_none());
        let delaunay = r.methods["delaunay"].delaunay.as_ref().expect("stats");
        assert_eq!((delaunay.charts, delaunay.rebuilt_frames), (10, 1));
        assert_eq!(delaunay.frames.len(), 2);
    }
}
