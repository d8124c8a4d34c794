//! The PLY document model: encodings, scalar types, typed columns (with their binary and
//! ascii encoding), properties, elements, whole documents and the extras kept for writing back.

use std::fmt;
use std::io::Write;

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
    pub(super) fn header_name(self) -> &'static str {
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
    pub(super) fn to_i64_or_minus_one(&self) -> Vec<i64> {
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

    pub(super) fn get_i64(&self, i: usize) -> Option<i64> {
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
    pub(super) fn to_unit_color(&self) -> Vec<f32> {
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

    pub(super) fn push_binary(&mut self, bytes: &[u8], big_endian: bool) {
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
    pub(super) fn extend_strided(
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
    pub(super) fn write_strided(
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

    pub(super) fn write_binary(&self, i: usize, out: &mut Vec<u8>, big_endian: bool) {
        each_column!(self, v => {
            let x = v[i];
            if big_endian {
                out.extend_from_slice(&x.to_be_bytes());
            } else {
                out.extend_from_slice(&x.to_le_bytes());
            }
        });
    }

    pub(super) fn write_ascii(&self, i: usize, out: &mut Vec<u8>) {
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
pub(super) fn write_float<T: fmt::Display + fmt::LowerExp>(
    out: &mut Vec<u8>,
    magnitude: f64,
    x: T,
) {
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
pub(super) fn float_to_i64(x: f64) -> Option<i64> {
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
    pub(super) fn rows(&self) -> usize {
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

    pub(super) fn scalar(&self, name: &str) -> Option<&ScalarColumn> {
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

/// What a PLY file held besides the mesh or point data: written back by [`write_ply_mesh`](super::write_ply_mesh).
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
