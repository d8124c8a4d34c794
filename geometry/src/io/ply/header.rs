//! The PLY header: element and property declarations, parsed and checked, and the size
//! limits (header length, block size) the reader and writer share.

use std::path::Path;

use super::model::{PlyEncoding, ScalarType};
use crate::io::error::IoError;

#[derive(Clone, Debug)]
pub(super) enum PropKind {
    Scalar(ScalarType),
    List { count: ScalarType, item: ScalarType },
}

#[derive(Clone, Debug)]
pub(super) struct PropDef {
    pub(super) name: String,
    pub(super) kind: PropKind,
}

#[derive(Clone, Debug)]
pub(super) struct ElementDef {
    pub(super) name: String,
    pub(super) count: usize,
    pub(super) props: Vec<PropDef>,
}

pub(super) struct Header {
    pub(super) encoding: PlyEncoding,
    pub(super) comments: Vec<String>,
    pub(super) obj_info: Vec<String>,
    pub(super) elements: Vec<ElementDef>,
    pub(super) body_start: usize,
}

/// Rows of fixed-size elements are read and written in blocks of about this many bytes, so
/// that each block stays in cache while it is decoded or encoded column by column.
pub(super) const BLOCK_BYTES: usize = 1 << 18;

/// Longest header we accept (real headers are a few kilobytes at most).
const MAX_HEADER_BYTES: usize = 1 << 20;

pub(super) fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, IoError> {
    let bad =
        |line: usize, msg: String| IoError::malformed(path, format!("header line {line}"), msg);
    if !bytes.starts_with(b"ply") {
        return Err(IoError::malformed(
            path,
            "header line 1",
            "not a PLY file (it does not start with `ply`)",
        ));
    }
    let mut pos = 0;
    let mut line_no = 0;
    let mut encoding = None;
    let mut comments = Vec::new();
    let mut obj_info = Vec::new();
    let mut elements: Vec<ElementDef> = Vec::new();
    loop {
        if pos >= bytes.len() || pos > MAX_HEADER_BYTES {
            return Err(bad(
                line_no + 1,
                "the header has no `end_header` line (truncated file?)".into(),
            ));
        }
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| pos + i);
        let raw = &bytes[pos..end];
        pos = (end + 1).min(bytes.len() + 1);
        line_no += 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| bad(line_no, "header is not ASCII text".into()))?
            .trim_end_matches('\r');
        let mut words = line.split_ascii_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        match keyword {
            "ply" if line_no == 1 => {}
            "format" => {
                let enc = match words.next() {
                    Some("ascii") => PlyEncoding::Ascii,
                    Some("binary_little_endian") => PlyEncoding::BinaryLittleEndian,
                    Some("binary_big_endian") => PlyEncoding::BinaryBigEndian,
                    other => {
                        return Err(bad(
                            line_no,
                            format!("unknown format {:?}", other.unwrap_or("")),
                        ));
                    }
                };
                encoding = Some(enc);
            }
            "comment" => comments.push(rest_of(line, "comment")),
            "obj_info" => obj_info.push(rest_of(line, "obj_info")),
            "element" => {
                let name = words
                    .next()
                    .ok_or_else(|| bad(line_no, "element without a name".into()))?;
                let count = words
                    .next()
                    .and_then(|c| c.parse::<usize>().ok())
                    .ok_or_else(|| {
                        bad(
                            line_no,
                            format!("element `{name}` needs a non-negative count"),
                        )
                    })?;
                elements.push(ElementDef {
                    name: name.to_owned(),
                    count,
                    props: Vec::new(),
                });
            }
            "property" => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| bad(line_no, "property before any element".into()))?;
                let ty = words.next().unwrap_or("");
                let kind = if ty == "list" {
                    let count = words.next().and_then(ScalarType::from_ply_name);
                    let item = words.next().and_then(ScalarType::from_ply_name);
                    match (count, item) {
                        (Some(count), Some(item)) if count.is_integer() => {
                            PropKind::List { count, item }
                        }
                        _ => {
                            return Err(bad(line_no, format!("bad list property `{line}`")));
                        }
                    }
                } else {
                    PropKind::Scalar(
                        ScalarType::from_ply_name(ty)
                            .ok_or_else(|| bad(line_no, format!("unknown property type `{ty}`")))?,
                    )
                };
                let name = words
                    .next()
                    .ok_or_else(|| bad(line_no, "property without a name".into()))?;
                element.props.push(PropDef {
                    name: name.to_owned(),
                    kind,
                });
            }
            "end_header" => break,
            other => {
                return Err(bad(line_no, format!("unknown header keyword `{other}`")));
            }
        }
    }
    let encoding =
        encoding.ok_or_else(|| bad(line_no, "the header has no `format` line".into()))?;
    Ok(Header {
        encoding,
        comments,
        obj_info,
        elements,
        body_start: pos.min(bytes.len()),
    })
}

fn rest_of(line: &str, keyword: &str) -> String {
    line.trim_start()
        .strip_prefix(keyword)
        .unwrap_or("")
        .strip_prefix(' ')
        .unwrap_or("")
        .to_owned()
}
