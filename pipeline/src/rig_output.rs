//! `<method>_rig.glb` (`extract --targets rig`): the template's rig moved onto a method's
//! first key mesh ([`crate::rig`]), written with one animation of the run's frames (node
//! transforms and morph weights, no vertex data), then read back and played by geometry's
//! glTF evaluator at every frame against the carried mesh the pipeline places there, the
//! error recorded in the report ([`RigRecord`]).
//!
//! Several keys (`--topology adaptive`): the rig is of the track's first key (frame 0's mesh),
//! and its error is measured against that key carried to every frame, as `fixed` places it.

use std::ops::Range;
use std::path::Path;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate, RigPose};
use trisplat_geometry::io::{RigAnimation, write_rigged_glb};

use crate::carry::CarriedMesh;
use crate::input::WeldedTemplate;
use crate::report::RigRecord;
use crate::rig::{RigError, transfer};

/// What a rig is made from: a method's first key mesh bound to the template, the welded
/// template, the animation and the run's local origin.
#[derive(Clone, Copy)]
pub struct RigInputs<'a> {
    /// The track's first key mesh, bound (local coordinates).
    pub carried: &'a CarriedMesh,
    /// The welded template the key is bound to.
    pub welded: &'a WeldedTemplate,
    /// The animation of the run.
    pub animation: &'a dyn AnimatedTemplate,
    /// The local origin the session works relative to.
    pub origin: DVec3,
}

/// The largest `f32` not above `t` (a glTF key time, as the writer stores it).
fn key_time(t: f64) -> f64 {
    let k = t as f32;
    if f64::from(k) > t {
        f64::from(k.next_down())
    } else {
        f64::from(k)
    }
}

/// Writes the rig of `inputs` over `frames` to `path` (atomically) and measures it (see the
/// module docs); the file is removed again when it cannot be measured.
///
/// # Errors
/// [`RigError::NoRig`] when the animation is not a glTF template's skin or morph targets driven
/// by its clip or a weights track; the transfer's, the writer's and the evaluator's errors.
pub fn write_rig(
    inputs: &RigInputs<'_>,
    frames: Range<usize>,
    path: &Path,
) -> Result<RigRecord, RigError> {
    let start = Instant::now();
    let animation = inputs.animation;
    let template = animation.gltf_rig().ok_or_else(|| {
        RigError::NoRig(
            "the animation is not a glTF template's skin or morph targets (driven by its clip \
             or by a weights track): there is no rig to transfer"
                .to_owned(),
        )
    })?;
    let rig = template.rig()?;
    let carried = inputs.carried;
    let welded = inputs.welded;
    let mesh = transfer(
        carried.key(),
        carried.binding(),
        welded.mesh.triangles(),
        &welded.first,
        &rig,
    )?;
    let poses: Vec<(f64, RigPose)> = frames
        .clone()
        .into_par_iter()
        .map(|f| {
            let pose = animation
                .frame_rig_pose(f)
                .ok_or_else(|| RigError::NoRig("the animation gives no rig pose".to_owned()))??;
            let time = animation.frame_time(f).ok_or_else(|| {
                RigError::Mismatch(format!("frame {f} is past the animation's end"))
            })?;
            Ok::<_, RigError>((time, pose))
        })
        .collect::<Result<_, _>>()?;
    let (times, poses): (Vec<f64>, Vec<RigPose>) = poses.into_iter().unzip();
    write_rigged_glb(
        path,
        &mesh,
        &RigAnimation {
            nodes: &rig.nodes,
            joints: &rig.joints,
            inverse_bind: &rig.inverse_bind,
            times: &times,
            poses: &poses,
        },
    )?;
    let write_ms = start.elapsed().as_secs_f64() * 1e3;
    let measured = measure(inputs, frames.clone(), &times, path);
    let errors = match measured {
        Ok(e) => e,
        Err(e) => {
            let _ = std::fs::remove_file(path);
            return Err(e);
        }
    };
    let bytes = std::fs::metadata(path).map_or(0, |m| m.len());
    let mut medians: Vec<f64> = errors.iter().map(|e| e.1).collect();
    medians.sort_by(f64::total_cmp);
    let (worst_frame, max_error) = errors
        .iter()
        .zip(frames.clone())
        .map(|(e, f)| (f, e.0))
        .fold((frames.start, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    Ok(RigRecord {
        file: path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        bytes,
        vertices: mesh.positions.len(),
        triangles: mesh.triangles.len(),
        joints: rig.joints.len(),
        targets: mesh.targets.len(),
        deltas: mesh.targets.iter().map(|t| t.1.len()).sum(),
        frames: frames.len(),
        max_error,
        median_error: medians.get(medians.len() / 2).copied().unwrap_or(0.0),
        worst_frame,
        write_ms,
        measure_ms: start.elapsed().as_secs_f64() * 1e3 - write_ms,
    })
}

/// Per frame: the largest and the median distance between the rig at `path` played by
/// geometry's evaluator at the frame's key time and the key mesh carried there.
fn measure(
    inputs: &RigInputs<'_>,
    frames: Range<usize>,
    times: &[f64],
    path: &Path,
) -> Result<Vec<(f64, f64)>, RigError> {
    let played = GltfTemplate::open(path, &Clip::Index(0))?;
    frames
        .zip(times)
        .map(|(f, &t)| {
            let stored = inputs.animation.frame(f)?;
            let count = stored.len();
            let mut positions = inputs.welded.positions(stored).ok_or_else(|| {
                RigError::Mismatch(format!(
                    "frame {f} has {count} vertices, the template {}",
                    inputs.welded.stored_vertices
                ))
            })?;
            positions.iter_mut().for_each(|p| *p -= inputs.origin);
            let mut carried = Vec::new();
            inputs
                .carried
                .place(&positions, inputs.welded.mesh.triangles(), &mut carried);
            let rig = played.evaluate_at(key_time(t))?;
            if rig.len() != carried.len() {
                return Err(RigError::Mismatch(format!(
                    "{} plays {} vertices, the key mesh has {}",
                    path.display(),
                    rig.len(),
                    carried.len()
                )));
            }
            let mut d: Vec<f64> = rig
                .par_iter()
                .zip(&carried)
                .map(|(r, c)| (*r - (*c + inputs.origin)).length())
                .collect();
            d.sort_by(f64::total_cmp);
            Ok((
                d.last().copied().unwrap_or(0.0),
                d.get(d.len() / 2).copied().unwrap_or(0.0),
            ))
        })
        .collect()
}
