//! The error type of every animated-template reader and evaluator.

use std::path::PathBuf;

use crate::io::error::IoError;
use crate::mesh::MeshError;

/// A failed read or evaluation of an animated template. Every variant that comes from a file
/// names the file and, where there is one, the glTF element (accessor, node, skin, animation,
/// buffer index), the frame file or the weights-file entry at fault.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnimationError {
    /// The operating system refused (missing file, permissions).
    ///
    /// The underlying errors of this and the next two variants are part of the message and
    /// deliberately not exposed as [`std::error::Error::source`], so a reporter that prints the
    /// cause chain prints them once (as [`crate::io::IoError`] does).
    #[error("{path}: {error}")]
    Os {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The glTF JSON or GLB container could not be parsed or failed the `gltf` crate's
    /// validation (indices out of range, missing required fields).
    #[error("{path}: {error}")]
    Gltf {
        /// The glTF file.
        path: PathBuf,
        /// The `gltf` crate's error (its message says what failed: `invalid glTF: ...`,
        /// `JSON error: ...`).
        error: gltf::Error,
    },
    /// A buffer's external file (`.bin`) cannot be read.
    #[error("{path}: buffer {buffer} ({uri}): cannot read {resolved}: {error}")]
    MissingBuffer {
        /// The glTF file.
        path: PathBuf,
        /// Buffer index.
        buffer: usize,
        /// The URI written in the file.
        uri: String,
        /// The file the URI resolves to.
        resolved: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A buffer is malformed (bad data URI, shorter than its declared `byteLength`).
    #[error("{path}: buffer {buffer}: {message}")]
    Buffer {
        /// The glTF file.
        path: PathBuf,
        /// Buffer index.
        buffer: usize,
        /// What is wrong.
        message: String,
    },
    /// An accessor cannot be read (out of its buffer, unsupported type, non-finite values).
    #[error("{path}: accessor {accessor}: {message}")]
    Accessor {
        /// The glTF file.
        path: PathBuf,
        /// Accessor index.
        accessor: usize,
        /// What is wrong.
        message: String,
    },
    /// A node is unusable (non-finite or zero rotation, a cycle in the hierarchy).
    #[error("{path}: node {node}: {message}")]
    Node {
        /// The glTF file.
        path: PathBuf,
        /// Node index.
        node: usize,
        /// What is wrong.
        message: String,
    },
    /// A mesh primitive is unusable (no positions, indices out of range, bad morph target).
    #[error("{path}: mesh {mesh} primitive {primitive}: {message}")]
    Primitive {
        /// The glTF file.
        path: PathBuf,
        /// Mesh index.
        mesh: usize,
        /// Primitive index within the mesh.
        primitive: usize,
        /// What is wrong.
        message: String,
    },
    /// A skin is unusable (joint index out of range, too few inverse bind matrices).
    #[error("{path}: skin {skin}: {message}")]
    Skin {
        /// The glTF file.
        path: PathBuf,
        /// Skin index.
        skin: usize,
        /// What is wrong.
        message: String,
    },
    /// An animation channel or sampler is unusable (missing accessor, times not increasing,
    /// wrong number of output values, NaN or zero quaternions).
    #[error("{path}: animation {animation} channel {channel}: {message}")]
    Animation {
        /// The glTF file.
        path: PathBuf,
        /// Animation index.
        animation: usize,
        /// Channel index within the animation.
        channel: usize,
        /// What is wrong.
        message: String,
    },
    /// A clip cannot be retargeted onto a template.
    #[error("{path}: {message}")]
    Retarget {
        /// The glTF file holding the clip.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The requested clip does not exist.
    #[error("{path}: no animation {clip} (the file has: {available})")]
    ClipNotFound {
        /// The glTF file.
        path: PathBuf,
        /// The name or index asked for.
        clip: String,
        /// The clips present, as `index:name`, comma-separated.
        available: String,
    },
    /// The scene has no triangles to animate.
    #[error("{path}: the scene has no triangle primitives")]
    NoTriangles {
        /// The glTF file.
        path: PathBuf,
    },
    /// A frame index past the end.
    #[error("frame {frame} out of range: the template has {count} frames")]
    FrameOutOfRange {
        /// The frame asked for.
        frame: usize,
        /// Number of frames.
        count: usize,
    },
    /// A time that is not finite.
    #[error("time {time} is not finite")]
    BadTime {
        /// The time asked for.
        time: f64,
    },
    /// A mesh file (sequence frame, neutral or blendshape target) could not be read.
    #[error(transparent)]
    Mesh(#[from] IoError),
    /// The evaluated positions do not make a valid mesh (a non-finite position).
    #[error(transparent)]
    Invalid(#[from] MeshError),
    /// A sequence frame or blendshape target does not have the topology of the first mesh.
    #[error("{path}: topology differs from {reference}: {message}")]
    TopologyMismatch {
        /// The offending file.
        path: PathBuf,
        /// The file whose topology is the reference (first frame or neutral).
        reference: PathBuf,
        /// What differs.
        message: String,
    },
    /// A directory or pattern matched no frame files.
    #[error("{pattern}: no frame files found")]
    NoFrames {
        /// The directory or pattern.
        pattern: String,
    },
    /// A weights file is malformed: `element` says where (`names`, `frames[12].weights[3]`).
    #[error("{path}: {element}: {message}")]
    Weights {
        /// The weights file.
        path: PathBuf,
        /// Where in the file.
        element: String,
        /// What is wrong.
        message: String,
    },
    /// A weight vector whose length is not the number of blendshape targets.
    #[error("{found} weights given for {expected} blendshape targets")]
    WeightCount {
        /// Number of targets.
        expected: usize,
        /// Number of weights given.
        found: usize,
    },
    /// The template has no rig to transfer (neither a skin nor morph targets), or one the rig
    /// export cannot describe.
    #[error("{path}: no rig to transfer: {message}")]
    NoRig {
        /// The template file.
        path: PathBuf,
        /// What is missing.
        message: String,
    },
    /// The weights track and the blendshape targets share no name.
    #[error("{path}: none of the {channels} weight names matches a blendshape target ({targets})")]
    NoMatchingTargets {
        /// The weights file.
        path: PathBuf,
        /// Number of weight channels in the file.
        channels: usize,
        /// The target names, comma-separated.
        targets: String,
    },
}

impl From<crate::io::gltf_data::GltfDataError> for AnimationError {
    fn from(e: crate::io::gltf_data::GltfDataError) -> Self {
        use crate::io::gltf_data::GltfDataErrorKind as K;
        let path = e.path;
        match e.kind {
            K::Os(error) => Self::Os { path, error },
            K::Document(error) => Self::Gltf { path, error },
            K::GlbHeader(message) => Self::Mesh(IoError::malformed(path, "GLB header", message)),
            K::Attribute {
                mesh,
                primitive,
                message,
            } => Self::Primitive {
                path,
                mesh,
                primitive,
                message,
            },
            K::MissingBuffer {
                buffer,
                uri,
                resolved,
                error,
            } => Self::MissingBuffer {
                path,
                buffer,
                uri,
                resolved,
                error,
            },
            K::Buffer { buffer, message } => Self::Buffer {
                path,
                buffer,
                message,
            },
            K::Accessor { accessor, message } => Self::Accessor {
                path,
                accessor,
                message,
            },
        }
    }
}
