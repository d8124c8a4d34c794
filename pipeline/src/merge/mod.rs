//! Shards joined into one run: `trisplat extract --frames A..B` run into separate folders
//! (on one machine or many, e.g. a Slurm array or a Kubernetes indexed job), then
//! `trisplat merge SHARD... -o DIR` writes what one run over all their frames would have.
//!
//! Each shard is a finished run folder (its `report.json` and frame files). The shards must be
//! the same job: same version, template, animation, Gaussians, mode, ground truth, metric
//! settings, resolved parameters and methods with the same parameters; only the frames differ,
//! and no frame may be in two shards. The merged folder gets every shard's frame files (hard
//! links where the file system allows, else copies), one animated glTF per method assembled
//! from them (in parts past 4 GiB), and a report whose frames, per-frame records, failures,
//! means and Delaunay statistics are those of all shards in frame order, with the thumbnails
//! of the shard whose pictured frame is nearest the middle of all frames. Frame files, and
//! hence the glTF, are byte-identical to one run's at the default `--hop-threshold 0` (each
//! shard's incremental Delaunay starts with a rebuild, which equals the incremental update
//! there); the report differs in the timings, the incremental Delaunay statistics and the
//! thumbnails' frame.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use trisplat_geometry::io::{GltfCompression, IoError};

use crate::config::OutputTarget;
use crate::error::PipelineError;
use crate::lock::FolderLock;
use crate::output::{
    FrameFilesByMethod, file_sources, frame_file, refuse_used_output, remove_frame_files,
    write_outputs,
};
mod checks;

use crate::report::{
    DelaunayStats, MethodReport, REPORT_JSON, Report, Summary, THUMBNAIL_DIR, Thumbnails,
};

/// Merges the finished shard runs in `shards` into `out` (see the module docs); returns the
/// merged report. `force`: start over in an output folder that holds a run.
///
/// # Errors
/// [`PipelineError::Merge`] naming the shard for a missing or unreadable report, a shard still
/// running (its lock held), a folder given twice, a shard of another job (and the field that
/// differs), `--shard` runs of different splits or a shard missing or given twice, a frame in
/// two shards or in none, a missing frame file, the output folder being a shard;
/// [`PipelineError::UsedOutput`] for an output folder holding a run (without `force`); write
/// errors. Nothing is written when the shards are refused.
pub fn merge(shards: &[PathBuf], out: &Path, force: bool) -> Result<Report, PipelineError> {
    merge_with(shards, out, force, &MergeOutputs::default())
}

/// What a merge writes: `extract`'s `--targets`, `--gltf-compression` and
/// `--gltf-morph-tolerance` (the shards' reports do not record theirs).
#[derive(Clone, Debug, PartialEq)]
pub struct MergeOutputs {
    /// The outputs; without [`OutputTarget::Meshes`] the linked frame files are removed once
    /// the glTF and USD cache are assembled.
    pub targets: Vec<OutputTarget>,
    /// How the glTF stores its data.
    pub gltf_compression: GltfCompression,
    /// The glTF's morph basis tolerance, as extract's `--gltf-morph-tolerance` (0: none).
    pub gltf_morph_tolerance: f64,
    /// The glTFs given a morph basis, as extract's `--gltf-morph-above` (megabytes).
    pub gltf_morph_above: f64,
}

impl Default for MergeOutputs {
    /// `extract`'s defaults.
    fn default() -> Self {
        Self {
            targets: OutputTarget::ALL.to_vec(),
            gltf_compression: GltfCompression::default(),
            gltf_morph_tolerance: trisplat_geometry::io::DEFAULT_MORPH_BASIS_TOLERANCE,
            gltf_morph_above: crate::config::DEFAULT_MORPH_ABOVE_MB,
        }
    }
}

/// [`merge`] writing `outputs`.
///
/// # Errors
/// As [`merge`].
pub fn merge_with(
    shards: &[PathBuf],
    out: &Path,
    force: bool,
    outputs: &MergeOutputs,
) -> Result<Report, PipelineError> {
    let bad = |path: &Path, problem: String| PipelineError::Merge {
        path: path.to_path_buf(),
        problem,
    };
    if shards.is_empty() {
        return Err(bad(out, "no shard folders to merge".to_owned()));
    }
    // Held until the merge returns: a shard cannot start running meanwhile.
    let mut shard_locks = Vec::with_capacity(shards.len());
    let mut reports = Vec::with_capacity(shards.len());
    for (i, shard) in shards.iter().enumerate() {
        if same_folder(shard, out) {
            return Err(bad(shard, "is also the output folder".to_owned()));
        }
        if let Some(other) = shards[..i].iter().find(|s| same_folder(s, shard)) {
            return Err(bad(
                shard,
                format!("is given twice (also as {})", other.display()),
            ));
        }
        shard_locks.push(checks::not_running(shard)?);
        let path = shard.join(REPORT_JSON);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            bad(
                &path,
                format!("cannot read the shard's report ({e}); is the run finished?"),
            )
        })?;
        let report: Report = serde_json::from_str(&text)
            .map_err(|e| bad(&path, format!("not a trisplat report: {e}")))?;
        reports.push((shard.as_path(), report));
    }
    checks::one_job(&reports)?;
    let owner = checks::frame_owners(&reports)?;
    std::fs::create_dir_all(out).map_err(|cause| PipelineError::OutputDir {
        path: out.to_path_buf(),
        cause,
    })?;
    // Held until the merge returns: a run into this folder is refused meanwhile.
    let _lock = FolderLock::acquire(out)?;
    refuse_used_output(out, force)?;
    let mut merged = merged_report(&reports);
    // The frame files, linked or copied into the merged folder.
    let mut frame_files: FrameFilesByMethod = BTreeMap::new();
    for m in merged.methods.values() {
        let dir = out.join(&m.ply_dir);
        std::fs::create_dir_all(&dir).map_err(|cause| PipelineError::OutputDir {
            path: dir.clone(),
            cause,
        })?;
        for record in &m.frames {
            let shard = reports[owner[&record.frame]].0;
            let name = frame_file(record.frame);
            let src = shard.join(&m.ply_dir).join(&name);
            if !src.is_file() {
                return Err(bad(
                    &src,
                    "frame file listed in the shard's report is missing".to_owned(),
                ));
            }
            let dst = dir.join(&name);
            let _ = std::fs::remove_file(&dst);
            if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst).map_err(|e| PipelineError::Io(IoError::os(&dst, e)))?;
            }
            frame_files.entry(m.method).or_default().push(dst);
        }
    }
    merged.thumbnails = if outputs.targets.contains(&OutputTarget::Report) {
        link_thumbnails(&reports, out, &merged.frames)?
    } else {
        None
    };
    write_outputs(
        out,
        &mut merged,
        &file_sources(&frame_files),
        &outputs.targets,
        outputs.gltf_compression,
        crate::config::morph_basis(outputs.gltf_morph_tolerance, outputs.gltf_morph_above),
    )?;
    if !outputs.targets.contains(&OutputTarget::Meshes) {
        // Linked only to assemble the glTF or the USD cache.
        remove_frame_files(&frame_files);
    }
    Ok(merged)
}

/// Links (or copies) into `out` the thumbnails of the shard whose thumbnail frame is nearest
/// the middle of the merged `frames` (each shard pictures its own middle frame); `None` when
/// no shard has thumbnails.
fn link_thumbnails(
    reports: &[(&Path, Report)],
    out: &Path,
    frames: &[usize],
) -> Result<Option<Thumbnails>, PipelineError> {
    let middle = frames
        .get(frames.len().saturating_sub(1) / 2)
        .copied()
        .unwrap_or(0);
    let Some((shard, t)) = reports
        .iter()
        .filter_map(|(shard, r)| r.thumbnails.as_ref().map(|t| (*shard, t)))
        .min_by_key(|(_, t)| t.frame.abs_diff(middle))
    else {
        return Ok(None);
    };
    let dir = out.join(THUMBNAIL_DIR);
    std::fs::create_dir_all(&dir).map_err(|cause| PipelineError::OutputDir {
        path: dir.clone(),
        cause,
    })?;
    for file in t.ground_truth.iter().chain(t.methods.values()) {
        let (src, dst) = (shard.join(file), out.join(file));
        if !src.is_file() {
            return Err(PipelineError::Merge {
                path: src,
                problem: "thumbnail listed in the shard's report is missing".to_owned(),
            });
        }
        let _ = std::fs::remove_file(&dst);
        if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).map_err(|e| PipelineError::Io(IoError::os(&dst, e)))?;
        }
    }
    Ok(Some(t.clone()))
}

/// One report over the frames of all shards, in frame order.
fn merged_report(reports: &[(&Path, Report)]) -> Report {
    let mut rows: Vec<(usize, f64, f64, usize)> = reports
        .iter()
        .flat_map(|(_, r)| {
            // Reports written before the count was recorded have none: 0 per frame.
            let collapsed = r
                .collapsed_triangles
                .iter()
                .copied()
                .chain(std::iter::repeat(0));
            r.frames
                .iter()
                .zip(&r.frame_times)
                .zip(&r.deform_ms)
                .zip(collapsed)
                .map(|(((&f, &t), &d), c)| (f, t, d, c))
        })
        .collect();
    rows.sort_by_key(|row| row.0);
    let mut merged = reports[0].1.clone();
    merged.shard = None;
    merged.frames = rows.iter().map(|r| r.0).collect();
    merged.frame_times = rows.iter().map(|r| r.1).collect();
    merged.deform_ms = rows.iter().map(|r| r.2).collect();
    merged.collapsed_triangles = rows.iter().map(|r| r.3).collect();
    merged.failed_frames = reports
        .iter()
        .flat_map(|(_, r)| r.failed_frames.iter().cloned())
        .collect();
    merged.failed_frames.sort_by_key(|f| f.frame);
    merged.serial_methods = reports.iter().all(|(_, r)| r.serial_methods);
    for (name, m) in &mut merged.methods {
        let mut frames: Vec<_> = reports
            .iter()
            .filter_map(|(_, r)| r.methods.get(name))
            .flat_map(|x| x.frames.iter().cloned())
            .collect();
        frames.sort_by_key(|r| r.frame);
        let delaunay = m.delaunay.as_ref().map(|d| {
            let mut per_frame: Vec<_> = reports
                .iter()
                .filter_map(|(_, r)| r.methods.get(name).and_then(|x| x.delaunay.as_ref()))
                .flat_map(|x| x.frames.iter().copied())
                .collect();
            per_frame.sort_by_key(|f| f.frame);
            DelaunayStats::new(d.charts, d.gaussians, per_frame)
        });
        let mean = Summary::of(&frames);
        *m = MethodReport {
            method: m.method,
            parameters: m.parameters.clone(),
            relation: mean.relation(),
            mean,
            frames,
            ply_dir: m.ply_dir.clone(),
            glb: m.glb.clone(),
            glb_parts: Vec::new(),
            delaunay,
            rig: None,
        };
    }
    merged
}

/// Whether two paths name the same folder (by their canonical forms when both exist).
fn same_folder(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}
