//! Blendshape sets (neutral + targets of one topology) and weight tracks in the LAM/ARKit JSON
//! layout, driving either OBJ/PLY blendshapes or glTF morph targets by name.
//!
//! A frame is `neutral + Σ wᵢ · (targetᵢ − neutral)`, differences and sums in f64.
//!
//! # Weights file
//! A JSON object with `names` (one string per channel) and `frames`, each an object with
//! `weights` (one number per name) and optionally `time` (seconds). LAM's top-level
//! `head_pose` (one `[x, y, z]` per frame) is the head's rotation as an axis-angle vector in
//! radians, in world axes: a glTF template turns its skin's joint named `head` by it, about
//! the joint's origin, on top of the morph targets (without such a joint `head_pose` is listed
//! as an unused channel). Per-frame `rotation` (empty in LAM's files) is ignored. Without `time` on every frame, frame `i` is
//! at `i / fps` with `fps` from a top-level `fps` key or [`DEFAULT_FPS`]. `NaN`/`Infinity`
//! tokens (Python's `json` writes them) and `null` weights are refused with the frame and the
//! channel named.
//!
//! # Name matching
//! A target takes the channel with exactly its name, else the channel with the same
//! [`canonical_target_name`] (so ICT FaceKit's `eyeBlink_L` takes ARKit's `eyeBlinkLeft`).
//! Targets without a channel stay at zero (or the glTF default weight); channels without a
//! target are ignored and listed by `unused_channels`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};
use rayon::prelude::*;

use super::error::AnimationError;
use super::gltf::{GltfTemplate, JointTurn, RigPose};
use super::sequence::check_topology;
use super::template::{AnimatedTemplate, DEFAULT_FPS};
use crate::io::files::read_mesh;
use crate::mesh::TriMesh;

/// A name in the form used to match blendshape targets with weight channels: lower case,
/// a trailing `_L`/`_R` (or `.L`/`.R`) spelled `left`/`right`, `_` and `.` removed.
/// `eyeBlink_L` and `eyeBlinkLeft` both become `eyeblinkleft`.
#[must_use]
pub fn canonical_target_name(name: &str) -> String {
    let lower = name.trim().to_ascii_lowercase();
    let spelled = if let Some(stem) = lower
        .strip_suffix("_l")
        .or_else(|| lower.strip_suffix(".l"))
    {
        format!("{stem}left")
    } else if let Some(stem) = lower
        .strip_suffix("_r")
        .or_else(|| lower.strip_suffix(".r"))
    {
        format!("{stem}right")
    } else {
        lower
    };
    spelled.chars().filter(|c| *c != '_' && *c != '.').collect()
}

/// Per-frame weights of named channels (ARKit blendshapes in the LAM layout).
#[derive(Clone, Debug)]
pub struct WeightsTrack {
    path: PathBuf,
    names: Vec<String>,
    times: Vec<f64>,
    /// `frames × names`, row-major.
    weights: Vec<f64>,
    /// LAM's `head_pose`: per frame, the head's rotation as an axis-angle vector in radians.
    head_pose: Option<Vec<DVec3>>,
}

/// Replaces the bare tokens `NaN`, `Infinity` and `-Infinity` outside strings by `null`, so
/// that a file written by Python's `json` parses and its bad values can be reported by place.
fn nulls_for_non_finite(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_string = false;
    let mut escaped = false;
    let mut rest = text;
    while let Some(c) = rest.chars().next() {
        if in_string {
            if escaped {
                escaped = false;
            } else if c == '\\' {
                escaped = true;
            } else if c == '"' {
                in_string = false;
            }
        } else if c == '"' {
            in_string = true;
        } else {
            let token = ["-Infinity", "Infinity", "NaN"]
                .into_iter()
                .find(|t| rest.starts_with(t));
            if let Some(token) = token {
                out.push_str("null");
                rest = &rest[token.len()..];
                continue;
            }
        }
        out.push(c);
        rest = &rest[c.len_utf8()..];
    }
    out
}

/// The key of LAM's head rotation track, and the channel name under which a track whose
/// template has no head joint lists it as unused.
pub const HEAD_POSE: &str = "head_pose";

/// The joint LAM's `head_pose` turns (compared without case).
pub const HEAD_JOINT: &str = "head";

/// Parses `head_pose`: one `[x, y, z]` axis-angle vector (radians) per frame.
fn parse_head_pose(
    value: &serde_json::Value,
    frames: usize,
    err: &dyn Fn(&str, String) -> AnimationError,
) -> Result<Vec<DVec3>, AnimationError> {
    let Some(list) = value.as_array() else {
        return Err(err(
            HEAD_POSE,
            "expected a list of [x, y, z] per frame".into(),
        ));
    };
    if list.len() != frames {
        return Err(err(
            HEAD_POSE,
            format!("has {} rotations for {frames} frames", list.len()),
        ));
    }
    list.iter()
        .enumerate()
        .map(|(f, r)| {
            let bad = || {
                err(
                    &format!("{HEAD_POSE}[{f}]"),
                    format!("{r} is not three finite numbers (an axis-angle vector, radians)"),
                )
            };
            let v = r.as_array().filter(|v| v.len() == 3).ok_or_else(bad)?;
            let c: Vec<f64> = v.iter().filter_map(serde_json::Value::as_f64).collect();
            match c.as_slice() {
                [x, y, z] if c.iter().all(|x| x.is_finite()) => Ok(DVec3::new(*x, *y, *z)),
                _ => Err(bad()),
            }
        })
        .collect()
}

impl WeightsTrack {
    /// Reads a weights file (see the module docs for the layout).
    ///
    /// # Errors
    /// [`AnimationError::Os`] when unreadable; [`AnimationError::Weights`] naming the entry at
    /// fault (missing `names` or `frames`, a weight count that differs from the names, a
    /// NaN/infinite/null/non-number weight, a bad time).
    pub fn read(path: &Path) -> Result<Self, AnimationError> {
        let text = std::fs::read_to_string(path).map_err(|error| AnimationError::Os {
            path: path.to_path_buf(),
            error,
        })?;
        Self::parse(&text, path)
    }

    /// Parses weights-file text; `path` is only used in error messages.
    ///
    /// # Errors
    /// As [`Self::read`].
    pub fn parse(text: &str, path: &Path) -> Result<Self, AnimationError> {
        let err = |element: &str, message: String| AnimationError::Weights {
            path: path.to_path_buf(),
            element: element.to_string(),
            message,
        };
        let value: serde_json::Value = serde_json::from_str(&nulls_for_non_finite(text))
            .map_err(|e| err("file", format!("not JSON: {e}")))?;
        let Some(object) = value.as_object() else {
            return Err(err(
                "file",
                "expected a JSON object with `names` and `frames`".into(),
            ));
        };
        let names: Vec<String> = match object.get("names").and_then(|n| n.as_array()) {
            None => {
                return Err(err(
                    "names",
                    "missing (expected a list of channel names)".into(),
                ));
            }
            Some(list) => list
                .iter()
                .enumerate()
                .map(|(i, n)| {
                    n.as_str()
                        .map(str::to_string)
                        .ok_or_else(|| err(&format!("names[{i}]"), "is not a string".into()))
                })
                .collect::<Result<_, _>>()?,
        };
        if names.is_empty() {
            return Err(err("names", "is empty".into()));
        }
        let mut seen = HashMap::new();
        for (i, n) in names.iter().enumerate() {
            if let Some(first) = seen.insert(n.as_str(), i) {
                return Err(err(
                    &format!("names[{i}]"),
                    format!("{n:?} repeats names[{first}]"),
                ));
            }
        }
        let Some(frames) = object.get("frames").and_then(|f| f.as_array()) else {
            return Err(err(
                "frames",
                "missing (expected a list of {\"weights\": [...]})".into(),
            ));
        };
        if frames.is_empty() {
            return Err(err("frames", "is empty".into()));
        }
        let fps = match object.get("fps") {
            None => DEFAULT_FPS,
            Some(v) => match v.as_f64() {
                Some(f) if f.is_finite() && f > 0.0 => f,
                _ => return Err(err("fps", format!("{v} is not a positive number"))),
            },
        };
        let mut weights = Vec::with_capacity(frames.len() * names.len());
        let mut times = Vec::with_capacity(frames.len());
        let mut all_timed = true;
        for (f, frame) in frames.iter().enumerate() {
            let list = frame
                .get("weights")
                .and_then(|w| w.as_array())
                .ok_or_else(|| err(&format!("frames[{f}].weights"), "missing".into()))?;
            if list.len() != names.len() {
                return Err(err(
                    &format!("frames[{f}].weights"),
                    format!("has {} values for {} names", list.len(), names.len()),
                ));
            }
            for (k, w) in list.iter().enumerate() {
                match w.as_f64() {
                    Some(v) if v.is_finite() => weights.push(v),
                    _ => {
                        return Err(err(
                            &format!("frames[{f}].weights[{k}] ({})", names[k]),
                            format!(
                                "{w} is not a finite number (NaN, infinite and null are refused)"
                            ),
                        ));
                    }
                }
            }
            match frame.get("time") {
                None => all_timed = false,
                Some(t) => match t.as_f64() {
                    Some(v) if v.is_finite() => times.push(v),
                    _ => {
                        return Err(err(
                            &format!("frames[{f}].time"),
                            format!("{t} is not a finite number"),
                        ));
                    }
                },
            }
        }
        if all_timed {
            if let Some(k) = times.windows(2).position(|w| w[1] < w[0]) {
                return Err(err(
                    &format!("frames[{}].time", k + 1),
                    "times decrease".into(),
                ));
            }
        } else {
            times = (0..frames.len()).map(|i| i as f64 / fps).collect();
        }
        let head_pose = match object.get(HEAD_POSE) {
            None => None,
            Some(value) => Some(parse_head_pose(value, frames.len(), &err)?),
        };
        Ok(Self {
            path: path.to_path_buf(),
            names,
            times,
            weights,
            head_pose,
        })
    }

    /// LAM's head rotation of `frame` (axis-angle, radians, world axes), if the track has one.
    #[must_use]
    pub fn head_pose(&self, frame: usize) -> Option<DVec3> {
        self.head_pose.as_ref()?.get(frame).copied()
    }

    /// Whether the track carries LAM's `head_pose`.
    #[must_use]
    pub fn has_head_pose(&self) -> bool {
        self.head_pose.is_some()
    }

    /// The file this track was read from.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Channel names.
    #[must_use]
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Number of frames.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.times.len()
    }

    /// Time of `frame` in seconds.
    #[must_use]
    pub fn time(&self, frame: usize) -> Option<f64> {
        self.times.get(frame).copied()
    }

    /// Weights of `frame`, one per name.
    #[must_use]
    pub fn weights(&self, frame: usize) -> Option<&[f64]> {
        let n = self.names.len();
        self.weights.get(frame * n..(frame + 1) * n)
    }

    /// For each of `targets`, the channel that drives it (see the module docs).
    #[must_use]
    pub fn map_targets(&self, targets: &[String]) -> Vec<Option<usize>> {
        let exact: HashMap<&str, usize> = self
            .names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.as_str(), i))
            .collect();
        let mut canonical: HashMap<String, usize> = HashMap::new();
        for (i, n) in self.names.iter().enumerate() {
            canonical.entry(canonical_target_name(n)).or_insert(i);
        }
        targets
            .iter()
            .map(|t| {
                exact
                    .get(t.as_str())
                    .copied()
                    .or_else(|| canonical.get(&canonical_target_name(t)).copied())
            })
            .collect()
    }
}

/// A neutral mesh and named targets with its topology.
#[derive(Clone, Debug)]
pub struct BlendshapeSet {
    neutral: TriMesh,
    names: Vec<String>,
    targets: Vec<Vec<DVec3>>,
}

impl BlendshapeSet {
    /// Reads the neutral mesh and the target meshes (OBJ/PLY); target names are the file
    /// stems (`jawOpen.obj` → `jawOpen`).
    ///
    /// # Errors
    /// Read errors naming the file; [`AnimationError::TopologyMismatch`] naming the target
    /// whose vertex count or triangles differ from the neutral.
    pub fn from_files(neutral: &Path, targets: &[PathBuf]) -> Result<Self, AnimationError> {
        let base = read_mesh(neutral)?;
        let read: Vec<Result<(String, Vec<DVec3>), AnimationError>> = targets
            .par_iter()
            .map(|path| {
                let mesh = read_mesh(path)?;
                check_topology(&mesh, &base, path, neutral)?;
                let name = path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                Ok((name, mesh.into_parts().0))
            })
            .collect();
        let mut names = Vec::new();
        let mut positions = Vec::new();
        for r in read {
            let (n, p) = r?;
            names.push(n);
            positions.push(p);
        }
        Ok(Self {
            neutral: base,
            names,
            targets: positions,
        })
    }

    /// A set from meshes in memory; `targets` are `(name, positions)` with one position per
    /// neutral vertex.
    ///
    /// # Errors
    /// [`AnimationError::TopologyMismatch`] (the target named as the path) when a target's
    /// vertex count differs; [`AnimationError::Invalid`] for non-finite positions.
    pub fn from_meshes(
        neutral: TriMesh,
        targets: Vec<(String, Vec<DVec3>)>,
    ) -> Result<Self, AnimationError> {
        let mut names = Vec::new();
        let mut positions = Vec::new();
        for (name, p) in targets {
            if p.len() != neutral.vertex_count() {
                return Err(AnimationError::TopologyMismatch {
                    path: PathBuf::from(&name),
                    reference: PathBuf::from("neutral"),
                    message: format!("{} vertices instead of {}", p.len(), neutral.vertex_count()),
                });
            }
            if let Some(v) = p.iter().position(|q| !q.is_finite()) {
                return Err(crate::mesh::MeshError::NonFinitePosition { vertex: v }.into());
            }
            names.push(name);
            positions.push(p);
        }
        Ok(Self {
            neutral,
            names,
            targets: positions,
        })
    }

    /// The neutral mesh.
    #[must_use]
    pub fn neutral(&self) -> &TriMesh {
        &self.neutral
    }

    /// Target names, in order.
    #[must_use]
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// `neutral + Σ wᵢ · (targetᵢ − neutral)`, one weight per target.
    ///
    /// # Errors
    /// [`AnimationError::WeightCount`] when `weights` does not have one value per target.
    pub fn evaluate(&self, weights: &[f64]) -> Result<Vec<DVec3>, AnimationError> {
        if weights.len() != self.targets.len() {
            return Err(AnimationError::WeightCount {
                expected: self.targets.len(),
                found: weights.len(),
            });
        }
        let active: Vec<(f64, &Vec<DVec3>)> = weights
            .iter()
            .zip(&self.targets)
            .filter(|(w, _)| **w != 0.0)
            .map(|(w, t)| (*w, t))
            .collect();
        let neutral = self.neutral.positions();
        Ok((0..neutral.len())
            .into_par_iter()
            .map(|v| {
                let n = neutral[v];
                let mut acc = DVec3::ZERO;
                for (w, t) in &active {
                    acc += *w * (t[v] - n);
                }
                n + acc
            })
            .collect())
    }
}

/// A [`BlendshapeSet`] played by a [`WeightsTrack`].
#[derive(Clone, Debug)]
pub struct BlendshapeAnimation {
    set: BlendshapeSet,
    track: WeightsTrack,
    mapping: Vec<Option<usize>>,
}

/// Refuses a mapping where no target found a channel (most likely the wrong file).
fn require_match(
    mapping: &[Option<usize>],
    track: &WeightsTrack,
    targets: &[String],
) -> Result<(), AnimationError> {
    if mapping.iter().all(Option::is_none) {
        return Err(AnimationError::NoMatchingTargets {
            path: track.path.clone(),
            channels: track.names.len(),
            targets: targets.join(", "),
        });
    }
    Ok(())
}

impl BlendshapeAnimation {
    /// Pairs targets with channels by name.
    ///
    /// # Errors
    /// [`AnimationError::NoMatchingTargets`] when no target has a channel.
    pub fn new(set: BlendshapeSet, track: WeightsTrack) -> Result<Self, AnimationError> {
        let mapping = track.map_targets(&set.names);
        require_match(&mapping, &track, &set.names)?;
        Ok(Self {
            set,
            track,
            mapping,
        })
    }

    /// The blendshape set.
    #[must_use]
    pub fn set(&self) -> &BlendshapeSet {
        &self.set
    }

    /// Targets that no channel drives (they stay at weight 0).
    #[must_use]
    pub fn unmatched_targets(&self) -> Vec<&str> {
        self.set
            .names
            .iter()
            .zip(&self.mapping)
            .filter(|(_, m)| m.is_none())
            .map(|(n, _)| n.as_str())
            .collect()
    }

    /// The weight of every target at `frame`.
    fn target_weights(&self, frame: usize) -> Result<Vec<f64>, AnimationError> {
        let w = self
            .track
            .weights(frame)
            .ok_or(AnimationError::FrameOutOfRange {
                frame,
                count: self.track.frame_count(),
            })?;
        Ok(self
            .mapping
            .iter()
            .map(|m| m.map_or(0.0, |c| w[c]))
            .collect())
    }
}

fn unused<'a>(
    track: &'a WeightsTrack,
    used: impl Iterator<Item = &'a Option<usize>>,
) -> Vec<&'a str> {
    let mut is_used = vec![false; track.names.len()];
    used.flatten().for_each(|&c| is_used[c] = true);
    track
        .names
        .iter()
        .zip(is_used)
        .filter(|(_, u)| !u)
        .map(|(n, _)| n.as_str())
        .collect()
}

impl AnimatedTemplate for BlendshapeAnimation {
    fn frame_count(&self) -> usize {
        self.track.frame_count()
    }

    fn frame_time(&self, frame: usize) -> Option<f64> {
        self.track.time(frame)
    }

    fn topology(&self) -> &[[u32; 3]] {
        self.set.neutral.triangles()
    }

    fn rest(&self) -> &TriMesh {
        &self.set.neutral
    }

    fn frame(&self, frame: usize) -> Result<Vec<DVec3>, AnimationError> {
        self.set.evaluate(&self.target_weights(frame)?)
    }

    fn unused_channels(&self) -> Vec<&str> {
        let mut list = unused(&self.track, self.mapping.iter());
        if self.track.has_head_pose() {
            // OBJ/PLY blendshapes have no joint to turn.
            list.push(HEAD_POSE);
        }
        list
    }
}

/// glTF morph targets (named by `extras.targetNames`) played by a [`WeightsTrack`]; the
/// template's own clip, if any, is evaluated at the track's frame times too.
#[derive(Clone, Debug)]
pub struct GltfMorphAnimation {
    template: GltfTemplate,
    track: WeightsTrack,
    /// The joint `head_pose` turns ([`HEAD_JOINT`]), when the track has a head pose and the
    /// template such a joint.
    head: Option<usize>,
    /// Per mesh, per target: the driving channel.
    mapping: Vec<Vec<Option<usize>>>,
}

impl GltfMorphAnimation {
    /// Pairs every mesh's morph targets with the track's channels by name.
    ///
    /// # Errors
    /// [`AnimationError::NoMatchingTargets`] when no target of any mesh has a channel.
    pub fn new(template: GltfTemplate, track: WeightsTrack) -> Result<Self, AnimationError> {
        let names: Vec<Vec<String>> = template
            .morph_target_names()
            .into_iter()
            .map(<[String]>::to_vec)
            .collect();
        let mapping: Vec<Vec<Option<usize>>> = names.iter().map(|n| track.map_targets(n)).collect();
        let flat: Vec<Option<usize>> = mapping.iter().flatten().copied().collect();
        require_match(&flat, &track, &names.concat())?;
        let head = if track.has_head_pose() {
            template.joint_named(HEAD_JOINT)
        } else {
            None
        };
        Ok(Self {
            template,
            track,
            head,
            mapping,
        })
    }

    /// Hands frame `frame`'s clip time, its weights by (mesh, morph target) and the head turn
    /// (with a head pose and a head joint) to `f`, the way the frame's mesh and its rig pose
    /// are both made.
    ///
    /// # Errors
    /// [`AnimationError::FrameOutOfRange`] past the track.
    fn drive<R>(
        &self,
        frame: usize,
        f: impl FnOnce(f64, &dyn Fn(usize, usize) -> Option<f64>, Option<JointTurn>) -> R,
    ) -> Result<R, AnimationError> {
        let (Some(w), Some(t)) = (self.track.weights(frame), self.track.time(frame)) else {
            return Err(AnimationError::FrameOutOfRange {
                frame,
                count: self.track.frame_count(),
            });
        };
        let lookup = |mesh: usize, target: usize| -> Option<f64> {
            self.mapping
                .get(mesh)?
                .get(target)
                .copied()
                .flatten()
                .map(|c| w[c])
        };
        let turn = self
            .head
            .zip(self.track.head_pose(frame))
            .map(|(node, r)| JointTurn {
                node,
                rotation: DQuat::from_scaled_axis(r),
            });
        Ok(f(self.template.clip_time(t), &lookup, turn))
    }

    /// The glTF template.
    #[must_use]
    pub fn template(&self) -> &GltfTemplate {
        &self.template
    }
}

impl AnimatedTemplate for GltfMorphAnimation {
    fn frame_count(&self) -> usize {
        self.track.frame_count()
    }

    fn unused_channels(&self) -> Vec<&str> {
        let mut list = unused(&self.track, self.mapping.iter().flatten());
        if self.track.has_head_pose() && self.head.is_none() {
            list.push(HEAD_POSE);
        }
        list.extend(self.template.unused_channels());
        list
    }

    fn frame_time(&self, frame: usize) -> Option<f64> {
        self.track.time(frame)
    }

    fn topology(&self) -> &[[u32; 3]] {
        self.template.topology()
    }

    fn rest(&self) -> &TriMesh {
        self.template.rest()
    }

    fn frame(&self, frame: usize) -> Result<Vec<DVec3>, AnimationError> {
        self.drive(frame, |t, lookup, turn| {
            self.template.evaluate_turned(Some(t), lookup, turn)
        })?
    }

    fn gltf_rig(&self) -> Option<&GltfTemplate> {
        Some(&self.template)
    }

    fn frame_rig_pose(&self, frame: usize) -> Option<Result<RigPose, AnimationError>> {
        Some(self.drive(frame, |t, lookup, turn| {
            self.template.rig_pose(Some(t), lookup, turn)
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_names() {
        assert_eq!(canonical_target_name("eyeBlink_L"), "eyeblinkleft");
        assert_eq!(canonical_target_name("eyeBlinkLeft"), "eyeblinkleft");
        assert_eq!(canonical_target_name("mouthSmile_R"), "mouthsmileright");
        assert_eq!(canonical_target_name("jawOpen"), "jawopen");
    }

    #[test]
    fn non_finite_tokens_become_null_outside_strings() {
        let s = nulls_for_non_finite(r#"{"names": ["NaN"], "w": [NaN, -Infinity, Infinity, 1]}"#);
        assert_eq!(s, r#"{"names": ["NaN"], "w": [null, null, null, 1]}"#);
    }
}
