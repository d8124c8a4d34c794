//! A rigged mesh as one `.glb`: a skinned mesh with morph targets, its skeleton, and one
//! animation of node transforms and morph weights. No vertex data per frame.
//!
//! # Contents
//! - **Nodes**: the skeleton as given ([`RigNode`]: every node of the template, rest
//!   translation/rotation/scale, the same parents), then one root node `rig` with the mesh and
//!   the skin (no transform of its own, as glTF wants of a skinned mesh).
//! - **Mesh**: one triangle primitive: `POSITION` (f32, bind space), `JOINTS_0` (u16) and
//!   `WEIGHTS_0` (f32, the four largest influences, summing to 1; unused slots joint 0 with
//!   weight 0), `indices` (u32), and one morph target per [`RiggedMesh::targets`] entry with
//!   `POSITION` deltas stored as a *sparse* accessor (only the vertices a target moves: a face
//!   target moves a small part of a head), named in `mesh.extras.targetNames`.
//! - **Skin**: the joints and their inverse bind matrices.
//! - **Animation** `rig`: one key per frame at the frame's time (the largest `f32` not above
//!   it, as the sequence writer keys its frames), LINEAR: a `weights` channel on `rig` (every
//!   target, every frame) and `translation`/`rotation`/`scale` channels for the nodes whose
//!   transform changes over the frames (rotations kept on one side of the quaternion sphere
//!   from key to key, so slerp between keys takes the short way).
//!
//! Everything is plain glTF 2.0 (no extension): every reader that plays skins and morph
//! targets plays it. The file is written atomically.

use std::path::Path;

use glam::{DMat4, DQuat, Vec3};
use serde_json::{Value, json};

use super::atomic::write_atomically;
use super::error::IoError;
use super::gltf_sequence::key_times;
use crate::animation::{RigNode, RigPose};

/// A node's local translation, rotation and scale.
type Trs = (glam::DVec3, DQuat, glam::DVec3);

/// A mesh with a skin and morph targets, in the bind space of its skeleton.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RiggedMesh {
    /// Bind-space positions.
    pub positions: Vec<Vec3>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Up to four joints per vertex (indices into the skin's joints).
    pub joints: Vec<[u16; 4]>,
    /// Their weights, summing to 1 (zero for unused slots).
    pub weights: Vec<[f32; 4]>,
    /// Morph targets: name and the non-zero position deltas `(vertex, delta)`, vertices
    /// increasing.
    pub targets: Vec<(String, Vec<(u32, Vec3)>)>,
}

/// The skeleton a [`RiggedMesh`] is skinned to and how it moves.
#[derive(Clone, Debug, PartialEq)]
pub struct RigAnimation<'a> {
    /// Every node, parents by index, with its rest transform.
    pub nodes: &'a [RigNode],
    /// The node of each joint of the skin.
    pub joints: &'a [usize],
    /// Each joint's inverse bind matrix.
    pub inverse_bind: &'a [DMat4],
    /// Each key's time in seconds (increasing).
    pub times: &'a [f64],
    /// Each key's pose: every node's local transform and every target's weight.
    pub poses: &'a [RigPose],
}

/// The binary buffer being laid out, with its views and accessors.
#[derive(Default)]
struct Buffer {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Buffer {
    /// A view of `data` (padded to 4 bytes), `target` an optional buffer-view target.
    fn view(&mut self, data: &[u8], target: Option<u32>) -> usize {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        let mut view =
            json!({"buffer": 0, "byteOffset": self.bytes.len(), "byteLength": data.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.bytes.extend_from_slice(data);
        self.views.push(view);
        self.views.len() - 1
    }

    fn accessor(&mut self, accessor: Value) -> usize {
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// An f32 accessor of `kind` (`VEC3`, ...) over `values` with `min`/`max` when `bounds`.
    fn floats(
        &mut self,
        values: &[f32],
        width: usize,
        kind: &str,
        target: Option<u32>,
        bounds: bool,
    ) -> usize {
        let view = self.view(&f32_bytes(values), target);
        let mut a = json!({"bufferView": view, "componentType": 5126,
            "count": values.len() / width, "type": kind});
        if bounds {
            let (min, max) = min_max(values, width);
            a["min"] = json!(min);
            a["max"] = json!(max);
        }
        self.accessor(a)
    }
}

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Per-component minimum and maximum of `values` read as rows of `width`.
fn min_max(values: &[f32], width: usize) -> (Vec<f32>, Vec<f32>) {
    let mut min = vec![f32::INFINITY; width];
    let mut max = vec![f32::NEG_INFINITY; width];
    for row in values.chunks_exact(width) {
        for (c, &v) in row.iter().enumerate() {
            min[c] = min[c].min(v);
            max[c] = max[c].max(v);
        }
    }
    if values.is_empty() {
        return (vec![0.0; width], vec![0.0; width]);
    }
    (min, max)
}

/// The error of an element that cannot be written.
fn bad(path: &Path, element: impl Into<String>, message: impl Into<String>) -> IoError {
    IoError::malformed(path, element, message)
}

/// Checks the mesh and the animation against each other and for finite values.
fn check(path: &Path, mesh: &RiggedMesh, rig: &RigAnimation<'_>) -> Result<(), IoError> {
    let n = mesh.positions.len();
    if n == 0 || mesh.triangles.is_empty() {
        return Err(bad(path, "mesh", "no vertices or no triangles to write"));
    }
    if mesh.joints.len() != n || mesh.weights.len() != n {
        return Err(bad(
            path,
            "skin",
            format!(
                "{} joint rows and {} weight rows for {n} vertices",
                mesh.joints.len(),
                mesh.weights.len()
            ),
        ));
    }
    if let Some(v) = mesh.positions.iter().position(|p| !p.is_finite()) {
        return Err(bad(path, format!("vertex {v}"), "position is not finite"));
    }
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= n))
    {
        return Err(bad(
            path,
            format!("triangle {t}"),
            format!("refers past the {n} vertices"),
        ));
    }
    if let Some(v) = mesh
        .joints
        .iter()
        .position(|j| j.iter().any(|&j| j as usize >= rig.joints.len()))
    {
        return Err(bad(
            path,
            format!("vertex {v}"),
            format!("joint past the skin's {}", rig.joints.len()),
        ));
    }
    if rig.joints.is_empty()
        || rig.joints.len() != rig.inverse_bind.len()
        || rig.joints.iter().any(|&j| j >= rig.nodes.len())
    {
        return Err(bad(
            path,
            "skin",
            "joints do not match the nodes or the inverse bind matrices",
        ));
    }
    for (k, (name, deltas)) in mesh.targets.iter().enumerate() {
        let element = || format!("morph target {k} ({name})");
        if deltas.windows(2).any(|w| w[1].0 <= w[0].0)
            || deltas.last().is_some_and(|d| d.0 as usize >= n)
        {
            return Err(bad(
                path,
                element(),
                "vertices are not increasing within the mesh",
            ));
        }
        if deltas.iter().any(|d| !d.1.is_finite()) {
            return Err(bad(path, element(), "a delta is not finite"));
        }
    }
    if rig.poses.len() != rig.times.len() {
        return Err(bad(
            path,
            "animation",
            format!("{} poses for {} times", rig.poses.len(), rig.times.len()),
        ));
    }
    for (f, pose) in rig.poses.iter().enumerate() {
        let finite = pose
            .locals
            .iter()
            .all(|(t, r, s)| t.is_finite() && r.is_finite() && s.is_finite())
            && pose.weights.iter().all(|w| w.is_finite());
        if pose.locals.len() != rig.nodes.len()
            || pose.weights.len() != mesh.targets.len()
            || !finite
        {
            return Err(bad(
                path,
                format!("pose {f}"),
                "does not have one finite transform per node and one finite weight per target",
            ));
        }
    }
    Ok(())
}

/// Writes `mesh` skinned to `rig`'s skeleton, animated by its poses, as a `.glb` (see the
/// module docs).
///
/// # Errors
/// [`IoError::Malformed`] naming the element at fault (counts that do not match, a non-finite
/// value, times that are not increasing); [`IoError::Os`] when the file cannot be written.
pub fn write_rigged_glb(
    path: &Path,
    mesh: &RiggedMesh,
    rig: &RigAnimation<'_>,
) -> Result<(), IoError> {
    check(path, mesh, rig)?;
    let keys = key_times(path, rig.times.len(), rig.times)?;
    let mut buf = Buffer::default();
    let n = mesh.positions.len();
    let flat: Vec<f32> = mesh.positions.iter().flat_map(|p| p.to_array()).collect();
    let position = buf.floats(&flat, 3, "VEC3", Some(34962), true);
    let joints: Vec<u8> = mesh
        .joints
        .iter()
        .flatten()
        .flat_map(|j| j.to_le_bytes())
        .collect();
    let view = buf.view(&joints, Some(34962));
    let joints = buf
        .accessor(json!({"bufferView": view, "componentType": 5123, "count": n, "type": "VEC4"}));
    let weights: Vec<f32> = mesh.weights.iter().flatten().copied().collect();
    let weights = buf.floats(&weights, 4, "VEC4", Some(34962), false);
    let indices: Vec<u8> = mesh
        .triangles
        .iter()
        .flatten()
        .flat_map(|i| i.to_le_bytes())
        .collect();
    let view = buf.view(&indices, Some(34963));
    let indices = buf.accessor(json!({"bufferView": view, "componentType": 5125, "count": 3 * mesh.triangles.len(), "type": "SCALAR"}));
    let mut targets = Vec::new();
    for (_, deltas) in &mesh.targets {
        let values: Vec<f32> = deltas.iter().flat_map(|d| d.1.to_array()).collect();
        let (mut min, mut max) = min_max(&values, 3);
        if deltas.len() < n {
            // The vertices a sparse accessor leaves out are zero.
            min.iter_mut().for_each(|m| *m = m.min(0.0));
            max.iter_mut().for_each(|m| *m = m.max(0.0));
        }
        let mut a =
            json!({"componentType": 5126, "count": n, "type": "VEC3", "min": min, "max": max});
        if !deltas.is_empty() {
            let idx: Vec<u8> = deltas.iter().flat_map(|d| d.0.to_le_bytes()).collect();
            let idx = buf.view(&idx, None);
            let val = buf.view(&f32_bytes(&values), None);
            a["sparse"] = json!({"count": deltas.len(),
                "indices": {"bufferView": idx, "componentType": 5125},
                "values": {"bufferView": val}});
        }
        targets.push(json!({"POSITION": buf.accessor(a)}));
    }
    let ibm: Vec<f32> = rig
        .inverse_bind
        .iter()
        .flat_map(|m| m.to_cols_array().map(|v| v as f32))
        .collect();
    let ibm = buf.floats(&ibm, 16, "MAT4", None, false);

    // Nodes: the skeleton, then the mesh node.
    let mut nodes: Vec<Value> = rig.nodes.iter().map(node_json).collect();
    for (i, node) in rig.nodes.iter().enumerate() {
        if let Some(p) = node.parent {
            let children = nodes[p]
                .as_object_mut()
                .map(|o| o.entry("children").or_insert_with(|| json!([])));
            if let Some(Value::Array(c)) = children {
                c.push(json!(i));
            }
        }
    }
    let rig_node = nodes.len();
    nodes.push(json!({"name": "rig", "mesh": 0, "skin": 0}));
    let mut roots: Vec<usize> = (0..rig.nodes.len())
        .filter(|&i| rig.nodes[i].parent.is_none())
        .collect();
    roots.push(rig_node);

    // The animation.
    let time = buf.floats(&keys, 1, "SCALAR", None, true);
    let mut anim = Channels {
        time,
        samplers: Vec::new(),
        channels: Vec::new(),
    };
    for node in 0..rig.nodes.len() {
        let first = rig.poses.first().map(|p| p.locals[node]);
        let varies = |pick: &dyn Fn(&Trs) -> [f64; 4]| {
            rig.poses
                .iter()
                .any(|p| first.is_some_and(|f| pick(&p.locals[node]) != pick(&f)))
        };
        if varies(&|l| l.0.extend(0.0).to_array()) {
            let v: Vec<f32> = rig
                .poses
                .iter()
                .flat_map(|p| p.locals[node].0.as_vec3().to_array())
                .collect();
            anim.add(&mut buf, node, "translation", &v, 3, "VEC3");
        }
        if varies(&|l| l.1.to_array()) {
            let mut previous = DQuat::IDENTITY;
            let mut v = Vec::with_capacity(4 * rig.poses.len());
            for p in rig.poses {
                let mut q = p.locals[node].1.normalize();
                if q.dot(previous) < 0.0 {
                    q = -q;
                }
                previous = q;
                v.extend(q.as_quat().to_array());
            }
            anim.add(&mut buf, node, "rotation", &v, 4, "VEC4");
        }
        if varies(&|l| l.2.extend(0.0).to_array()) {
            let v: Vec<f32> = rig
                .poses
                .iter()
                .flat_map(|p| p.locals[node].2.as_vec3().to_array())
                .collect();
            anim.add(&mut buf, node, "scale", &v, 3, "VEC3");
        }
    }
    if mesh.targets.is_empty() {
        if anim.channels.is_empty() {
            // A still rig: one constant channel so that the file has its animation.
            let v: Vec<f32> = rig.poses.iter().flat_map(|_| [1.0f32; 3]).collect();
            anim.add(&mut buf, rig_node, "scale", &v, 3, "VEC3");
        }
    } else {
        let v: Vec<f32> = rig
            .poses
            .iter()
            .flat_map(|p| p.weights.iter().map(|&w| w as f32))
            .collect();
        anim.add(&mut buf, rig_node, "weights", &v, 1, "SCALAR");
    }
    let names: Vec<&str> = mesh.targets.iter().map(|t| t.0.as_str()).collect();
    let mut primitive = json!({"attributes": {"POSITION": position, "JOINTS_0": joints, "WEIGHTS_0": weights}, "indices": indices, "mode": 4});
    let mut gltf_mesh = json!({"name": "rig", "primitives": []});
    if !targets.is_empty() {
        primitive["targets"] = json!(targets);
        gltf_mesh["weights"] = json!(vec![0.0f32; targets.len()]);
        gltf_mesh["extras"] = json!({"targetNames": names});
    }
    gltf_mesh["primitives"] = json!([primitive]);
    while !buf.bytes.len().is_multiple_of(4) {
        buf.bytes.push(0);
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "trisplat rig"},
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "meshes": [gltf_mesh],
        "skins": [{"joints": rig.joints, "inverseBindMatrices": ibm}],
        "animations": [{"name": "rig", "channels": anim.channels, "samplers": anim.samplers}],
        "accessors": buf.accessors,
        "bufferViews": buf.views,
        "buffers": [{"byteLength": buf.bytes.len()}],
    });
    let mut text = serde_json::to_vec(&doc).map_err(|e| IoError::os(path, e.into()))?;
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + buf.bytes.len();
    let total = u32::try_from(total).map_err(|_| IoError::Unsupported {
        path: path.to_path_buf(),
        what: format!("a {total}-byte GLB (the format holds at most 4 GiB)"),
    })?;
    write_atomically(path, |w| {
        let mut head = Vec::with_capacity(28);
        head.extend_from_slice(b"glTF");
        head.extend_from_slice(&2u32.to_le_bytes());
        head.extend_from_slice(&total.to_le_bytes());
        head.extend_from_slice(&(text.len() as u32).to_le_bytes());
        head.extend_from_slice(b"JSON");
        w.write_all(&head).map_err(|e| IoError::os(path, e))?;
        w.write_all(&text).map_err(|e| IoError::os(path, e))?;
        w.write_all(&(buf.bytes.len() as u32).to_le_bytes())
            .map_err(|e| IoError::os(path, e))?;
        w.write_all(b"BIN\0").map_err(|e| IoError::os(path, e))?;
        w.write_all(&buf.bytes).map_err(|e| IoError::os(path, e))
    })
}

/// The animation's samplers and channels, all keyed by the accessor `time`.
struct Channels {
    time: usize,
    samplers: Vec<Value>,
    channels: Vec<Value>,
}

impl Channels {
    /// A LINEAR channel animating `property` of `node` by `values` (`width` per key).
    fn add(
        &mut self,
        buf: &mut Buffer,
        node: usize,
        property: &str,
        values: &[f32],
        width: usize,
        kind: &str,
    ) {
        let output = buf.floats(values, width, kind, None, false);
        self.samplers
            .push(json!({"input": self.time, "output": output, "interpolation": "LINEAR"}));
        self.channels
            .push(json!({"sampler": self.samplers.len() - 1,
            "target": {"node": node, "path": property}}));
    }
}

/// A skeleton node as glTF JSON: name and the parts of its rest transform that are not the
/// identity's.
fn node_json(node: &RigNode) -> Value {
    let mut n = json!({});
    if let Some(name) = &node.name {
        n["name"] = json!(name);
    }
    let (t, r, s) = node.trs;
    if t != glam::DVec3::ZERO {
        n["translation"] = json!(t.as_vec3().to_array());
    }
    if r != DQuat::IDENTITY {
        n["rotation"] = json!(r.normalize().as_quat().normalize().to_array());
    }
    if s != glam::DVec3::ONE {
        n["scale"] = json!(s.as_vec3().to_array());
    }
    n
}
