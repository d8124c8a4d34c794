//! The linear-blend skinning of a glTF template as data: per-vertex influences on a palette
//! of matrices, and the palette at any time.

use glam::{DMat4, DVec3};

use super::model::GltfTemplate;
use crate::animation::error::AnimationError;

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
    /// the stored scene for `None` (the pose of [`AnimatedTemplate::rest`](crate::animation::AnimatedTemplate::rest)).
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

    /// The palette of `frame` (at [`AnimatedTemplate::frame_time`](crate::animation::AnimatedTemplate::frame_time)).
    ///
    /// # Errors
    /// [`AnimationError::FrameOutOfRange`] past the last frame.
    pub fn frame_palette(&self, frame: usize) -> Result<Vec<DMat4>, AnimationError> {
        let t = self.checked_frame_time(frame)?;
        self.palette_at(Some(t))
    }
}
