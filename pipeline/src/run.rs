//! The main job's frame loop: a [`Session`] per run, each frame's meshes written as the
//! session returns them and journalled, a failing frame recorded and the run going on. The
//! loop emits [`Event`]s; the report is assembled from them ([`ReportBuilder`]) and written
//! with the animated glTFs at the end (module `output`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use rayon::prelude::*;
use trisplat_geometry::io::{WriteOptions, write_mesh};
use trisplat_geometry::metrics::Tau;
use trisplat_splat::Axes;

use crate::carried_frames::{CarriedFrames, TemplateSpool, carries_frames, writes_frame_files};
use crate::config::{ExtractConfig, ExtractOptions, Method, OutputTarget, RunControl};
use crate::error::{PipelineError, first_error_in_order};
use crate::event::Event;
use crate::journal::{Journal, Previous};
use crate::lock::FolderLock;
use crate::metrics::GtSamples;
use crate::output::{
    SequenceSources, check_outputs, file_sources, frame_file, frame_files, refuse_used_output,
    remove_frame_files, remove_stale_temporaries, rig_file, thumbnails_of, write_outputs,
};
use crate::records::{DelaunayFrame, FailedFrame, FrameEntry, FrameRecord};
use crate::report::thumbnail::{self, Colouring, Picture};
use crate::report::{GT_THUMBNAIL, Report, ReportBuilder, THUMBNAIL_DIR, thumbnail_file};
use crate::rig::RigError;
use crate::rig_output::write_rig;
use crate::session::{FrameResult, MethodFrame, Session};

/// Runs the main job and writes every output (see the crate docs); returns the report.
/// `on_event` is told what happens as it happens ([`Event`]).
///
/// Each frame's files are written as soon as they exist and recorded in the run journal
/// (`journal.jsonl`, [`crate::JOURNAL`]); a frame that fails is recorded and the run goes on (unless
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
    on_event: &mut dyn FnMut(&Event),
) -> Result<Report, PipelineError> {
    let o = &config.options;
    let methods = config.methods();
    if methods.is_empty() {
        return Err(PipelineError::NoMethod);
    }
    let mut session = Session::open(config)?;
    session.set_serial_methods(control.serial_methods);
    if o.outputs.writes(OutputTarget::Rig) {
        session.check_rig(methods[0])?;
    }
    let frames = session.frames();
    let out = &config.output;
    check_outputs(config, &methods, frames.clone(), session.input_files())?;
    // Held until the run returns: a second run into this folder is refused meanwhile.
    let _lock = FolderLock::acquire(out)?;
    let (mut journal, previous) = open_journal(out, config, control)?;

    // The report reads the same events as the caller.
    let mut report = ReportBuilder::default();
    let mut emit = |event: Event| {
        report.consume(&event);
        on_event(&event);
    };
    let total = frames.len();
    if !session.unused_channels().is_empty() {
        emit(Event::Notice(format!(
            "{}: {} channel(s) drive no morph target and are ignored: {} (--strict refuses)",
            session.label(),
            session.unused_channels().len(),
            session.unused_channels().join(", ")
        )));
    }
    if !previous.done.is_empty() {
        emit(Event::Notice(format!(
            "resuming: {} of {total} frame(s) already done",
            previous.done.keys().filter(|f| frames.contains(f)).count()
        )));
    }
    emit(session.started(config, total));
    // The frame files: asked for, or the glTF or USD cache is assembled from them (unless
    // they are made from the carried frames, module `carried_frames`).
    let frame_files_wanted = writes_frame_files(o);
    let carried = carries_frames(o);
    if carried {
        session.keep_keys();
    }
    // report.html shows the meshes of the middle frame.
    let thumbnail_frame = frames.start + frames.len().saturating_sub(1) / 2;
    let extras = |f: usize| FrameExtras {
        write_files: frame_files_wanted,
        error_colors: o.outputs.error_colors,
        thumbnails: o.outputs.writes(OutputTarget::Report) && f == thumbnail_frame,
        threshold: o.metrics.threshold(),
        view_axes: o.outputs.view_axes,
    };
    let mut previous = previous.done;
    for (index, f) in frames.clone().enumerate() {
        let done = index + 1;
        let resumed = previous.remove(&f).filter(|entry| {
            !frame_files_wanted
                || entry
                    .methods
                    .keys()
                    .all(|m| out.join(m).join(frame_file(f)).is_file())
        });
        if let Some(entry) = resumed {
            emit(Event::FrameDone {
                done,
                total,
                entry,
                resumed: true,
            });
        } else {
            match run_frame(&mut session, out, f, &extras(f)) {
                Ok((entry, results)) => {
                    journal.frame(&entry)?;
                    for (method, record) in results {
                        emit(Event::MethodDone {
                            method,
                            record: Box::new(record),
                        });
                    }
                    emit(Event::FrameDone {
                        done,
                        total,
                        entry,
                        resumed: false,
                    });
                }
                Err(e) => {
                    let failure = FailedFrame {
                        frame: f,
                        error: e.to_string(),
                    };
                    journal.failed(&failure)?;
                    if control.fail_fast {
                        return Err(e);
                    }
                    emit(Event::Notice(format!(
                        "frame {f} failed, the run goes on: {e}"
                    )));
                    emit(Event::FrameFailed {
                        done,
                        total,
                        failure,
                    });
                }
            }
        }
        // A frame's transient memory goes back to the system, so that peak memory does not
        // grow with the frame count through fragmentation (module `memory`).
        crate::memory::release_free_memory();
    }
    emit(Event::Finishing);

    let Some(mut report) = report.finish() else {
        return Err(PipelineError::Internal {
            what: "a run that started has facts",
        });
    };
    if o.outputs.writes(OutputTarget::Report) {
        report.thumbnails = thumbnails_of(out, thumbnail_frame, &report);
    }
    if o.outputs.writes(OutputTarget::Rig) {
        write_rigs(&mut session, out, &methods, frames, &mut report)?;
    }
    let frame_files = frame_files(out, &report);
    if carried {
        write_carried_outputs(&mut session, out, &mut report, o)?;
    } else {
        let sources = file_sources(&frame_files);
        write_outputs(
            out,
            &mut report,
            &sources,
            &o.outputs.targets,
            o.outputs.gltf_compression,
            o.outputs.morph_basis(),
        )?;
    }
    if frame_files_wanted && !o.outputs.writes(OutputTarget::Meshes) {
        // Written only to assemble the glTF or the USD cache.
        remove_frame_files(&frame_files);
    }
    Ok(report)
}

/// The outputs (module `output`) with each method's glTF and USD cache made from its carried
/// frames (module `carried_frames`): the keys the run did not meet met again, the template's
/// positions of every frame spooled, each frame placed again as the writers ask.
fn write_carried_outputs(
    session: &mut Session,
    out: &Path,
    report: &mut Report,
    o: &ExtractOptions,
) -> Result<(), PipelineError> {
    let frames: BTreeSet<usize> = report
        .methods
        .values()
        .flat_map(|m| m.frames.iter().map(|r| r.frame))
        .collect();
    if let Some(&last) = frames.last() {
        session.see_frames_before(last + 1);
    }
    let spool = TemplateSpool::write(out, frames.iter().copied(), |f| session.positions(f))?;
    let session = &*session;
    let mut sources: SequenceSources<'_> = BTreeMap::new();
    for m in report.methods.values() {
        let keyed: Option<Vec<(usize, usize)>> = m
            .frames
            .iter()
            .map(|r| r.topology.map(|t| (r.frame, t.key)))
            .collect();
        let (Some(keyed), Some(keys)) = (keyed, session.kept_keys(m.method)) else {
            return Err(PipelineError::Internal {
                what: "a carried method's frames have keys, and its carrier kept them",
            });
        };
        let frames = CarriedFrames::new(
            keyed,
            keys,
            &spool,
            session.welded().mesh.triangles(),
            session.origin(),
            out.join(&m.ply_dir),
        );
        sources.insert(m.method, Box::new(frames));
    }
    write_outputs(
        out,
        report,
        &sources,
        &o.outputs.targets,
        o.outputs.gltf_compression,
        o.outputs.morph_basis(),
    )
}

/// Each method's `<method>_rig.glb` over the run's frames (module `rig_output`), its record
/// in the report; a failure names the file and the method.
fn write_rigs(
    session: &mut Session,
    out: &Path,
    methods: &[Method],
    frames: std::ops::Range<usize>,
    report: &mut Report,
) -> Result<(), PipelineError> {
    for &method in methods {
        let path = out.join(rig_file(method));
        let fail = |cause: RigError| PipelineError::Rig {
            path: path.clone(),
            method,
            cause: Box::new(cause),
        };
        let Some(inputs) = session.rig_inputs(method)? else {
            continue;
        };
        let record = write_rig(&inputs, frames.clone(), &path).map_err(fail)?;
        if let Some(r) = report.methods.get_mut(method.name()) {
            r.rig = Some(record);
        }
    }
    Ok(())
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
    view_axes: Axes,
}

/// One frame: meshed by every method, each mesh written (atomically) to its frame file, with
/// the colours and thumbnails `extras` asks for.
fn run_frame(
    session: &mut Session,
    out: &Path,
    f: usize,
    extras: &FrameExtras,
) -> Result<(FrameEntry, Vec<(Method, FrameRecord)>), PipelineError> {
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
        first_error_in_order(result.methods.par_iter().map(|m: &MethodFrame| {
            if write_files {
                let path = out.join(m.method.name()).join(frame_file(f));
                write_mesh(&path, &m.output.mesh, WriteOptions::default())?;
            }
            let delaunay = m.output.delaunay.as_ref().map(|s| DelaunayFrame::new(f, s));
            Ok::<_, PipelineError>((m.method, m.record(f, result.time), delaunay))
        }))?;
    let mut results = Vec::with_capacity(written.len());
    for (m, record, delaunay) in written {
        if delaunay.is_some() {
            entry.delaunay = delaunay;
        }
        entry.methods.insert(m.name().to_owned(), record.clone());
        results.push((m, record));
    }
    Ok((entry, results))
}

/// The thumbnails of one frame: the ground truth (grey) and each method's mesh (coloured by
/// the distance to it up to `scale`, or grey without one), from one camera fitted to the
/// ground truth (else to the meshes). A mesh that cannot be pictured (beyond the spatial
/// index's range) is left out.
fn frame_pictures(
    r: &FrameResult,
    gt: Option<&GtSamples>,
    scale: Option<f64>,
    view_axes: Axes,
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
    let distance_to_gt = |p: glam::DVec3| gt.and_then(|g| g.distance(p));
    let colouring = match (gt, scale) {
        (Some(_), Some(scale)) => Colouring::Distance {
            distance: &distance_to_gt,
            scale,
        },
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
