//! Reading a glTF scene into a [`GltfTemplate`]: nodes, primitives (triangulated, morph
//! targets, skin influences) and the rest mesh.

use std::path::Path;

use glam::{DMat4, DQuat, DVec3};

use super::clip::check_animation_references;
use super::model::{
    Clip, GltfTemplate, Influences, Local, MeshData, NodeData, PrimData, SkinData, Trs,
    world_matrices,
};
use crate::animation::error::AnimationError;
use crate::animation::template::DEFAULT_FPS;
use crate::io::gltf_data::GltfData;
use crate::mesh::TriMesh;

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
}
