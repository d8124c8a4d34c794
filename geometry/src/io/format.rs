//! The mesh file formats and how a path's extension names one.

use std::path::Path;

use super::error::IoError;

/// Mesh file formats known by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Format {
    /// Stanford PLY (`.ply`).
    Ply,
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// glTF 2.0 JSON with external or embedded buffers (`.gltf`).
    Gltf,
    /// Binary glTF (`.glb`).
    Glb,
}

impl Format {
    /// The format of `path` from its extension (case-insensitive).
    ///
    /// # Errors
    /// [`IoError::UnknownFormat`] when the extension is missing or unsupported.
    pub fn from_path(path: &Path) -> Result<Self, IoError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("ply") => Ok(Self::Ply),
            Some("obj") => Ok(Self::Obj),
            Some("gltf") => Ok(Self::Gltf),
            Some("glb") => Ok(Self::Glb),
            _ => Err(IoError::UnknownFormat {
                path: path.to_path_buf(),
            }),
        }
    }
}
