//! Mesh and point-cloud file formats: PLY (ascii, binary both endians), OBJ, glTF/GLB.
//!
//! The format is chosen from the file extension. Every reader validates what it reads (counts
//! against the bytes present, indices in range, finite coordinates) and reports the file and
//! the element at fault; every writer writes to a temporary file in the destination folder and
//! renames it into place, so a failed write never leaves a partial file.

mod atomic;
mod error;

use std::path::Path;

pub use atomic::write_atomically;
pub use error::IoError;

use crate::{PointCloud, TriMesh};

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

/// Options for writing files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriteOptions {
    /// Write PLY as ascii instead of binary little-endian.
    pub ascii: bool,
}

/// Reads a triangle mesh (PLY, OBJ, glTF/GLB in its rest state), chosen by extension.
///
/// # Errors
/// [`IoError`] naming the file and the element at fault.
pub fn read_mesh(path: &Path) -> Result<TriMesh, IoError> {
    let _ = Format::from_path(path)?;
    Err(IoError::Unsupported {
        path: path.to_path_buf(),
        what: "reading (not yet implemented)".into(),
    })
}

/// Writes a triangle mesh atomically, format by extension.
///
/// # Errors
/// [`IoError`] when the file cannot be written.
pub fn write_mesh(path: &Path, mesh: &TriMesh, options: WriteOptions) -> Result<(), IoError> {
    let _ = (Format::from_path(path)?, mesh, options);
    Err(IoError::Unsupported {
        path: path.to_path_buf(),
        what: "writing (not yet implemented)".into(),
    })
}

/// Reads a point cloud: a PLY `vertex` element with optional normals and colours, or the
/// vertices of any mesh file (with its area-weighted vertex normals when the file has none).
///
/// # Errors
/// [`IoError`] naming the file and the element at fault.
pub fn read_points(path: &Path) -> Result<PointCloud, IoError> {
    let _ = Format::from_path(path)?;
    Err(IoError::Unsupported {
        path: path.to_path_buf(),
        what: "reading (not yet implemented)".into(),
    })
}

/// Writes a point cloud as PLY (binary unless `options.ascii`), atomically.
///
/// # Errors
/// [`IoError`] when the file cannot be written.
pub fn write_points(
    path: &Path,
    points: &PointCloud,
    options: WriteOptions,
) -> Result<(), IoError> {
    let _ = (points, options);
    Err(IoError::Unsupported {
        path: path.to_path_buf(),
        what: "writing (not yet implemented)".into(),
    })
}
