//! The output folder of a run: the frame files' names, never an output over an input, files
//! removed again when a run fails (docs/conventions.md §10), a folder that holds another run
//! refused or cleared, and the animated glTFs and report files written at the end.

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use trisplat_geometry::io::{
    FrameFiles, FrameSource, GLB_PART_LIMIT, GltfCompression, MorphBasis, SequenceLayout,
    SequenceOptions, SequenceSummary, write_sequence_parts_summarised, write_usd_sequence,
};

use crate::config::{ExtractConfig, Method, OutputTarget};
use crate::error::{PipelineError, first_error_in_order};
use crate::journal::JOURNAL;
use crate::report::{
    GT_THUMBNAIL, GlbStorage, PLOT_PNG, PLOT_SVG, REPORT_HTML, REPORT_JSON, REPORT_MD, Report,
    THUMBNAIL_DIR, Thumbnails, html, plot, thumbnail_file,
};

/// Name of frame `frame`'s file in an output folder (`frame_000042.ply`).
#[must_use]
pub fn frame_file(frame: usize) -> String {
    format!("frame_{frame:06}.ply")
}

/// Name of `method`'s rig in an output folder (`tsdf_rig.glb`, `--targets rig`).
#[must_use]
pub fn rig_file(method: Method) -> String {
    format!("{}_rig.glb", method.name())
}

/// The input files of a run, compared by canonical path (symbolic links and `..` resolved).
#[derive(Clone, Debug, Default)]
pub struct Inputs(HashSet<PathBuf>);

impl Inputs {
    /// The canonical paths of `paths` that exist (folders included: their files are not
    /// listed).
    #[must_use]
    pub fn new(paths: &[PathBuf]) -> Self {
        Self(paths.iter().filter_map(|p| p.canonicalize().ok()).collect())
    }

    /// Errors when writing `path` would replace one of the inputs.
    ///
    /// # Errors
    /// [`PipelineError::OverwriteInput`].
    pub fn check(&self, path: &Path) -> Result<(), PipelineError> {
        if path.canonicalize().is_ok_and(|c| self.0.contains(&c)) {
            return Err(PipelineError::OverwriteInput {
                path: path.to_path_buf(),
            });
        }
        Ok(())
    }
}

/// Files a run created, removed again if the run fails.
#[derive(Clone, Debug, Default)]
pub struct Created(Vec<PathBuf>);

impl Created {
    /// Records `path` as created by this run unless it `existed` before.
    pub fn note(&mut self, path: &Path, existed: bool) {
        if !existed {
            self.0.push(path.to_path_buf());
        }
    }

    /// Removes every recorded file (best effort: the error being reported matters more than a
    /// leftover file).
    pub fn remove(&self) {
        for p in &self.0 {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// The per-frame mesh files of each method, in frame order: the animated glTF is assembled
/// from them at the end, one frame at a time (no frame's mesh stays in memory), unless the
/// run carries its meshes (module `carried_frames`).
pub type FrameFilesByMethod = BTreeMap<Method, Vec<PathBuf>>;

/// Each method's frames for the glTF and USD cache, handed over one at a time: read from its
/// frame files, or placed again from the run's carried keys (module `carried_frames`).
pub type SequenceSources<'a> = BTreeMap<Method, Box<dyn FrameSource + Sync + 'a>>;

/// The frames of `files`, read from the files.
#[must_use]
pub fn file_sources(files: &FrameFilesByMethod) -> SequenceSources<'_> {
    files
        .iter()
        .map(|(m, f)| {
            let source: Box<dyn FrameSource + Sync> = Box::new(FrameFiles(f));
            (*m, source)
        })
        .collect()
}

/// The frame files in `out` of every frame `report` lists, per method.
#[must_use]
pub fn frame_files(out: &Path, report: &Report) -> FrameFilesByMethod {
    report
        .methods
        .values()
        .map(|m| {
            let dir = out.join(&m.ply_dir);
            let files = m.frames.iter().map(|r| dir.join(frame_file(r.frame)));
            (m.method, files.collect())
        })
        .collect()
}

/// Removes `files` (best effort): frame files written only to assemble the glTF.
pub fn remove_frame_files(files: &FrameFilesByMethod) {
    for file in files.values().flatten() {
        let _ = std::fs::remove_file(file);
    }
}

/// The thumbnails of frame `frame` in `out` (written by this run or the one it resumes), as
/// the report lists them; `None` when there are none.
pub fn thumbnails_of(out: &Path, frame: usize, report: &Report) -> Option<Thumbnails> {
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

/// Refuses an output folder that holds a previous run (its journal or report), unless `force`:
/// then that run's outputs are removed first.
pub fn refuse_used_output(out: &Path, force: bool) -> Result<(), PipelineError> {
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
pub fn remove_stale_temporaries(out: &Path) {
    let folders = [out.to_path_buf(), out.join(THUMBNAIL_DIR)]
        .into_iter()
        .chain(Method::ALL.map(|m| out.join(m.name())));
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
    for m in Method::ALL {
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
        let _ = std::fs::remove_file(out.join(format!("{}.usda", m.name())));
        let _ = std::fs::remove_file(out.join(rig_file(m)));
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
pub fn check_outputs(
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
        inputs.check(&out.join(format!("{}.usda", m.name())))?;
        inputs.check(&out.join(rig_file(*m)))?;
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
/// report), one USD mesh cache per method when asked (`<method>.usda`), the report files
/// (JSON, Markdown, HTML) and the plot (SVG, PNG). `compression` and `morph_basis`: how the glTF
/// stores its data (`--gltf-compression`, `--gltf-morph-tolerance`); what each method's glTF
/// became is recorded in the report ([`Report::glb_storage`]).
pub fn write_outputs(
    out: &Path,
    report: &mut Report,
    frames: &SequenceSources<'_>,
    targets: &[OutputTarget],
    compression: GltfCompression,
    morph_basis: MorphBasis,
) -> Result<(), PipelineError> {
    report.glb_storage.clear();
    if targets.contains(&OutputTarget::Glb) {
        // One method per task: reading the frame files back is most of the work.
        let written: Vec<(Method, SequenceSummary)> =
            first_error_in_order(frames.par_iter().map(|(m, source)| {
                let glb = out.join(format!("{}.glb", m.name()));
                let options = SequenceOptions {
                    layout: SequenceLayout::Auto,
                    compression,
                    morph_basis,
                };
                write_sequence_parts_summarised(
                    &glb,
                    &**source,
                    &report.frame_times,
                    &options,
                    GLB_PART_LIMIT,
                )
                .map(|summary| (*m, summary))
            }))?;
        for (m, summary) in written {
            let tolerance =
                if compression.quantizes() && morph_basis.applies_to(summary.target_payload) {
                    morph_basis.tolerance
                } else {
                    0.0
                };
            report
                .glb_storage
                .insert(m.name().to_owned(), glb_storage(&summary, tolerance));
            let parts = summary.parts;
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
    if targets.contains(&OutputTarget::Usd) {
        // One method at a time: the writer formats each frame's points in parallel.
        for (m, source) in frames {
            let usda = out.join(format!("{}.usda", m.name()));
            write_usd_sequence(&usda, &**source, &report.frame_times)?;
        }
    }
    if targets.contains(&OutputTarget::Report) {
        report.write_json(&out.join(REPORT_JSON))?;
        report.write_markdown(&out.join(REPORT_MD))?;
        let svg = plot::write_svg(&out.join(PLOT_SVG), report)?;
        plot::write_png(&out.join(PLOT_PNG), report)?;
        html::write_html(&out.join(REPORT_HTML), report, &svg)?;
    }
    Ok(())
}

/// The report's record of one method's glTF from what the writer made of it.
fn glb_storage(summary: &SequenceSummary, tolerance: f64) -> GlbStorage {
    let runs = &summary.segments;
    let basis: Vec<usize> = runs.iter().filter_map(|r| r.basis).collect();
    let mut frame_errors: Vec<f64> = runs.iter().flat_map(|r| r.frame_errors.clone()).collect();
    frame_errors.sort_by(f64::total_cmp);
    let median = match frame_errors.len() {
        0 => 0.0,
        n if n % 2 == 1 => frame_errors[n / 2],
        n => 0.5 * (frame_errors[n / 2 - 1] + frame_errors[n / 2]),
    };
    GlbStorage {
        runs: runs.len(),
        basis_runs: basis.len(),
        basis_vectors: basis.iter().sum(),
        largest_basis: basis.iter().copied().max().unwrap_or(0),
        frame_targets: runs
            .iter()
            .filter(|r| r.basis.is_none())
            .map(|r| r.frames.len().saturating_sub(1))
            .sum(),
        tolerance,
        max_error: runs.iter().map(|r| r.max_error).fold(0.0, f64::max),
        max_error_relative: runs
            .iter()
            .filter(|r| r.diagonal > 0.0)
            .map(|r| r.max_error / r.diagonal)
            .fold(0.0, f64::max),
        median_frame_error: median,
    }
}
