//! The scene a glTF template keeps: node transforms, meshes with morph targets and skin
//! influences, skins, the selected clip, and the world matrices of a node hierarchy.

use std::path::PathBuf;

use glam::{DMat4, DQuat, DVec3};

use crate::animation::sampler::Sampler;
use crate::mesh::TriMesh;

/// Slack (in frames) when counting the frames of a clip, so that a clip end that falls on a
/// frame boundary (2.0 s at 30 fps) is not lost to rounding.
pub(super) const FRAME_TIME_SLACK: f64 = 1e-9;

/// Which animation of a glTF file to play.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Clip {
    /// No animation: the scene as stored (one frame).
    None,
    /// The animation with this index.
    Index(usize),
    /// The first animation with this name.
    Name(String),
    /// The first animation when the file has one, else the scene as stored.
    FirstIfAny,
}

/// The local transform of a node.
#[derive(Clone, Copy, Debug)]
pub(super) struct Trs {
    pub(super) translation: DVec3,
    pub(super) rotation: DQuat,
    pub(super) scale: DVec3,
}

impl Trs {
    pub(super) fn matrix(&self) -> DMat4 {
        DMat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

#[derive(Clone, Copy, Debug)]
pub(super) enum Local {
    Trs(Trs),
    Matrix(DMat4),
}

#[derive(Clone, Debug)]
pub(super) struct NodeData {
    pub(super) name: Option<String>,
    pub(super) local: Local,
    pub(super) mesh: Option<usize>,
    pub(super) skin: Option<usize>,
    pub(super) weights: Option<Vec<f64>>,
}

/// Per-vertex joint influences in CSR form, weights normalised to sum 1.
#[derive(Clone, Debug)]
pub(super) struct Influences {
    pub(super) offsets: Vec<u32>,
    pub(super) joints: Vec<u32>,
    pub(super) weights: Vec<f64>,
}

#[derive(Clone, Debug)]
pub(super) struct PrimData {
    pub(super) positions: Vec<DVec3>,
    /// Per morph target, the non-zero deltas as `(vertex, delta)` in vertex order (face
    /// targets move a small part of a head: LAM's average 3.7k of 20k vertices).
    pub(super) targets: Vec<Vec<(u32, DVec3)>>,
    pub(super) influences: Option<Influences>,
    pub(super) triangles: Vec<[u32; 3]>,
}

#[derive(Clone, Debug)]
pub(super) struct MeshData {
    pub(super) prims: Vec<PrimData>,
    pub(super) weights: Vec<f64>,
    pub(super) target_count: usize,
    pub(super) target_names: Vec<String>,
}

#[derive(Clone, Debug)]
pub(super) struct SkinData {
    pub(super) joints: Vec<usize>,
    pub(super) inverse_bind: Vec<DMat4>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Property {
    Translation,
    Rotation,
    Scale,
    Weights,
}

#[derive(Clone, Debug)]
pub(super) struct Channel {
    pub(super) node: usize,
    pub(super) property: Property,
    pub(super) sampler: Sampler,
}

#[derive(Clone, Debug)]
pub(super) struct ClipData {
    pub(super) index: usize,
    pub(super) name: Option<String>,
    pub(super) channels: Vec<Channel>,
    pub(super) end: f64,
}

/// A rotation of one joint on top of a pose: `rotation` in world axes about the joint's own
/// origin, so everything the joint carries (its children, the vertices it skins) turns with it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointTurn {
    /// The joint's node index.
    pub node: usize,
    /// The rotation, in world axes.
    pub rotation: DQuat,
}

/// A glTF scene with (optionally) one animation clip: evaluates world-space vertex positions
/// at any time and, sampled at a fixed rate, is an [`AnimatedTemplate`](crate::animation::AnimatedTemplate).
#[derive(Clone, Debug)]
pub struct GltfTemplate {
    pub(super) path: PathBuf,
    pub(super) nodes: Vec<NodeData>,
    /// Every node, parents before children (for world matrices).
    pub(super) order: Vec<usize>,
    pub(super) parents: Vec<Option<usize>>,
    /// Mesh nodes in output order, with the index of their first vertex.
    pub(super) instances: Vec<(usize, usize)>,
    pub(super) meshes: Vec<MeshData>,
    pub(super) skins: Vec<SkinData>,
    pub(super) clip: Option<ClipData>,
    pub(super) clip_names: Vec<Option<String>>,
    pub(super) fps: f64,
    pub(super) rest: TriMesh,
    /// Joints of a retargeted clip ([`GltfTemplate::retarget`]) that no node of this template
    /// is named after (their channels are dropped).
    pub(super) unmatched_joints: Vec<String>,
    /// Whether the clip came from another file ([`GltfTemplate::retarget`]).
    pub(super) retargeted: bool,
}

/// World matrices of every node from local transforms, `order` listing parents first.
pub(super) fn world_matrices(
    locals: &[Local],
    order: &[usize],
    parents: &[Option<usize>],
) -> Vec<DMat4> {
    let mut world = vec![DMat4::IDENTITY; locals.len()];
    for &i in order {
        let local = match locals[i] {
            Local::Trs(trs) => trs.matrix(),
            Local::Matrix(m) => m,
        };
        world[i] = match parents[i] {
            Some(p) => world[p] * local,
            None => local,
        };
    }
    world
}
