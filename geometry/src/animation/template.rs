//! The animated-template trait every source of a moving mesh implements, and the default
//! frame rate.

use glam::DVec3;

use super::error::AnimationError;
use super::gltf::{GltfTemplate, RigPose};
use crate::mesh::TriMesh;

/// Frame rate used when a source has no timing of its own (the LAM/ARKit tracks are 30 fps).
pub const DEFAULT_FPS: f64 = 30.0;

/// `fps` when it is a usable frame rate (finite and > 0), else `current`: the rule of every
/// `with_fps`.
pub(crate) fn frame_rate_or(fps: f64, current: f64) -> f64 {
    if fps.is_finite() && fps > 0.0 {
        fps
    } else {
        current
    }
}

/// A triangle mesh whose vertices move over a sequence of frames with fixed topology.
pub trait AnimatedTemplate: Send + Sync {
    /// Number of frames.
    fn frame_count(&self) -> usize;

    /// Time of `frame` in seconds, `None` past the last frame.
    fn frame_time(&self, frame: usize) -> Option<f64>;

    /// The triangles shared by every frame (those of [`Self::rest`]).
    fn topology(&self) -> &[[u32; 3]];

    /// The rest (neutral, bind or first-frame) mesh.
    fn rest(&self) -> &TriMesh;

    /// World-space vertex positions of `frame`, one per vertex of [`Self::rest`].
    ///
    /// # Errors
    /// [`AnimationError::FrameOutOfRange`] past the last frame; source errors (an unreadable
    /// or mismatched frame file) naming the file.
    fn frame(&self, frame: usize) -> Result<Vec<DVec3>, AnimationError>;

    /// Channels of the driving track that move nothing (a weights track's names that match no
    /// morph target or blendshape, such as ARKit's `tongueOut` on a head without a tongue
    /// target); empty for every other animation.
    fn unused_channels(&self) -> Vec<&str> {
        Vec::new()
    }

    /// The glTF template whose rig (skin, morph targets: [`GltfTemplate::rig`]) plays this
    /// animation: a glTF template driven by its clip, or its morph targets driven by a weights
    /// track; `None` for every other animation.
    fn gltf_rig(&self) -> Option<&GltfTemplate> {
        None
    }

    /// The pose of [`Self::gltf_rig`]'s rig at `frame`: node transforms and morph weights
    /// that make the rig evaluate to [`Self::frame`]; `None` without a glTF rig.
    fn frame_rig_pose(&self, frame: usize) -> Option<Result<RigPose, AnimationError>> {
        let _ = frame;
        None
    }

    /// `frame` as a mesh with the template's topology.
    ///
    /// # Errors
    /// As [`Self::frame`], and [`AnimationError::Invalid`] for non-finite positions.
    fn frame_mesh(&self, frame: usize) -> Result<TriMesh, AnimationError> {
        Ok(TriMesh::try_new(
            self.frame(frame)?,
            self.topology().to_vec(),
        )?)
    }
}
