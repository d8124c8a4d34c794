//! Stanford PLY: a general reader and writer (ascii, binary little- and big-endian) and the
//! mapping between PLY elements and [`TriMesh`] / [`PointCloud`].
//!
//! The reader is hand-written rather than built on `ply-rs-bw` so that every failure names the
//! element and row at fault and so that no allocation is ever sized from a header count alone:
//! before an element is read, its count is checked against the bytes left in the file (each row
//! needs at least its fixed-size part in binary, at least two bytes per property in ascii).
//!
//! What becomes mesh data:
//! - `vertex`: `x y z` (any numeric type; NaN or infinite is an error naming the vertex),
//!   normals `nx ny nz`, colours `red green blue [alpha]` (integers are divided by the type's
//!   maximum, so `uchar` 255 is 1.0; floats are taken as they are), texture coordinates as
//!   `texture_u texture_v`, `u v`, `s t` or `texture_s texture_t` (the names trimesh tries).
//! - `face`: a list property `vertex_indices` or `vertex_index` of any integer types; polygons
//!   are fan-triangulated (`0 1 2`, `0 2 3`, ...), faces with fewer than three corners are
//!   skipped. An index out of range is an error naming the face.
//! - `tristrips`: a list `vertex_indices` where `-1` restarts the strip; triangle `k` of a strip
//!   is `(s[k], s[k+1], s[k+2])` for even `k` and `(s[k+1], s[k], s[k+2])` for odd `k`, and
//!   triangles with a repeated index (strip-joining degenerates) are dropped.
//!
//! Everything else is kept in [`PlyExtras`] and written back by [`write_ply_mesh`]: extra vertex
//! properties (one value per vertex), extra face properties when every face was a triangle
//! (so faces map one to one; after fan triangulation they are dropped), and whole other
//! elements verbatim. Comments and `obj_info` lines are kept too.

use std::fmt;
use std::io::Write;
use std::path::Path;

use glam::{DVec3, Vec2, Vec3};

use super::IoError;
use crate::mesh::Rgba;
use crate::{PointCloud, TriMesh};

/// How a PLY body is encoded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlyEncoding {
    /// `format ascii 1.0`.
    Ascii,
    /// `format binary_little_endian 1.0` (the default for writing).
    #[default]
    BinaryLittleEndian,
    /// `format binary_big_endian 1.0`.
    BinaryBigEndian,
}

impl PlyEncoding {
    fn header_name(self) -> &'static str {
        match self {
            Self::Ascii => "ascii",
            Self::BinaryLittleEndian => "binary_little_endian",
            Self::BinaryBigEndian => "binary_big_endian",
        }
    }
}

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalarType {
    /// `char` / `int8`.
    I8,
    /// `uchar` / `uint8`.
    U8,
    /// `short` / `int16`.
    I16,
    /// `ushort` / `uint16`.
    U16,
    /// `int` / `int32`.
    I32,
    /// `uint` / `uint32`.
    U32,
    /// `float` / `float32`.
    F32,
    /// `double` / `float64`.
    F64,
}

impl ScalarType {
    /// Size in bytes in a binary file.
    #[must_use]
    pub fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// Parses a PLY type name (both the classic and the sized spellings).
    #[must_use]
    pub fn from_ply_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    /// The classic PLY name written in headers (`uchar`, `int`, `float`, ...).
    #[must_use]
    pub fn ply_name(self) -> &'static str {
        match self {
            Self::I8 => "char",
            Self::U8 => "uchar",
            Self::I16 => "short",
            Self::U16 => "ushort",
            Self::I32 => "int",
            Self::U32 => "uint",
            Self::F32 => "float",
            Self::F64 => "double",
        }
    }

    /// Whether the type is an integer type.
    #[must_use]
    pub fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }
}

/// Values of one scalar property (or the flattened items of a list property), typed as stored.
#[derive(Clone, Debug, PartialEq)]
#[expect(
    missing_docs,
    reason = "one variant per scalar type, named like the type"
)]
pub enum ScalarColumn {
    I8(Vec<i8>),
    U8(Vec<u8>),
    I16(Vec<i16>),
    U16(Vec<u16>),
    I32(Vec<i32>),
    U32(Vec<u32>),
    F32(Vec<f32>),
    F64(Vec<f64>),
}

macro_rules! each_column {
    ($self:expr, $v:ident => $body:expr) => {
        match $self {
            ScalarColumn::I8($v) => $body,
            ScalarColumn::U8($v) => $body,
            ScalarColumn::I16($v) => $body,
            ScalarColumn::U16($v) => $body,
            ScalarColumn::I32($v) => $body,
            ScalarColumn::U32($v) => $body,
            ScalarColumn::F32($v) => $body,
            ScalarColumn::F64($v) => $body,
        }
    };
}

impl ScalarColumn {
    /// The values at `indices`, in that order (indices past the end are skipped).
    #[must_use]
    pub fn gather(&self, indices: &[usize]) -> Self {
        macro_rules! gathered {
            ($($variant:ident),*) => {
                match self {
                    $(Self::$variant(v) => {
                        Self::$variant(indices.iter().filter_map(|&i| v.get(i).copied()).collect())
                    })*
                }
            };
        }
        gathered!(I8, U8, I16, U16, I32, U32, F32, F64)
    }

    /// An empty column of type `ty` with room for `capacity` values.
    #[must_use]
    pub fn with_capacity(ty: ScalarType, capacity: usize) -> Self {
        match ty {
            ScalarType::I8 => Self::I8(Vec::with_capacity(capacity)),
            ScalarType::U8 => Self::U8(Vec::with_capacity(capacity)),
            ScalarType::I16 => Self::I16(Vec::with_capacity(capacity)),
            ScalarType::U16 => Self::U16(Vec::with_capacity(capacity)),
            ScalarType::I32 => Self::I32(Vec::with_capacity(capacity)),
            ScalarType::U32 => Self::U32(Vec::with_capacity(capacity)),
            ScalarType::F32 => Self::F32(Vec::with_capacity(capacity)),
            ScalarType::F64 => Self::F64(Vec::with_capacity(capacity)),
        }
    }

    /// The stored type.
    #[must_use]
    pub fn scalar_type(&self) -> ScalarType {
        match self {
            Self::I8(_) => ScalarType::I8,
            Self::U8(_) => ScalarType::U8,
            Self::I16(_) => ScalarType::I16,
            Self::U16(_) => ScalarType::U16,
            Self::I32(_) => ScalarType::I32,
            Self::U32(_) => ScalarType::U32,
            Self::F32(_) => ScalarType::F32,
            Self::F64(_) => ScalarType::F64,
        }
    }

    /// Number of values.
    #[must_use]
    pub fn len(&self) -> usize {
        each_column!(self, v => v.len())
    }

    /// True when there are no values.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Value `i` as f64 (exact for every PLY type), `None` when out of range.
    #[must_use]
    pub fn get_f64(&self, i: usize) -> Option<f64> {
        match self {
            Self::I8(v) => v.get(i).map(|&x| f64::from(x)),
            Self::U8(v) => v.get(i).map(|&x| f64::from(x)),
            Self::I16(v) => v.get(i).map(|&x| f64::from(x)),
            Self::U16(v) => v.get(i).map(|&x| f64::from(x)),
            Self::I32(v) => v.get(i).map(|&x| f64::from(x)),
            Self::U32(v) => v.get(i).map(|&x| f64::from(x)),
            Self::F32(v) => v.get(i).map(|&x| f64::from(x)),
            Self::F64(v) => v.get(i).copied(),
        }
    }

    /// Value `i` as i64 when it is an integer type or a float with an integral value.
    /// Every value as [`ScalarColumn::get_i64`] reads it, `-1` where it has no integer value
    /// (one pass per column instead of a type dispatch per value).
    fn to_i64_or_minus_one(&self) -> Vec<i64> {
        fn float(x: f64) -> i64 {
            float_to_i64(x).unwrap_or(-1)
        }
        match self {
            Self::F32(v) => v.iter().map(|&x| float(f64::from(x))).collect(),
            Self::F64(v) => v.iter().map(|&x| float(x)).collect(),
            Self::I8(v) => v.iter().map(|&x| i64::from(x)).collect(),
            Self::U8(v) => v.iter().map(|&x| i64::from(x)).collect(),
            Self::I16(v) => v.iter().map(|&x| i64::from(x)).collect(),
            Self::U16(v) => v.iter().map(|&x| i64::from(x)).collect(),
            Self::I32(v) => v.iter().map(|&x| i64::from(x)).collect(),
            Self::U32(v) => v.iter().map(|&x| i64::from(x)).collect(),
        }
    }

    fn get_i64(&self, i: usize) -> Option<i64> {
        match self {
            Self::F32(v) => v.get(i).and_then(|&x| float_to_i64(f64::from(x))),
            Self::F64(v) => v.get(i).and_then(|&x| float_to_i64(x)),
            Self::I8(v) => v.get(i).map(|&x| i64::from(x)),
            Self::U8(v) => v.get(i).map(|&x| i64::from(x)),
            Self::I16(v) => v.get(i).map(|&x| i64::from(x)),
            Self::U16(v) => v.get(i).map(|&x| i64::from(x)),
            Self::I32(v) => v.get(i).map(|&x| i64::from(x)),
            Self::U32(v) => v.get(i).map(|&x| i64::from(x)),
        }
    }

    /// All values converted to f64 (exact for every PLY scalar type).
    #[must_use]
    pub fn to_f64(&self) -> Vec<f64> {
        match self {
            Self::F32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            Self::F64(v) => v.clone(),
            other => (0..other.len())
                .map(|i| other.get_f64(i).unwrap_or(0.0))
                .collect(),
        }
    }

    /// All values converted to f32 (rounding f64 and large integers).
    #[must_use]
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_precision_loss,
        reason = "f32 storage is the documented precision of meshes"
    )]
    pub fn to_f32(&self) -> Vec<f32> {
        match self {
            Self::F32(v) => v.clone(),
            Self::F64(v) => v.iter().map(|&x| x as f32).collect(),
            Self::I32(v) => v.iter().map(|&x| x as f32).collect(),
            Self::U32(v) => v.iter().map(|&x| x as f32).collect(),
            other => (0..other.len())
                .map(|i| other.get_f64(i).unwrap_or(0.0) as f32)
                .collect(),
        }
    }

    /// Values scaled to `[0, 1]` colour floats: integers divided by their type's maximum.
    #[expect(clippy::cast_possible_truncation, reason = "colours are f32")]
    fn to_unit_color(&self) -> Vec<f32> {
        let max = match self.scalar_type() {
            ScalarType::U8 => 255.0,
            ScalarType::I8 => 127.0,
            ScalarType::U16 => 65535.0,
            ScalarType::I16 => 32767.0,
            ScalarType::U32 => f64::from(u32::MAX),
            ScalarType::I32 => f64::from(i32::MAX),
            ScalarType::F32 | ScalarType::F64 => 1.0,
        };
        (0..self.len())
            .map(|i| (self.get_f64(i).unwrap_or(0.0) / max) as f32)
            .collect()
    }

    fn push_binary(&mut self, bytes: &[u8], big_endian: bool) {
        macro_rules! push {
            ($v:ident, $t:ty) => {{
                let mut a = [0u8; std::mem::size_of::<$t>()];
                a.copy_from_slice(&bytes[..std::mem::size_of::<$t>()]);
                $v.push(if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                });
            }};
        }
        match self {
            Self::I8(v) => push!(v, i8),
            Self::U8(v) => push!(v, u8),
            Self::I16(v) => push!(v, i16),
            Self::U16(v) => push!(v, u16),
            Self::I32(v) => push!(v, i32),
            Self::U32(v) => push!(v, u32),
            Self::F32(v) => push!(v, f32),
            Self::F64(v) => push!(v, f64),
        }
    }

    /// Parses an ascii token into this column; `false` when it is not a valid value of the type
    /// (integer columns also take integral float tokens such as `3.0`).
    pub fn push_token(&mut self, token: &str) -> bool {
        fn int<T: TryFrom<i64>>(token: &str) -> Option<T> {
            let x: i64 = match token.parse() {
                Ok(x) => x,
                Err(_) => float_to_i64(token.parse::<f64>().ok()?)?,
            };
            T::try_from(x).ok()
        }
        match self {
            Self::I8(v) => int(token).map(|x| v.push(x)).is_some(),
            Self::U8(v) => int(token).map(|x| v.push(x)).is_some(),
            Self::I16(v) => int(token).map(|x| v.push(x)).is_some(),
            Self::U16(v) => int(token).map(|x| v.push(x)).is_some(),
            Self::I32(v) => int(token).map(|x| v.push(x)).is_some(),
            Self::U32(v) => int(token).map(|x| v.push(x)).is_some(),
            Self::F32(v) => token.parse().map(|x| v.push(x)).is_ok(),
            Self::F64(v) => token.parse().map(|x| v.push(x)).is_ok(),
        }
    }

    /// Appends `rows` values read from a row-major binary block: the value of row `r` starts
    /// at byte `offset + r * stride` of `block` (the caller checked the block holds them all).
    fn extend_strided(
        &mut self,
        block: &[u8],
        offset: usize,
        stride: usize,
        rows: usize,
        big_endian: bool,
    ) {
        macro_rules! extend {
            ($v:ident, $t:ty) => {{
                const SIZE: usize = std::mem::size_of::<$t>();
                let values = (0..rows).map(|r| {
                    let at = offset + r * stride;
                    let mut a = [0u8; SIZE];
                    a.copy_from_slice(&block[at..at + SIZE]);
                    a
                });
                if big_endian {
                    $v.extend(values.map(<$t>::from_be_bytes));
                } else {
                    $v.extend(values.map(<$t>::from_le_bytes));
                }
            }};
        }
        match self {
            Self::I8(v) => extend!(v, i8),
            Self::U8(v) => extend!(v, u8),
            Self::I16(v) => extend!(v, i16),
            Self::U16(v) => extend!(v, u16),
            Self::I32(v) => extend!(v, i32),
            Self::U32(v) => extend!(v, u32),
            Self::F32(v) => extend!(v, f32),
            Self::F64(v) => extend!(v, f64),
        }
    }

    /// Writes values `first..first + rows` into a row-major binary block: value `first + r` goes
    /// to byte `offset + r * stride` of `block` (the caller sized the block).
    fn write_strided(
        &self,
        first: usize,
        rows: usize,
        block: &mut [u8],
        offset: usize,
        stride: usize,
        big_endian: bool,
    ) {
        each_column!(self, v => {
            for (r, x) in v[first..first + rows].iter().enumerate() {
                let bytes = if big_endian { x.to_be_bytes() } else { x.to_le_bytes() };
                let at = offset + r * stride;
                block[at..at + bytes.len()].copy_from_slice(&bytes);
            }
        });
    }

    fn write_binary(&self, i: usize, out: &mut Vec<u8>, big_endian: bool) {
        each_column!(self, v => {
            let x = v[i];
            if big_endian {
                out.extend_from_slice(&x.to_be_bytes());
            } else {
                out.extend_from_slice(&x.to_le_bytes());
            }
        });
    }

    fn write_ascii(&self, i: usize, out: &mut Vec<u8>) {
        // Rust's `Display` and `LowerExp` of floats give the shortest digits that round-trip.
        match self {
            Self::F32(v) => write_float(out, f64::from(v[i]), v[i]),
            Self::F64(v) => write_float(out, v[i], v[i]),
            other => each_column!(other, v => {
                let _ = write!(out, "{}", v[i]);
            }),
        }
    }
}

/// Writes a float in positional notation for ordinary magnitudes and in exponent notation for
/// tiny or huge ones (`1e-30`, not thirty zeros); both are the shortest digits that read back
/// to the same value.
fn write_float<T: fmt::Display + fmt::LowerExp>(out: &mut Vec<u8>, magnitude: f64, x: T) {
    let a = magnitude.abs();
    let _ = if a == 0.0 || !a.is_finite() || (1e-5..1e16).contains(&a) {
        write!(out, "{x}")
    } else {
        write!(out, "{x:e}")
    };
}

#[expect(
    clippy::cast_possible_truncation,
    reason = "checked to be integral and in range"
)]
fn float_to_i64(x: f64) -> Option<i64> {
    (x.is_finite() && x.fract() == 0.0 && x.abs() < 9.0e15).then_some(x as i64)
}

/// The data of one property of an element.
#[derive(Clone, Debug, PartialEq)]
pub enum PropertyData {
    /// One value per row.
    Scalar(ScalarColumn),
    /// A variable-length list per row: row `i` holds `values[offsets[i]..offsets[i + 1]]`.
    List {
        /// Type of the per-row count.
        count_type: ScalarType,
        /// `rows + 1` offsets into `values`.
        offsets: Vec<usize>,
        /// All items, row after row.
        values: ScalarColumn,
    },
}

impl PropertyData {
    fn rows(&self) -> usize {
        match self {
            Self::Scalar(c) => c.len(),
            Self::List { offsets, .. } => offsets.len().saturating_sub(1),
        }
    }
}

/// One named property with its data.
#[derive(Clone, Debug, PartialEq)]
pub struct PlyProperty {
    /// Property name.
    pub name: String,
    /// Its values.
    pub data: PropertyData,
}

/// One element (`vertex`, `face`, ...) with its rows stored column by column.
#[derive(Clone, Debug, PartialEq)]
pub struct PlyElement {
    /// Element name.
    pub name: String,
    /// Number of rows.
    pub count: usize,
    /// Properties in file order.
    pub properties: Vec<PlyProperty>,
}

impl PlyElement {
    /// The property called `name`.
    #[must_use]
    pub fn property(&self, name: &str) -> Option<&PropertyData> {
        self.properties
            .iter()
            .find(|p| p.name == name)
            .map(|p| &p.data)
    }

    fn scalar(&self, name: &str) -> Option<&ScalarColumn> {
        match self.property(name) {
            Some(PropertyData::Scalar(c)) => Some(c),
            _ => None,
        }
    }
}

/// A whole PLY file: encoding, comments and elements.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyDocument {
    /// Encoding read (or to write).
    pub encoding: PlyEncoding,
    /// `comment` lines, without the keyword.
    pub comments: Vec<String>,
    /// `obj_info` lines, without the keyword.
    pub obj_info: Vec<String>,
    /// Elements in file order.
    pub elements: Vec<PlyElement>,
}

impl PlyDocument {
    /// The element called `name`.
    #[must_use]
    pub fn element(&self, name: &str) -> Option<&PlyElement> {
        self.elements.iter().find(|e| e.name == name)
    }
}

/// What a PLY file held besides the mesh or point data: written back by [`write_ply_mesh`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyExtras {
    /// Comments of the source file.
    pub comments: Vec<String>,
    /// `obj_info` lines of the source file.
    pub obj_info: Vec<String>,
    /// Vertex properties that are not positions, normals, colours or uvs (one value per vertex).
    pub vertex_properties: Vec<PlyProperty>,
    /// Face properties other than the index list, kept only when every face was a triangle.
    pub face_properties: Vec<PlyProperty>,
    /// Elements other than `vertex`, `face` and `tristrips`, verbatim.
    pub other_elements: Vec<PlyElement>,
}

// ---------------------------------------------------------------------------------------------
// Header

#[derive(Clone, Debug)]
enum PropKind {
    Scalar(ScalarType),
    List { count: ScalarType, item: ScalarType },
}

#[derive(Clone, Debug)]
struct PropDef {
    name: String,
    kind: PropKind,
}

#[derive(Clone, Debug)]
struct ElementDef {
    name: String,
    count: usize,
    props: Vec<PropDef>,
}

struct Header {
    encoding: PlyEncoding,
    comments: Vec<String>,
    obj_info: Vec<String>,
    elements: Vec<ElementDef>,
    body_start: usize,
}

/// Rows of fixed-size elements are read and written in blocks of about this many bytes, so
/// that each block stays in cache while it is decoded or encoded column by column.
const BLOCK_BYTES: usize = 1 << 18;

/// Longest header we accept (real headers are a few kilobytes at most).
const MAX_HEADER_BYTES: usize = 1 << 20;

fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, IoError> {
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

// ---------------------------------------------------------------------------------------------
// Body

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

fn count_limit_error(path: &Path, def: &ElementDef, possible: usize) -> IoError {
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

// ---------------------------------------------------------------------------------------------
// Writing

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

// ---------------------------------------------------------------------------------------------
// Mesh and point mapping

const UV_NAMES: [(&str, &str); 4] = [
    ("texture_u", "texture_v"),
    ("u", "v"),
    ("s", "t"),
    ("texture_s", "texture_t"),
];
const FACE_INDEX_NAMES: [&str; 2] = ["vertex_indices", "vertex_index"];

/// Vertex data decoded from a `vertex` element.
struct VertexData {
    /// f64: `double` coordinates are kept exactly (meshes store f64 positions).
    positions: Vec<DVec3>,
    normals: Option<Vec<Vec3>>,
    colors: Option<Vec<Rgba>>,
    uvs: Option<Vec<Vec2>>,
    used: Vec<&'static str>,
}

fn triple<'a>(e: &'a PlyElement, names: [&str; 3]) -> Option<[&'a ScalarColumn; 3]> {
    Some([
        e.scalar(names[0])?,
        e.scalar(names[1])?,
        e.scalar(names[2])?,
    ])
}

fn zip3(c: [&ScalarColumn; 3]) -> Vec<Vec3> {
    let [x, y, z] = c.map(ScalarColumn::to_f32);
    x.iter()
        .zip(&y)
        .zip(&z)
        .map(|((&x, &y), &z)| Vec3::new(x, y, z))
        .collect()
}

fn zip3_f64(c: [&ScalarColumn; 3]) -> Vec<DVec3> {
    let [x, y, z] = c.map(ScalarColumn::to_f64);
    x.iter()
        .zip(&y)
        .zip(&z)
        .map(|((&x, &y), &z)| DVec3::new(x, y, z))
        .collect()
}

fn decode_vertices(path: &Path, doc: &PlyDocument) -> Result<VertexData, IoError> {
    let Some(v) = doc.element("vertex") else {
        return Err(IoError::malformed(path, "header", "no `vertex` element"));
    };
    let xyz = triple(v, ["x", "y", "z"]).ok_or_else(|| {
        IoError::malformed(
            path,
            "element vertex",
            "needs scalar properties `x`, `y` and `z`",
        )
    })?;
    let positions = zip3_f64(xyz);
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        let p = positions[i];
        return Err(IoError::malformed(
            path,
            format!("vertex {i}"),
            format!("non-finite coordinate ({}, {}, {})", p.x, p.y, p.z),
        ));
    }
    let mut used = vec!["x", "y", "z"];
    let normals = triple(v, ["nx", "ny", "nz"]).map(|c| {
        used.extend(["nx", "ny", "nz"]);
        zip3(c)
    });
    if let Some(n) = &normals
        && let Some(i) = n.iter().position(|p| !p.is_finite())
    {
        let p = n[i];
        return Err(IoError::malformed(
            path,
            format!("vertex {i}"),
            format!("non-finite normal ({}, {}, {})", p.x, p.y, p.z),
        ));
    }
    let colors = triple(v, ["red", "green", "blue"]).map(|[r, g, b]| {
        used.extend(["red", "green", "blue"]);
        let (r, g, b) = (r.to_unit_color(), g.to_unit_color(), b.to_unit_color());
        let a = v.scalar("alpha").map(|a| {
            used.push("alpha");
            a.to_unit_color()
        });
        (0..r.len())
            .map(|i| [r[i], g[i], b[i], a.as_ref().map_or(1.0, |a| a[i])])
            .collect()
    });
    let mut uvs = None;
    for (un, vn) in UV_NAMES {
        if let (Some(u), Some(w)) = (v.scalar(un), v.scalar(vn)) {
            let (u, w) = (u.to_f32(), w.to_f32());
            uvs = Some(u.iter().zip(&w).map(|(&u, &w)| Vec2::new(u, w)).collect());
            used.extend([un, vn]);
            break;
        }
    }
    Ok(VertexData {
        positions,
        normals,
        colors,
        uvs,
        used,
    })
}

fn index_list(e: &PlyElement) -> Option<(&str, &[usize], &ScalarColumn)> {
    FACE_INDEX_NAMES
        .iter()
        .find_map(|&name| match e.property(name) {
            Some(PropertyData::List {
                offsets, values, ..
            }) => Some((name, offsets.as_slice(), values)),
            _ => None,
        })
}

/// `raw` (a list value, `-1` when it is not an integer) as a vertex index below `n`.
fn checked_index(path: &Path, what: &str, row: usize, raw: i64, n: usize) -> Result<u32, IoError> {
    match u32::try_from(raw) {
        Ok(v) if (v as usize) < n => Ok(v),
        _ => Err(IoError::malformed(
            path,
            format!("{what} {row}"),
            format!("vertex index {raw} is out of range (the file has {n} vertices)"),
        )),
    }
}

/// Triangles of the `face` and `tristrips` elements; also whether every face was a triangle.
fn decode_triangles(
    path: &Path,
    doc: &PlyDocument,
    n: usize,
) -> Result<(Vec<[u32; 3]>, bool), IoError> {
    let mut triangles = Vec::new();
    let mut all_triangles = true;
    if let Some(face) = doc.element("face") {
        let (_, offsets, values) = index_list(face).ok_or_else(|| {
            IoError::malformed(
                path,
                "element face",
                "needs a list property `vertex_indices` or `vertex_index`",
            )
        })?;
        triangles.reserve(face.count);
        let values = values.to_i64_or_minus_one();
        for row in 0..face.count {
            let (a, b) = (offsets[row], offsets[row + 1]);
            if b - a != 3 {
                all_triangles = false;
            }
            if b - a < 3 {
                continue;
            }
            let first = checked_index(path, "face", row, values[a], n)?;
            let mut prev = checked_index(path, "face", row, values[a + 1], n)?;
            for &raw in &values[a + 2..b] {
                let cur = checked_index(path, "face", row, raw, n)?;
                triangles.push([first, prev, cur]);
                prev = cur;
            }
        }
    }
    if let Some(strips) = doc.element("tristrips") {
        all_triangles = false;
        let (_, offsets, values) = index_list(strips).ok_or_else(|| {
            IoError::malformed(
                path,
                "element tristrips",
                "needs a list property `vertex_indices`",
            )
        })?;
        for row in 0..strips.count {
            let mut strip: Vec<u32> = Vec::new();
            let flush = |strip: &mut Vec<u32>, out: &mut Vec<[u32; 3]>| {
                for k in 0..strip.len().saturating_sub(2) {
                    let (a, b, c) = (strip[k], strip[k + 1], strip[k + 2]);
                    if a == b || b == c || a == c {
                        continue;
                    }
                    out.push(if k % 2 == 0 { [a, b, c] } else { [b, a, c] });
                }
                strip.clear();
            };
            for i in offsets[row]..offsets[row + 1] {
                if values.get_i64(i) == Some(-1) {
                    flush(&mut strip, &mut triangles);
                } else {
                    let raw = values.get_i64(i).unwrap_or(-1);
                    strip.push(checked_index(path, "tristrips", row, raw, n)?);
                }
            }
            flush(&mut strip, &mut triangles);
        }
    }
    Ok((triangles, all_triangles))
}

fn extras_of(doc: &PlyDocument, used_vertex: &[&str], keep_face: bool) -> PlyExtras {
    let mut extras = PlyExtras {
        comments: doc.comments.clone(),
        obj_info: doc.obj_info.clone(),
        ..PlyExtras::default()
    };
    for e in &doc.elements {
        match e.name.as_str() {
            "vertex" => {
                extras.vertex_properties = e
                    .properties
                    .iter()
                    .filter(|p| !used_vertex.contains(&p.name.as_str()))
                    .cloned()
                    .collect();
            }
            "face" => {
                if keep_face {
                    let index_name = index_list(e).map(|(n, _, _)| n);
                    extras.face_properties = e
                        .properties
                        .iter()
                        .filter(|p| Some(p.name.as_str()) != index_name)
                        .cloned()
                        .collect();
                }
            }
            "tristrips" => {}
            _ => extras.other_elements.push(e.clone()),
        }
    }
    extras
}

/// Builds a mesh (and the rest of the file) from a parsed PLY document.
///
/// # Errors
/// [`IoError::Malformed`] for a missing `vertex` element or coordinates, a non-finite position
/// (naming the vertex) or an index out of range (naming the face).
pub fn ply_to_mesh(path: &Path, doc: &PlyDocument) -> Result<(TriMesh, PlyExtras), IoError> {
    let v = decode_vertices(path, doc)?;
    let (triangles, all_triangles) = decode_triangles(path, doc, v.positions.len())?;
    let extras = extras_of(doc, &v.used, all_triangles);
    let bad_len = |e: crate::MeshError| IoError::malformed(path, "element vertex", e.to_string());
    let mut mesh = TriMesh::try_new(v.positions, triangles).map_err(bad_len)?;
    if let Some(n) = v.normals {
        mesh = mesh.with_normals(n).map_err(bad_len)?;
    }
    if let Some(c) = v.colors {
        mesh = mesh.with_colors(c).map_err(bad_len)?;
    }
    if let Some(uv) = v.uvs {
        mesh = mesh.with_uvs(uv).map_err(bad_len)?;
    }
    Ok((mesh, extras))
}

/// Builds a point cloud from the `vertex` element of a parsed PLY document (faces ignored).
///
/// # Errors
/// [`IoError::Malformed`] for a missing `vertex` element or a non-finite position.
pub fn ply_to_points(path: &Path, doc: &PlyDocument) -> Result<(PointCloud, PlyExtras), IoError> {
    ply_to_points_around(path, doc, DVec3::ZERO).map(|(cloud, extras, _)| (cloud, extras))
}

/// [`ply_to_points`] with the positions relative to a local origin, returned beside them:
/// the points' [`crate::Aabb::local_origin`] (zero unless they are far from the world origin),
/// subtracted from the file's values in `f64` before they are stored in `f32`.
///
/// # Errors
/// As [`ply_to_points`].
pub fn ply_to_points_local(
    path: &Path,
    doc: &PlyDocument,
) -> Result<(PointCloud, PlyExtras, DVec3), IoError> {
    ply_to_points_around(path, doc, DVec3::NAN)
}

/// The points of `doc` relative to `origin`, or to their local origin when `origin` is NaN.
fn ply_to_points_around(
    path: &Path,
    doc: &PlyDocument,
    origin: DVec3,
) -> Result<(PointCloud, PlyExtras, DVec3), IoError> {
    let v = decode_vertices(path, doc)?;
    let extras = extras_of(doc, &v.used, false);
    let bad = |e: crate::MeshError| IoError::malformed(path, "element vertex", e.to_string());
    let origin = if origin.is_nan() {
        crate::Aabb::from_dpoints(&v.positions).map_or(DVec3::ZERO, |b| b.local_origin())
    } else {
        origin
    };
    let positions = v
        .positions
        .iter()
        .map(|&p| (p - origin).as_vec3())
        .collect();
    let mut cloud = PointCloud::try_new(positions).map_err(bad)?;
    if let Some(n) = v.normals {
        cloud = cloud.with_normals(n).map_err(bad)?;
    }
    if let Some(c) = v.colors {
        cloud = cloud.with_colors(c).map_err(bad)?;
    }
    Ok((cloud, extras, origin))
}

/// Reads a PLY mesh and everything else it holds.
///
/// # Errors
/// See [`read_ply_document`] and [`ply_to_mesh`].
pub fn read_ply_mesh(path: &Path) -> Result<(TriMesh, PlyExtras), IoError> {
    ply_to_mesh(path, &read_ply_document(path)?)
}

fn f32_column(values: impl Iterator<Item = f32>) -> PropertyData {
    PropertyData::Scalar(ScalarColumn::F32(values.collect()))
}

#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "clamped to [0, 255] first"
)]
fn u8_color(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn prop(name: &str, data: PropertyData) -> PlyProperty {
    PlyProperty {
        name: name.to_owned(),
        data,
    }
}

/// `x y z` columns of f32 points.
fn position_columns_f32(positions: &[Vec3]) -> [PlyProperty; 3] {
    [
        prop("x", f32_column(positions.iter().map(|p| p.x))),
        prop("y", f32_column(positions.iter().map(|p| p.y))),
        prop("z", f32_column(positions.iter().map(|p| p.z))),
    ]
}

/// `x y z` columns of f64 mesh vertices: `float` when every coordinate is an f32 value (the
/// file is then what an f32 writer would write), else `double`, so nothing is rounded.
fn position_columns_f64(positions: &[DVec3]) -> [PlyProperty; 3] {
    let exact_in_f32 = positions.iter().all(|p| p.as_vec3().as_dvec3() == *p);
    if exact_in_f32 {
        return position_columns_f32(&positions.iter().map(|p| p.as_vec3()).collect::<Vec<_>>());
    }
    let column = |axis: usize| {
        PropertyData::Scalar(ScalarColumn::F64(
            positions.iter().map(|p| p[axis]).collect(),
        ))
    };
    [
        prop("x", column(0)),
        prop("y", column(1)),
        prop("z", column(2)),
    ]
}

fn vertex_element(
    positions: [PlyProperty; 3],
    normals: Option<&[Vec3]>,
    uvs: Option<&[Vec2]>,
    colors: Option<&[Rgba]>,
    extra: &[PlyProperty],
) -> PlyElement {
    let count = positions[0].data.rows();
    let mut props = positions.to_vec();
    if let Some(n) = normals {
        props.push(prop("nx", f32_column(n.iter().map(|p| p.x))));
        props.push(prop("ny", f32_column(n.iter().map(|p| p.y))));
        props.push(prop("nz", f32_column(n.iter().map(|p| p.z))));
    }
    if let Some(uv) = uvs {
        props.push(prop("s", f32_column(uv.iter().map(|p| p.x))));
        props.push(prop("t", f32_column(uv.iter().map(|p| p.y))));
    }
    if let Some(c) = colors {
        for (k, name) in ["red", "green", "blue", "alpha"].into_iter().enumerate() {
            let column = ScalarColumn::U8(c.iter().map(|c| u8_color(c[k])).collect());
            props.push(prop(name, PropertyData::Scalar(column)));
        }
    }
    for p in extra {
        if p.data.rows() == count && !props.iter().any(|q| q.name == p.name) {
            props.push(p.clone());
        }
    }
    PlyElement {
        name: "vertex".into(),
        count,
        properties: props,
    }
}

/// The PLY document for `mesh` plus `extras`: `vertex` (`x y z` float, or double when a
/// coordinate is not an f32 value, `nx ny nz`, `s t`,
/// `red green blue alpha` uchar when present, then extra properties), `face` (`list uchar int
/// vertex_indices`, then extra face properties when their row count matches), other elements.
/// Extras whose row count does not match the mesh are left out.
#[must_use]
pub fn mesh_to_ply(mesh: &TriMesh, extras: &PlyExtras) -> PlyDocument {
    let vertex = vertex_element(
        position_columns_f64(mesh.positions()),
        mesh.normals(),
        mesh.uvs(),
        mesh.colors(),
        &extras.vertex_properties,
    );
    let tris = mesh.triangles();
    #[expect(clippy::cast_possible_wrap, reason = "vertex counts fit i32 in PLY")]
    let indices = ScalarColumn::I32(tris.iter().flatten().map(|&i| i as i32).collect());
    let mut face_props = vec![prop(
        "vertex_indices",
        PropertyData::List {
            count_type: ScalarType::U8,
            offsets: (0..=tris.len()).map(|i| 3 * i).collect(),
            values: indices,
        },
    )];
    for p in &extras.face_properties {
        if p.data.rows() == tris.len() && p.name != "vertex_indices" {
            face_props.push(p.clone());
        }
    }
    let mut elements = vec![
        vertex,
        PlyElement {
            name: "face".into(),
            count: tris.len(),
            properties: face_props,
        },
    ];
    elements.extend(extras.other_elements.iter().cloned());
    PlyDocument {
        encoding: PlyEncoding::default(),
        comments: extras.comments.clone(),
        obj_info: extras.obj_info.clone(),
        elements,
    }
}

/// The PLY document for a point cloud: one `vertex` element (see [`mesh_to_ply`]).
#[must_use]
pub fn points_to_ply(points: &PointCloud, extras: &PlyExtras) -> PlyDocument {
    points_to_ply_at(points, DVec3::ZERO, extras)
}

/// [`points_to_ply`] for points stored relative to `origin` (see
/// [`super::read_points_local`]): written at `p + origin`, computed in f64, as `double` when
/// that is not an f32 value.
#[must_use]
pub fn points_to_ply_at(points: &PointCloud, origin: DVec3, extras: &PlyExtras) -> PlyDocument {
    let positions = if origin == DVec3::ZERO {
        position_columns_f32(points.positions())
    } else {
        position_columns_f64(
            &points
                .positions()
                .iter()
                .map(|p| p.as_dvec3() + origin)
                .collect::<Vec<_>>(),
        )
    };
    let mut elements = vec![vertex_element(
        positions,
        points.normals(),
        None,
        points.colors(),
        &extras.vertex_properties,
    )];
    elements.extend(extras.other_elements.iter().cloned());
    PlyDocument {
        encoding: PlyEncoding::default(),
        comments: extras.comments.clone(),
        obj_info: extras.obj_info.clone(),
        elements,
    }
}

/// Writes a mesh with the extras of the file it came from, atomically.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be written.
pub fn write_ply_mesh(
    path: &Path,
    mesh: &TriMesh,
    extras: &PlyExtras,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    let doc = mesh_to_ply(mesh, extras);
    super::write_atomically(path, |w| write_ply_document(path, w, &doc, encoding))
}

/// Writes a point cloud with the extras of the file it came from, atomically.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be written.
pub fn write_ply_points(
    path: &Path,
    points: &PointCloud,
    extras: &PlyExtras,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    write_ply_points_at(path, points, DVec3::ZERO, extras, encoding)
}

/// [`write_ply_points`] for points stored relative to `origin` ([`points_to_ply_at`]).
///
/// # Errors
/// [`IoError::Os`] when the file cannot be written.
pub fn write_ply_points_at(
    path: &Path,
    points: &PointCloud,
    origin: DVec3,
    extras: &PlyExtras,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    let doc = points_to_ply_at(points, origin, extras);
    super::write_atomically(path, |w| write_ply_document(path, w, &doc, encoding))
}

#[cfg(test)]
mod tests {
    use super::*;

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
