//! Reading a PLY body (ascii or binary) into a [`PlyDocument`], every element count checked
//! against the bytes left before anything is allocated from it.

use std::path::Path;

use super::header::{BLOCK_BYTES, ElementDef, Header, PropDef, PropKind, parse_header};
use super::model::{
    PlyDocument, PlyElement, PlyEncoding, PlyProperty, PropertyData, ScalarColumn, ScalarType,
    float_to_i64,
};
use crate::io::error::IoError;

fn new_data(def: &PropDef, capacity: usize) -> PropertyData {
    match def.kind {
        PropKind::Scalar(t) => PropertyData::Scalar(ScalarColumn::with_capacity(t, capacity)),
        PropKind::List { count, item } => {
            let mut offsets = Vec::with_capacity(capacity + 1);
            offsets.push(0);
            PropertyData::List {
                count_type: count,
                offsets,
                values: ScalarColumn::with_capacity(item, capacity.saturating_mul(3)),
            }
        }
    }
}

pub(super) fn count_limit_error(path: &Path, def: &ElementDef, possible: usize) -> IoError {
    IoError::malformed(
        path,
        format!("element {}", def.name),
        format!(
            "the header declares {} rows but the rest of the file can hold at most {possible} \
             (truncated file or wrong count)",
            def.count
        ),
    )
}

fn read_binary_body(
    path: &Path,
    header: &Header,
    body: &[u8],
    big_endian: bool,
) -> Result<Vec<PlyElement>, IoError> {
    let mut pos = 0usize;
    let mut elements = Vec::with_capacity(header.elements.len());
    for def in &header.elements {
        let min_row: usize = def
            .props
            .iter()
            .map(|p| match p.kind {
                PropKind::Scalar(t) => t.size(),
                PropKind::List { count, .. } => count.size(),
            })
            .sum();
        let left = body.len() - pos;
        if min_row > 0 && def.count > left / min_row {
            return Err(count_limit_error(path, def, left / min_row));
        }
        let capacity = if min_row == 0 { 0 } else { def.count };
        let mut data: Vec<PropertyData> = def.props.iter().map(|p| new_data(p, capacity)).collect();
        if def
            .props
            .iter()
            .all(|p| matches!(p.kind, PropKind::Scalar(_)))
        {
            // Fixed-size rows (checked above to fit): decoded block by block, column by column.
            let stride = min_row;
            let block_rows = (BLOCK_BYTES / stride.max(1)).max(1);
            let mut first = 0;
            while first < def.count && stride > 0 {
                let rows = block_rows.min(def.count - first);
                let block = &body[pos..pos + rows * stride];
                let mut offset = 0;
                for column in &mut data {
                    if let PropertyData::Scalar(c) = column {
                        c.extend_strided(block, offset, stride, rows, big_endian);
                        offset += c.scalar_type().size();
                    }
                }
                pos += rows * stride;
                first += rows;
            }
            elements.push(finish_element(def, data));
            continue;
        }
        let truncated = |row: usize| {
            IoError::malformed(
                path,
                format!("{} {row}", def.name),
                "file ends early (truncated)",
            )
        };
        for row in 0..def.count {
            for (prop, column) in def.props.iter().zip(&mut data) {
                match column {
                    PropertyData::Scalar(c) => {
                        let size = c.scalar_type().size();
                        let bytes = body.get(pos..pos + size).ok_or_else(|| truncated(row))?;
                        c.push_binary(bytes, big_endian);
                        pos += size;
                    }
                    PropertyData::List {
                        count_type,
                        offsets,
                        values,
                    } => {
                        let size = count_type.size();
                        let bytes = body.get(pos..pos + size).ok_or_else(|| truncated(row))?;
                        pos += size;
                        let n = binary_count(*count_type, bytes, big_endian).unwrap_or(-1);
                        let n = usize::try_from(n).map_err(|_| {
                            IoError::malformed(
                                path,
                                format!("{} {row}", def.name),
                                format!("negative list length {n} in `{}`", prop.name),
                            )
                        })?;
                        let item = values.scalar_type().size();
                        let len = n.saturating_mul(item);
                        if len > body.len() - pos {
                            return Err(truncated(row));
                        }
                        values.extend_strided(&body[pos..pos + len], 0, item, n, big_endian);
                        pos += len;
                        offsets.push(values.len());
                    }
                }
            }
        }
        elements.push(finish_element(def, data));
    }
    Ok(elements)
}

/// A list length of type `t` from its first bytes, as [`ScalarColumn`]'s integer view reads
/// it (floats only when integral), without a column per row.
fn binary_count(t: ScalarType, bytes: &[u8], big_endian: bool) -> Option<i64> {
    macro_rules! read {
        ($t:ty) => {{
            let mut a = [0u8; std::mem::size_of::<$t>()];
            a.copy_from_slice(bytes.get(..std::mem::size_of::<$t>())?);
            if big_endian {
                <$t>::from_be_bytes(a)
            } else {
                <$t>::from_le_bytes(a)
            }
        }};
    }
    match t {
        ScalarType::I8 => Some(i64::from(read!(i8))),
        ScalarType::U8 => Some(i64::from(read!(u8))),
        ScalarType::I16 => Some(i64::from(read!(i16))),
        ScalarType::U16 => Some(i64::from(read!(u16))),
        ScalarType::I32 => Some(i64::from(read!(i32))),
        ScalarType::U32 => Some(i64::from(read!(u32))),
        ScalarType::F32 => float_to_i64(f64::from(read!(f32))),
        ScalarType::F64 => float_to_i64(read!(f64)),
    }
}

fn finish_element(def: &ElementDef, data: Vec<PropertyData>) -> PlyElement {
    PlyElement {
        name: def.name.clone(),
        count: def.count,
        properties: def
            .props
            .iter()
            .zip(data)
            .map(|(p, data)| PlyProperty {
                name: p.name.clone(),
                data,
            })
            .collect(),
    }
}

fn read_ascii_body(path: &Path, header: &Header, body: &[u8]) -> Result<Vec<PlyElement>, IoError> {
    let mut tokens = AsciiTokens { body, pos: 0 };
    let mut elements = Vec::with_capacity(header.elements.len());
    for def in &header.elements {
        // Each scalar needs at least one character and one separator.
        let min_row = def.props.len() * 2;
        let left = body.len() - tokens.pos;
        if min_row > 0 && def.count > left / min_row + 1 {
            return Err(count_limit_error(path, def, left / min_row + 1));
        }
        let capacity = if min_row == 0 { 0 } else { def.count };
        let mut data: Vec<PropertyData> = def.props.iter().map(|p| new_data(p, capacity)).collect();
        for row in 0..def.count {
            let at = |msg: String| IoError::malformed(path, format!("{} {row}", def.name), msg);
            for (prop, column) in def.props.iter().zip(&mut data) {
                let mut next = || -> Result<&str, IoError> {
                    match tokens.next() {
                        Some(Ok(t)) => Ok(t),
                        Some(Err(())) => Err(at("the body is not ASCII text".into())),
                        None => Err(at("file ends early (truncated)".into())),
                    }
                };
                match column {
                    PropertyData::Scalar(c) => {
                        let token = next()?;
                        if !c.push_token(token) {
                            return Err(at(format!(
                                "`{token}` is not a valid {} for `{}`",
                                c.scalar_type(),
                                prop.name
                            )));
                        }
                    }
                    PropertyData::List {
                        offsets, values, ..
                    } => {
                        let token = next()?;
                        let n: usize = token.parse().map_err(|_| {
                            at(format!(
                                "`{token}` is not a list length for `{}`",
                                prop.name
                            ))
                        })?;
                        for _ in 0..n {
                            let token = next()?;
                            if !values.push_token(token) {
                                return Err(at(format!(
                                    "`{token}` is not a valid {} in `{}`",
                                    values.scalar_type(),
                                    prop.name
                                )));
                            }
                        }
                        offsets.push(values.len());
                    }
                }
            }
        }
        elements.push(finish_element(def, data));
    }
    Ok(elements)
}

struct AsciiTokens<'a> {
    body: &'a [u8],
    pos: usize,
}

impl<'a> AsciiTokens<'a> {
    fn next(&mut self) -> Option<Result<&'a str, ()>> {
        let b = self.body;
        while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        if self.pos >= b.len() {
            return None;
        }
        let start = self.pos;
        while self.pos < b.len() && !b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Some(std::str::from_utf8(&b[start..self.pos]).map_err(|_| ()))
    }
}

/// Parses a whole PLY file already in memory.
///
/// # Errors
/// [`IoError::Malformed`] naming the header line or the element row at fault.
pub fn parse_ply(path: &Path, bytes: &[u8]) -> Result<PlyDocument, IoError> {
    let header = parse_header(path, bytes)?;
    let body = &bytes[header.body_start..];
    let elements = match header.encoding {
        PlyEncoding::Ascii => read_ascii_body(path, &header, body)?,
        PlyEncoding::BinaryLittleEndian => read_binary_body(path, &header, body, false)?,
        PlyEncoding::BinaryBigEndian => read_binary_body(path, &header, body, true)?,
    };
    Ok(PlyDocument {
        encoding: header.encoding,
        comments: header.comments,
        obj_info: header.obj_info,
        elements,
    })
}

/// Reads a whole PLY file into a [`PlyDocument`].
///
/// # Errors
/// [`IoError::Os`] when the file cannot be read, [`IoError::Malformed`] naming the header line
/// or element row at fault.
pub fn read_ply_document(path: &Path) -> Result<PlyDocument, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::os(path, e))?;
    parse_ply(path, &bytes)
}
