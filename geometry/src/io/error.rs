//! The error type of every reader and writer.

use std::path::PathBuf;

/// A failed read or write. Every variant names the file; parse errors also name the element.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// The operating system refused (missing file, permissions, disk full).
    ///
    /// The OS error is part of the message and deliberately not exposed as
    /// [`std::error::Error::source`], so a reporter that prints the cause chain prints it once.
    #[error("{path}: {error}")]
    Os {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The extension names no format we read or write.
    #[error("{path}: unknown file format (expected .ply, .obj, .gltf or .glb)")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The file is malformed: `element` says where (e.g. `face 12`, `header line 3`).
    #[error("{path}: {element}: {message}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// Where in the file: element name and index, header line, accessor, ...
        element: String,
        /// What is wrong.
        message: String,
    },
    /// The file refers to another file (an external glTF buffer) that cannot be read.
    #[error("{path}: refers to {reference}, which cannot be read: {error}")]
    MissingReference {
        /// The file holding the reference.
        path: PathBuf,
        /// The referenced file, resolved against the folder of `path`.
        reference: PathBuf,
        /// Why it cannot be read (in the message, not a `source`: see [`IoError::Os`]).
        error: std::io::Error,
    },
    /// The file is well formed but uses something we do not support.
    #[error("{path}: unsupported: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is not supported.
        what: String,
    },
}

impl IoError {
    /// A [`IoError::Malformed`] for `path` at `element`.
    pub fn malformed(
        path: impl Into<PathBuf>,
        element: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self::Malformed {
            path: path.into(),
            element: element.into(),
            message: message.into(),
        }
    }

    /// An [`IoError::Os`] for `path`.
    pub fn os(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Os {
            path: path.into(),
            error,
        }
    }
}

impl From<super::gltf_data::GltfDataError> for IoError {
    fn from(e: super::gltf_data::GltfDataError) -> Self {
        use super::gltf_data::GltfDataErrorKind as K;
        let path = e.path;
        match e.kind {
            K::Os(error) => Self::Os { path, error },
            K::Document(error) => Self::malformed(path, "document", error.to_string()),
            K::GlbHeader(message) => Self::malformed(path, "GLB header", message),
            K::Attribute {
                mesh,
                primitive,
                message,
            } => Self::malformed(path, format!("mesh {mesh} primitive {primitive}"), message),
            K::MissingBuffer {
                resolved, error, ..
            } => Self::MissingReference {
                path,
                reference: resolved,
                error,
            },
            K::Buffer { buffer, message } => {
                Self::malformed(path, format!("buffer {buffer}"), message)
            }
            K::Accessor { accessor, message } => {
                Self::malformed(path, format!("accessor {accessor}"), message)
            }
        }
    }
}
