//! The file around a built document: `.glb` (a JSON chunk and a binary chunk, the buffer
//! streamed in a second pass or copied from a spool) or `.gltf` (the buffer as a base64 data
//! URI), written atomically.

use std::path::Path;

use base64::Engine as _;

use super::builder::Document;
use super::sink::{Sink, Spool, Stream};
use crate::io::atomic::write_atomically;
use crate::io::error::IoError;

/// The GLB header and JSON chunk of `doc` and the binary chunk's header for `bin_len` bytes;
/// returns the bytes to write before the buffer and the buffer's padding.
fn glb_head(path: &Path, doc: &Document, bin_len: usize) -> Result<(Vec<u8>, usize), IoError> {
    let mut json = serde_json::to_vec(doc).map_err(|e| IoError::os(path, e.into()))?;
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let padding = (4 - bin_len % 4) % 4;
    let padded = bin_len + padding;
    let total = 12 + 8 + json.len() + 8 + padded;
    let too_big = || IoError::Unsupported {
        path: path.to_path_buf(),
        what: format!("a {total}-byte GLB (the format holds at most 4 GiB)"),
    };
    let total32 = u32::try_from(total).map_err(|_| too_big())?;
    let json_len = u32::try_from(json.len()).map_err(|_| too_big())?;
    let bin_len32 = u32::try_from(padded).map_err(|_| too_big())?;
    let mut head = Vec::with_capacity(28 + json.len());
    head.extend_from_slice(b"glTF");
    head.extend_from_slice(&2u32.to_le_bytes());
    head.extend_from_slice(&total32.to_le_bytes());
    head.extend_from_slice(&json_len.to_le_bytes());
    head.extend_from_slice(b"JSON");
    head.extend_from_slice(&json);
    head.extend_from_slice(&bin_len32.to_le_bytes());
    head.extend_from_slice(b"BIN\0");
    Ok((head, padding))
}

/// Writes the document and a buffer of `bin_len` bytes, produced by `fill` into the sink it is
/// given, as `.glb` (JSON chunk padded with spaces, binary chunk with zeros, both to 4 bytes).
pub(super) fn write_glb(
    path: &Path,
    doc: &Document,
    bin_len: usize,
    fill: impl Fn(&mut dyn Sink) -> Result<(), IoError>,
) -> Result<(), IoError> {
    let (head, padding) = glb_head(path, doc, bin_len)?;
    write_atomically(path, |w| {
        w.write_all(&head).map_err(|e| IoError::os(path, e))?;
        let mut stream = Stream {
            out: &mut *w,
            path,
            written: 0,
        };
        fill(&mut stream)?;
        if stream.written != bin_len {
            return Err(IoError::malformed(
                path,
                "buffer",
                format!(
                    "the frames gave {} bytes on the second reading, {bin_len} on the first \
                     (a frame changed while the sequence was written)",
                    stream.written
                ),
            ));
        }
        w.write_all(&[0u8; 3][..padding])
            .map_err(|e| IoError::os(path, e))
    })
}

/// Writes the document and the buffer held in `spool` as `.glb`.
pub(super) fn write_glb_spooled(
    path: &Path,
    doc: &Document,
    spool: Spool<'_>,
) -> Result<(), IoError> {
    let (head, padding) = glb_head(path, doc, spool.len)?;
    write_atomically(path, move |w| {
        w.write_all(&head).map_err(|e| IoError::os(path, e))?;
        spool.copy_to(&mut *w)?;
        w.write_all(&[0u8; 3][..padding])
            .map_err(|e| IoError::os(path, e))
    })
}

/// Writes the document as `.gltf` text with the buffer (buffer 0) embedded as a base64 data
/// URI.
pub(super) fn write_gltf(path: &Path, mut doc: Document, bin: &[u8]) -> Result<(), IoError> {
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bin)
    );
    doc.buffers[0]["byteLength"] = bin.len().into();
    doc.buffers[0]["uri"] = uri.into();
    write_atomically(path, |w| {
        serde_json::to_writer(&mut *w, &doc).map_err(|e| IoError::os(path, e.into()))
    })
}
