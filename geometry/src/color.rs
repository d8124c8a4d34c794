//! The colour type shared by meshes, point clouds, base colours and the file formats.

/// Per-vertex RGBA colour in linear `[0, 1]` floats.
pub type Rgba = [f32; 4];
