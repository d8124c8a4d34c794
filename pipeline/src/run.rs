//! The main job's outputs: a [`Session`] per run, each frame's meshes written as the session
//! returns them, then the animated glTFs, the reports and the plot.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use trisplat_geometry::io::{
    FrameFiles, GLB_PART_LIMIT, SequenceLayout, WriteOptions, write_mesh, write_sequence_parts,
};

pub use crate::output::frame_file;

use crate::config::{ExtractConfig, GroundTruth, Method};
use crate::error::PipelineError;
use crate::input::GaussianSource;
use crate::output::{Created, Inputs};
use crate::plot;
use crate::report::{
    DelaunayFrame, DelaunayStats, FrameRecord, MethodReport, Report, Summary, is_watertight,
};
use crate::session::{MethodFrame, Session};

/// File name of the JSON report in the output folder.
pub const REPORT_JSON: &str = "report.json";
/// File name of the Markdown report.
pub const REPORT_MD: &str = "report.md";
/// File name of the plot.
pub const PLOT_PNG: &str = "error_vs_time.png";

/// Progress of a run, for a progress bar.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Progress {
    /// Inputs read; `frames` frames will be meshed.
    Started {
        /// Frames to mesh.
        frames: usize,
    },
    /// `done` frames of `total` meshed (all methods).
    Frame {
        /// Frames done.
        done: usize,
        /// Frames in all.
        total: usize,
    },
    /// Writing the sequences, reports and plot.
    Finishing,
    /// Something the user should know before the frames run, told once (a weights track's
    /// channels that drive nothing).
    Notice(String),
}

/// The per-frame mesh files of each method, in frame order: the animated glTF is assembled
/// from them at the end, one frame at a time (no frame's mesh stays in memory).
type FrameFilesByMethod = BTreeMap<Method, Vec<PathBuf>>;

/// Runs the main job and writes every output (see the crate docs); returns the report.
/// `progress` is told when frames are done.
///
/// # Errors
/// Bad inputs (named), an output that would replace an input, a failed method or write. The
/// files this run created are removed again on failure.
pub fn run(
    config: &ExtractConfig,
    progress: &mut dyn FnMut(Progress),
) -> Result<Report, PipelineError> {
    let mut created = Created::default();
    let result = run_inner(config, progress, &mut created);
    if result.is_err() {
        created.remove();
    }
    result
}

fn run_inner(
    config: &ExtractConfig,
    progress: &mut dyn FnMut(Progress),
    created: &mut Created,
) -> Result<Report, PipelineError> {
    let o = &config.options;
    let methods = config.methods();
    if methods.is_empty() {
        return Err(PipelineError::NoMethod);
    }
    let mut session = Session::open(config)?;
    let frames = session.frames();
    check_outputs(config, &methods, frames.clone(), session.input_files())?;

    let out = &config.output;
    let total = frames.len();
    if !session.unused_channels().is_empty() {
        progress(Progress::Notice(format!(
            "{}: {} channel(s) drive no morph target and are ignored: {} (--strict refuses)",
            session.label(),
            session.unused_channels().len(),
            session.unused_channels().join(", ")
        )));
    }
    progress(Progress::Started { frames: total });
    let mut records: BTreeMap<Method, Vec<FrameRecord>> = BTreeMap::new();
    let mut delaunay_frames: Vec<DelaunayFrame> = Vec::new();
    let mut frame_files: FrameFilesByMethod = BTreeMap::new();
    let mut frame_times = Vec::with_capacity(total);
    let mut deform_ms = Vec::with_capacity(total);
    for (done, f) in frames.clone().enumerate() {
        let result = session.frame(f)?;
        deform_ms.push(result.deform_ms);
        frame_times.push(result.time);
        for MethodFrame {
            method: m,
            output,
            metrics,
        } in result.methods
        {
            if let Some(stats) = &output.delaunay {
                delaunay_frames.push(DelaunayFrame::new(f, stats));
            }
            let path = out.join(m.name()).join(frame_file(f));
            let existed = path.exists();
            write_mesh(&path, &output.mesh, WriteOptions::default())?;
            created.note(&path, existed);
            records.entry(m).or_default().push(FrameRecord {
                frame: f,
                time: result.time,
                ms: output.ms,
                render_ms: output.render_ms,
                vertices: output.mesh.vertex_count(),
                faces: output.mesh.triangle_count(),
                watertight: is_watertight(&output.mesh),
                metrics,
            });
            frame_files.entry(m).or_default().push(path);
        }
        progress(Progress::Frame {
            done: done + 1,
            total,
        });
    }
    progress(Progress::Finishing);

    let resolved = *session.resolved();
    let mut method_reports = BTreeMap::new();
    for (m, frames_of) in records {
        let mut parameters = BTreeMap::new();
        match m {
            Method::Tsdf => {
                parameters.insert("voxel".to_owned(), resolved.voxel);
                parameters.insert("views".to_owned(), o.views as f64);
                parameters.insert("resolution".to_owned(), f64::from(o.resolution));
            }
            Method::Delaunay => {
                parameters.insert("rebuild_every".to_owned(), o.rebuild_every as f64);
                parameters.insert("hop_threshold".to_owned(), o.hop_threshold);
            }
            Method::Alpha => {
                parameters.insert("alpha".to_owned(), resolved.alpha);
            }
        }
        let mean = Summary::of(&frames_of);
        method_reports.insert(
            m.name().to_owned(),
            MethodReport {
                method: m,
                parameters,
                frames: frames_of,
                mean,
                ply_dir: m.name().to_owned(),
                glb: format!("{}.glb", m.name()),
                glb_parts: Vec::new(),
                delaunay: (m == Method::Delaunay).then(|| {
                    DelaunayStats::new(
                        session.template().triangle_count(),
                        session.gaussians().len(),
                        std::mem::take(&mut delaunay_frames),
                    )
                }),
            },
        );
    }
    let mut report = Report {
        version: env!("CARGO_PKG_VERSION").to_owned(),
        template: config.template.display().to_string(),
        template_vertices: session.welded().stored_vertices,
        welded_vertices: session.template().vertex_count(),
        animation: session.label().to_owned(),
        gaussians: match session.source() {
            GaussianSource::File(p) => p.display().to_string(),
            GaussianSource::Bound(n) => format!("bound here: {n} per triangle"),
        },
        gaussian_count: session.gaussians().len(),
        mode: o.mode.name().to_owned(),
        frames: frames.collect(),
        frame_times,
        deform_ms,
        unused_channels: session.unused_channels().to_vec(),
        ground_truth: config.gt.as_ref().map(GroundTruth::label),
        samples: o.samples,
        tau: o.tau,
        resolved,
        methods: method_reports,
    };
    write_outputs(out, &mut report, &frame_files, created)?;
    Ok(report)
}

/// Refuses outputs that would replace an input, then creates the method folders.
fn check_outputs(
    config: &ExtractConfig,
    methods: &[Method],
    frames: std::ops::Range<usize>,
    input_files: &[PathBuf],
) -> Result<(), PipelineError> {
    let inputs = Inputs::new(input_files);
    let out = &config.output;
    for m in methods {
        let dir = out.join(m.name());
        for f in frames.clone() {
            inputs.check(&dir.join(frame_file(f)))?;
        }
        inputs.check(&out.join(format!("{}.glb", m.name())))?;
    }
    for name in [REPORT_JSON, REPORT_MD, PLOT_PNG] {
        inputs.check(&out.join(name))?;
    }
    for m in methods {
        let dir = out.join(m.name());
        std::fs::create_dir_all(&dir).map_err(|source| PipelineError::OutputDir {
            path: dir,
            cause: source,
        })?;
    }
    Ok(())
}

/// Writes one animated glTF per method (in parts past glTF's 4 GiB limit, recorded in the
/// report), the report files and the plot.
fn write_outputs(
    out: &Path,
    report: &mut Report,
    frame_files: &FrameFilesByMethod,
    created: &mut Created,
) -> Result<(), PipelineError> {
    for (m, files) in frame_files {
        let glb = out.join(format!("{}.glb", m.name()));
        let existed = glb.exists();
        let written = write_sequence_parts(
            &glb,
            &FrameFiles(files),
            &report.frame_times,
            SequenceLayout::Auto,
            GLB_PART_LIMIT,
        )?;
        if written.len() == 1 {
            created.note(&glb, existed);
        } else {
            for part in &written {
                created.note(part, false);
            }
            if let Some(r) = report.methods.get_mut(m.name()) {
                r.glb_parts = written
                    .iter()
                    .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect();
            }
        }
    }
    let json = out.join(REPORT_JSON);
    let existed = json.exists();
    report.write_json(&json)?;
    created.note(&json, existed);
    let md = out.join(REPORT_MD);
    let existed = md.exists();
    report.write_markdown(&md)?;
    created.note(&md, existed);
    let png = out.join(PLOT_PNG);
    let existed = png.exists();
    plot::write_plot(&png, report)?;
    created.note(&png, existed);
    Ok(())
}
