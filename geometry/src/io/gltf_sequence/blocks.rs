//! Accessor data ready for the buffer: plain `f32` and `u32` blocks, and the quantised ones of
//! `KHR_mesh_quantization` (`SHORT` positions and deltas, normalised `BYTE` normals).

use glam::Vec3;

use crate::io::gltf_codes::{
    ARRAY_BUFFER, BYTE, ELEMENT_ARRAY_BUFFER, FLOAT, SHORT, UNSIGNED_INT, UNSIGNED_SHORT,
};

/// The name of frame `k`'s node (node per frame) or morph target (`k ≥ 1`).
pub(super) fn frame_name(k: usize) -> String {
    format!("frame_{k:06}")
}

/// An accessor's `min` or `max`: floats, or integers for integer component types.
#[derive(Clone, Debug, serde::Serialize)]
#[serde(untagged)]
pub(super) enum Bound {
    Float(Vec<f32>),
    Int(Vec<i32>),
}

/// How `EXT_meshopt_compression` encodes a block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Codec {
    /// Mode ATTRIBUTES (vertex and animation data).
    Attributes,
    /// Mode TRIANGLES (a triangle list's indices), with the vertex count they index.
    Triangles(usize),
}

/// One accessor's data, ready to be appended to the buffer.
pub(super) struct Block {
    /// The data as the accessor reads it, each element padded to `stride` bytes.
    pub(super) bytes: Vec<u8>,
    pub(super) count: usize,
    pub(super) kind: &'static str,
    pub(super) component_type: u32,
    pub(super) normalized: bool,
    pub(super) target: Option<u32>,
    /// Bytes per element (the meshopt stride).
    pub(super) stride: usize,
    /// Whether the view declares `byteStride` (vertex attributes whose elements are padded).
    pub(super) declares_stride: bool,
    pub(super) codec: Codec,
    pub(super) bounds: Option<(Bound, Bound)>,
}

/// `values` (`width` floats per element) as a float accessor block, with per-component
/// `min`/`max` when `bounds`.
pub(super) fn float_block(
    values: &[f32],
    width: usize,
    target: Option<u32>,
    bounds: bool,
) -> Block {
    let kind = match width {
        1 => "SCALAR",
        2 => "VEC2",
        3 => "VEC3",
        _ => "VEC4",
    };
    let bounds = bounds.then(|| {
        let mut min = vec![f32::INFINITY; width];
        let mut max = vec![f32::NEG_INFINITY; width];
        for element in values.chunks_exact(width) {
            for (c, &x) in element.iter().enumerate() {
                min[c] = min[c].min(x);
                max[c] = max[c].max(x);
            }
        }
        (Bound::Float(min), Bound::Float(max))
    });
    Block {
        bytes: values.iter().flat_map(|x| x.to_le_bytes()).collect(),
        count: values.len() / width,
        kind,
        component_type: FLOAT,
        normalized: false,
        target,
        stride: 4 * width,
        declares_stride: false,
        codec: Codec::Attributes,
        bounds,
    }
}

pub(super) fn vec3_block(values: &[Vec3], target: Option<u32>, bounds: bool) -> Block {
    let flat: Vec<f32> = values.iter().flat_map(|v| v.to_array()).collect();
    float_block(&flat, 3, target, bounds)
}

/// The triangles' indices: `u32`, or `u16` when `narrow` and every index fits (below 65535).
pub(super) fn index_block(triangles: &[[u32; 3]], vertex_count: usize, narrow: bool) -> Block {
    let short = narrow && vertex_count < usize::from(u16::MAX);
    let flat = triangles.iter().flatten();
    let bytes: Vec<u8> = if short {
        #[expect(
            clippy::cast_possible_truncation,
            reason = "every index is below 65535"
        )]
        flat.flat_map(|&i| (i as u16).to_le_bytes()).collect()
    } else {
        flat.flat_map(|i| i.to_le_bytes()).collect()
    };
    Block {
        bytes,
        count: triangles.len() * 3,
        kind: "SCALAR",
        component_type: if short { UNSIGNED_SHORT } else { UNSIGNED_INT },
        normalized: false,
        target: Some(ELEMENT_ARRAY_BUFFER),
        stride: if short { 2 } else { 4 },
        declares_stride: false,
        codec: Codec::Triangles(vertex_count),
        bounds: None,
    }
}

/// Integer VEC3s (`SHORT` positions or deltas), each padded to 8 bytes as the 4-byte vertex
/// alignment asks, with their exact `min`/`max`.
pub(super) fn short_block(values: &[[i16; 3]]) -> Block {
    let mut min = [i32::MAX; 3];
    let mut max = [i32::MIN; 3];
    let mut bytes = Vec::with_capacity(8 * values.len());
    for v in values {
        for (c, &x) in v.iter().enumerate() {
            min[c] = min[c].min(i32::from(x));
            max[c] = max[c].max(i32::from(x));
            bytes.extend_from_slice(&x.to_le_bytes());
        }
        bytes.extend_from_slice(&[0, 0]);
    }
    if values.is_empty() {
        (min, max) = ([0; 3], [0; 3]);
    }
    Block {
        bytes,
        count: values.len(),
        kind: "VEC3",
        component_type: SHORT,
        normalized: false,
        target: Some(ARRAY_BUFFER),
        stride: 8,
        declares_stride: true,
        codec: Codec::Attributes,
        bounds: Some((Bound::Int(min.to_vec()), Bound::Int(max.to_vec()))),
    }
}

/// Normalised `BYTE` VEC3s (normals or normal deltas), each padded to 4 bytes.
pub(super) fn byte_block(values: &[[i8; 3]]) -> Block {
    let bytes = values
        .iter()
        .flat_map(|v| {
            [
                v[0].to_le_bytes()[0],
                v[1].to_le_bytes()[0],
                v[2].to_le_bytes()[0],
                0,
            ]
        })
        .collect();
    Block {
        bytes,
        count: values.len(),
        kind: "VEC3",
        component_type: BYTE,
        normalized: true,
        target: Some(ARRAY_BUFFER),
        stride: 4,
        declares_stride: true,
        codec: Codec::Attributes,
        bounds: None,
    }
}

/// glTF wants unit normals: zero or non-finite ones become +z (as in the static writer).
pub(super) fn unit_normals(normals: &[Vec3]) -> Vec<Vec3> {
    normals
        .iter()
        .map(|v| v.try_normalize().unwrap_or(Vec3::Z))
        .collect()
}
