//! Evaluating a glTF template: clip time, node poses (with joint turns and retargeting),
//! morphs and skinning to world-space vertices, and the [`AnimatedTemplate`] frames.

use std::collections::HashMap;
use std::path::Path;

use glam::{DMat4, DQuat, DVec3};
use rayon::prelude::*;

use super::model::{
    Channel, ClipData, FRAME_TIME_SLACK, GltfTemplate, JointTurn, Local, Property, Trs,
    world_matrices,
};
use crate::animation::error::AnimationError;
use crate::animation::template::{AnimatedTemplate, frame_rate_or};
use crate::mesh::TriMesh;

impl GltfTemplate {
    /// Sets the rate at which frames are sampled (frames per second, finite and > 0;
    /// other values keep the current rate).
    #[must_use]
    pub fn with_fps(mut self, fps: f64) -> Self {
        self.fps = frame_rate_or(fps, self.fps);
        self
    }

    /// The time of `frame`, or [`AnimationError::FrameOutOfRange`] past the last frame.
    pub(super) fn checked_frame_time(&self, frame: usize) -> Result<f64, AnimationError> {
        self.frame_time(frame)
            .ok_or(AnimationError::FrameOutOfRange {
                frame,
                count: self.frame_count(),
            })
    }

    /// The file this template was read from.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Index and name of the selected clip, if any.
    #[must_use]
    pub fn clip(&self) -> Option<(usize, Option<&str>)> {
        self.clip.as_ref().map(|c| (c.index, c.name.as_deref()))
    }

    /// Names of every animation in the file (`None` for unnamed ones), by index.
    #[must_use]
    pub fn clip_names(&self) -> &[Option<String>] {
        &self.clip_names
    }

    /// Length of the selected clip: the last key time over its channels (0 without a clip).
    #[must_use]
    pub fn duration(&self) -> f64 {
        self.clip.as_ref().map_or(0.0, |c| c.end)
    }

    /// Morph target names of every mesh (from `extras.targetNames`), by mesh index.
    #[must_use]
    pub fn morph_target_names(&self) -> Vec<&[String]> {
        self.meshes
            .iter()
            .map(|m| m.target_names.as_slice())
            .collect()
    }

    /// World-space vertex positions with the selected clip evaluated at time `t` (seconds;
    /// before the first key the first value holds, after the last the last).
    ///
    /// # Errors
    /// [`AnimationError::BadTime`] when `t` is not finite.
    pub fn evaluate_at(&self, t: f64) -> Result<Vec<DVec3>, AnimationError> {
        if !t.is_finite() {
            return Err(AnimationError::BadTime { time: t });
        }
        self.evaluate_pose(Some(t), None, None)
    }

    /// Like [`Self::evaluate_at`] (or the stored scene when `t` is `None`), with the morph
    /// weights of every mesh replaced by `weights(mesh, target)` wherever it returns `Some`.
    ///
    /// # Errors
    /// [`AnimationError::BadTime`] when `t` is not finite.
    pub fn evaluate_with_weights(
        &self,
        t: Option<f64>,
        weights: &dyn Fn(usize, usize) -> Option<f64>,
    ) -> Result<Vec<DVec3>, AnimationError> {
        self.evaluate_turned(t, weights, None)
    }

    /// [`Self::evaluate_with_weights`] with one joint turned on top of the pose (a head
    /// rotation of a face track).
    ///
    /// # Errors
    /// [`AnimationError::BadTime`] when `t` is not finite.
    pub fn evaluate_turned(
        &self,
        t: Option<f64>,
        weights: &dyn Fn(usize, usize) -> Option<f64>,
        turn: Option<JointTurn>,
    ) -> Result<Vec<DVec3>, AnimationError> {
        if let Some(t) = t.filter(|t| !t.is_finite()) {
            return Err(AnimationError::BadTime { time: t });
        }
        self.evaluate_pose(t, Some(weights), turn)
    }

    /// This template posed by `source`'s clip instead of its own: every channel of the clip
    /// goes to this template's node with the same name as the channel's node in `source`
    /// (rotation, translation and scale copied as they are, so both rigs must share their
    /// joints' rest frames, as LAM's `animation.glb` and `skin.glb` do). Channels of nodes
    /// without a namesake are dropped and listed by [`AnimatedTemplate::unused_channels`].
    ///
    /// # Errors
    /// [`AnimationError::Retarget`] when `source` has no clip, or none of its channels' nodes has
    /// a namesake here.
    pub fn retarget(mut self, source: &Self) -> Result<Self, AnimationError> {
        let fail = |message: String| AnimationError::Retarget {
            path: source.path.clone(),
            message,
        };
        let Some(clip) = &source.clip else {
            return Err(fail("has no animation clip to retarget".into()));
        };
        let mut by_name: HashMap<&str, usize> = HashMap::new();
        for (i, n) in self.nodes.iter().enumerate().rev() {
            if let Some(name) = &n.name {
                by_name.insert(name.as_str(), i);
            }
        }
        let mut channels = Vec::new();
        let mut unmatched: Vec<String> = Vec::new();
        for ch in &clip.channels {
            let name = source.nodes[ch.node].name.as_deref().unwrap_or("");
            match by_name.get(name) {
                Some(&node) => channels.push(Channel {
                    node,
                    property: ch.property,
                    sampler: ch.sampler.clone(),
                }),
                None => {
                    let label = if name.is_empty() {
                        format!("node {}", ch.node)
                    } else {
                        name.to_owned()
                    };
                    if !unmatched.contains(&label) {
                        unmatched.push(label);
                    }
                }
            }
        }
        if channels.is_empty() {
            return Err(fail(format!(
                "none of the clip's {} animated nodes is named like a node of {}",
                unmatched.len(),
                self.path.display()
            )));
        }
        self.clip = Some(ClipData {
            index: clip.index,
            name: clip.name.clone(),
            channels,
            end: clip.end,
        });
        self.clip_names.clone_from(&source.clip_names);
        self.unmatched_joints = unmatched
            .into_iter()
            .map(|n| format!("joint:{n}"))
            .collect();
        self.retargeted = true;
        Ok(self)
    }

    /// Where a track's time `t` falls in the clip: `t` itself, or for a retargeted clip
    /// ([`GltfTemplate::retarget`]) `t` modulo the clip's length, so that a short clip (an idle
    /// loop) plays on under a long expression track.
    #[must_use]
    pub fn clip_time(&self, t: f64) -> f64 {
        match &self.clip {
            Some(c) if self.retargeted => {
                if c.end > 0.0 {
                    t.rem_euclid(c.end)
                } else {
                    0.0
                }
            }
            _ => t,
        }
    }

    /// The first node named `name` (compared without case) that is a joint of a skin, if any.
    #[must_use]
    pub fn joint_named(&self, name: &str) -> Option<usize> {
        self.skins
            .iter()
            .flat_map(|s| s.joints.iter().copied())
            .find(|&j| {
                self.nodes
                    .get(j)
                    .and_then(|n| n.name.as_deref())
                    .is_some_and(|n| n.eq_ignore_ascii_case(name))
            })
    }

    /// World matrices of every node and the animated morph weights (by node) at time `t`
    /// (`None`: the stored scene).
    pub(super) fn pose(
        &self,
        t: Option<f64>,
        turn: Option<JointTurn>,
    ) -> (Vec<DMat4>, HashMap<usize, Vec<f64>>) {
        let (locals, anim_weights) = self.pose_locals(t, turn);
        (
            world_matrices(&locals, &self.order, &self.parents),
            anim_weights,
        )
    }

    /// Local transforms of every node and the animated morph weights (by node) at time `t`
    /// (`None`: the stored scene), with `turn` applied.
    pub(super) fn pose_locals(
        &self,
        t: Option<f64>,
        turn: Option<JointTurn>,
    ) -> (Vec<Local>, HashMap<usize, Vec<f64>>) {
        // Local transforms (matrix nodes that are animated are decomposed first).
        let mut locals: Vec<Local> = self.nodes.iter().map(|n| n.local).collect();
        let mut anim_weights: HashMap<usize, Vec<f64>> = HashMap::new();
        if let (Some(t), Some(clip)) = (t, &self.clip) {
            let mut buf = Vec::new();
            for ch in &clip.channels {
                buf.resize(ch.sampler.width(), 0.0);
                ch.sampler.sample(t, &mut buf);
                if ch.property == Property::Weights {
                    anim_weights.insert(ch.node, buf.clone());
                    continue;
                }
                let mut trs = match locals[ch.node] {
                    Local::Trs(trs) => trs,
                    Local::Matrix(m) => {
                        let (scale, rotation, translation) = m.to_scale_rotation_translation();
                        Trs {
                            translation,
                            rotation,
                            scale,
                        }
                    }
                };
                match ch.property {
                    Property::Translation => trs.translation = DVec3::new(buf[0], buf[1], buf[2]),
                    Property::Scale => trs.scale = DVec3::new(buf[0], buf[1], buf[2]),
                    Property::Rotation => {
                        trs.rotation = DQuat::from_xyzw(buf[0], buf[1], buf[2], buf[3])
                    }
                    Property::Weights => {}
                }
                locals[ch.node] = Local::Trs(trs);
            }
        }
        if let Some(turn) = turn.filter(|j| j.node < locals.len()) {
            // A rotation in world axes about the joint's own origin: with the parent's world
            // rotation P, the local rotation becomes (P⁻¹ R P) · local.
            let parents = world_matrices(&locals, &self.order, &self.parents);
            let p = self.parents[turn.node].map_or(DQuat::IDENTITY, |q| {
                let (_, r, _) = parents[q].to_scale_rotation_translation();
                r
            });
            let local = match locals[turn.node] {
                Local::Trs(trs) => trs.matrix(),
                Local::Matrix(m) => m,
            };
            let spin = DMat4::from_quat((p.inverse() * turn.rotation * p).normalize());
            // Turned about the joint's origin (the local translation, in the parent's frame).
            let translation = local.w_axis.truncate();
            locals[turn.node] = Local::Matrix(
                DMat4::from_translation(translation)
                    * spin
                    * DMat4::from_translation(-translation)
                    * local,
            );
        }
        (locals, anim_weights)
    }

    pub(super) fn evaluate_pose(
        &self,
        t: Option<f64>,
        override_weights: Option<&dyn Fn(usize, usize) -> Option<f64>>,
        turn: Option<JointTurn>,
    ) -> Result<Vec<DVec3>, AnimationError> {
        let (world, anim_weights) = self.pose(t, turn);
        let mut out = Vec::with_capacity(self.rest.vertex_count());
        for &(node, _) in &self.instances {
            let data = &self.nodes[node];
            let Some(m) = data.mesh else { continue };
            let mesh = &self.meshes[m];
            let mut weights = anim_weights
                .get(&node)
                .cloned()
                .or_else(|| data.weights.clone())
                .unwrap_or_else(|| mesh.weights.clone());
            if let Some(f) = override_weights {
                for (k, w) in weights.iter_mut().enumerate() {
                    if let Some(v) = f(m, k) {
                        *w = v;
                    }
                }
            }
            let joint_mats: Option<Vec<DMat4>> = data.skin.map(|s| {
                let skin = &self.skins[s];
                skin.joints
                    .iter()
                    .zip(&skin.inverse_bind)
                    .map(|(&j, ibm)| world[j] * *ibm)
                    .collect()
            });
            let node_world = world[node];
            for prim in &mesh.prims {
                // Morph first (a sparse scatter in target order), then skin in parallel.
                let mut morphed = prim.positions.clone();
                for (w, target) in weights.iter().zip(&prim.targets) {
                    if *w != 0.0 {
                        for &(v, d) in target {
                            morphed[v as usize] += *w * d;
                        }
                    }
                }
                let positions: Vec<DVec3> = (0..morphed.len())
                    .into_par_iter()
                    .map(|v| {
                        let p = morphed[v];
                        match (&joint_mats, &prim.influences) {
                            (Some(mats), Some(infl)) => {
                                let (a, b) =
                                    (infl.offsets[v] as usize, infl.offsets[v + 1] as usize);
                                if a == b {
                                    node_world.transform_point3(p)
                                } else {
                                    let mut acc = DVec3::ZERO;
                                    for k in a..b {
                                        acc += infl.weights[k]
                                            * mats[infl.joints[k] as usize].transform_point3(p);
                                    }
                                    acc
                                }
                            }
                            _ => node_world.transform_point3(p),
                        }
                    })
                    .collect();
                out.extend(positions);
            }
        }
        Ok(out)
    }
}

impl AnimatedTemplate for GltfTemplate {
    fn unused_channels(&self) -> Vec<&str> {
        self.unmatched_joints.iter().map(String::as_str).collect()
    }

    fn frame_count(&self) -> usize {
        match &self.clip {
            // Frames at i / fps up to the clip end.
            Some(c) => (c.end * self.fps + FRAME_TIME_SLACK).floor() as usize + 1,
            None => 1,
        }
    }

    fn frame_time(&self, frame: usize) -> Option<f64> {
        (frame < self.frame_count()).then(|| frame as f64 / self.fps)
    }

    fn topology(&self) -> &[[u32; 3]] {
        self.rest.triangles()
    }

    fn rest(&self) -> &TriMesh {
        &self.rest
    }

    fn frame(&self, frame: usize) -> Result<Vec<DVec3>, AnimationError> {
        let t = self.checked_frame_time(frame)?;
        self.evaluate_pose(Some(t), None, None)
    }

    fn gltf_rig(&self) -> Option<&GltfTemplate> {
        Some(self)
    }

    fn frame_rig_pose(&self, frame: usize) -> Option<Result<super::RigPose, AnimationError>> {
        Some(
            self.checked_frame_time(frame)
                .map(|t| self.rig_pose(Some(t), &|_, _| None, None)),
        )
    }
}
