//! The bytes of a glTF file, for every glTF reader of the crate (static meshes in
//! [`super::gltf`], animation in [`crate::animation`]): the document, its raw JSON (for
//! `extras`), its buffers, and accessors decoded into f64 with every check the spec asks for:
//! offsets, strides and counts against the bytes actually present (sparse accessors included),
//! matrix column padding, normalised integers, finite floats. The `gltf` crate's own readers
//! assume the component type and skip sparse accessors in some paths, and its validation
//! indexes the accessor array with a primitive's attribute index unchecked (a panic on a bad
//! index), so attribute indices are checked first. A bad file is an error naming the file and
//! the buffer, accessor or primitive, never a panic.

use std::path::{Path, PathBuf};

use base64::Engine as _;
use gltf::accessor::{DataType, Dimensions};

/// Accessors without a buffer view (zeros, or sparse substitutions only) may describe at most
/// this many times the bytes of all buffers, plus a MiB: a count the file cannot back is
/// refused rather than allocated.
const UNBACKED_ACCESSOR_FACTOR: usize = 4;

/// What is wrong with a glTF file (the file itself is in [`GltfDataError::path`]).
#[derive(Debug)]
pub(crate) enum GltfDataErrorKind {
    /// The file cannot be read.
    Os(std::io::Error),
    /// Not a glTF document (or an invalid one).
    Document(gltf::Error),
    /// The GLB header is malformed (checked before the `gltf` crate reads it).
    GlbHeader(String),
    /// A primitive attribute names an accessor the file does not have.
    Attribute {
        mesh: usize,
        primitive: usize,
        message: String,
    },
    /// An external buffer file cannot be read.
    MissingBuffer {
        buffer: usize,
        uri: String,
        resolved: PathBuf,
        error: std::io::Error,
    },
    /// A buffer is malformed or shorter than it says.
    Buffer { buffer: usize, message: String },
    /// An accessor does not fit its data or holds bad values.
    Accessor { accessor: usize, message: String },
}

/// An error reading glTF data: the file and what is wrong; each reader turns it into its own
/// error type (`IoError`, `AnimationError`).
#[derive(Debug)]
pub(crate) struct GltfDataError {
    pub(crate) path: PathBuf,
    pub(crate) kind: GltfDataErrorKind,
}

/// A glTF file's document, raw JSON and loaded buffers.
pub(crate) struct GltfData {
    path: PathBuf,
    /// The parsed, validated document.
    pub(crate) document: gltf::Document,
    /// The document's JSON, for `extras` and the reference checks.
    pub(crate) json: serde_json::Value,
    buffers: Vec<Vec<u8>>,
}

/// Size of the GLB header: magic, version, total length (u32 each).
const GLB_HEADER_BYTES: usize = 12;

/// Checks the GLB header's total length, which `gltf::binary::Glb::from_slice` subtracts the
/// header size from unchecked (an overflow panic in builds with overflow checks).
fn check_glb_header(bytes: &[u8]) -> Result<(), String> {
    let Some(length) = bytes.get(8..GLB_HEADER_BYTES) else {
        return Err(format!(
            "the file has {} bytes, fewer than the {GLB_HEADER_BYTES} of a GLB header",
            bytes.len()
        ));
    };
    let length = u32::from_le_bytes([length[0], length[1], length[2], length[3]]);
    if (length as usize) < GLB_HEADER_BYTES {
        return Err(format!(
            "the header's total length {length} is shorter than the header itself \
             ({GLB_HEADER_BYTES} bytes)"
        ));
    }
    Ok(())
}

impl GltfData {
    /// Reads `path` (`.gltf` with data-URI or external buffers, or `.glb`) and loads every
    /// buffer: the GLB `BIN` chunk, base64 data URIs, or files resolved against the folder of
    /// `path`.
    pub(crate) fn open(path: &Path) -> Result<Self, GltfDataError> {
        let err = |kind| GltfDataError {
            path: path.to_path_buf(),
            kind,
        };
        let bytes = std::fs::read(path).map_err(|e| err(GltfDataErrorKind::Os(e)))?;
        let (json_bytes, blob): (Vec<u8>, Option<Vec<u8>>) = if bytes.starts_with(b"glTF") {
            check_glb_header(&bytes).map_err(|m| err(GltfDataErrorKind::GlbHeader(m)))?;
            let glb = gltf::binary::Glb::from_slice(&bytes)
                .map_err(|e| err(GltfDataErrorKind::Document(e)))?;
            (glb.json.into_owned(), glb.bin.map(|b| b.into_owned()))
        } else {
            (bytes, None)
        };
        // The reference checks read this plain JSON, so a document the `gltf` crate accepts
        // but plain JSON does not (invalid UTF-8 in a string the crate skips) is refused rather
        // than checked as empty; and it is read first, so that no document reaches the
        // crate's validation unchecked.
        let json = serde_json::from_slice(&json_bytes)
            .map_err(|e| err(GltfDataErrorKind::Document(gltf::Error::Deserialize(e))))?;
        check_attribute_indices(&json).map_err(err)?;
        let document = match gltf::Gltf::from_slice(&json_bytes) {
            Ok(g) => g.document,
            // Extension-defined attribute semantics (`KHR_gaussian_splatting:SCALE`) are valid
            // glTF, but the `gltf` crate's validation knows only the core names and `_`-prefixed
            // ones: validate a copy in which they are renamed `_...` (readers look attributes
            // up in the file's own JSON).
            Err(e) => match renamed_extension_semantics(&json_bytes) {
                Some(renamed) => {
                    gltf::Gltf::from_slice(&renamed)
                        .map_err(|e| err(GltfDataErrorKind::Document(e)))?
                        .document
                }
                None => return Err(err(GltfDataErrorKind::Document(e))),
            },
        };
        let buffers = load_buffers(path, &document, blob).map_err(err)?;
        Ok(Self {
            path: path.to_path_buf(),
            document,
            json,
            buffers,
        })
    }

    /// The file's path.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    fn error(&self, accessor: usize, message: impl Into<String>) -> GltfDataError {
        GltfDataError {
            path: self.path.clone(),
            kind: GltfDataErrorKind::Accessor {
                accessor,
                message: message.into(),
            },
        }
    }

    /// The bytes of buffer view `view` (an accessor's or an image's), checked against its
    /// buffer; the message says what is wrong.
    pub(crate) fn buffer_view_bytes(&self, view: &gltf::buffer::View<'_>) -> Result<&[u8], String> {
        let buffer = self
            .buffers
            .get(view.buffer().index())
            .ok_or_else(|| format!("buffer view {} refers to a missing buffer", view.index()))?;
        view.offset()
            .checked_add(view.length())
            .and_then(|end| buffer.get(view.offset()..end))
            .ok_or_else(|| {
                format!(
                    "buffer view {} (offset {}, length {}) runs past its buffer of {} bytes",
                    view.index(),
                    view.offset(),
                    view.length(),
                    buffer.len()
                )
            })
    }

    /// The bytes of a buffer view, checked against its buffer ([`Self::buffer_view_bytes`],
    /// the error naming `accessor`).
    fn view_bytes(
        &self,
        accessor: usize,
        view: &gltf::buffer::View<'_>,
    ) -> Result<&[u8], GltfDataError> {
        self.buffer_view_bytes(view)
            .map_err(|message| self.error(accessor, message))
    }

    /// Reads `count` elements of `dims` from `bytes` at `offset` with `stride` (the element
    /// size when `None`), every byte checked to be present.
    #[expect(clippy::too_many_arguments, reason = "the fields of an accessor")]
    fn read_strided(
        &self,
        accessor: usize,
        bytes: &[u8],
        offset: usize,
        stride: Option<usize>,
        count: usize,
        dims: Dimensions,
        ty: DataType,
        normalized: bool,
    ) -> Result<Vec<f64>, GltfDataError> {
        let size = ty.size();
        let elem = element_size(dims, size);
        let stride = stride.unwrap_or(elem);
        if stride < elem {
            return Err(self.error(
                accessor,
                format!("byteStride {stride} is smaller than the element size {elem}"),
            ));
        }
        let needed = if count == 0 {
            Some(0)
        } else {
            (count - 1)
                .checked_mul(stride)
                .and_then(|x| x.checked_add(elem))
                .and_then(|x| x.checked_add(offset))
        };
        if !matches!(needed, Some(n) if n <= bytes.len()) {
            return Err(self.error(
                accessor,
                format!(
                    "{count} elements of {elem} bytes (stride {stride}, offset {offset}) do not \
                     fit in the {} bytes of their buffer view",
                    bytes.len()
                ),
            ));
        }
        let n = dims.multiplicity();
        let mut out = Vec::with_capacity(count * n);
        for i in 0..count {
            let base = offset + i * stride;
            for c in 0..n {
                let at = base + component_offset(dims, size, c);
                out.push(component(&bytes[at..at + size], ty, normalized));
            }
        }
        Ok(out)
    }

    /// Reads `accessor` as `count × components` f64 values (row after row; matrices column
    /// by column), converting normalised integers per the glTF spec and applying sparse
    /// substitution. Float values must be finite.
    pub(crate) fn read(&self, accessor: &gltf::Accessor<'_>) -> Result<Vec<f64>, GltfDataError> {
        let index = accessor.index();
        let dims = accessor.dimensions();
        let n = dims.multiplicity();
        let count = accessor.count();
        let ty = accessor.data_type();
        let normalized = accessor.normalized();
        let total = count
            .checked_mul(n)
            .ok_or_else(|| self.error(index, "count overflows"))?;
        let mut values = match accessor.view() {
            Some(view) => self.read_strided(
                index,
                self.view_bytes(index, &view)?,
                accessor.offset(),
                view.stride(),
                count,
                dims,
                ty,
                normalized,
            )?,
            None => {
                let bytes: usize = self.buffers.iter().map(Vec::len).sum();
                let cap = bytes.saturating_mul(UNBACKED_ACCESSOR_FACTOR) + (1 << 20);
                if total.saturating_mul(ty.size()) > cap {
                    return Err(self.error(
                        index,
                        format!(
                            "count {count} without a buffer view is far larger than the file's data"
                        ),
                    ));
                }
                vec![0.0; total]
            }
        };
        if let Some(sparse) = accessor.sparse() {
            let k = sparse.count();
            let indices = sparse.indices();
            let index_type = match indices.index_type() {
                gltf::accessor::sparse::IndexType::U8 => DataType::U8,
                gltf::accessor::sparse::IndexType::U16 => DataType::U16,
                gltf::accessor::sparse::IndexType::U32 => DataType::U32,
            };
            let targets = self.read_strided(
                index,
                self.view_bytes(index, &indices.view())?,
                indices.offset(),
                None,
                k,
                Dimensions::Scalar,
                index_type,
                false,
            )?;
            let sv = sparse.values();
            let replacements = self.read_strided(
                index,
                self.view_bytes(index, &sv.view())?,
                sv.offset(),
                None,
                k,
                dims,
                ty,
                normalized,
            )?;
            for (j, &target) in targets.iter().enumerate() {
                #[expect(
                    clippy::cast_possible_truncation,
                    clippy::cast_sign_loss,
                    reason = "unsigned integer indices read exactly into f64"
                )]
                let target = target as usize;
                if target >= count {
                    return Err(self.error(
                        index,
                        format!(
                            "sparse index {target} (entry {j}) is out of range for count {count}"
                        ),
                    ));
                }
                values[target * n..(target + 1) * n]
                    .copy_from_slice(&replacements[j * n..(j + 1) * n]);
            }
        }
        if ty == DataType::F32
            && let Some(bad) = values.iter().position(|v| !v.is_finite())
        {
            return Err(self.error(index, format!("element {} is not finite", bad / n.max(1))));
        }
        Ok(values)
    }

    /// Reads `accessor` and checks that it has `dims` components per element.
    pub(crate) fn read_dims(
        &self,
        accessor: &gltf::Accessor<'_>,
        dims: usize,
    ) -> Result<Vec<f64>, GltfDataError> {
        let have = accessor.dimensions().multiplicity();
        if have != dims {
            return Err(self.error(
                accessor.index(),
                format!("expected {dims} components per element, found {have}"),
            ));
        }
        self.read(accessor)
    }

    /// Reads an index or joint accessor: unsigned integers only.
    pub(crate) fn read_unsigned(
        &self,
        accessor: &gltf::Accessor<'_>,
    ) -> Result<Vec<u32>, GltfDataError> {
        if !matches!(
            accessor.data_type(),
            DataType::U8 | DataType::U16 | DataType::U32
        ) || accessor.normalized()
        {
            return Err(self.error(
                accessor.index(),
                "expected unsigned integers (not normalised)",
            ));
        }
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "u32 values are exact in f64"
        )]
        Ok(self.read(accessor)?.into_iter().map(|v| v as u32).collect())
    }
}

/// The JSON with every primitive attribute (and morph target) name that holds a `:` renamed
/// `_` + the name with `:` as `_`; `None` when there is none (or the JSON does not parse).
fn renamed_extension_semantics(json_bytes: &[u8]) -> Option<Vec<u8>> {
    let mut json: serde_json::Value = serde_json::from_slice(json_bytes).ok()?;
    let mut renamed = false;
    let mut rename = |map: &mut serde_json::Map<String, serde_json::Value>| {
        let names: Vec<String> = map.keys().filter(|k| k.contains(':')).cloned().collect();
        for name in names {
            if let Some(v) = map.remove(&name) {
                map.insert(format!("_{}", name.replace(':', "_")), v);
                renamed = true;
            }
        }
    };
    for mesh in json.get_mut("meshes")?.as_array_mut()? {
        let Some(primitives) = mesh.get_mut("primitives").and_then(|p| p.as_array_mut()) else {
            continue;
        };
        for primitive in primitives {
            if let Some(map) = primitive
                .get_mut("attributes")
                .and_then(|a| a.as_object_mut())
            {
                rename(map);
            }
            if let Some(targets) = primitive.get_mut("targets").and_then(|t| t.as_array_mut()) {
                for target in targets {
                    if let Some(map) = target.as_object_mut() {
                        rename(map);
                    }
                }
            }
        }
    }
    renamed.then(|| json.to_string().into_bytes())
}

/// Refuses a primitive attribute (or morph-target attribute) that names an accessor the file
/// does not have (the `gltf` crate's validation indexes the accessor array with `POSITION`
/// unchecked). Read from the plain JSON, so it holds whatever the `gltf` crate makes of the
/// rest of the document (an unknown semantic such as `NOR:AL` included).
fn check_attribute_indices(json: &serde_json::Value) -> Result<(), GltfDataErrorKind> {
    let accessors = json
        .get("accessors")
        .and_then(|a| a.as_array())
        .map_or(0, Vec::len);
    let Some(meshes) = json.get("meshes").and_then(|m| m.as_array()) else {
        return Ok(());
    };
    for (mesh, m) in meshes.iter().enumerate() {
        let Some(primitives) = m.get("primitives").and_then(|p| p.as_array()) else {
            continue;
        };
        for (primitive, p) in primitives.iter().enumerate() {
            let targets = p
                .get("targets")
                .and_then(|t| t.as_array())
                .into_iter()
                .flatten();
            let maps = p.get("attributes").into_iter().chain(targets);
            for map in maps.filter_map(|m| m.as_object()) {
                for (semantic, accessor) in map {
                    // Non-integers are refused by the validated parse.
                    let Some(index) = accessor.as_u64() else {
                        continue;
                    };
                    if usize::try_from(index).map_or(true, |i| i >= accessors) {
                        return Err(GltfDataErrorKind::Attribute {
                            mesh,
                            primitive,
                            message: format!(
                                "attribute {semantic:?} refers to accessor {index}, which does \
                                 not exist"
                            ),
                        });
                    }
                }
            }
        }
    }
    Ok(())
}

/// Loads every buffer of `document`.
fn load_buffers(
    path: &Path,
    document: &gltf::Document,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>, GltfDataErrorKind> {
    let base = path.parent().unwrap_or_else(|| Path::new("."));
    let mut data = Vec::new();
    for buffer in document.buffers() {
        let index = buffer.index();
        let bad = |message: String| GltfDataErrorKind::Buffer {
            buffer: index,
            message,
        };
        let bytes = match buffer.source() {
            gltf::buffer::Source::Bin => blob
                .take()
                .ok_or_else(|| bad("refers to the GLB BIN chunk, which is missing".into()))?,
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let (_, payload) = uri.split_once(";base64,").ok_or_else(|| {
                    bad("data URI is not base64 (only base64 data URIs are supported)".into())
                })?;
                base64::engine::general_purpose::STANDARD
                    .decode(payload)
                    .map_err(|e| bad(format!("bad base64 data URI: {e}")))?
            }
            gltf::buffer::Source::Uri(uri) => {
                let resolved = base.join(percent_decode(uri));
                std::fs::read(&resolved).map_err(|error| GltfDataErrorKind::MissingBuffer {
                    buffer: index,
                    uri: uri.to_string(),
                    resolved: resolved.clone(),
                    error,
                })?
            }
        };
        if bytes.len() < buffer.length() {
            return Err(bad(format!(
                "holds {} bytes, but byteLength is {} (truncated?)",
                bytes.len(),
                buffer.length()
            )));
        }
        data.push(bytes);
    }
    Ok(data)
}

/// Decodes `%XX` escapes in a relative URI (spaces and non-ASCII names in real files).
pub(crate) fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%'
            && let Some(v) = bytes
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// One little-endian component as f64, normalised per the glTF 2.0 spec (§3.11) when asked.
fn component(b: &[u8], ty: DataType, normalized: bool) -> f64 {
    let raw = match ty {
        DataType::I8 => f64::from(i8::from_le_bytes([b[0]])),
        DataType::U8 => f64::from(b[0]),
        DataType::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
        DataType::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
        DataType::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        DataType::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
    };
    if !normalized {
        return raw;
    }
    match ty {
        DataType::I8 => (raw / 127.0).max(-1.0),
        DataType::U8 => raw / 255.0,
        DataType::I16 => (raw / 32767.0).max(-1.0),
        DataType::U16 => raw / 65535.0,
        DataType::U32 => raw / f64::from(u32::MAX),
        DataType::F32 => raw,
    }
}

/// Byte offset of component `c` inside one element (matrix columns are padded to 4 bytes).
fn component_offset(dims: Dimensions, size: usize, c: usize) -> usize {
    let rows = match dims {
        Dimensions::Mat2 => 2,
        Dimensions::Mat3 => 3,
        Dimensions::Mat4 => 4,
        _ => return c * size,
    };
    let column_stride = (rows * size).div_ceil(4) * 4;
    (c / rows) * column_stride + (c % rows) * size
}

/// Bytes of one element, column padding included.
fn element_size(dims: Dimensions, size: usize) -> usize {
    component_offset(dims, size, dims.multiplicity() - 1) + size
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("plain.bin"), "plain.bin");
        assert_eq!(percent_decode("bad%2"), "bad%2");
        assert_eq!(percent_decode("x%"), "x%");
    }

    #[test]
    fn normalised_components() {
        assert_eq!(component(&[127], DataType::I8, true), 1.0);
        assert_eq!(component(&[0x80], DataType::I8, true), -1.0);
        assert_eq!(component(&[255], DataType::U8, true), 1.0);
        assert_eq!(component(&32767i16.to_le_bytes(), DataType::I16, true), 1.0);
        assert_eq!(
            component(&(-32768i16).to_le_bytes(), DataType::I16, true),
            -1.0
        );
        assert_eq!(component(&65535u16.to_le_bytes(), DataType::U16, true), 1.0);
        assert_eq!(component(&7u16.to_le_bytes(), DataType::U16, false), 7.0);
        assert_eq!(component(&1.5f32.to_le_bytes(), DataType::F32, false), 1.5);
    }

    #[test]
    fn matrix_columns_are_padded_to_four_bytes() {
        // MAT3 of u8: three columns of 3 bytes, each padded to 4.
        assert_eq!(component_offset(Dimensions::Mat3, 1, 3), 4);
        assert_eq!(element_size(Dimensions::Mat3, 1), 11);
        assert_eq!(element_size(Dimensions::Mat4, 4), 64);
        assert_eq!(element_size(Dimensions::Vec3, 4), 12);
    }
}
