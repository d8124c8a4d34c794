//! glTF buffers and accessors, read into f64 with every check the spec asks for: byte strides,
//! normalised integers, sparse substitution, bounds against the bytes actually present, finite
//! values. The `gltf` crate's own readers assume the component type and skip sparse accessors
//! in some paths, so the animation code reads everything through here.

use std::path::{Path, PathBuf};

use base64::Engine as _;
use gltf::accessor::{DataType, Dimensions};

use super::AnimationError;

/// Largest number of scalar values one accessor may produce when it has no buffer view
/// (a zero-filled or purely sparse accessor): a count the file cannot back is refused
/// rather than allocated.
const MAX_UNBACKED_VALUES: usize = 1 << 28;

/// The loaded buffers of one glTF file and the file's path (for error messages).
pub(crate) struct Buffers {
    path: PathBuf,
    data: Vec<Vec<u8>>,
}

impl Buffers {
    /// Loads every buffer of `document`: the GLB `BIN` chunk, base64 data URIs, or external
    /// files resolved against the folder of `path`.
    pub(crate) fn load(
        path: &Path,
        document: &gltf::Document,
        mut blob: Option<Vec<u8>>,
    ) -> Result<Self, AnimationError> {
        let base = path.parent().unwrap_or_else(|| Path::new("."));
        let mut data = Vec::new();
        for buffer in document.buffers() {
            let index = buffer.index();
            let bad = |message: String| AnimationError::Buffer {
                path: path.to_path_buf(),
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
                    std::fs::read(&resolved).map_err(|error| AnimationError::MissingBuffer {
                        path: path.to_path_buf(),
                        buffer: index,
                        uri: uri.to_string(),
                        resolved: resolved.clone(),
                        error,
                    })?
                }
            };
            if bytes.len() < buffer.length() {
                return Err(bad(format!(
                    "holds {} bytes, but byteLength is {}",
                    bytes.len(),
                    buffer.length()
                )));
            }
            data.push(bytes);
        }
        Ok(Self {
            path: path.to_path_buf(),
            data,
        })
    }

    fn error(&self, accessor: usize, message: impl Into<String>) -> AnimationError {
        AnimationError::Accessor {
            path: self.path.clone(),
            accessor,
            message: message.into(),
        }
    }

    /// The bytes of a buffer view, checked against its buffer.
    fn view_bytes(
        &self,
        accessor: usize,
        view: &gltf::buffer::View,
    ) -> Result<&[u8], AnimationError> {
        let buffer = self
            .data
            .get(view.buffer().index())
            .ok_or_else(|| self.error(accessor, "buffer view refers to a missing buffer"))?;
        let end = view.offset().checked_add(view.length());
        match end {
            Some(end) if end <= buffer.len() => Ok(&buffer[view.offset()..end]),
            _ => Err(self.error(
                accessor,
                format!(
                    "buffer view {} (offset {}, length {}) runs past its buffer of {} bytes",
                    view.index(),
                    view.offset(),
                    view.length(),
                    buffer.len()
                ),
            )),
        }
    }

    /// Reads `accessor` as `count × components` f64 values (row after row), converting
    /// normalised integers per the glTF spec and applying sparse substitution. Float values
    /// must be finite.
    pub(crate) fn read(&self, accessor: &gltf::Accessor) -> Result<Vec<f64>, AnimationError> {
        let index = accessor.index();
        let dims = accessor.dimensions().multiplicity();
        let ctype = accessor.data_type();
        let csize = ctype.size();
        if matches!(accessor.dimensions(), Dimensions::Mat2 | Dimensions::Mat3) && csize < 4 {
            return Err(self.error(
                index,
                "padded MAT2/MAT3 of 8- or 16-bit components is not supported",
            ));
        }
        let elem = dims * csize;
        let count = accessor.count();
        let normalized = accessor.normalized();
        let total = count
            .checked_mul(dims)
            .ok_or_else(|| self.error(index, "count overflows"))?;
        let mut values = match accessor.view() {
            Some(view) => {
                let bytes = self.view_bytes(index, &view)?;
                let stride = view.stride().unwrap_or(elem);
                if stride < elem {
                    return Err(self.error(
                        index,
                        format!("byteStride {stride} is smaller than the element size {elem}"),
                    ));
                }
                if count > 0 {
                    let need = (count - 1)
                        .checked_mul(stride)
                        .and_then(|v| v.checked_add(elem))
                        .and_then(|v| v.checked_add(accessor.offset()));
                    match need {
                        Some(need) if need <= bytes.len() => {}
                        _ => {
                            return Err(self.error(
                                index,
                                format!(
                                    "{count} elements of {elem} bytes (stride {stride}, offset {}) do not fit in buffer view {} of {} bytes",
                                    accessor.offset(),
                                    view.index(),
                                    bytes.len()
                                ),
                            ));
                        }
                    }
                }
                let mut out = Vec::with_capacity(total);
                for i in 0..count {
                    let start = accessor.offset() + i * stride;
                    for c in 0..dims {
                        let at = start + c * csize;
                        out.push(component(&bytes[at..at + csize], ctype, normalized));
                    }
                }
                out
            }
            None => {
                if total > MAX_UNBACKED_VALUES {
                    return Err(self.error(
                        index,
                        format!("count {count} without a buffer view is too large"),
                    ));
                }
                vec![0.0; total]
            }
        };
        if let Some(sparse) = accessor.sparse() {
            let n = sparse.count();
            let ind = sparse.indices();
            let ind_view = ind.view();
            let ind_bytes = self.view_bytes(index, &ind_view)?;
            let isize = ind.index_type().size();
            let val = sparse.values();
            let val_view = val.view();
            let val_bytes = self.view_bytes(index, &val_view)?;
            let ind_need = n
                .checked_mul(isize)
                .and_then(|v| v.checked_add(ind.offset()));
            let val_need = n
                .checked_mul(elem)
                .and_then(|v| v.checked_add(val.offset()));
            if !matches!(ind_need, Some(k) if k <= ind_bytes.len())
                || !matches!(val_need, Some(k) if k <= val_bytes.len())
            {
                return Err(self.error(
                    index,
                    format!("sparse: {n} indices/values do not fit in their buffer views"),
                ));
            }
            for s in 0..n {
                let at = ind.offset() + s * isize;
                let target = match ind.index_type() {
                    gltf::accessor::sparse::IndexType::U8 => usize::from(ind_bytes[at]),
                    gltf::accessor::sparse::IndexType::U16 => {
                        usize::from(u16::from_le_bytes([ind_bytes[at], ind_bytes[at + 1]]))
                    }
                    gltf::accessor::sparse::IndexType::U32 => u32::from_le_bytes([
                        ind_bytes[at],
                        ind_bytes[at + 1],
                        ind_bytes[at + 2],
                        ind_bytes[at + 3],
                    ]) as usize,
                };
                if target >= count {
                    return Err(self.error(
                        index,
                        format!(
                            "sparse index {target} (entry {s}) is out of range for count {count}"
                        ),
                    ));
                }
                let start = val.offset() + s * elem;
                for c in 0..dims {
                    let at = start + c * csize;
                    values[target * dims + c] =
                        component(&val_bytes[at..at + csize], ctype, normalized);
                }
            }
        }
        if ctype == DataType::F32
            && let Some(bad) = values.iter().position(|v| !v.is_finite())
        {
            return Err(self.error(
                index,
                format!("element {} is not finite", bad / dims.max(1)),
            ));
        }
        Ok(values)
    }

    /// Reads `accessor` and checks that it has `dims` components per element.
    pub(crate) fn read_dims(
        &self,
        accessor: &gltf::Accessor,
        dims: usize,
    ) -> Result<Vec<f64>, AnimationError> {
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
        accessor: &gltf::Accessor,
    ) -> Result<Vec<u32>, AnimationError> {
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
        // u32 values are exact in f64.
        Ok(self.read(accessor)?.into_iter().map(|v| v as u32).collect())
    }
}

/// One little-endian component as f64, normalised per the glTF 2.0 spec (§3.11) when asked.
fn component(b: &[u8], ctype: DataType, normalized: bool) -> f64 {
    match ctype {
        DataType::I8 => {
            let v = f64::from(i8::from_le_bytes([b[0]]));
            if normalized { (v / 127.0).max(-1.0) } else { v }
        }
        DataType::U8 => {
            let v = f64::from(b[0]);
            if normalized { v / 255.0 } else { v }
        }
        DataType::I16 => {
            let v = f64::from(i16::from_le_bytes([b[0], b[1]]));
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = f64::from(u16::from_le_bytes([b[0], b[1]]));
            if normalized { v / 65535.0 } else { v }
        }
        DataType::U32 => {
            let v = f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
            if normalized { v / 4_294_967_295.0 } else { v }
        }
        DataType::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
    }
}

/// Decodes `%XX` escapes in a relative URI (spaces and non-ASCII names in real files).
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok();
            if let Some(v) = hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
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
}
