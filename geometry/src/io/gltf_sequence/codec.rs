//! `EXT_meshopt_compression` through the `meshopt` crate: a block's bytes in the bitstream of
//! its mode (ATTRIBUTES: vertex codec version 0, header `0xa0`, as the extension specifies;
//! TRIANGLES: index codec version 1, header `0xe1`).

use std::path::Path;

use super::blocks::{Block, Codec};
use crate::io::error::IoError;

/// The extension's name for `codec`.
pub(super) fn mode_name(codec: Codec) -> &'static str {
    match codec {
        Codec::Attributes => "ATTRIBUTES",
        Codec::Triangles(_) => "TRIANGLES",
    }
}

/// `block` compressed in its mode; errors name `path` and `element` (the view).
pub(super) fn encode(path: &Path, element: &str, block: &Block) -> Result<Vec<u8>, IoError> {
    let failed = |what: String| IoError::malformed(path, element, what);
    let encoded = match block.codec {
        Codec::Attributes => match block.stride {
            4 => attributes::<4>(&block.bytes),
            8 => attributes::<8>(&block.bytes),
            12 => attributes::<12>(&block.bytes),
            16 => attributes::<16>(&block.bytes),
            s => return Err(failed(format!("no meshopt attribute stride {s}"))),
        },
        Codec::Triangles(vertex_count) => {
            let indices: Vec<u32> = match block.stride {
                2 => block
                    .bytes
                    .chunks_exact(2)
                    .map(|c| u32::from(u16::from_le_bytes([c[0], c[1]])))
                    .collect(),
                _ => block
                    .bytes
                    .chunks_exact(4)
                    .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect(),
            };
            meshopt::encode_index_buffer(&indices, vertex_count)
        }
    };
    encoded.map_err(|e| failed(format!("meshopt could not encode it: {e}")))
}

/// The vertex codec (version 0, the one `EXT_meshopt_compression` reads) over elements of `N`
/// bytes.
fn attributes<const N: usize>(bytes: &[u8]) -> meshopt::Result<Vec<u8>> {
    let elements: Vec<[u8; N]> = bytes
        .chunks_exact(N)
        .map(|c| {
            let mut e = [0u8; N];
            e.copy_from_slice(c);
            e
        })
        .collect();
    meshopt::encode_vertex_buffer_level(&elements, 2, Some(0))
}
