//! Animated templates: "a template that can give you frame i".
//!
//! Every source of a moving template mesh implements [`AnimatedTemplate`], so later stages
//! (binding, deformation, extraction) do not care where frames come from:
//!
//! - [`GltfTemplate`]: a glTF/GLB scene with skins, morph targets and one animation clip,
//!   evaluated at any time ([`GltfTemplate::evaluate_at`]) and sampled at a fixed rate;
//! - [`MeshSequence`]: OBJ/PLY files of fixed topology, one per frame (a directory or a
//!   pattern);
//! - [`BlendshapeAnimation`]: a [`BlendshapeSet`] (neutral + targets, e.g. ICT FaceKit OBJs)
//!   or [`GltfMorphAnimation`]: glTF morph targets by name, both driven by a
//!   [`WeightsTrack`] (the LAM/ARKit JSON layout).
//!
//! Evaluation runs in f64; positions are stored as f32. Frames always have the topology of
//! [`AnimatedTemplate::rest`].

mod blendshape;
mod error;
mod gltf;
mod sampler;
mod sequence;
mod template;

pub use self::blendshape::{
    BlendshapeAnimation, BlendshapeSet, GltfMorphAnimation, WeightsTrack, canonical_target_name,
};
pub use self::error::AnimationError;
pub use self::gltf::{
    Clip, GltfTemplate, JointTurn, RigNode, RigPose, RigTarget, TemplateRig, VertexSkinning,
};
pub use self::sampler::Interpolation;
pub use self::sequence::{MeshSequence, check_topology, natural_cmp};
pub use self::template::{AnimatedTemplate, DEFAULT_FPS};
