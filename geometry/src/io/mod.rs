//! Mesh and point-cloud file formats: PLY (ascii, binary both endians), OBJ, glTF/GLB; and
//! Radiance `.hdr` images ([`hdr`], environment maps).
//!
//! The format is chosen from the file extension. Every reader validates what it reads (counts
//! against the bytes present, indices in range, finite coordinates) and reports the file and
//! the element at fault; every writer writes to a temporary file in the destination folder and
//! renames it into place, so a failed write never leaves a partial file.
//!
//! Per format, see [`ply`] (what PLY elements and properties become, what is kept for writing
//! back), [`obj`] (vertex order and uv seams), [`gltf`] (scene graph, primitives, rest state)
//! and [`gltf_material`] (base colour: materials, textures, corner uvs).

pub(crate) mod atomic;
pub(crate) mod error;
pub(crate) mod files;
mod format;
pub mod gltf;
pub mod gltf_codes;
pub(crate) mod gltf_data;
pub mod gltf_material;
pub mod gltf_sequence;
pub mod hdr;
mod npy;
pub mod obj;
pub mod ply;
mod rig_glb;
mod usd_sequence;

pub use atomic::{abandon_writes, write_atomically};
pub use error::IoError;
pub use files::{
    ReadOptions, WriteOptions, read_mesh, read_mesh_with, read_points, read_points_local,
    write_mesh, write_points, write_points_at,
};
pub use format::Format;
pub use gltf_material::{MAX_TEXTURE_PIXELS, read_gltf_base_color};
pub use gltf_sequence::{
    DEFAULT_MORPH_BASIS_MAX_COMPONENTS, DEFAULT_MORPH_BASIS_MIN_PAYLOAD,
    DEFAULT_MORPH_BASIS_TOLERANCE, FrameFiles, FrameSource, GLB_PART_LIMIT, GltfCompression,
    MorphBasis, SegmentSummary, SequenceLayout, SequenceOptions, SequenceSummary,
    write_mesh_sequence, write_sequence, write_sequence_parts, write_sequence_parts_summarised,
    write_sequence_parts_with, write_sequence_with,
};
pub use npy::{NpyArray, parse_npy, read_npy, write_npy};
pub use obj::ObjVertices;
pub use ply::{PlyEncoding, PlyExtras};
pub use rig_glb::{RigAnimation, RiggedMesh, write_rigged_glb};
pub use usd_sequence::{UsdCacheSummary, write_usd_sequence};
