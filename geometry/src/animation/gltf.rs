//! glTF 2.0 animation evaluation: node TRS hierarchy, skins, morph targets and clips, to
//! world-space vertex positions.
//!
//! # Vertex and triangle order
//! The template's vertices are those of every triangle primitive (`TRIANGLES`,
//! `TRIANGLE_STRIP`, `TRIANGLE_FAN`; points and lines are skipped) of every node that has a
//! mesh, visited depth-first in pre-order from the roots of the default scene (or scene 0, or
//! every parentless node when the file has no scene), children in file order; within a node the
//! primitives in file order. Each primitive contributes its full vertex array (not welded) and
//! its triangles, offset by the vertices before it. A mesh used by two nodes appears twice.
//! Strips give `(a, b, c)` for even and `(b, a, c)` for odd triangles, fans `(vᵢ, vᵢ₊₁, v₀)`;
//! a node whose stored world transform mirrors (negative determinant) has its triangles'
//! winding reversed. This is exactly the order of [`crate::io::read_mesh`] on the same file,
//! so a template's vertex `i` is the static mesh's vertex `i`.
//!
//! # Evaluation
//! All transforms are composed in f64; positions are stored as f32. A skinned vertex is
//! `Σ wᵢ (world(jointᵢ) · inverseBindᵢ) · p`, with the weights of every `JOINTS_n/WEIGHTS_n`
//! set normalised by their sum on read; the mesh node's own transform is ignored (glTF spec).
//! A vertex whose weights sum to zero is placed by its node's world transform (its bind pose).
//! Morphed position `p = base + Σ wₜ Δₜ`, with weights from the clip's weight track of the
//! node, else `node.weights`, else `mesh.weights`, else zero.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3};
use rayon::prelude::*;

use super::error::AnimationError;
use super::sampler::{Interpolation, Sampler};
use super::template::{AnimatedTemplate, DEFAULT_FPS};
use crate::io::gltf_data::GltfData;
use crate::mesh::TriMesh;

/// Slack (in frames) when counting the frames of a clip, so that a clip end that falls on a
/// frame boundary (2.0 s at 30 fps) is not lost to rounding.
const FRAME_TIME_SLACK: f64 = 1e-9;

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
struct Trs {
    translation: DVec3,
    rotation: DQuat,
    scale: DVec3,
}

impl Trs {
    fn matrix(&self) -> DMat4 {
        DMat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

#[derive(Clone, Copy, Debug)]
enum Local {
    Trs(Trs),
    Matrix(DMat4),
}

#[derive(Clone, Debug)]
struct NodeData {
    name: Option<String>,
    local: Local,
    mesh: Option<usize>,
    skin: Option<usize>,
    weights: Option<Vec<f64>>,
}

/// Per-vertex joint influences in CSR form, weights normalised to sum 1.
#[derive(Clone, Debug)]
struct Influences {
    offsets: Vec<u32>,
    joints: Vec<u32>,
    weights: Vec<f64>,
}

#[derive(Clone, Debug)]
struct PrimData {
    positions: Vec<DVec3>,
    /// Per morph target, the non-zero deltas as `(vertex, delta)` in vertex order (face
    /// targets move a small part of a head: LAM's average 3.7k of 20k vertices).
    targets: Vec<Vec<(u32, DVec3)>>,
    influences: Option<Influences>,
    triangles: Vec<[u32; 3]>,
}

#[derive(Clone, Debug)]
struct MeshData {
    prims: Vec<PrimData>,
    weights: Vec<f64>,
    target_count: usize,
    target_names: Vec<String>,
}

#[derive(Clone, Debug)]
struct SkinData {
    joints: Vec<usize>,
    inverse_bind: Vec<DMat4>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Property {
    Translation,
    Rotation,
    Scale,
    Weights,
}

#[derive(Clone, Debug)]
struct Channel {
    node: usize,
    property: Property,
    sampler: Sampler,
}

#[derive(Clone, Debug)]
struct ClipData {
    index: usize,
    name: Option<String>,
    channels: Vec<Channel>,
    end: f64,
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
/// at any time and, sampled at a fixed rate, is an [`AnimatedTemplate`].
#[derive(Clone, Debug)]
pub struct GltfTemplate {
    path: PathBuf,
    nodes: Vec<NodeData>,
    /// Every node, parents before children (for world matrices).
    order: Vec<usize>,
    parents: Vec<Option<usize>>,
    /// Mesh nodes in output order, with the index of their first vertex.
    instances: Vec<(usize, usize)>,
    meshes: Vec<MeshData>,
    skins: Vec<SkinData>,
    clip: Option<ClipData>,
    clip_names: Vec<Option<String>>,
    fps: f64,
    rest: TriMesh,
    /// Joints of a retargeted clip ([`GltfTemplate::retarget`]) that no node of this template
    /// is named after (their channels are dropped).
    unmatched_joints: Vec<String>,
    /// Whether the clip came from another file ([`GltfTemplate::retarget`]).
    retargeted: bool,
}

/// Names of morph targets per mesh: an explicit JSON parse of `meshes[i].extras.targetNames`
/// (the `gltf` crate drops extras unless a feature is on).
fn target_names(json: &serde_json::Value) -> Vec<Vec<String>> {
    let Some(meshes) = json.get("meshes").and_then(|m| m.as_array()) else {
        return Vec::new();
    };
    meshes
        .iter()
        .map(|m| {
            m.get("extras")
                .and_then(|e| e.get("targetNames"))
                .and_then(|n| n.as_array())
                .map(|a| {
                    a.iter()
                        .map(|v| v.as_str().unwrap_or_default().to_string())
                        .collect()
                })
                .unwrap_or_default()
        })
        .collect()
}

/// Triangles of a primitive from its index list (or `0..n`), per draw mode.
fn triangulate(mode: gltf::mesh::Mode, idx: &[u32]) -> Option<Vec<[u32; 3]>> {
    use gltf::mesh::Mode;
    let tris = match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => (0..idx.len().saturating_sub(2))
            .map(|i| {
                if i % 2 == 0 {
                    [idx[i], idx[i + 1], idx[i + 2]]
                } else {
                    [idx[i + 1], idx[i], idx[i + 2]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..idx.len().saturating_sub(1))
            .map(|i| [idx[i], idx[i + 1], idx[0]])
            .collect(),
        _ => return None,
    };
    Some(tris)
}

/// World matrices of every node from local transforms, `order` listing parents first.
fn world_matrices(locals: &[Local], order: &[usize], parents: &[Option<usize>]) -> Vec<DMat4> {
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

/// Checks what the `gltf` crate takes on trust in animations (it panics on them): every
/// channel's target path is one of glTF's four and its node and sampler exist, and every
/// sampler's accessors exist.
fn check_animation_references(path: &Path, json: &serde_json::Value) -> Result<(), AnimationError> {
    let count = |key: &str| json.get(key).and_then(|v| v.as_array()).map_or(0, Vec::len);
    let (nodes, accessors) = (count("nodes"), count("accessors"));
    let empty = Vec::new();
    let animations = json
        .get("animations")
        .and_then(|a| a.as_array())
        .unwrap_or(&empty);
    for (a, anim) in animations.iter().enumerate() {
        let samplers = anim
            .get("samplers")
            .and_then(|s| s.as_array())
            .unwrap_or(&empty);
        let channels = anim
            .get("channels")
            .and_then(|c| c.as_array())
            .unwrap_or(&empty);
        let fail = |channel: usize, message: String| AnimationError::Animation {
            path: path.to_path_buf(),
            animation: a,
            channel,
            message,
        };
        for (c, channel) in channels.iter().enumerate() {
            let target = channel.get("target");
            let path_name = target.and_then(|t| t.get("path")).and_then(|p| p.as_str());
            if !matches!(
                path_name,
                Some("translation" | "rotation" | "scale" | "weights")
            ) {
                return Err(fail(
                    c,
                    format!(
                        "target path {} is not translation, rotation, scale or weights",
                        path_name.map_or_else(|| "(missing)".to_owned(), |p| format!("{p:?}"))
                    ),
                ));
            }
            match target
                .and_then(|t| t.get("node"))
                .and_then(serde_json::Value::as_u64)
            {
                Some(n) if (n as usize) < nodes => {}
                other => {
                    return Err(fail(
                        c,
                        format!(
                            "targets node {}, but the file has {nodes} nodes",
                            other.map_or_else(|| "(missing)".to_owned(), |n| n.to_string())
                        ),
                    ));
                }
            }
            match channel.get("sampler").and_then(serde_json::Value::as_u64) {
                Some(k) if (k as usize) < samplers.len() => {}
                _ => {
                    return Err(fail(
                        c,
                        format!("its sampler does not exist ({} samplers)", samplers.len()),
                    ));
                }
            }
        }
        for (k, sampler) in samplers.iter().enumerate() {
            for key in ["input", "output"] {
                match sampler.get(key).and_then(serde_json::Value::as_u64) {
                    Some(i) if (i as usize) < accessors => {}
                    _ => {
                        return Err(AnimationError::Animation {
                            path: path.to_path_buf(),
                            animation: a,
                            channel: k,
                            message: format!(
                                "sampler {k}: its {key} accessor does not exist ({accessors} \
                                 accessors)"
                            ),
                        });
                    }
                }
            }
        }
    }
    Ok(())
}

fn to_vec3s(v: &[f64]) -> Vec<DVec3> {
    v.chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect()
}

impl GltfTemplate {
    /// Opens a `.gltf` or `.glb` file (buffers in the GLB, in data URIs or in external files)
    /// and selects `clip`. Frames are sampled at [`DEFAULT_FPS`]; see [`Self::with_fps`].
    ///
    /// # Errors
    /// [`AnimationError`] naming the file and the buffer, accessor, node, mesh, skin or
    /// animation at fault; [`AnimationError::ClipNotFound`] when `clip` does not exist.
    pub fn open(path: &Path, clip: &Clip) -> Result<Self, AnimationError> {
        let data = GltfData::open(path)?;
        check_animation_references(path, &data.json)?;
        Self::build(path, &data.document, &data, &target_names(&data.json), clip)
    }

    fn build(
        path: &Path,
        doc: &gltf::Document,
        buffers: &GltfData,
        names: &[Vec<String>],
        clip: &Clip,
    ) -> Result<Self, AnimationError> {
        let node_err = |node: usize, message: String| AnimationError::Node {
            path: path.to_path_buf(),
            node,
            message,
        };
        // Nodes.
        let mut nodes = Vec::new();
        let mut parents: Vec<Option<usize>> = vec![None; doc.nodes().len()];
        for node in doc.nodes() {
            let i = node.index();
            let local = match node.transform() {
                gltf::scene::Transform::Matrix { matrix } => {
                    let m = DMat4::from_cols_array_2d(&matrix.map(|c| c.map(f64::from)));
                    if !m.is_finite() {
                        return Err(node_err(i, "matrix is not finite".into()));
                    }
                    Local::Matrix(m)
                }
                gltf::scene::Transform::Decomposed {
                    translation,
                    rotation,
                    scale,
                } => {
                    let t = DVec3::from_array(translation.map(f64::from));
                    let r = DQuat::from_array(rotation.map(f64::from));
                    let s = DVec3::from_array(scale.map(f64::from));
                    if !(t.is_finite() && r.is_finite() && s.is_finite()) {
                        return Err(node_err(i, "transform is not finite".into()));
                    }
                    if r.length() == 0.0 {
                        return Err(node_err(i, "rotation is the zero quaternion".into()));
                    }
                    Local::Trs(Trs {
                        translation: t,
                        rotation: r.normalize(),
                        scale: s,
                    })
                }
            };
            for child in node.children() {
                let c = child.index();
                if parents[c].is_some() || c == i {
                    return Err(node_err(c, "has more than one parent".into()));
                }
                parents[c] = Some(i);
            }
            let weights = node
                .weights()
                .map(|w| w.iter().map(|&v| f64::from(v)).collect());
            nodes.push(NodeData {
                name: node.name().map(str::to_owned),
                local,
                mesh: node.mesh().map(|m| m.index()),
                skin: node.skin().map(|s| s.index()),
                weights,
            });
        }
        // Parents before children; nodes unreachable from parentless roots are in a cycle.
        let mut order = Vec::with_capacity(nodes.len());
        let mut stack: Vec<usize> = (0..nodes.len())
            .rev()
            .filter(|&i| parents[i].is_none())
            .collect();
        while let Some(i) = stack.pop() {
            order.push(i);
            let node = doc
                .nodes()
                .nth(i)
                .ok_or_else(|| node_err(i, "missing".into()))?;
            let children: Vec<usize> = node.children().map(|c| c.index()).collect();
            stack.extend(children.into_iter().rev());
        }
        if order.len() != nodes.len() {
            let mut seen = vec![false; nodes.len()];
            order.iter().for_each(|&i| seen[i] = true);
            let bad = seen.iter().position(|s| !s).unwrap_or(0);
            return Err(node_err(
                bad,
                "is part of a cycle in the node hierarchy".into(),
            ));
        }
        // Scene traversal order for mesh instances.
        let roots: Vec<usize> = match doc.default_scene().or_else(|| doc.scenes().next()) {
            Some(scene) => scene.nodes().map(|n| n.index()).collect(),
            None => (0..nodes.len()).filter(|&i| parents[i].is_none()).collect(),
        };
        let mut visit = Vec::new();
        let mut stack: Vec<usize> = roots.into_iter().rev().collect();
        let mut seen = vec![false; nodes.len()];
        while let Some(i) = stack.pop() {
            if std::mem::replace(&mut seen[i], true) {
                continue;
            }
            visit.push(i);
            if let Some(node) = doc.nodes().nth(i) {
                let children: Vec<usize> = node.children().map(|c| c.index()).collect();
                stack.extend(children.into_iter().rev());
            }
        }
        // Meshes.
        let mut meshes = Vec::new();
        for mesh in doc.meshes() {
            meshes.push(Self::read_mesh(
                path,
                buffers,
                &mesh,
                names.get(mesh.index()),
            )?);
        }
        for (i, node) in nodes.iter().enumerate() {
            if let (Some(m), Some(w)) = (node.mesh, &node.weights)
                && w.len() != meshes[m].target_count
            {
                return Err(node_err(
                    i,
                    format!(
                        "has {} weights, its mesh {} morph targets",
                        w.len(),
                        meshes[m].target_count
                    ),
                ));
            }
        }
        // Skins.
        let mut skins = Vec::new();
        for skin in doc.skins() {
            let s = skin.index();
            let skin_err = |message: String| AnimationError::Skin {
                path: path.to_path_buf(),
                skin: s,
                message,
            };
            let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
            let inverse_bind = match skin.inverse_bind_matrices() {
                Some(acc) => {
                    let v = buffers.read_dims(&acc, 16)?;
                    if v.len() / 16 < joints.len() {
                        return Err(skin_err(format!(
                            "{} inverse bind matrices for {} joints",
                            v.len() / 16,
                            joints.len()
                        )));
                    }
                    v.chunks_exact(16)
                        .map(|c| {
                            let mut a = [0.0; 16];
                            a.copy_from_slice(c);
                            DMat4::from_cols_array(&a)
                        })
                        .collect()
                }
                None => vec![DMat4::IDENTITY; joints.len()],
            };
            skins.push(SkinData {
                joints,
                inverse_bind,
            });
        }
        // Instances and topology; influences must address the instance's skin.
        let locals: Vec<Local> = nodes.iter().map(|n| n.local).collect();
        let rest_world = world_matrices(&locals, &order, &parents);
        let mut instances = Vec::new();
        let mut triangles = Vec::new();
        let mut vertex_count = 0usize;
        for &i in &visit {
            let Some(m) = nodes[i].mesh else { continue };
            let joint_count = nodes[i].skin.map(|s| skins[s].joints.len());
            instances.push((i, vertex_count));
            for (p, prim) in meshes[m].prims.iter().enumerate() {
                if let (Some(infl), Some(count)) = (&prim.influences, joint_count)
                    && let Some(&j) = infl.joints.iter().find(|&&j| j as usize >= count)
                {
                    return Err(AnimationError::Primitive {
                        path: path.to_path_buf(),
                        mesh: m,
                        primitive: p,
                        message: format!(
                            "joint index {j} is out of range for skin {} with {count} joints",
                            nodes[i].skin.unwrap_or(0)
                        ),
                    });
                }
                let base =
                    u32::try_from(vertex_count).map_err(|_| AnimationError::NoTriangles {
                        path: path.to_path_buf(),
                    })?;
                // As the static reader: a mirroring node transform (in the stored scene)
                // reverses the winding, skinned or not.
                let mirrored = rest_world[i].determinant() < 0.0;
                triangles.extend(prim.triangles.iter().map(|t| {
                    let t = t.map(|v| v + base);
                    if mirrored { [t[0], t[2], t[1]] } else { t }
                }));
                vertex_count += prim.positions.len();
            }
        }
        if triangles.is_empty() {
            return Err(AnimationError::NoTriangles {
                path: path.to_path_buf(),
            });
        }
        let clip_names = doc
            .animations()
            .map(|a| a.name().map(str::to_string))
            .collect();
        let mut template = Self {
            path: path.to_path_buf(),
            nodes,
            order,
            parents,
            instances,
            meshes,
            skins,
            clip: None,
            clip_names,
            fps: DEFAULT_FPS,
            rest: TriMesh::default(),
            unmatched_joints: Vec::new(),
            retargeted: false,
        };
        let rest_positions = template.evaluate_pose(None, None, None)?;
        template.rest = TriMesh::try_new(rest_positions, triangles)?;
        template.clip = template.read_clip(doc, buffers, clip)?;
        Ok(template)
    }

    fn read_mesh(
        path: &Path,
        buffers: &GltfData,
        mesh: &gltf::Mesh,
        names: Option<&Vec<String>>,
    ) -> Result<MeshData, AnimationError> {
        let m = mesh.index();
        let mut prims = Vec::new();
        let mut target_count = None;
        for prim in mesh.primitives() {
            let p = prim.index();
            let err = |message: String| AnimationError::Primitive {
                path: path.to_path_buf(),
                mesh: m,
                primitive: p,
                message,
            };
            let Some(pos) = prim.get(&gltf::Semantic::Positions) else {
                continue; // nothing to draw (the static reader skips it too)
            };
            let positions = to_vec3s(&buffers.read_dims(&pos, 3)?);
            let n = positions.len();
            let indices = match prim.indices() {
                Some(acc) => buffers.read_unsigned(&acc)?,
                None => {
                    (0..u32::try_from(n).map_err(|_| err("too many vertices".into()))?).collect()
                }
            };
            let Some(tris) = triangulate(prim.mode(), &indices) else {
                continue; // points and lines: not part of a triangle template
            };
            if let Some(bad) = indices.iter().find(|&&v| v as usize >= n) {
                return Err(err(format!("index {bad} is out of range for {n} vertices")));
            }
            let mut targets = Vec::new();
            for (t, target) in prim.morph_targets().enumerate() {
                let delta = match target.positions() {
                    Some(acc) => to_vec3s(&buffers.read_dims(&acc, 3)?),
                    None => vec![DVec3::ZERO; n],
                };
                if delta.len() != n {
                    return Err(err(format!(
                        "morph target {t} has {} positions, the primitive {n}",
                        delta.len()
                    )));
                }
                targets.push(
                    (0u32..)
                        .zip(delta)
                        .filter(|(_, d)| *d != DVec3::ZERO)
                        .collect(),
                );
            }
            match target_count {
                None => target_count = Some(targets.len()),
                Some(c) if c != targets.len() => {
                    return Err(err(format!(
                        "has {} morph targets, an earlier primitive {c}",
                        targets.len()
                    )));
                }
                Some(_) => {}
            }
            let influences = Self::read_influences(buffers, &prim, n).map_err(|e| match e {
                Ok(message) => err(message),
                Err(e) => e,
            })?;
            prims.push(PrimData {
                positions,
                targets,
                influences,
                triangles: tris,
            });
        }
        let target_count = target_count.unwrap_or(0);
        let weights: Vec<f64> = match mesh.weights() {
            Some(w) => w.iter().map(|&v| f64::from(v)).collect(),
            None => vec![0.0; target_count],
        };
        if weights.len() != target_count || weights.iter().any(|w| !w.is_finite()) {
            return Err(AnimationError::Primitive {
                path: path.to_path_buf(),
                mesh: m,
                primitive: 0,
                message: format!(
                    "mesh weights ({}) do not match its {target_count} morph targets or are not finite",
                    weights.len()
                ),
            });
        }
        Ok(MeshData {
            prims,
            weights,
            target_count,
            target_names: names.cloned().unwrap_or_default(),
        })
    }

    /// Reads every `JOINTS_n`/`WEIGHTS_n` pair, drops zero weights and normalises by the sum.
    /// The inner `Ok(String)` error is a message for the caller to attach to the primitive.
    fn read_influences(
        buffers: &GltfData,
        prim: &gltf::Primitive,
        n: usize,
    ) -> Result<Option<Influences>, Result<String, AnimationError>> {
        let mut sets = Vec::new();
        for set in 0.. {
            let j = prim.get(&gltf::Semantic::Joints(set));
            let w = prim.get(&gltf::Semantic::Weights(set));
            match (j, w) {
                (None, None) => break,
                (Some(j), Some(w)) => {
                    let joints = buffers.read_unsigned(&j).map_err(|e| Err(e.into()))?;
                    let weights = buffers.read_dims(&w, 4).map_err(|e| Err(e.into()))?;
                    if joints.len() != 4 * n || weights.len() != 4 * n {
                        return Err(Ok(format!(
                            "JOINTS_{set}/WEIGHTS_{set} must be VEC4 with {n} elements"
                        )));
                    }
                    sets.push((joints, weights));
                }
                _ => {
                    return Err(Ok(format!(
                        "JOINTS_{set} and WEIGHTS_{set} must come together"
                    )));
                }
            }
        }
        if sets.is_empty() {
            return Ok(None);
        }
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0u32);
        let mut joints = Vec::new();
        let mut weights = Vec::new();
        for v in 0..n {
            let start = weights.len();
            for (js, ws) in &sets {
                for c in 0..4 {
                    let w = ws[4 * v + c];
                    if w < 0.0 {
                        return Err(Ok(format!("vertex {v} has a negative joint weight {w}")));
                    }
                    if w > 0.0 {
                        joints.push(js[4 * v + c]);
                        weights.push(w);
                    }
                }
            }
            let sum: f64 = weights[start..].iter().sum();
            if sum > 0.0 {
                weights[start..].iter_mut().for_each(|w| *w /= sum);
            }
            let end = u32::try_from(weights.len())
                .map_err(|_| Ok("too many joint influences".to_string()))?;
            offsets.push(end);
        }
        Ok(Some(Influences {
            offsets,
            joints,
            weights,
        }))
    }

    fn read_clip(
        &self,
        doc: &gltf::Document,
        buffers: &GltfData,
        clip: &Clip,
    ) -> Result<Option<ClipData>, AnimationError> {
        let not_found = |what: String| AnimationError::ClipNotFound {
            path: self.path.clone(),
            clip: what,
            available: self
                .clip_names
                .iter()
                .enumerate()
                .map(|(i, n)| format!("{i}:{}", n.as_deref().unwrap_or("")))
                .collect::<Vec<_>>()
                .join(", "),
        };
        let anim = match clip {
            Clip::None => return Ok(None),
            Clip::FirstIfAny => match doc.animations().next() {
                Some(a) => a,
                None => return Ok(None),
            },
            Clip::Index(i) => doc
                .animations()
                .nth(*i)
                .ok_or_else(|| not_found(i.to_string()))?,
            Clip::Name(name) => doc
                .animations()
                .find(|a| a.name() == Some(name.as_str()))
                .ok_or_else(|| not_found(format!("{name:?}")))?,
        };
        let a = anim.index();
        let mut channels = Vec::new();
        let mut end = 0.0f64;
        for (c, channel) in anim.channels().enumerate() {
            let err = |message: String| AnimationError::Animation {
                path: self.path.clone(),
                animation: a,
                channel: c,
                message,
            };
            let node = channel.target().node().index();
            let property = match channel.target().property() {
                gltf::animation::Property::Translation => Property::Translation,
                gltf::animation::Property::Rotation => Property::Rotation,
                gltf::animation::Property::Scale => Property::Scale,
                gltf::animation::Property::MorphTargetWeights => Property::Weights,
            };
            let width = match property {
                Property::Translation | Property::Scale => 3,
                Property::Rotation => 4,
                Property::Weights => {
                    let Some(m) = self.nodes[node].mesh else {
                        return Err(err(format!(
                            "animates the weights of node {node}, which has no mesh"
                        )));
                    };
                    self.meshes[m].target_count
                }
            };
            let sampler = channel.sampler();
            let times = buffers.read_dims(&sampler.input(), 1)?;
            let output = sampler.output();
            let values = buffers.read(&output)?;
            let interpolation = Interpolation::from(sampler.interpolation());
            let sampler = Sampler::new(
                times,
                values,
                width,
                interpolation,
                property == Property::Rotation,
            )
            .map_err(err)?;
            end = end.max(sampler.end());
            channels.push(Channel {
                node,
                property,
                sampler,
            });
        }
        Ok(Some(ClipData {
            index: a,
            name: anim.name().map(str::to_string),
            channels,
            end,
        }))
    }

    /// Sets the rate at which frames are sampled (frames per second, finite and > 0;
    /// other values keep the current rate).
    #[must_use]
    pub fn with_fps(mut self, fps: f64) -> Self {
        if fps.is_finite() && fps > 0.0 {
            self.fps = fps;
        }
        self
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
    fn pose(
        &self,
        t: Option<f64>,
        turn: Option<JointTurn>,
    ) -> (Vec<DMat4>, HashMap<usize, Vec<f64>>) {
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
        (
            world_matrices(&locals, &self.order, &self.parents),
            anim_weights,
        )
    }

    fn evaluate_pose(
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

/// Linear-blend-skinning data of a [`GltfTemplate`] in its vertex order: every vertex's
/// influences on a *palette* of matrices ([`GltfTemplate::palette_at`]), as compressed rows.
///
/// The palette holds, for each mesh instance in output order, first the instance node's world
/// matrix, then (for a skinned node) `world(joint_j) · inverseBind_j` for every joint `j` of its
/// skin. A skinned vertex's influences are its normalised `JOINTS_n/WEIGHTS_n`; a vertex
/// without weights (or of an unskinned node) has the single influence 1 on its node's
/// matrix. So `Σ_k w_k P_k · p` over a vertex's influences, applied to its morphed mesh-space
/// position `p`, is exactly the evaluated vertex (without morph targets: its base position).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VertexSkinning {
    /// Row `v` is `offsets[v]..offsets[v + 1]` in `entries`/`weights` (`vertex count + 1`
    /// offsets).
    pub offsets: Vec<u32>,
    /// Palette indices.
    pub entries: Vec<u32>,
    /// Weights, summing to 1 per vertex.
    pub weights: Vec<f64>,
    /// Length of the palette.
    pub palette_len: usize,
    /// Mesh-space base positions (before morph targets and transforms), one per vertex.
    pub base_positions: Vec<DVec3>,
}

impl VertexSkinning {
    /// Influences of vertex `v` as `(palette index, weight)` (empty past the end).
    pub fn influences(&self, v: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let (a, b) = match (self.offsets.get(v), self.offsets.get(v + 1)) {
            (Some(&a), Some(&b)) => (a as usize, b as usize),
            _ => (0, 0),
        };
        let entries = self.entries.get(a..b).unwrap_or(&[]);
        let weights = self.weights.get(a..b).unwrap_or(&[]);
        entries.iter().zip(weights).map(|(&e, &w)| (e as usize, w))
    }
}

impl GltfTemplate {
    /// Whether any mesh instance is skinned.
    #[must_use]
    pub fn is_skinned(&self) -> bool {
        self.instances.iter().any(|&(node, _)| {
            let data = &self.nodes[node];
            data.skin.is_some()
                && data
                    .mesh
                    .is_some_and(|m| self.meshes[m].prims.iter().any(|p| p.influences.is_some()))
        })
    }

    /// Start of each instance's block in the palette, and the palette length.
    fn palette_layout(&self) -> (Vec<usize>, usize) {
        let mut starts = Vec::with_capacity(self.instances.len());
        let mut len = 0;
        for &(node, _) in &self.instances {
            starts.push(len);
            len += 1 + self.nodes[node]
                .skin
                .map_or(0, |s| self.skins[s].joints.len());
        }
        (starts, len)
    }

    /// The blend-skinning data of every vertex (see [`VertexSkinning`]).
    #[must_use]
    pub fn skinning(&self) -> VertexSkinning {
        let (starts, palette_len) = self.palette_layout();
        let mut out = VertexSkinning {
            offsets: vec![0],
            palette_len,
            ..VertexSkinning::default()
        };
        for (&(node, _), &start) in self.instances.iter().zip(&starts) {
            let data = &self.nodes[node];
            let Some(m) = data.mesh else { continue };
            for prim in &self.meshes[m].prims {
                for v in 0..prim.positions.len() {
                    let row = match (data.skin, &prim.influences) {
                        (Some(_), Some(infl)) => {
                            infl.offsets[v] as usize..infl.offsets[v + 1] as usize
                        }
                        _ => 0..0,
                    };
                    match &prim.influences {
                        Some(infl) if !row.is_empty() => {
                            for k in row {
                                // Joint indices were checked against the skin on open.
                                out.entries
                                    .push((start + 1 + infl.joints[k] as usize) as u32);
                                out.weights.push(infl.weights[k]);
                            }
                        }
                        _ => {
                            out.entries.push(start as u32);
                            out.weights.push(1.0);
                        }
                    }
                    out.offsets.push(out.entries.len() as u32);
                }
                out.base_positions.extend_from_slice(&prim.positions);
            }
        }
        out
    }

    /// The skinning palette (see [`VertexSkinning`]) with the clip at time `t` (seconds), or of
    /// the stored scene for `None` (the pose of [`AnimatedTemplate::rest`]).
    ///
    /// # Errors
    /// [`AnimationError::BadTime`] when `t` is not finite.
    pub fn palette_at(&self, t: Option<f64>) -> Result<Vec<DMat4>, AnimationError> {
        if let Some(t) = t.filter(|t| !t.is_finite()) {
            return Err(AnimationError::BadTime { time: t });
        }
        let (world, _) = self.pose(t, None);
        let (_, len) = self.palette_layout();
        let mut palette = Vec::with_capacity(len);
        for &(node, _) in &self.instances {
            palette.push(world[node]);
            if let Some(s) = self.nodes[node].skin {
                let skin = &self.skins[s];
                palette.extend(
                    skin.joints
                        .iter()
                        .zip(&skin.inverse_bind)
                        .map(|(&j, ibm)| world[j] * *ibm),
                );
            }
        }
        Ok(palette)
    }

    /// The palette of `frame` (at [`AnimatedTemplate::frame_time`]).
    ///
    /// # Errors
    /// [`AnimationError::FrameOutOfRange`] past the last frame.
    pub fn frame_palette(&self, frame: usize) -> Result<Vec<DMat4>, AnimationError> {
        let t = self
            .frame_time(frame)
            .ok_or(AnimationError::FrameOutOfRange {
                frame,
                count: self.frame_count(),
            })?;
        self.palette_at(Some(t))
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
        let t = self
            .frame_time(frame)
            .ok_or(AnimationError::FrameOutOfRange {
                frame,
                count: self.frame_count(),
            })?;
        self.evaluate_pose(Some(t), None, None)
    }
}
