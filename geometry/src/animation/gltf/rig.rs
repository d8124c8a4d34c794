//! A glTF template's rig as data, for moving it onto another mesh: the skeleton (every node's
//! rest transform), one skin over all mesh instances, each template vertex's bind position
//! and joint weights, the morph targets as bind-space deltas, and the pose (node transforms and
//! morph weights) at any time.
//!
//! # Bind space
//! Vertices are given in the *bind world*: where the stored scene puts them
//! (`Σ wᵢ world(jointᵢ) · inverseBindᵢ · p`, the pose of
//! [`AnimatedTemplate::rest`](crate::animation::AnimatedTemplate::rest) without morph weights).
//! The rig's inverse bind matrices are then `world(joint at rest)⁻¹`, so a glTF client places a
//! vertex at time `t` at `Σ wᵢ world(jointᵢ, t) · world(jointᵢ, rest)⁻¹ · x`. This equals the
//! template's own skinning wherever the joints influencing a vertex agree at rest
//! (`world(j) · inverseBind_j` equal for all of them, as in a file stored in its bind pose, LAM's
//! `skin.glb` among them); elsewhere it is the linear-blend approximation of it. A vertex of an
//! unskinned mesh instance has its instance node as its one joint, so node animation moves it
//! exactly. Morph deltas are turned into the bind world by the linear part of the vertex's
//! blended rest matrix.

use glam::{DMat4, DQuat, DVec3};

use super::model::{GltfTemplate, JointTurn, Local};
use crate::animation::error::AnimationError;

/// A node of the skeleton: its name, parent and rest transform.
#[derive(Clone, Debug, PartialEq)]
pub struct RigNode {
    /// The node's name in the template.
    pub name: Option<String>,
    /// The parent node.
    pub parent: Option<usize>,
    /// Rest translation, rotation and scale.
    pub trs: (DVec3, DQuat, DVec3),
}

/// One morph target of one mesh instance, in bind-world deltas.
#[derive(Clone, Debug, PartialEq)]
pub struct RigTarget {
    /// `extras.targetNames` of its mesh, else `target_<k>`.
    pub name: String,
    /// The non-zero deltas as `(template vertex, delta)`, in vertex order.
    pub deltas: Vec<(u32, DVec3)>,
}

/// A template's rig (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct TemplateRig {
    /// Every node of the template, by index.
    pub nodes: Vec<RigNode>,
    /// The node of each joint of the rig's skin.
    pub joints: Vec<usize>,
    /// Each joint's inverse bind matrix, `world(joint at rest)⁻¹`.
    pub inverse_bind: Vec<DMat4>,
    /// Each template vertex's bind-world position.
    pub positions: Vec<DVec3>,
    /// Row `v` is `offsets[v]..offsets[v + 1]` of `influences` (vertex count + 1 offsets).
    pub offsets: Vec<u32>,
    /// `(joint index in `joints`, weight)`, the weights of a vertex summing to 1.
    pub influences: Vec<(u32, f64)>,
    /// Every morph target of every mesh instance (instances in vertex order).
    pub targets: Vec<RigTarget>,
}

impl TemplateRig {
    /// Influences of template vertex `v` (empty past the end).
    pub fn influences_of(&self, v: usize) -> &[(u32, f64)] {
        match (self.offsets.get(v), self.offsets.get(v + 1)) {
            (Some(&a), Some(&b)) => self.influences.get(a as usize..b as usize).unwrap_or(&[]),
            _ => &[],
        }
    }
}

/// The pose of a rig at one time: every node's local transform and every target's weight.
#[derive(Clone, Debug, PartialEq)]
pub struct RigPose {
    /// Local translation, rotation and scale of every node.
    pub locals: Vec<(DVec3, DQuat, DVec3)>,
    /// The weight of every [`TemplateRig::targets`] entry.
    pub weights: Vec<f64>,
}

/// A local transform as translation, rotation and scale (a matrix decomposed).
fn trs(local: &Local) -> (DVec3, DQuat, DVec3) {
    match local {
        Local::Trs(t) => (t.translation, t.rotation, t.scale),
        Local::Matrix(m) => {
            let (s, r, t) = m.to_scale_rotation_translation();
            (t, r, s)
        }
    }
}

impl GltfTemplate {
    /// The template's rig (see the module docs).
    ///
    /// # Errors
    /// [`AnimationError::NoRig`] when no mesh instance is skinned and no mesh has morph
    /// targets, or a joint's rest matrix cannot be inverted.
    pub fn rig(&self) -> Result<TemplateRig, AnimationError> {
        let no_rig = |message: String| AnimationError::NoRig {
            path: self.path.clone(),
            message,
        };
        let has_targets = self.instances.iter().any(|&(node, _)| {
            self.nodes[node]
                .mesh
                .is_some_and(|m| self.meshes[m].target_count > 0)
        });
        if !self.is_skinned() && !has_targets {
            return Err(no_rig(
                "it has neither a skinned mesh (a glTF skin with JOINTS_0/WEIGHTS_0) nor morph \
                 targets"
                    .to_owned(),
            ));
        }
        let (world, _) = self.pose(None, None);
        let skinning = self.skinning();
        // The node of every palette entry (see `VertexSkinning`): each instance's node, then
        // its skin's joints.
        let mut entry_node = Vec::with_capacity(skinning.palette_len);
        for &(node, _) in &self.instances {
            entry_node.push(node);
            if let Some(s) = self.nodes[node].skin {
                entry_node.extend_from_slice(&self.skins[s].joints);
            }
        }
        let palette = self
            .palette_at(None)
            .map_err(|e| no_rig(format!("the rest pose: {e}")))?;
        let mut joint_of_node = vec![u32::MAX; self.nodes.len()];
        let mut joints = Vec::new();
        let mut offsets = Vec::with_capacity(skinning.offsets.len());
        offsets.push(0u32);
        let mut influences = Vec::with_capacity(skinning.entries.len());
        let mut positions = Vec::with_capacity(skinning.base_positions.len());
        let mut linear = Vec::with_capacity(skinning.base_positions.len());
        for (v, &p) in skinning.base_positions.iter().enumerate() {
            let mut blended = DMat4::ZERO;
            for (e, w) in skinning.influences(v) {
                let node = entry_node[e];
                if joint_of_node[node] == u32::MAX {
                    joint_of_node[node] = joints.len() as u32;
                    joints.push(node);
                }
                blended += palette[e] * w;
                influences.push((joint_of_node[node], w));
            }
            offsets.push(influences.len() as u32);
            positions.push(blended.transform_point3(p));
            linear.push(blended);
        }
        let inverse_bind = joints
            .iter()
            .map(|&j| {
                let inverse = world[j].inverse();
                if inverse.is_finite() && world[j].determinant().abs() > 1e-300 {
                    Ok(inverse)
                } else {
                    Err(no_rig(format!(
                        "joint node {j}'s rest matrix cannot be inverted"
                    )))
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut targets = Vec::new();
        for &(node, first) in &self.instances {
            let Some(m) = self.nodes[node].mesh else {
                continue;
            };
            let mesh = &self.meshes[m];
            for k in 0..mesh.target_count {
                let mut deltas = Vec::new();
                let mut start = first;
                for prim in &mesh.prims {
                    for &(v, d) in &prim.targets[k] {
                        let g = start + v as usize;
                        deltas.push((g as u32, linear[g].transform_vector3(d)));
                    }
                    start += prim.positions.len();
                }
                let name = mesh
                    .target_names
                    .get(k)
                    .cloned()
                    .unwrap_or_else(|| format!("target_{k}"));
                targets.push(RigTarget { name, deltas });
            }
        }
        let nodes = self
            .nodes
            .iter()
            .zip(&self.parents)
            .map(|(n, &parent)| RigNode {
                name: n.name.clone(),
                parent,
                trs: trs(&n.local),
            })
            .collect();
        Ok(TemplateRig {
            nodes,
            joints,
            inverse_bind,
            positions,
            offsets,
            influences,
            targets,
        })
    }

    /// The rig's pose with the clip at time `t` (`None`: the stored scene), the morph weights
    /// replaced by `weights(mesh, target)` wherever it returns `Some`, and `turn` applied: what
    /// [`GltfTemplate::evaluate_turned`] evaluates, as node transforms and target weights.
    #[must_use]
    pub fn rig_pose(
        &self,
        t: Option<f64>,
        weights: &dyn Fn(usize, usize) -> Option<f64>,
        turn: Option<JointTurn>,
    ) -> RigPose {
        let (locals, anim_weights) = self.pose_locals(t, turn);
        let mut out = Vec::new();
        for &(node, _) in &self.instances {
            let data = &self.nodes[node];
            let Some(m) = data.mesh else { continue };
            let mesh = &self.meshes[m];
            let mut w = anim_weights
                .get(&node)
                .cloned()
                .or_else(|| data.weights.clone())
                .unwrap_or_else(|| mesh.weights.clone());
            w.resize(mesh.target_count, 0.0);
            for (k, value) in w.iter_mut().enumerate() {
                if let Some(v) = weights(m, k) {
                    *value = v;
                }
            }
            out.extend(w);
        }
        RigPose {
            locals: locals.iter().map(trs).collect(),
            weights: out,
        }
    }
}
