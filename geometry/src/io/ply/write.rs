//! Writing PLY: whole documents, and single elements from borrowed columns block by block.

use std::fmt;
use std::io::Write;
use std::path::Path;

use glam::Vec3;

use super::header::BLOCK_BYTES;
use super::model::{PlyDocument, PlyEncoding, PropertyData, ScalarColumn, ScalarType, write_float};
use crate::io::error::IoError;

impl fmt::Display for ScalarType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.ply_name())
    }
}

/// Writes `doc` with `encoding` (the document's own encoding is ignored).
///
/// # Errors
/// [`IoError::Malformed`] when a property does not have one row per element row,
/// [`IoError::Os`] when writing fails.
pub fn write_ply_document(
    path: &Path,
    out: &mut dyn Write,
    doc: &PlyDocument,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    let os = |e| IoError::os(path, e);
    let mut head = String::new();
    head.push_str("ply\n");
    head.push_str(&format!("format {} 1.0\n", encoding.header_name()));
    for c in &doc.comments {
        head.push_str(&format!("comment {}\n", c.replace('\n', " ")));
    }
    for c in &doc.obj_info {
        head.push_str(&format!("obj_info {}\n", c.replace('\n', " ")));
    }
    for e in &doc.elements {
        head.push_str(&format!("element {} {}\n", e.name, e.count));
        for p in &e.properties {
            if p.data.rows() != e.count {
                return Err(IoError::malformed(
                    path,
                    format!("element {}", e.name),
                    format!(
                        "property `{}` has {} rows, the element {}",
                        p.name,
                        p.data.rows(),
                        e.count
                    ),
                ));
            }
            match &p.data {
                PropertyData::Scalar(c) => {
                    head.push_str(&format!("property {} {}\n", c.scalar_type(), p.name));
                }
                PropertyData::List {
                    count_type, values, ..
                } => head.push_str(&format!(
                    "property list {} {} {}\n",
                    count_type,
                    values.scalar_type(),
                    p.name
                )),
            }
        }
    }
    head.push_str("end_header\n");
    out.write_all(head.as_bytes()).map_err(os)?;

    let big = encoding == PlyEncoding::BinaryBigEndian;
    let ascii = encoding == PlyEncoding::Ascii;
    let mut buf = Vec::with_capacity(1 << 16);
    for e in &doc.elements {
        if !ascii {
            let scalars: Option<Vec<ColumnView<'_>>> = e
                .properties
                .iter()
                .map(|p| match &p.data {
                    PropertyData::Scalar(c) => Some(ColumnView::Column(c)),
                    PropertyData::List { .. } => None,
                })
                .collect();
            if let Some(columns) = scalars {
                out.write_all(&buf).map_err(os)?;
                buf.clear();
                write_fixed_rows(out, &columns, e.count, big).map_err(os)?;
                continue;
            }
        }
        for row in 0..e.count {
            for (k, p) in e.properties.iter().enumerate() {
                if ascii && k > 0 {
                    buf.push(b' ');
                }
                match &p.data {
                    PropertyData::Scalar(c) => {
                        if ascii {
                            c.write_ascii(row, &mut buf);
                        } else {
                            c.write_binary(row, &mut buf, big);
                        }
                    }
                    PropertyData::List {
                        count_type,
                        offsets,
                        values,
                    } => {
                        let (a, b) = (offsets[row], offsets[row + 1]);
                        let n = b - a;
                        write_count(path, *count_type, n, ascii, big, &mut buf, &e.name, row)?;
                        for i in a..b {
                            if ascii {
                                buf.push(b' ');
                                values.write_ascii(i, &mut buf);
                            } else {
                                values.write_binary(i, &mut buf, big);
                            }
                        }
                    }
                }
            }
            if ascii {
                buf.push(b'\n');
            }
            if buf.len() >= 1 << 16 {
                out.write_all(&buf).map_err(os)?;
                buf.clear();
            }
        }
    }
    out.write_all(&buf).map_err(os)?;
    Ok(())
}

/// The values of one scalar property to write, borrowed: a stored column, or every `stride`-th
/// `f32` of `values` from `offset` on (quaternions, interleaved coefficients), or one component
/// of a slice of vectors, so data kept in another layout is written without being copied into
/// columns.
#[derive(Clone, Copy, Debug)]
pub enum ColumnView<'a> {
    /// A stored column.
    Column(&'a ScalarColumn),
    /// Row `i` is component `axis` (0 = x) of `values[i]`.
    Vec3Axis {
        /// The vectors.
        values: &'a [Vec3],
        /// Which component.
        axis: usize,
    },
    /// Row `i` is `values[offset + i * stride]`.
    StridedF32 {
        /// The values.
        values: &'a [f32],
        /// Index of row 0's value.
        offset: usize,
        /// Distance between consecutive rows' values.
        stride: usize,
    },
}

impl ColumnView<'_> {
    /// The type written.
    #[must_use]
    pub fn scalar_type(&self) -> ScalarType {
        match self {
            Self::Column(c) => c.scalar_type(),
            Self::Vec3Axis { .. } | Self::StridedF32 { .. } => ScalarType::F32,
        }
    }

    /// Number of rows the view holds.
    #[must_use]
    pub fn rows(&self) -> usize {
        match *self {
            Self::Column(c) => c.len(),
            Self::Vec3Axis { values, .. } => values.len(),
            Self::StridedF32 {
                values,
                offset,
                stride,
            } => values.len().saturating_sub(offset).div_ceil(stride.max(1)),
        }
    }

    /// As [`ScalarColumn`]'s `write_strided`, for rows `first..first + rows`.
    fn write_strided(
        &self,
        first: usize,
        rows: usize,
        block: &mut [u8],
        offset: usize,
        stride: usize,
        big_endian: bool,
    ) {
        match *self {
            Self::Column(c) => c.write_strided(first, rows, block, offset, stride, big_endian),
            _ => {
                for r in 0..rows {
                    let x = self.f32_at(first + r);
                    let bytes = if big_endian {
                        x.to_be_bytes()
                    } else {
                        x.to_le_bytes()
                    };
                    let at = offset + r * stride;
                    block[at..at + 4].copy_from_slice(&bytes);
                }
            }
        }
    }

    /// Row `i` of a float view (0 for a stored column, which is written by its own code).
    fn f32_at(&self, i: usize) -> f32 {
        match *self {
            Self::Column(_) => 0.0,
            Self::Vec3Axis { values, axis } => values[i][axis],
            Self::StridedF32 {
                values,
                offset,
                stride,
            } => values[offset + i * stride],
        }
    }

    fn write_ascii(&self, i: usize, out: &mut Vec<u8>) {
        match *self {
            Self::Column(c) => c.write_ascii(i, out),
            _ => {
                let x = self.f32_at(i);
                write_float(out, f64::from(x), x);
            }
        }
    }
}

/// Writes a PLY file of one element whose properties are all scalars, from borrowed columns
/// (binary: block by block, column by column).
///
/// # Errors
/// [`IoError::Malformed`] when a property holds fewer than `count` rows, [`IoError::Os`] when
/// writing fails.
pub fn write_ply_columns(
    path: &Path,
    out: &mut dyn Write,
    encoding: PlyEncoding,
    element: &str,
    count: usize,
    properties: &[(&str, ColumnView<'_>)],
) -> Result<(), IoError> {
    let os = |e| IoError::os(path, e);
    let mut head = format!(
        "ply\nformat {} 1.0\nelement {element} {count}\n",
        encoding.header_name()
    );
    for (name, view) in properties {
        if view.rows() < count {
            return Err(IoError::malformed(
                path,
                format!("element {element}"),
                format!(
                    "property `{name}` has {} rows, the element {count}",
                    view.rows()
                ),
            ));
        }
        head.push_str(&format!("property {} {name}\n", view.scalar_type()));
    }
    head.push_str("end_header\n");
    out.write_all(head.as_bytes()).map_err(os)?;
    let views: Vec<ColumnView<'_>> = properties.iter().map(|(_, v)| *v).collect();
    match encoding {
        PlyEncoding::Ascii => {
            let mut buf = Vec::with_capacity(1 << 16);
            for row in 0..count {
                for (k, v) in views.iter().enumerate() {
                    if k > 0 {
                        buf.push(b' ');
                    }
                    v.write_ascii(row, &mut buf);
                }
                buf.push(b'\n');
                if buf.len() >= 1 << 16 {
                    out.write_all(&buf).map_err(os)?;
                    buf.clear();
                }
            }
            out.write_all(&buf).map_err(os)
        }
        PlyEncoding::BinaryLittleEndian => write_fixed_rows(out, &views, count, false).map_err(os),
        PlyEncoding::BinaryBigEndian => write_fixed_rows(out, &views, count, true).map_err(os),
    }
}

/// Writes `count` binary rows of scalar columns (each checked to hold `count` values), block by
/// block, column by column.
fn write_fixed_rows(
    out: &mut dyn Write,
    columns: &[ColumnView<'_>],
    count: usize,
    big: bool,
) -> std::io::Result<()> {
    let stride: usize = columns.iter().map(|c| c.scalar_type().size()).sum();
    if stride == 0 {
        return Ok(());
    }
    let block_rows = (BLOCK_BYTES / stride).max(1);
    let mut block = vec![0u8; block_rows.min(count) * stride];
    let mut first = 0;
    while first < count {
        let rows = block_rows.min(count - first);
        let bytes = &mut block[..rows * stride];
        let mut offset = 0;
        for c in columns {
            c.write_strided(first, rows, bytes, offset, stride, big);
            offset += c.scalar_type().size();
        }
        out.write_all(bytes)?;
        first += rows;
    }
    Ok(())
}

#[expect(clippy::too_many_arguments, reason = "a private helper of one loop")]
fn write_count(
    path: &Path,
    ty: ScalarType,
    n: usize,
    ascii: bool,
    big: bool,
    buf: &mut Vec<u8>,
    element: &str,
    row: usize,
) -> Result<(), IoError> {
    let too_long = || {
        IoError::malformed(
            path,
            format!("{element} {row}"),
            format!("list of {n} items does not fit a {ty} count"),
        )
    };
    let column = match ty {
        ScalarType::U8 => ScalarColumn::U8(vec![u8::try_from(n).map_err(|_| too_long())?]),
        ScalarType::I8 => ScalarColumn::I8(vec![i8::try_from(n).map_err(|_| too_long())?]),
        ScalarType::U16 => ScalarColumn::U16(vec![u16::try_from(n).map_err(|_| too_long())?]),
        ScalarType::I16 => ScalarColumn::I16(vec![i16::try_from(n).map_err(|_| too_long())?]),
        ScalarType::U32 => ScalarColumn::U32(vec![u32::try_from(n).map_err(|_| too_long())?]),
        ScalarType::I32 | ScalarType::F32 | ScalarType::F64 => {
            ScalarColumn::I32(vec![i32::try_from(n).map_err(|_| too_long())?])
        }
    };
    if ascii {
        column.write_ascii(0, buf);
    } else {
        column.write_binary(0, buf, big);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::ply::{PlyElement, PlyProperty, parse_ply};

    /// Borrowed views write what the same values as stored columns write, in every encoding;
    /// a view shorter than the element is refused naming the property.
    #[test]
    fn column_views_write_as_columns_do() {
        let vectors = [Vec3::new(1.0, 2.0, 3.0), Vec3::new(-4.5, 1e-30, 6.0)];
        let quats = [0.5f32, 0.1, 0.2, 0.3, 0.25, 1e20, 0.0, -0.75];
        let ids = ScalarColumn::U8(vec![7, 200]);
        let views = [
            (
                "y",
                ColumnView::Vec3Axis {
                    values: &vectors,
                    axis: 1,
                },
            ),
            (
                "r1",
                ColumnView::StridedF32 {
                    values: &quats,
                    offset: 1,
                    stride: 4,
                },
            ),
            ("id", ColumnView::Column(&ids)),
        ];
        let stored = PlyDocument {
            elements: vec![PlyElement {
                name: "vertex".into(),
                count: 2,
                properties: [
                    ("y", ScalarColumn::F32(vec![2.0, 1e-30])),
                    ("r1", ScalarColumn::F32(vec![0.1, 1e20])),
                    ("id", ids.clone()),
                ]
                .into_iter()
                .map(|(name, c)| PlyProperty {
                    name: name.into(),
                    data: PropertyData::Scalar(c),
                })
                .collect(),
            }],
            ..PlyDocument::default()
        };
        let path = Path::new("v.ply");
        for encoding in [
            PlyEncoding::Ascii,
            PlyEncoding::BinaryLittleEndian,
            PlyEncoding::BinaryBigEndian,
        ] {
            let (mut a, mut b) = (Vec::new(), Vec::new());
            write_ply_columns(path, &mut a, encoding, "vertex", 2, &views).expect("views");
            write_ply_document(path, &mut b, &stored, encoding).expect("columns");
            assert_eq!(a, b, "{encoding:?}");
            let back = parse_ply(path, &a).expect("reads back");
            assert_eq!(back.elements, stored.elements, "{encoding:?}");
        }
        let err = write_ply_columns(
            path,
            &mut Vec::new(),
            PlyEncoding::Ascii,
            "vertex",
            3,
            &views,
        )
        .expect_err("too few rows");
        assert!(
            err.to_string().contains("`y` has 2 rows, the element 3"),
            "{err}"
        );
    }
}
