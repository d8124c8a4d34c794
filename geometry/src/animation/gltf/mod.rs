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
//!
//! One job a file: `model` holds the scene a template keeps (nodes, meshes, skins, the clip),
//! `read` builds it from a file, `clip` reads and checks the animation, `evaluate` samples the
//! clip and poses the scene, `skinning` exposes the skinning palette, and `rig` the skeleton, skin and morph targets as
//! data (for a rig moved onto another mesh).

mod clip;
mod evaluate;
mod model;
mod read;
mod rig;
mod skinning;

pub use model::{Clip, GltfTemplate, JointTurn};
pub use rig::{RigNode, RigPose, RigTarget, TemplateRig};
pub use skinning::VertexSkinning;
