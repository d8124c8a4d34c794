//! NumPy `.npy` arrays of floats (format versions 1-3, little- and big-endian `f4`/`f8`,
//! C order), the image format of depth, alpha and normal maps (docs/conventions.md §2).

use std::path::Path;

use super::atomic::write_atomically;
use super::error::IoError;

/// A float array with its shape (C order: the last axis varies fastest).
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Axis lengths, e.g. `[H, W]` or `[H, W, 3]`.
    pub shape: Vec<usize>,
    /// `shape.iter().product()` values.
    pub data: Vec<f32>,
}

const MAGIC: &[u8] = b"\x93NUMPY";

/// Reads a `.npy` file of `<f4`, `>f4`, `<f8` or `>f8` values in C order as f32.
///
/// # Errors
/// [`IoError`] naming the file: bad magic, unsupported dtype or Fortran order, a shape that
/// the file does not hold.
pub fn read_npy(path: &Path) -> Result<NpyArray, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::os(path, e))?;
    parse_npy(path, &bytes)
}

/// Parses the bytes of a `.npy` file held in memory; `path` only names it in errors.
///
/// # Errors
/// As [`read_npy`], but for an unreadable file.
pub fn parse_npy(path: &Path, bytes: &[u8]) -> Result<NpyArray, IoError> {
    let bad = |msg: &str| IoError::malformed(path, "npy header", msg);
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(bad("not a .npy file (bad magic)"));
    }
    let (header_len, start): (usize, usize) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(bad(&format!("unsupported format version {v}"))),
    };
    let end = start
        .checked_add(header_len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| bad("header runs past the end of the file"))?;
    let header = std::str::from_utf8(&bytes[start..end]).map_err(|_| bad("header is not text"))?;
    let descr = dict_value(header, "descr").ok_or_else(|| bad("no 'descr'"))?;
    let fortran = dict_value(header, "fortran_order").ok_or_else(|| bad("no 'fortran_order'"))?;
    let shape_text = dict_value(header, "shape").ok_or_else(|| bad("no 'shape'"))?;
    if fortran.trim() != "False" {
        return Err(bad("Fortran order is not supported"));
    }
    let descr = descr.trim().trim_matches(|c| c == '\'' || c == '"');
    let (size, big, double) = match descr {
        "<f4" | "|f4" => (4, false, false),
        ">f4" => (4, true, false),
        "<f8" => (8, false, true),
        ">f8" => (8, true, true),
        other => return Err(bad(&format!("dtype {other} is not supported (f4 or f8)"))),
    };
    let shape = parse_shape(shape_text).ok_or_else(|| bad("bad 'shape'"))?;
    let count = shape
        .iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .ok_or_else(|| bad("shape overflows"))?;
    let body = &bytes[end..];
    if count.checked_mul(size).is_none_or(|n| n > body.len()) {
        return Err(IoError::malformed(
            path,
            "npy data",
            format!(
                "shape {shape:?} needs {count} values but the file holds {}",
                body.len() / size
            ),
        ));
    }
    // One loop per encoding (a branch per value would keep the loops from vectorising).
    let body = &body[..count * size];
    let four = |c: &[u8]| [c[0], c[1], c[2], c[3]];
    let eight = |c: &[u8]| [c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]];
    let data = match (double, big) {
        (false, false) => body
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(four(c)))
            .collect(),
        (false, true) => body
            .chunks_exact(4)
            .map(|c| f32::from_be_bytes(four(c)))
            .collect(),
        (true, false) => body
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(eight(c)) as f32)
            .collect(),
        (true, true) => body
            .chunks_exact(8)
            .map(|c| f64::from_be_bytes(eight(c)) as f32)
            .collect(),
    };
    Ok(NpyArray { shape, data })
}

/// Writes a little-endian `f4` `.npy` file (version 1), atomically.
///
/// # Errors
/// [`IoError::Malformed`] when `data` does not match `shape`, [`IoError::Os`] when writing fails.
pub fn write_npy(path: &Path, shape: &[usize], data: &[f32]) -> Result<(), IoError> {
    if shape.iter().product::<usize>() != data.len() {
        return Err(IoError::malformed(
            path,
            "npy data",
            format!("shape {shape:?} does not match {} values", data.len()),
        ));
    }
    let dims: Vec<String> = shape.iter().map(usize::to_string).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape_text}, }}");
    // Pad with spaces so the data starts on a 64-byte boundary, ending in a newline.
    let unpadded = MAGIC.len() + 4 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let header_len = u16::try_from(header.len())
        .map_err(|_| IoError::malformed(path, "npy header", "shape too long"))?;
    write_atomically(path, |w| {
        let os = |e| IoError::os(path, e);
        w.write_all(MAGIC).map_err(os)?;
        w.write_all(&[1, 0]).map_err(os)?;
        w.write_all(&header_len.to_le_bytes()).map_err(os)?;
        w.write_all(header.as_bytes()).map_err(os)?;
        let mut buf = Vec::with_capacity(data.len().min(1 << 16) * 4);
        for chunk in data.chunks(1 << 16) {
            buf.clear();
            buf.extend(chunk.iter().flat_map(|v| v.to_le_bytes()));
            w.write_all(&buf).map_err(os)?;
        }
        Ok(())
    })
}

/// The text after `'key':` in a Python dict literal, up to the next top-level comma.
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let pattern_single = format!("'{key}'");
    let pattern_double = format!("\"{key}\"");
    let at = header
        .find(&pattern_single)
        .map(|i| i + pattern_single.len())
        .or_else(|| {
            header
                .find(&pattern_double)
                .map(|i| i + pattern_double.len())
        })?;
    let rest = header[at..].trim_start().strip_prefix(':')?;
    let mut depth = 0i32;
    for (i, ch) in rest.char_indices() {
        match ch {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ',' | '}' if depth == 0 => return Some(rest[..i].trim()),
            _ => {}
        }
    }
    None
}

/// Parses `(3, 4)`, `(5,)` or `()` into axis lengths.
fn parse_shape(text: &str) -> Option<Vec<usize>> {
    let inner = text.trim().strip_prefix('(')?.strip_suffix(')')?;
    inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse().ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_alignment() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("depth.npy");
        let data: Vec<f32> = (0..24).map(|i| i as f32 * 0.5).collect();
        write_npy(&path, &[2, 4, 3], &data).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!((bytes.len() - data.len() * 4) % 64, 0);
        let back = read_npy(&path).unwrap();
        assert_eq!(back.shape, vec![2, 4, 3]);
        assert_eq!(back.data, data);
    }

    #[test]
    fn reads_numpy_f8_big_endian_and_rejects_short_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        let header = "{'descr': '>f8', 'fortran_order': False, 'shape': (2,), }";
        let mut bytes = MAGIC.to_vec();
        bytes.extend([1, 0]);
        bytes.extend((header.len() as u16).to_le_bytes());
        bytes.extend(header.as_bytes());
        bytes.extend(1.5f64.to_be_bytes());
        bytes.extend((-2.0f64).to_be_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(read_npy(&path).unwrap().data, vec![1.5, -2.0]);
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        let err = read_npy(&path).unwrap_err().to_string();
        assert!(
            err.contains("a.npy") && err.contains("needs 2 values"),
            "{err}"
        );
        std::fs::write(&path, b"garbage").unwrap();
        assert!(read_npy(&path).is_err());
    }
}
