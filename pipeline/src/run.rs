//! The main job's outputs: a [`Session`] per run, each frame's meshes written as the session
//! returns them, then the animated glTFs, the reports and the plot.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use trisplat_geometry::io::{
    FrameFiles, GLB_PART_LIMIT, SequenceLayout, WriteOptions, write_mesh, write_sequence_parts,
};

pub use crate::output::frame_file;

use crate::config::{
    DepthKind, ExtractConfig, GroundTruth, Method, OutputTarget, RunControl, SplatDepthRule,
};
use crate::error::{PipelineError, first_error_in_order};
use crate::input::GaussianSource;
use crate::journal::{FailedFrame, FrameEntry, JOURNAL, Journal, Previous};
use crate::lock::FolderLock;
use crate::output::Inputs;
use crate::plot;
use crate::report::{
    DelaunayFrame, DelaunayStats, FrameRecord, GtSamples, MethodReport, Report, Summary,
    Thumbnails, is_watertight,
};
use crate::session::{FrameResult, MethodFrame, Session};
use crate::thumbnail::{self, Colouring, Picture, THUMBNAIL_DIR, thumbnail_file};
use trisplat_geometry::metrics::Tau;

/// File name of the JSON report in the output folder.
pub const REPORT_JSON: &str = "report.json";
/// File name of the Markdown report.
pub const REPORT_MD: &str = "report.md";
/// File name of the plot as PNG.
pub const PLOT_PNG: &str = "error_vs_time.png";
/// File name of the plot as SVG.
pub const PLOT_SVG: &str = "error_vs_time.svg";
/// File name of the HTML report.
pub const REPORT_HTML: &str = "report.html";

/// Progress of a run, for a progress bar.
#[derive(Clone, Debug, PartialEq)]
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
        /// Milliseconds each method took on this frame (empty when the frame failed or was
        /// done by the run being resumed).
        method_ms: Vec<(Method, f64)>,
    },
    /// Writing the sequences, reports and plot.
    Finishing,
    /// Something the user should know before the frames run, told once (a weights track's
    /// channels that drive nothing).
    Notice(String),
}

/// The per-frame mesh files of each method, in frame order: the animated glTF is assembled
/// from them at the end, one frame at a time (no frame's mesh stays in memory).
pub(crate) type FrameFilesByMethod = BTreeMap<Method, Vec<PathBuf>>;

/// Runs the main job and writes every output (see the crate docs); returns the report.
/// `progress` is told when frames are done.
///
/// Each frame's files are written as soon as they exist and recorded in the run journal
/// (module [`crate::journal`]); a frame that fails is recorded and the run goes on (unless
/// `control.fail_fast`), and the report lists it. Completed frames are never removed, so an
/// interrupted run can be continued with `control.resume`.
///
/// # Errors
/// Bad inputs (named), an output that would replace an input, an output folder that holds a
/// previous run (without `resume` or `force`), a resume that does not match, a failed write of
/// the sequences or reports; with `fail_fast`, the first failing frame.
pub fn run(
    config: &ExtractConfig,
    control: RunControl,
    progress: &mut dyn FnMut(Progress),
) -> Result<Report, PipelineError> {
    let o = &config.options;
    let methods = config.methods();
    if methods.is_empty() {
        return Err(PipelineError::NoMethod);
    }
    let mut session = Session::open(config)?;
    session.set_serial_methods(control.serial_methods);
    let frames = session.frames();
    let out = &config.output;
    check_outputs(config, &methods, frames.clone(), session.input_files())?;
    // Held until the run returns: a second run into this folder is refused meanwhile.
    let _lock = FolderLock::acquire(out)?;
    let (mut journal, previous) = open_journal(out, config, control)?;

    let total = frames.len();
    if !session.unused_channels().is_empty() {
        progress(Progress::Notice(format!(
            "{}: {} channel(s) drive no morph target and are ignored: {} (--strict refuses)",
            session.label(),
            session.unused_channels().len(),
            session.unused_channels().join(", ")
        )));
    }
    if !previous.done.is_empty() {
        progress(Progress::Notice(format!(
            "resuming: {} of {total} frame(s) already done",
            previous.done.keys().filter(|f| frames.contains(f)).count()
        )));
    }
    progress(Progress::Started { frames: total });
    // The frame files: asked for, or the glTF is assembled from them.
    let frame_files_wanted = o.writes(OutputTarget::Meshes) || o.writes(OutputTarget::Glb);
    // report.html shows the meshes of the middle frame.
    let thumbnail_frame = frames.start + frames.len().saturating_sub(1) / 2;
    let extras = |f: usize| FrameExtras {
        write_files: frame_files_wanted,
        error_colors: o.error_colors,
        thumbnails: o.writes(OutputTarget::Report) && f == thumbnail_frame,
        threshold: o.threshold(),
        view_axes: o.view_axes,
    };
    let mut done_frames = previous.done;
    let mut failed: Vec<FailedFrame> = Vec::new();
    for (done, f) in frames.clone().enumerate() {
        let finished = done_frames.get(&f).is_some_and(|entry| {
            !frame_files_wanted
                || entry
                    .methods
                    .keys()
                    .all(|m| out.join(m).join(frame_file(f)).is_file())
        });
        let mut method_ms = Vec::new();
        if !finished {
            match run_frame(&mut session, out, f, &extras(f)) {
                Ok(entry) => {
                    method_ms = Method::ALL
                        .into_iter()
                        .filter_map(|m| entry.methods.get(m.name()).map(|r| (m, r.ms)))
                        .collect();
                    journal.frame(&entry)?;
                    done_frames.insert(f, entry);
                }
                Err(e) => {
                    let record = FailedFrame {
                        frame: f,
                        error: e.to_string(),
                    };
                    journal.failed(&record)?;
                    if control.fail_fast {
                        return Err(e);
                    }
                    progress(Progress::Notice(format!(
                        "frame {f} failed, the run goes on: {e}"
                    )));
                    done_frames.remove(&f);
                    failed.push(record);
                }
            }
        }
        // A frame's transient memory goes back to the system, so that peak memory does not
        // grow with the frame count through fragmentation (module `memory`).
        crate::memory::release_free_memory();
        progress(Progress::Frame {
            done: done + 1,
            total,
            method_ms,
        });
    }
    progress(Progress::Finishing);

    // The report and the sequences from the journal's frames (this run's and resumed ones).
    let entries: Vec<&FrameEntry> = done_frames
        .values()
        .filter(|e| frames.contains(&e.frame))
        .collect();
    let mut records: BTreeMap<Method, Vec<FrameRecord>> = BTreeMap::new();
    let mut frame_files: FrameFilesByMethod = BTreeMap::new();
    let mut delaunay_frames: Vec<DelaunayFrame> = Vec::new();
    for e in &entries {
        for m in &methods {
            if let Some(r) = e.methods.get(m.name()) {
                records.entry(*m).or_default().push(r.clone());
                frame_files
                    .entry(*m)
                    .or_default()
                    .push(out.join(m.name()).join(frame_file(e.frame)));
            }
        }
        delaunay_frames.extend(e.delaunay);
    }
    let frame_times: Vec<f64> = entries.iter().map(|e| e.time).collect();
    let deform_ms: Vec<f64> = entries.iter().map(|e| e.deform_ms).collect();
    let collapsed_triangles: Vec<usize> = entries.iter().map(|e| e.collapsed_triangles).collect();
    let resolved = *session.resolved();
    let mut method_reports = BTreeMap::new();
    for (m, frames_of) in records {
        let mut parameters = BTreeMap::new();
        match m {
            Method::Tsdf => {
                parameters.insert("voxel".to_owned(), resolved.voxel);
                parameters.insert("views".to_owned(), o.views as f64);
                parameters.insert("resolution".to_owned(), f64::from(o.resolution));
                parameters.insert(
                    "median_depth".to_owned(),
                    f64::from(u8::from(o.tsdf_depth == DepthKind::Median)),
                );
                parameters.insert(
                    "ray_depth".to_owned(),
                    f64::from(u8::from(o.tsdf_splat_depth == SplatDepthRule::Ray)),
                );
                parameters.insert("colors".to_owned(), f64::from(u8::from(o.tsdf_colors)));
                parameters.insert("alpha_cut".to_owned(), f64::from(o.tsdf_alpha_cut));
            }
            Method::Delaunay => {
                parameters.insert("rebuild_every".to_owned(), o.rebuild_every as f64);
                parameters.insert(
                    "auto_rebuild".to_owned(),
                    f64::from(u8::from(!o.no_auto_rebuild)),
                );
                parameters.insert("hop_threshold".to_owned(), o.hop_threshold);
            }
            Method::Alpha => {
                parameters.insert("alpha".to_owned(), resolved.alpha);
                parameters.insert("keep_clusters".to_owned(), o.alpha_keep_clusters as f64);
            }
        }
        let mean = Summary::of(&frames_of);
        method_reports.insert(
            m.name().to_owned(),
            MethodReport {
                method: m,
                parameters,
                frames: frames_of,
                relation: mean.relation(),
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
            GaussianSource::Lam(p) => {
                format!(
                    "{} (LAM per-vertex, bound here around its vertices)",
                    p.display()
                )
            }
        },
        gaussian_count: session.gaussians().len(),
        mode: o.mode.name().to_owned(),
        frames: entries.iter().map(|e| e.frame).collect(),
        frame_times,
        deform_ms,
        collapsed_triangles,
        failed_frames: failed,
        unused_channels: session.unused_channels().to_vec(),
        ground_truth: config.gt.as_ref().map(GroundTruth::label),
        samples: o.samples,
        tau: o.tau_fraction.is_none().then_some(o.tau),
        tau_fraction: o.tau_fraction,
        resolved,
        gaussians_used: config
            .methods
            .iter()
            .any(|m| matches!(m, Method::Delaunay | Method::Alpha))
            .then(|| session.visibility().used),
        serial_methods: control.serial_methods,
        methods: method_reports,
        thumbnails: None,
    };
    if o.writes(OutputTarget::Report) {
        report.thumbnails = thumbnails_of(out, thumbnail_frame, &report);
    }
    write_outputs(out, &mut report, &frame_files, &o.targets)?;
    if o.writes(OutputTarget::Glb) && !o.writes(OutputTarget::Meshes) {
        // Written only to assemble the glTF.
        for file in frame_files.values().flatten() {
            let _ = std::fs::remove_file(file);
        }
    }
    Ok(report)
}

/// What a frame writes besides its numbers.
struct FrameExtras {
    /// The frame files.
    write_files: bool,
    /// Vertex colours by distance to the ground truth (`--error-colors`).
    error_colors: bool,
    /// The thumbnails of report.html.
    thumbnails: bool,
    /// The F-score threshold: the colour scale is twice it.
    threshold: Tau,
    /// The template's axes, for the thumbnails' camera.
    view_axes: trisplat_splat::Axes,
}

/// One frame: meshed by every method, each mesh written (atomically) to its frame file, with
/// the colours and thumbnails `extras` asks for.
fn run_frame(
    session: &mut Session,
    out: &Path,
    f: usize,
    extras: &FrameExtras,
) -> Result<FrameEntry, PipelineError> {
    let write_files = extras.write_files;
    let (result, pictures) = session.frame_with(f, |r, gt| {
        let scale = gt.map(|g| 2.0 * extras.threshold.resolve(g.diagonal()));
        if extras.error_colors
            && let (Some(gt), Some(scale)) = (gt, scale)
        {
            for m in &mut r.methods {
                let Some(d) = gt.distances(m.output.mesh.positions()) else {
                    continue;
                };
                let mesh = std::mem::take(&mut m.output.mesh);
                m.output.mesh = mesh
                    .with_colors(thumbnail::error_colors(&d, scale))
                    .map_err(|_| PipelineError::Internal {
                        what: "one error colour per vertex",
                    })?;
            }
        }
        Ok::<_, PipelineError>(if extras.thumbnails {
            frame_pictures(r, gt, scale, extras.view_axes)
        } else {
            Vec::new()
        })
    })?;
    let pictures = pictures?;
    if !pictures.is_empty() {
        let dir = out.join(THUMBNAIL_DIR);
        std::fs::create_dir_all(&dir).map_err(|cause| PipelineError::OutputDir {
            path: dir.clone(),
            cause,
        })?;
        for (name, picture) in &pictures {
            picture.write_png(&out.join(thumbnail_file(name, f)))?;
        }
    }
    let mut entry = FrameEntry {
        frame: f,
        time: result.time,
        deform_ms: result.deform_ms,
        collapsed_triangles: result.collapsed.total(),
        methods: BTreeMap::new(),
        delaunay: None,
    };
    // Each method's frame file and watertightness, side by side (the meshes are large).
    let written: Vec<(Method, FrameRecord, Option<DelaunayFrame>)> =
        first_error_in_order(result.methods.into_par_iter().map(
            |MethodFrame {
                 method: m,
                 output,
                 metrics,
             }| {
                if write_files {
                    let path = out.join(m.name()).join(frame_file(f));
                    write_mesh(&path, &output.mesh, WriteOptions::default())?;
                }
                let record = FrameRecord {
                    frame: f,
                    time: result.time,
                    ms: output.ms,
                    render_ms: output.render_ms,
                    vertices: output.mesh.vertex_count(),
                    faces: output.mesh.triangle_count(),
                    watertight: is_watertight(&output.mesh),
                    metrics,
                };
                let delaunay = output.delaunay.as_ref().map(|s| DelaunayFrame::new(f, s));
                Ok::<_, PipelineError>((m, record, delaunay))
            },
        ))?;
    for (m, record, delaunay) in written {
        if delaunay.is_some() {
            entry.delaunay = delaunay;
        }
        entry.methods.insert(m.name().to_owned(), record);
    }
    Ok(entry)
}

/// The name of the ground truth's thumbnail (beside the methods' names).
const GT_THUMBNAIL: &str = "ground_truth";

/// The thumbnails of one frame: the ground truth (grey) and each method's mesh (coloured by
/// the distance to it up to `scale`, or grey without one), from one camera fitted to the
/// ground truth (else to the meshes). A mesh that cannot be pictured (beyond the spatial
/// index's range) is left out.
fn frame_pictures(
    r: &FrameResult,
    gt: Option<&GtSamples>,
    scale: Option<f64>,
    view_axes: trisplat_splat::Axes,
) -> Vec<(String, Picture)> {
    let points: Vec<glam::DVec3> = match gt {
        Some(g) => g.mesh.positions().to_vec(),
        None => r
            .methods
            .iter()
            .flat_map(|m| m.output.mesh.positions().iter().copied())
            .collect(),
    };
    let Some((camera, origin)) = thumbnail::frame_camera(&points, view_axes) else {
        return Vec::new();
    };
    let colouring = match (gt, scale) {
        (Some(gt), Some(scale)) => Colouring::Distance { gt, scale },
        _ => Colouring::Grey,
    };
    let mut pictures = Vec::new();
    if let Some(g) = gt
        && let Ok(p) = thumbnail::render(&g.mesh, &camera, origin, Colouring::Grey)
    {
        pictures.push((GT_THUMBNAIL.to_owned(), p));
    }
    for m in &r.methods {
        if let Ok(p) = thumbnail::render(&m.output.mesh, &camera, origin, colouring) {
            pictures.push((m.method.name().to_owned(), p));
        }
    }
    pictures
}

/// The thumbnails of frame `frame` in `out` (written by this run or the one it resumes), as
/// the report lists them; `None` when there are none.
fn thumbnails_of(out: &Path, frame: usize, report: &Report) -> Option<Thumbnails> {
    let exists = |name: &str| out.join(thumbnail_file(name, frame)).is_file();
    let methods: BTreeMap<String, String> = report
        .ordered()
        .iter()
        .map(|m| m.method.name())
        .filter(|name| exists(name))
        .map(|name| (name.to_owned(), thumbnail_file(name, frame)))
        .collect();
    let ground_truth = exists(GT_THUMBNAIL).then(|| thumbnail_file(GT_THUMBNAIL, frame));
    if methods.is_empty() && ground_truth.is_none() {
        return None;
    }
    // The colour scale: twice the frame's threshold, as its metrics recorded it.
    let scale = report
        .methods
        .values()
        .flat_map(|m| m.frames.iter())
        .find(|r| r.frame == frame && r.metrics.is_some())
        .and_then(|r| r.metrics.map(|x| 2.0 * x.tau));
    Some(Thumbnails {
        frame,
        scale,
        ground_truth,
        methods,
    })
}

/// The journal of this run: refuses a folder that holds another run unless told to resume it
/// (then the frames it lists are done) or to start over (then its outputs are removed first).
fn open_journal(
    out: &Path,
    config: &ExtractConfig,
    control: RunControl,
) -> Result<(Journal, Previous), PipelineError> {
    if control.resume {
        let resumed = Journal::resume(out, config)?;
        remove_stale_temporaries(out);
        return Ok(resumed);
    }
    refuse_used_output(out, control.force)?;
    Ok((Journal::create(out, config)?, Previous::default()))
}

/// Refuses an output folder that holds a previous run (its journal or report), unless `force`:
/// then that run's outputs are removed first.
pub(crate) fn refuse_used_output(out: &Path, force: bool) -> Result<(), PipelineError> {
    let marks = [JOURNAL, REPORT_JSON];
    if let Some(found) = marks.iter().find(|m| out.join(m).exists())
        && !force
    {
        return Err(PipelineError::UsedOutput {
            path: out.to_path_buf(),
            found: (*found).to_owned(),
        });
    }
    if force {
        remove_previous_outputs(out);
        remove_stale_temporaries(out);
    }
    Ok(())
}

/// Removes the temporary files (`.trisplat-*.tmp`) a run killed in the middle of an atomic
/// write left in `out` and its method folders (best effort).
fn remove_stale_temporaries(out: &Path) {
    let folders = [out.to_path_buf(), out.join(THUMBNAIL_DIR)]
        .into_iter()
        .chain([Method::Tsdf, Method::Delaunay, Method::Alpha].map(|m| out.join(m.name())));
    for dir in folders {
        let Ok(listing) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in listing.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with(".trisplat-") && name.ends_with(".tmp") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Removes what a previous run wrote into `out`: journal, reports, plot, every method's frame
/// files and sequences (best effort; files that cannot be removed are overwritten later).
fn remove_previous_outputs(out: &Path) {
    for name in [
        JOURNAL,
        REPORT_JSON,
        REPORT_MD,
        REPORT_HTML,
        PLOT_SVG,
        PLOT_PNG,
    ] {
        let _ = std::fs::remove_file(out.join(name));
    }
    if let Ok(listing) = std::fs::read_dir(out.join(THUMBNAIL_DIR)) {
        for e in listing.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.ends_with(".png") && name.contains("_frame_") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    for m in [Method::Tsdf, Method::Delaunay, Method::Alpha] {
        let dir = out.join(m.name());
        if let Ok(listing) = std::fs::read_dir(&dir) {
            for e in listing.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                if name.starts_with("frame_") && name.ends_with(".ply") {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        let _ = std::fs::remove_file(out.join(format!("{}.glb", m.name())));
        if let Ok(listing) = std::fs::read_dir(out) {
            let prefix = format!("{}_part", m.name());
            for e in listing.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                if name.starts_with(&prefix) && name.ends_with(".glb") {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
    }
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
    for name in [REPORT_JSON, REPORT_MD, REPORT_HTML, PLOT_SVG, PLOT_PNG] {
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
/// report), the report files (JSON, Markdown, HTML) and the plot (SVG, PNG).
pub(crate) fn write_outputs(
    out: &Path,
    report: &mut Report,
    frame_files: &FrameFilesByMethod,
    targets: &[OutputTarget],
) -> Result<(), PipelineError> {
    if targets.contains(&OutputTarget::Glb) {
        // One method per task: reading the frame files back is most of the work.
        let written: Vec<(Method, Vec<PathBuf>)> =
            first_error_in_order(frame_files.par_iter().map(|(m, files)| {
                let glb = out.join(format!("{}.glb", m.name()));
                write_sequence_parts(
                    &glb,
                    &FrameFiles(files),
                    &report.frame_times,
                    SequenceLayout::Auto,
                    GLB_PART_LIMIT,
                )
                .map(|parts| (*m, parts))
            }))?;
        for (m, parts) in written {
            if parts.len() > 1
                && let Some(r) = report.methods.get_mut(m.name())
            {
                r.glb_parts = parts
                    .iter()
                    .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect();
            }
        }
    }
    if targets.contains(&OutputTarget::Report) {
        report.write_json(&out.join(REPORT_JSON))?;
        report.write_markdown(&out.join(REPORT_MD))?;
        let svg = plot::write_svg(&out.join(PLOT_SVG), report)?;
        plot::write_png(&out.join(PLOT_PNG), report)?;
        crate::html::write_html(&out.join(REPORT_HTML), report, &svg)?;
    }
    Ok(())
}
