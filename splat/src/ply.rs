//! INRIA 3DGS PLY files: reading and writing [`GaussianSet`]s (docs/conventions.md §3).
//!
//! Reading finds properties by name in any order: `x y z`, `scale_0..2` (or only `scale_0..1`:
//! a 2DGS file), `rot_0..3` (w first), `opacity`, `f_dc_0..2` and `f_rest_*` (0, 9, 24 or 45 of
//! them: SH degree 0..3). A GaussianAvatars `binding_0` float property, or an integer `binding`,
//! becomes the [`Binding`] and marks the parameters as local. Every other vertex property is kept
//! by name, in its stored type, and written back. The standard properties are stored as `f32`;
//! when a file stores them in another type they are converted (exactly for `float`).
//!
//! The body can be binary little-endian (the fast path), big-endian or ascii. Header counts are
//! never trusted: a file shorter than its header says is an error, and nothing is allocated
//! beyond what the bytes present can hold. Non-finite values in standard properties and zero
//! quaternions are errors naming the file and the Gaussian.
//!
//! Writing keeps the property order of the file a set was read from (recorded in
//! [`GaussianParts::property_order`]); properties it does not list follow in the INRIA order
//! (`x y z f_dc f_rest opacity scale rot`, then extras, then the binding). Floats are written
//! bit for bit (ascii uses the shortest representation that reads back to the same `f32`), so
//! writing what was read reproduces every value exactly. Files are written atomically.

use std::borrow::Cow;
use std::io::Write;
use std::path::{Path, PathBuf};

use glam::Vec3;
use trisplat_geometry::TriId;
use trisplat_geometry::io::{IoError, write_atomically};

use crate::gaussians::{
    Binding, BindingEncoding, ExtraProperty, GaussianError, GaussianParts, GaussianSet,
    ParameterSpace, PropertyValues, ScalarType, ScaleDims, sh_coeffs_per_channel,
};

/// Longest header accepted, in bytes (a degree-3 file with many extras needs about 2 KiB).
pub const MAX_HEADER_BYTES: usize = 1 << 20;

/// Largest triangle index a `float` `binding_0` can hold exactly (2²⁴).
pub const MAX_FLOAT_BINDING: u32 = 1 << 24;

/// Errors of reading and writing Gaussian PLY files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlyError {
    /// The operating system refused (missing file, permissions).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The header is malformed or uses something we cannot read.
    #[error("{}: header line {line}: {message}", path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based header line (0 when the header has no end).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// No `vertex` element.
    #[error("{}: no `vertex` element", path.display())]
    NoVertexElement {
        /// The file.
        path: PathBuf,
    },
    /// A property a Gaussian needs is missing.
    #[error("{}: missing vertex property `{name}`", path.display())]
    MissingProperty {
        /// The file.
        path: PathBuf,
        /// The property.
        name: String,
    },
    /// A vertex property we cannot use (a list, a duplicate, an impossible `f_rest` count).
    #[error("{}: vertex property `{name}`: {message}", path.display())]
    BadProperty {
        /// The file.
        path: PathBuf,
        /// The property.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// The file ends before the header's count of elements.
    #[error("{}: {element} {index}: file ends early (the header says {expected})", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Element name.
        element: String,
        /// First index missing.
        index: usize,
        /// Count in the header.
        expected: usize,
    },
    /// An ascii value that does not parse as its type.
    #[error("{}: Gaussian {index}: property `{name}`: cannot read `{token}`", path.display())]
    BadValue {
        /// The file.
        path: PathBuf,
        /// Gaussian index.
        index: usize,
        /// The property.
        name: String,
        /// The text found.
        token: String,
    },
    /// A binding value that is not a triangle index (negative, fractional, not finite).
    #[error("{}: Gaussian {index}: binding {value} is not a triangle index", path.display())]
    BadBinding {
        /// The file.
        path: PathBuf,
        /// Gaussian index.
        index: usize,
        /// The value.
        value: f64,
    },
    /// The values read do not make a valid Gaussian set (NaN, zero quaternion, ...).
    #[error("{}: {source}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The problem, naming the Gaussian.
        source: GaussianError,
    },
    /// A binding that the chosen encoding cannot store.
    #[error("{}: Gaussian {index}: triangle {triangle} cannot be stored as {ty:?}", path.display())]
    BindingNotRepresentable {
        /// The file.
        path: PathBuf,
        /// Gaussian index.
        index: usize,
        /// The triangle.
        triangle: TriId,
        /// The property type.
        ty: ScalarType,
    },
    /// Writing failed; the target is untouched.
    #[error(transparent)]
    Write(IoError),
}

/// Body encodings of a PLY file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum PlyEncoding {
    /// `binary_little_endian` (what 3DGS tools write).
    #[default]
    BinaryLittleEndian,
    /// `binary_big_endian`.
    BinaryBigEndian,
    /// `ascii`.
    Ascii,
}

impl PlyEncoding {
    fn header_name(self) -> &'static str {
        match self {
            Self::BinaryLittleEndian => "binary_little_endian",
            Self::BinaryBigEndian => "binary_big_endian",
            Self::Ascii => "ascii",
        }
    }
}

/// Options for [`write_gaussians`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PlyWriteOptions {
    /// Body encoding.
    pub encoding: PlyEncoding,
}

// ----------------------------------------------------------------------------------------------
// Header

#[derive(Clone, Debug)]
enum PropKind {
    Scalar(ScalarType),
    List { count: ScalarType, item: ScalarType },
}

#[derive(Clone, Debug)]
struct Prop {
    name: String,
    kind: PropKind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

struct Header {
    encoding: PlyEncoding,
    elements: Vec<Element>,
    body_start: usize,
}

fn header_err(path: &Path, line: usize, message: impl Into<String>) -> PlyError {
    PlyError::Header {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, PlyError> {
    let limit = bytes.len().min(MAX_HEADER_BYTES);
    let window = &bytes[..limit];
    let mut pos = 0;
    let mut line_no = 0;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(nl) = window[pos..].iter().position(|&b| b == b'\n') else {
            return Err(header_err(path, 0, "no `end_header` line"));
        };
        let raw = &window[pos..pos + nl];
        pos += nl + 1;
        line_no += 1;
        let text = String::from_utf8_lossy(raw);
        let line = text.trim_end_matches('\r').trim();
        let mut words = line.split_ascii_whitespace();
        let first = words.next().unwrap_or("");
        if line_no == 1 {
            if line != "ply" {
                return Err(header_err(
                    path,
                    1,
                    "not a PLY file (first line is not `ply`)",
                ));
            }
            continue;
        }
        match first {
            "" | "comment" | "obj_info" => {}
            "format" => {
                let enc = match words.next() {
                    Some("ascii") => PlyEncoding::Ascii,
                    Some("binary_little_endian") => PlyEncoding::BinaryLittleEndian,
                    Some("binary_big_endian") => PlyEncoding::BinaryBigEndian,
                    other => {
                        return Err(header_err(
                            path,
                            line_no,
                            format!("unknown format `{}`", other.unwrap_or("")),
                        ));
                    }
                };
                encoding = Some(enc);
            }
            "element" => {
                let (Some(name), Some(count)) = (words.next(), words.next()) else {
                    return Err(header_err(path, line_no, "expected `element NAME COUNT`"));
                };
                let count: usize = count.parse().map_err(|_| {
                    header_err(path, line_no, format!("bad element count `{count}`"))
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(header_err(path, line_no, "property before any element"));
                };
                let words: Vec<&str> = words.collect();
                let ty = |w: &str| {
                    ScalarType::from_ply_name(w)
                        .ok_or_else(|| header_err(path, line_no, format!("unknown type `{w}`")))
                };
                let prop = match words.as_slice() {
                    ["list", count, item, name] => Prop {
                        name: (*name).to_string(),
                        kind: PropKind::List {
                            count: ty(count)?,
                            item: ty(item)?,
                        },
                    },
                    [t, name] => Prop {
                        name: (*name).to_string(),
                        kind: PropKind::Scalar(ty(t)?),
                    },
                    _ => return Err(header_err(path, line_no, "malformed property line")),
                };
                element.props.push(prop);
            }
            "end_header" => break,
            other => {
                return Err(header_err(
                    path,
                    line_no,
                    format!("unknown keyword `{other}`"),
                ));
            }
        }
    }
    let encoding = encoding.ok_or_else(|| header_err(path, line_no, "no `format` line"))?;
    Ok(Header {
        encoding,
        elements,
        body_start: pos,
    })
}

// ----------------------------------------------------------------------------------------------
// Property roles

/// Where each standard parameter lives among the vertex properties (indices into the property
/// list).
struct Layout {
    mean: [usize; 3],
    scale: Vec<usize>,
    rot: [usize; 4],
    opacity: usize,
    /// SH columns in storage order (dc 0..2, then rest 0..).
    sh: Vec<usize>,
    sh_degree: u8,
    binding: Option<(usize, BindingEncoding)>,
    extras: Vec<usize>,
}

impl Layout {
    /// Property indices of the standard (non-extra, non-binding) parameters.
    fn standard_columns(&self) -> Vec<usize> {
        let mut v: Vec<usize> = self.mean.to_vec();
        v.extend(&self.scale);
        v.extend(self.rot);
        v.push(self.opacity);
        v.extend(&self.sh);
        v
    }
}

fn find_layout(props: &[Prop], path: &Path) -> Result<Layout, PlyError> {
    let bad = |name: &str, message: &str| PlyError::BadProperty {
        path: path.to_path_buf(),
        name: name.to_string(),
        message: message.to_string(),
    };
    for (i, p) in props.iter().enumerate() {
        if props[..i].iter().any(|q| q.name == p.name) {
            return Err(bad(&p.name, "appears twice"));
        }
        if matches!(p.kind, PropKind::List { .. }) {
            return Err(bad(
                &p.name,
                "list properties are not supported on vertices",
            ));
        }
    }
    let find = |name: &str| props.iter().position(|p| p.name == name);
    let need = |name: &str| {
        find(name).ok_or_else(|| PlyError::MissingProperty {
            path: path.to_path_buf(),
            name: name.to_string(),
        })
    };
    let mean = [need("x")?, need("y")?, need("z")?];
    let mut scale = vec![need("scale_0")?, need("scale_1")?];
    if let Some(i) = find("scale_2") {
        scale.push(i);
    }
    let rot = [
        need("rot_0")?,
        need("rot_1")?,
        need("rot_2")?,
        need("rot_3")?,
    ];
    let opacity = need("opacity")?;
    let mut sh = vec![need("f_dc_0")?, need("f_dc_1")?, need("f_dc_2")?];
    let rest_count = props
        .iter()
        .filter(|p| p.name.starts_with("f_rest_"))
        .count();
    let sh_degree = match rest_count {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => {
            return Err(bad(
                "f_rest_*",
                &format!("{n} coefficients; expected 0, 9, 24 or 45 (SH degree 0..3)"),
            ));
        }
    };
    for k in 0..rest_count {
        sh.push(need(&format!("f_rest_{k}"))?);
    }
    let binding = match (find("binding_0"), find("binding")) {
        (Some(_), Some(_)) => return Err(bad("binding", "both `binding_0` and `binding` present")),
        (Some(i), None) => Some((i, BindingEncoding::Float)),
        (None, Some(i)) => match props[i].kind {
            PropKind::Scalar(t) if t.is_integer() => Some((i, BindingEncoding::Integer(t))),
            _ => Some((i, BindingEncoding::Float)),
        },
        (None, None) => None,
    };
    let mut used = vec![false; props.len()];
    for &i in mean
        .iter()
        .chain(&scale)
        .chain(&rot)
        .chain(std::iter::once(&opacity))
        .chain(&sh)
    {
        used[i] = true;
    }
    if let Some((i, _)) = binding {
        used[i] = true;
    }
    let extras = (0..props.len()).filter(|&i| !used[i]).collect();
    Ok(Layout {
        mean,
        scale,
        rot,
        opacity,
        sh,
        sh_degree,
        binding,
        extras,
    })
}

// ----------------------------------------------------------------------------------------------
// Reading

/// Reads a Gaussian PLY file.
///
/// # Errors
/// [`PlyError`] naming the file and, for bad values, the Gaussian index.
pub fn read_gaussians(path: &Path) -> Result<GaussianSet, PlyError> {
    let bytes = std::fs::read(path).map_err(|source| PlyError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    read_gaussians_from_bytes(&bytes, path)
}

/// Reads a Gaussian PLY file held in memory; `path` only names it in errors.
///
/// # Errors
/// As [`read_gaussians`].
pub fn read_gaussians_from_bytes(bytes: &[u8], path: &Path) -> Result<GaussianSet, PlyError> {
    let header = parse_header(bytes, path)?;
    let Some(vertex_at) = header.elements.iter().position(|e| e.name == "vertex") else {
        return Err(PlyError::NoVertexElement {
            path: path.to_path_buf(),
        });
    };
    let vertex = &header.elements[vertex_at];
    let layout = find_layout(&vertex.props, path)?;
    let body = &bytes[header.body_start..];
    let standard_cols = layout.standard_columns();
    let (columns, standard) = match header.encoding {
        PlyEncoding::Ascii => {
            let columns = read_ascii(body, &header.elements[..=vertex_at], path)?;
            let standard = standard_from_columns(&columns, &layout, vertex.count);
            (columns, standard)
        }
        enc => {
            let big = enc == PlyEncoding::BinaryBigEndian;
            let mut pos = 0;
            for e in &header.elements[..vertex_at] {
                pos = skip_binary(body, pos, e, big, path)?;
            }
            let all_f32 = standard_cols
                .iter()
                .all(|&i| matches!(vertex.props[i].kind, PropKind::Scalar(ScalarType::F32)));
            if all_f32 {
                // Fast path: one pass over the rows for the standard properties, columns only
                // for the binding and the extras.
                let mut skip = vec![false; vertex.props.len()];
                for &i in &standard_cols {
                    skip[i] = true;
                }
                let body = &body[pos..];
                let columns = read_binary(body, vertex, big, path, &skip)?;
                let standard = if big {
                    standard_from_rows::<true>(body, vertex, &layout)
                } else {
                    standard_from_rows::<false>(body, vertex, &layout)
                };
                (columns, standard)
            } else {
                let columns = read_binary(&body[pos..], vertex, big, path, &[])?;
                let standard = standard_from_columns(&columns, &layout, vertex.count);
                (columns, standard)
            }
        }
    };
    assemble(columns, standard, vertex, &layout, path)
}

/// One decoded column per vertex property, in the stored type.
type Columns = Vec<PropertyValues>;

fn scalar_size(kind: &PropKind) -> usize {
    match kind {
        PropKind::Scalar(t) => t.size(),
        PropKind::List { .. } => 0,
    }
}

fn read_uint(bytes: &[u8], ty: ScalarType, big: bool) -> Option<u64> {
    let v = decode_f64(bytes, ty, big)?;
    (v >= 0.0 && v.fract() == 0.0).then_some(v as u64)
}

fn decode_f64(b: &[u8], ty: ScalarType, big: bool) -> Option<f64> {
    macro_rules! get {
        ($t:ty, $n:expr) => {{
            let arr: [u8; $n] = b.get(..$n)?.try_into().ok()?;
            f64::from(if big {
                <$t>::from_be_bytes(arr)
            } else {
                <$t>::from_le_bytes(arr)
            })
        }};
    }
    Some(match ty {
        ScalarType::I8 => get!(i8, 1),
        ScalarType::U8 => get!(u8, 1),
        ScalarType::I16 => get!(i16, 2),
        ScalarType::U16 => get!(u16, 2),
        ScalarType::I32 => get!(i32, 4),
        ScalarType::U32 => get!(u32, 4),
        ScalarType::F32 => get!(f32, 4),
        ScalarType::F64 => {
            let arr: [u8; 8] = b.get(..8)?.try_into().ok()?;
            if big {
                f64::from_be_bytes(arr)
            } else {
                f64::from_le_bytes(arr)
            }
        }
    })
}

/// Skips a non-vertex element of a binary body; returns the position after it.
fn skip_binary(
    body: &[u8],
    mut pos: usize,
    e: &Element,
    big: bool,
    path: &Path,
) -> Result<usize, PlyError> {
    let truncated = |index| PlyError::Truncated {
        path: path.to_path_buf(),
        element: e.name.clone(),
        index,
        expected: e.count,
    };
    let has_lists = e
        .props
        .iter()
        .any(|p| matches!(p.kind, PropKind::List { .. }));
    if !has_lists {
        let stride: usize = e.props.iter().map(|p| scalar_size(&p.kind)).sum();
        let need = stride.checked_mul(e.count).ok_or_else(|| truncated(0))?;
        if body.len() - pos < need {
            return Err(truncated((body.len() - pos) / stride.max(1)));
        }
        return Ok(pos + need);
    }
    for index in 0..e.count {
        for p in &e.props {
            match p.kind {
                PropKind::Scalar(t) => pos += t.size(),
                PropKind::List { count, item } => {
                    let n = body
                        .get(pos..)
                        .and_then(|b| read_uint(b, count, big))
                        .ok_or_else(|| truncated(index))?;
                    let len = usize::try_from(n)
                        .ok()
                        .and_then(|n| n.checked_mul(item.size()))
                        .ok_or_else(|| truncated(index))?;
                    pos = pos
                        .checked_add(count.size() + len)
                        .ok_or_else(|| truncated(index))?;
                }
            }
            if pos > body.len() {
                return Err(truncated(index));
            }
        }
    }
    Ok(pos)
}

/// Decodes every vertex column except those flagged in `skip` (left empty).
fn read_binary(
    body: &[u8],
    vertex: &Element,
    big: bool,
    path: &Path,
    skip: &[bool],
) -> Result<Columns, PlyError> {
    let stride: usize = vertex.props.iter().map(|p| scalar_size(&p.kind)).sum();
    let available = body.len() / stride.max(1);
    if available < vertex.count {
        return Err(PlyError::Truncated {
            path: path.to_path_buf(),
            element: "vertex".into(),
            index: available,
            expected: vertex.count,
        });
    }
    let n = vertex.count;
    let mut offset = 0;
    let mut columns = Vec::with_capacity(vertex.props.len());
    for p in &vertex.props {
        let PropKind::Scalar(ty) = p.kind else {
            // Refused by `find_layout` before we get here.
            continue;
        };
        let j = columns.len();
        if skip.get(j).copied().unwrap_or(false) {
            columns.push(PropertyValues::with_capacity(ty, 0));
        } else {
            columns.push(decode_column(body, offset, stride, n, ty, big));
        }
        offset += ty.size();
    }
    Ok(columns)
}

/// Decodes one column of a fixed-stride binary body (the caller checked `n * stride` bytes are
/// present).
fn decode_column(
    body: &[u8],
    offset: usize,
    stride: usize,
    n: usize,
    ty: ScalarType,
    big: bool,
) -> PropertyValues {
    macro_rules! col {
        ($variant:ident, $t:ty, $size:expr) => {{
            let mut out: Vec<$t> = Vec::with_capacity(n);
            let rows = body[..n * stride].chunks_exact(stride);
            if big {
                out.extend(rows.map(|row| {
                    let mut a = [0u8; $size];
                    a.copy_from_slice(&row[offset..offset + $size]);
                    <$t>::from_be_bytes(a)
                }));
            } else {
                out.extend(rows.map(|row| {
                    let mut a = [0u8; $size];
                    a.copy_from_slice(&row[offset..offset + $size]);
                    <$t>::from_le_bytes(a)
                }));
            }
            PropertyValues::$variant(out)
        }};
    }
    if n == 0 || stride == 0 {
        return PropertyValues::with_capacity(ty, 0);
    }
    match ty {
        ScalarType::I8 => col!(I8, i8, 1),
        ScalarType::U8 => col!(U8, u8, 1),
        ScalarType::I16 => col!(I16, i16, 2),
        ScalarType::U16 => col!(U16, u16, 2),
        ScalarType::I32 => col!(I32, i32, 4),
        ScalarType::U32 => col!(U32, u32, 4),
        ScalarType::F32 => col!(F32, f32, 4),
        ScalarType::F64 => col!(F64, f64, 8),
    }
}

fn read_ascii(body: &[u8], elements: &[Element], path: &Path) -> Result<Columns, PlyError> {
    let text = String::from_utf8_lossy(body);
    let mut lines = text
        .split('\n')
        .map(|l| l.trim_end_matches('\r'))
        .filter(|l| !l.trim().is_empty());
    let Some((vertex, before)) = elements.split_last() else {
        return Ok(Vec::new());
    };
    for e in before {
        for index in 0..e.count {
            if lines.next().is_none() {
                return Err(PlyError::Truncated {
                    path: path.to_path_buf(),
                    element: e.name.clone(),
                    index,
                    expected: e.count,
                });
            }
        }
    }
    // Each value takes at least two bytes ("0 "): cap the allocation by the bytes present.
    let cap = vertex
        .count
        .min(body.len() / (2 * vertex.props.len().max(1)) + 1);
    let mut columns: Columns = vertex
        .props
        .iter()
        .map(|p| match p.kind {
            PropKind::Scalar(t) => PropertyValues::with_capacity(t, cap),
            PropKind::List { item, .. } => PropertyValues::with_capacity(item, 0),
        })
        .collect();
    for index in 0..vertex.count {
        let Some(line) = lines.next() else {
            return Err(PlyError::Truncated {
                path: path.to_path_buf(),
                element: "vertex".into(),
                index,
                expected: vertex.count,
            });
        };
        let mut tokens = line.split_ascii_whitespace();
        for (p, col) in vertex.props.iter().zip(columns.iter_mut()) {
            let token = tokens.next().ok_or_else(|| PlyError::BadValue {
                path: path.to_path_buf(),
                index,
                name: p.name.clone(),
                token: String::new(),
            })?;
            if !col.push_token(token) {
                return Err(PlyError::BadValue {
                    path: path.to_path_buf(),
                    index,
                    name: p.name.clone(),
                    token: token.chars().take(40).collect(),
                });
            }
        }
    }
    Ok(columns)
}

/// A column as `f32` (exact for `float`, rounded for `double`, converted for integers).
fn column_f32(col: &PropertyValues) -> Cow<'_, [f32]> {
    match col {
        PropertyValues::F32(v) => Cow::Borrowed(v),
        PropertyValues::F64(v) => Cow::Owned(v.iter().map(|&x| x as f32).collect()),
        other => Cow::Owned(
            (0..other.len())
                .map(|i| other.get_f64(i).unwrap_or(0.0) as f32)
                .collect(),
        ),
    }
}

/// The standard parameters of every Gaussian.
struct Standard {
    means: Vec<Vec3>,
    log_scales: Vec<Vec3>,
    rotations: Vec<[f32; 4]>,
    opacity_logits: Vec<f32>,
    sh: Vec<f32>,
}

fn standard_from_columns(columns: &Columns, layout: &Layout, n: usize) -> Standard {
    let col = |i: usize| column_f32(&columns[i]);
    let (x, y, z) = (
        col(layout.mean[0]),
        col(layout.mean[1]),
        col(layout.mean[2]),
    );
    let means: Vec<Vec3> = (0..n).map(|i| Vec3::new(x[i], y[i], z[i])).collect();
    let s: Vec<Cow<'_, [f32]>> = layout.scale.iter().map(|&i| col(i)).collect();
    let log_scales: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(s[0][i], s[1][i], s.get(2).map_or(0.0, |c| c[i])))
        .collect();
    let r: Vec<Cow<'_, [f32]>> = layout.rot.iter().map(|&i| col(i)).collect();
    let rotations: Vec<[f32; 4]> = (0..n)
        .map(|i| [r[0][i], r[1][i], r[2][i], r[3][i]])
        .collect();
    let opacity_logits = col(layout.opacity).into_owned();
    let sh_cols: Vec<Cow<'_, [f32]>> = layout.sh.iter().map(|&i| col(i)).collect();
    let mut sh = Vec::with_capacity(n * sh_cols.len());
    for i in 0..n {
        sh.extend(sh_cols.iter().map(|c| c[i]));
    }
    Standard {
        means,
        log_scales,
        rotations,
        opacity_logits,
        sh,
    }
}

/// Reads the standard parameters row by row from a binary body whose standard properties are
/// all `float` (the caller checked that `count × stride` bytes are present).
fn standard_from_rows<const BIG: bool>(body: &[u8], vertex: &Element, layout: &Layout) -> Standard {
    let mut offsets = Vec::with_capacity(vertex.props.len());
    let mut stride = 0;
    for p in &vertex.props {
        offsets.push(stride);
        stride += scalar_size(&p.kind);
    }
    let n = vertex.count;
    let at = |k: usize| offsets[k];
    let mean = layout.mean.map(at);
    let scale: Vec<usize> = layout.scale.iter().map(|&k| at(k)).collect();
    let rot = layout.rot.map(at);
    let opacity = at(layout.opacity);
    let sh_off: Vec<usize> = layout.sh.iter().map(|&k| at(k)).collect();
    let read = |row: &[u8], off: usize| -> f32 {
        let mut a = [0u8; 4];
        a.copy_from_slice(&row[off..off + 4]);
        if BIG {
            f32::from_be_bytes(a)
        } else {
            f32::from_le_bytes(a)
        }
    };
    let mut out = Standard {
        means: Vec::with_capacity(n),
        log_scales: Vec::with_capacity(n),
        rotations: Vec::with_capacity(n),
        opacity_logits: Vec::with_capacity(n),
        sh: Vec::with_capacity(n * sh_off.len()),
    };
    if stride == 0 {
        return out;
    }
    for row in body[..n * stride].chunks_exact(stride) {
        out.means.push(Vec3::new(
            read(row, mean[0]),
            read(row, mean[1]),
            read(row, mean[2]),
        ));
        out.log_scales.push(Vec3::new(
            read(row, scale[0]),
            read(row, scale[1]),
            scale.get(2).map_or(0.0, |&o| read(row, o)),
        ));
        out.rotations.push(rot.map(|o| read(row, o)));
        out.opacity_logits.push(read(row, opacity));
        out.sh.extend(sh_off.iter().map(|&o| read(row, o)));
    }
    out
}

fn assemble(
    mut columns: Columns,
    standard: Standard,
    vertex: &Element,
    layout: &Layout,
    path: &Path,
) -> Result<GaussianSet, PlyError> {
    let n = vertex.count;
    let scale_dims = if layout.scale.len() == 3 {
        ScaleDims::Three
    } else {
        ScaleDims::Two
    };
    let Standard {
        means,
        log_scales,
        rotations,
        opacity_logits,
        sh,
    } = standard;
    let binding = match layout.binding {
        None => None,
        Some((b, encoding)) => {
            let values = &columns[b];
            let mut triangles = Vec::with_capacity(n);
            for index in 0..n {
                let value = values.get_f64(index).unwrap_or(f64::NAN);
                let ok = value >= 0.0 && value.fract() == 0.0 && value <= f64::from(u32::MAX);
                if !ok {
                    return Err(PlyError::BadBinding {
                        path: path.to_path_buf(),
                        index,
                        value,
                    });
                }
                triangles.push(TriId(value as u32));
            }
            Some(Binding {
                triangles,
                encoding,
            })
        }
    };
    let extras = layout
        .extras
        .iter()
        .map(|&i| ExtraProperty {
            name: vertex.props[i].name.clone(),
            values: std::mem::replace(&mut columns[i], PropertyValues::F32(Vec::new())),
        })
        .collect();
    let space = if binding.is_some() {
        ParameterSpace::Local
    } else {
        ParameterSpace::World
    };
    let parts = GaussianParts {
        means,
        log_scales,
        scale_dims,
        rotations,
        opacity_logits,
        sh_degree: layout.sh_degree,
        sh,
        binding,
        space,
        extras,
        property_order: Some(vertex.props.iter().map(|p| p.name.clone()).collect()),
    };
    GaussianSet::try_new(parts).map_err(|source| PlyError::Invalid {
        path: path.to_path_buf(),
        source,
    })
}

// ----------------------------------------------------------------------------------------------
// Writing

/// A column to write.
enum Column<'a> {
    Mean(usize),
    LogScale(usize),
    Rot(usize),
    Opacity,
    Sh(usize),
    BindingFloat,
    BindingInt(ScalarType),
    Extra(&'a PropertyValues),
}

fn columns_to_write(set: &GaussianSet) -> Vec<(String, Column<'_>)> {
    let mut canonical: Vec<(String, Column<'_>)> = Vec::new();
    for (i, n) in ["x", "y", "z"].iter().enumerate() {
        canonical.push(((*n).to_string(), Column::Mean(i)));
    }
    let k = sh_coeffs_per_channel(set.sh_degree());
    for c in 0..3 {
        canonical.push((format!("f_dc_{c}"), Column::Sh(c)));
    }
    for j in 0..3 * (k - 1) {
        canonical.push((format!("f_rest_{j}"), Column::Sh(3 + j)));
    }
    canonical.push(("opacity".into(), Column::Opacity));
    for i in 0..set.scale_dims().count() {
        canonical.push((format!("scale_{i}"), Column::LogScale(i)));
    }
    for i in 0..4 {
        canonical.push((format!("rot_{i}"), Column::Rot(i)));
    }
    for e in set.extras() {
        canonical.push((e.name.clone(), Column::Extra(&e.values)));
    }
    if let Some(b) = set.binding() {
        match b.encoding {
            BindingEncoding::Float => canonical.push(("binding_0".into(), Column::BindingFloat)),
            BindingEncoding::Integer(t) => {
                canonical.push(("binding".into(), Column::BindingInt(t)));
            }
        }
    }
    let Some(order) = set.property_order() else {
        return canonical;
    };
    // The recorded order first (names we still write), then the rest in canonical order.
    let mut out = Vec::with_capacity(canonical.len());
    let mut slots: Vec<Option<(String, Column<'_>)>> = canonical.into_iter().map(Some).collect();
    for name in order {
        if let Some(slot) = slots
            .iter_mut()
            .find(|s| s.as_ref().is_some_and(|(n, _)| n == name))
        {
            out.extend(slot.take());
        }
    }
    out.extend(slots.into_iter().flatten());
    out
}

fn column_type(c: &Column<'_>) -> ScalarType {
    match c {
        Column::BindingInt(t) => *t,
        Column::Extra(v) => v.scalar_type(),
        _ => ScalarType::F32,
    }
}

/// Checks that every binding fits its encoding.
fn check_binding(set: &GaussianSet, path: &Path) -> Result<(), PlyError> {
    let Some(b) = set.binding() else {
        return Ok(());
    };
    let (limit, ty) = match b.encoding {
        BindingEncoding::Float => (u64::from(MAX_FLOAT_BINDING), ScalarType::F32),
        BindingEncoding::Integer(t) => {
            let limit = match t {
                ScalarType::I8 => i8::MAX as u64,
                ScalarType::U8 => u64::from(u8::MAX),
                ScalarType::I16 => i16::MAX as u64,
                ScalarType::U16 => u64::from(u16::MAX),
                ScalarType::I32 => i32::MAX as u64,
                ScalarType::U32 => u64::from(u32::MAX),
                ScalarType::F32 => u64::from(MAX_FLOAT_BINDING),
                ScalarType::F64 => u64::from(u32::MAX),
            };
            (limit, t)
        }
    };
    match b.triangles.iter().position(|t| u64::from(t.0) > limit) {
        Some(index) => Err(PlyError::BindingNotRepresentable {
            path: path.to_path_buf(),
            index,
            triangle: b.triangles[index],
            ty,
        }),
        None => Ok(()),
    }
}

/// Writes `set` to `path` atomically (temporary file + rename).
///
/// # Errors
/// [`PlyError::BindingNotRepresentable`] when a binding does not fit its encoding,
/// [`PlyError::Write`] when the file cannot be written (the target is then untouched).
pub fn write_gaussians(
    path: &Path,
    set: &GaussianSet,
    options: &PlyWriteOptions,
) -> Result<(), PlyError> {
    check_binding(set, path)?;
    write_atomically(path, |w| {
        write_gaussians_unchecked(w, set, options).map_err(|e| IoError::os(path, e))
    })
    .map_err(PlyError::Write)
}

/// Writes `set` as PLY to any writer (no atomicity; see [`write_gaussians`]).
///
/// # Errors
/// [`PlyError::BindingNotRepresentable`], or [`PlyError::Io`] (with an empty path) when the
/// writer fails.
pub fn write_gaussians_to(
    w: &mut dyn Write,
    set: &GaussianSet,
    options: &PlyWriteOptions,
) -> Result<(), PlyError> {
    check_binding(set, Path::new(""))?;
    write_gaussians_unchecked(w, set, options).map_err(|source| PlyError::Io {
        path: PathBuf::new(),
        source,
    })
}

/// Gaussians encoded per block before each `write_all` call.
const WRITE_BLOCK: usize = 1 << 14;

fn write_gaussians_unchecked(
    w: &mut dyn Write,
    set: &GaussianSet,
    options: &PlyWriteOptions,
) -> std::io::Result<()> {
    let columns = columns_to_write(set);
    let mut header = String::new();
    header.push_str("ply\n");
    header.push_str(&format!("format {} 1.0\n", options.encoding.header_name()));
    header.push_str(&format!("element vertex {}\n", set.len()));
    for (name, c) in &columns {
        header.push_str(&format!("property {} {name}\n", column_type(c).ply_name()));
    }
    header.push_str("end_header\n");
    w.write_all(header.as_bytes())?;

    let n = set.len();
    let sh_stride = 3 * sh_coeffs_per_channel(set.sh_degree());
    let binding = set.binding().map(|b| b.triangles.as_slice());
    let mut buf: Vec<u8> = Vec::new();
    let mut start = 0;
    while start < n {
        let end = (start + WRITE_BLOCK).min(n);
        buf.clear();
        for i in start..end {
            for (j, (_, c)) in columns.iter().enumerate() {
                let v = match c {
                    Column::Mean(a) => Value::F32(set.means()[i][*a]),
                    Column::LogScale(a) => Value::F32(set.log_scales()[i][*a]),
                    Column::Rot(a) => Value::F32(set.rotations()[i][*a]),
                    Column::Opacity => Value::F32(set.opacity_logits()[i]),
                    Column::Sh(a) => Value::F32(set.sh()[i * sh_stride + a]),
                    Column::BindingFloat => Value::F32(binding.map_or(0.0, |b| b[i].0 as f32)),
                    Column::BindingInt(t) => Value::from_u32(*t, binding.map_or(0, |b| b[i].0)),
                    Column::Extra(values) => Value::of(values, i),
                };
                match options.encoding {
                    PlyEncoding::BinaryLittleEndian => v.push_bytes(&mut buf, false),
                    PlyEncoding::BinaryBigEndian => v.push_bytes(&mut buf, true),
                    PlyEncoding::Ascii => {
                        if j > 0 {
                            buf.push(b' ');
                        }
                        v.push_text(&mut buf);
                    }
                }
            }
            if options.encoding == PlyEncoding::Ascii {
                buf.push(b'\n');
            }
        }
        w.write_all(&buf)?;
        start = end;
    }
    w.flush()
}

/// One value to write.
#[derive(Clone, Copy)]
enum Value {
    I8(i8),
    U8(u8),
    I16(i16),
    U16(u16),
    I32(i32),
    U32(u32),
    F32(f32),
    F64(f64),
}

impl Value {
    fn of(values: &PropertyValues, i: usize) -> Self {
        match values {
            PropertyValues::I8(v) => Self::I8(v.get(i).copied().unwrap_or(0)),
            PropertyValues::U8(v) => Self::U8(v.get(i).copied().unwrap_or(0)),
            PropertyValues::I16(v) => Self::I16(v.get(i).copied().unwrap_or(0)),
            PropertyValues::U16(v) => Self::U16(v.get(i).copied().unwrap_or(0)),
            PropertyValues::I32(v) => Self::I32(v.get(i).copied().unwrap_or(0)),
            PropertyValues::U32(v) => Self::U32(v.get(i).copied().unwrap_or(0)),
            PropertyValues::F32(v) => Self::F32(v.get(i).copied().unwrap_or(0.0)),
            PropertyValues::F64(v) => Self::F64(v.get(i).copied().unwrap_or(0.0)),
        }
    }

    /// `x` in type `t` (the caller checked it fits, see `check_binding`).
    fn from_u32(t: ScalarType, x: u32) -> Self {
        match t {
            ScalarType::I8 => Self::I8(x as i8),
            ScalarType::U8 => Self::U8(x as u8),
            ScalarType::I16 => Self::I16(x as i16),
            ScalarType::U16 => Self::U16(x as u16),
            ScalarType::I32 => Self::I32(x as i32),
            ScalarType::U32 => Self::U32(x),
            ScalarType::F32 => Self::F32(x as f32),
            ScalarType::F64 => Self::F64(f64::from(x)),
        }
    }

    fn push_bytes(self, buf: &mut Vec<u8>, big: bool) {
        macro_rules! put {
            ($v:expr) => {
                if big {
                    buf.extend_from_slice(&$v.to_be_bytes())
                } else {
                    buf.extend_from_slice(&$v.to_le_bytes())
                }
            };
        }
        match self {
            Self::I8(v) => put!(v),
            Self::U8(v) => put!(v),
            Self::I16(v) => put!(v),
            Self::U16(v) => put!(v),
            Self::I32(v) => put!(v),
            Self::U32(v) => put!(v),
            Self::F32(v) => put!(v),
            Self::F64(v) => put!(v),
        }
    }

    /// Shortest text that reads back to the same value (Rust's `Display` for floats).
    fn push_text(self, buf: &mut Vec<u8>) {
        let s = match self {
            Self::I8(v) => v.to_string(),
            Self::U8(v) => v.to_string(),
            Self::I16(v) => v.to_string(),
            Self::U16(v) => v.to_string(),
            Self::I32(v) => v.to_string(),
            Self::U32(v) => v.to_string(),
            Self::F32(v) => float_text(f64::from(v), v.to_string(), format!("{v:e}")),
            Self::F64(v) => float_text(v, v.to_string(), format!("{v:e}")),
        };
        buf.extend_from_slice(s.as_bytes());
    }
}

/// Positional notation for ordinary magnitudes, exponent notation for tiny or huge ones (both
/// are Rust's shortest round-trip digits).
fn float_text(v: f64, positional: String, exponent: String) -> String {
    let a = v.abs();
    if a == 0.0 || !a.is_finite() || (1e-5..1e16).contains(&a) {
        positional
    } else {
        exponent
    }
}
