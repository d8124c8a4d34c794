//! Errors of the neural appearance model and its weights file.

use std::path::PathBuf;

/// What can go wrong building, reading or applying a neural appearance model.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NeuralError {
    /// A configuration value out of range.
    #[error("neural appearance: configuration out of range: {0}")]
    Config(String),
    /// The Gaussians cannot be encoded (none, or a non-finite value).
    #[error("neural appearance: {0}")]
    Inputs(String),
    /// A weights file that is not one, or does not match.
    #[error("{}: {message}", path.display())]
    File {
        /// The weights file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl NeuralError {
    /// A [`NeuralError::File`] for `path`.
    pub fn file(path: &std::path::Path, message: impl Into<String>) -> Self {
        Self::File {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}
