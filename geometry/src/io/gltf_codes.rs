//! The numeric codes of the glTF 2.0 specification that the glTF writers and readers name
//! (buffer-view targets, accessor component types, primitive modes).

/// `bufferView.target` of vertex attributes.
pub const ARRAY_BUFFER: u32 = 34962;
/// `bufferView.target` of indices.
pub const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// `accessor.componentType`: signed 8-bit.
pub const BYTE: u32 = 5120;
/// `accessor.componentType`: unsigned 8-bit.
pub const UNSIGNED_BYTE: u32 = 5121;
/// `accessor.componentType`: signed 16-bit.
pub const SHORT: u32 = 5122;
/// `accessor.componentType`: unsigned 16-bit.
pub const UNSIGNED_SHORT: u32 = 5123;
/// `accessor.componentType`: unsigned 32-bit.
pub const UNSIGNED_INT: u32 = 5125;
/// `accessor.componentType`: 32-bit float.
pub const FLOAT: u32 = 5126;
/// `primitive.mode`: points.
pub const POINTS: u32 = 0;
/// `primitive.mode`: triangles.
pub const TRIANGLES: u32 = 4;
