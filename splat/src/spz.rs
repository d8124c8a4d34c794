//! Niantic SPZ files: reading and writing world-space [`GaussianSet`]s (docs/conventions.md §3,
//! "SPZ").
//!
//! Layout (as the reference library `nianticlabs/spz` reads and writes it; our own code):
//! - versions 1-3: one gzip stream holding a 16-byte header (`magic` 0x5053474e "NGSP",
//!   `version`, `numPoints` as little-endian u32; `shDegree`, `fractionalBits`, `flags`, a
//!   reserved byte) followed by the attribute arrays, each for every point in turn: positions,
//!   alphas, colours, scales, rotations, SH; extension records may follow;
//! - version 4: a plain 32-byte header (`magic`, `version`, `numPoints`, `shDegree`,
//!   `fractionalBits`, `flags`, `numStreams`, `tocByteOffset`, 12 reserved bytes), extension
//!   records up to `tocByteOffset`, a table of `numStreams` × (compressed, uncompressed) u64
//!   sizes, then one zstd stream per non-empty attribute array in the order above.
//!
//! Quantisation (per point): positions as 24-bit signed fixed point with `fractionalBits`
//! (version 1: float16); alpha `round(sigmoid(opacity) · 255)`; colour (the SH DC coefficient)
//! `round(dc · 0.15 · 255 + 127.5)`; log-scales `round((s + 10) · 16)`; rotations as the
//! unit quaternion's x, y, z (w ≥ 0) in 8 bits each (versions 1-2) or "smallest three": the
//! index of the largest component in 2 bits and the other three as sign + 9-bit magnitude
//! scaled by √2 (versions 3-4); SH rest coefficients `round(x · 128) + 128` snapped to buckets
//! of `2^(8 - bits)` (5 bits for degree 1, 4 above, by default), coefficient-major with the
//! channel inner (ours are channel-major: they are re-laid). Every byte is clamped to 0..=255.
//!
//! Axes: SPZ stores `RUB` (or what an `SPZ_ADOBE_coordinate_system` extension names);
//! [`SpzReadOptions::axes`] and [`SpzWriteOptions::axes`] name the frame of the set (default
//! `RDF`, the 3DGS training frame of INRIA PLYs; `None` stores the values as they are, as the
//! reference command-line tools do).
//!
//! Reading checks everything against the bytes present: the point count against a sane maximum
//! and against the decompressed bytes (nothing is allocated from a header count alone), the
//! table of contents against the file, every stream's size, extension records' lengths. A
//! stored alpha of 0 or 255 (opacity exactly 0 or 1) reads as the logit [`TRANSPARENT_LOGIT`]
//! or [`OPAQUE_LOGIT`] (the reference gives ±infinity). SH degree 4 (allowed by the format
//! since version 3) is refused: 3DGS files stop at 3. Other extension records are skipped
//! (their types are listed in [`SpzFile::skipped_extensions`]).
//!
//! Writing refuses bound sets (local parameters: bake world-space frames first), empty sets
//! (the reference reader refuses 0 points) and coordinates the fixed point cannot hold. Extra
//! properties are not stored. Files are written atomically.

use std::io::Read;
use std::path::{Path, PathBuf};

use glam::Vec3;
use trisplat_geometry::io::{IoError, write_atomically};

use crate::axes::{Axes, change_axes};
use crate::gaussians::{
    GaussianError, GaussianParts, GaussianSet, ParameterSpace, ScaleDims, sh_coeffs_per_channel,
};

/// The header magic, "NGSP" in file order.
pub const SPZ_MAGIC: u32 = 0x5053_474e;

/// Most points a file may hold (the reference reads the count as a signed 32-bit integer).
pub const SPZ_MAX_POINTS: u32 = i32::MAX as u32;

/// The newest version this module reads and writes.
pub const SPZ_LATEST_VERSION: u32 = 4;

/// The logit a stored alpha of 255 reads as: its sigmoid rounds to exactly 1 in f32.
pub const OPAQUE_LOGIT: f32 = 18.0;

/// The logit a stored alpha of 0 reads as: its sigmoid rounds to exactly 0 in f32.
pub const TRANSPARENT_LOGIT: f32 = -110.0;

/// Default fractional bits of the fixed-point positions (the reference's: 1/4096, about a
/// quarter of a millimetre in metres).
pub const DEFAULT_FRACTIONAL_BITS: u8 = 12;

/// Most fractional bits a reader accepts (positions of 24 bits scaled by `2^-31`).
pub const MAX_READ_FRACTIONAL_BITS: u8 = 31;

/// The `SPZ_ADOBE_coordinate_system` extension record type.
pub const COORDINATE_SYSTEM_EXTENSION: u32 = 0xADBE_0003;

/// Header flag: trained with anti-aliasing (Mip-Splatting).
const FLAG_ANTIALIASED: u8 = 0x1;
/// Header flag: extension records present.
const FLAG_EXTENSIONS: u8 = 0x2;

/// Legacy (versions 1-3) header bytes inside the gzip stream.
const LEGACY_HEADER: usize = 16;
/// Version 4 plain header bytes.
const NGSP_HEADER: usize = 32;
/// The most extension bytes read after the legacy arrays.
const MAX_TRAILING_EXTENSIONS: u64 = 1 << 20;
/// Most bytes a point needs at least (its version-4 position), for the count check.
const MIN_BYTES_PER_POINT: u64 = 9;
/// A generous bound of zstd's and gzip's compression ratio: a header claiming more points
/// than this many times the file's bytes could back is refused before anything is read.
const MAX_COMPRESSION_RATIO: u64 = 1032;

/// The largest zstd window a stream may ask for, unless its own size is larger.
const MIN_ZSTD_WINDOW_LIMIT: u64 = 8 << 20;

/// `1/√2` in f32, the scale of the smallest-three components.
const SQRT1_2: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// The SPZ colour scale of the DC coefficient.
const COLOR_SCALE: f32 = 0.15;

/// Errors of reading and writing SPZ files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SpzError {
    /// The file cannot be read, is malformed (naming the header field, stream or Gaussian) or
    /// uses something not supported; or the write failed (the target is then untouched).
    #[error(transparent)]
    Io(#[from] IoError),
    /// The values read do not make a valid Gaussian set.
    #[error("{}: {source}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The problem, naming the Gaussian.
        source: GaussianError,
    },
    /// The set cannot be written as SPZ (bound, empty, a coordinate out of range).
    #[error("{}: {message}", path.display())]
    Unrepresentable {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// Options of [`read_spz`] and [`decode_spz`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpzReadOptions {
    /// The axes the returned set is expressed in (converted from the file's `RUB`, or from
    /// the axes its coordinate-system extension names); `None` returns the stored values.
    pub axes: Option<Axes>,
}

impl Default for SpzReadOptions {
    fn default() -> Self {
        Self {
            axes: Some(Axes::Rdf),
        }
    }
}

/// Options of [`write_spz`] and [`encode_spz`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpzWriteOptions {
    /// Format version: 2 or 3 (gzip; 3 with smallest-three rotations, read by every SPZ
    /// reader) or 4 (zstd streams; the reference's newest).
    pub version: u32,
    /// The axes the set is expressed in; it is stored in `RUB`. `None` stores the values as
    /// they are.
    pub axes: Option<Axes>,
    /// Fractional bits of the fixed-point positions (0..=23). `None`:
    /// [`DEFAULT_FRACTIONAL_BITS`], or fewer when a coordinate needs them.
    pub fractional_bits: Option<u8>,
    /// Bits kept of the degree-1 SH coefficients (1..=8).
    pub sh1_bits: u8,
    /// Bits kept of the degree-2 and 3 SH coefficients (1..=8).
    pub sh_rest_bits: u8,
    /// The anti-aliased flag (Mip-Splatting).
    pub antialiased: bool,
}

impl Default for SpzWriteOptions {
    fn default() -> Self {
        Self {
            version: 3,
            axes: Some(Axes::Rdf),
            fractional_bits: None,
            sh1_bits: 5,
            sh_rest_bits: 4,
            antialiased: false,
        }
    }
}

/// A decoded SPZ file: the Gaussians and the header's facts.
#[derive(Clone, Debug, PartialEq)]
pub struct SpzFile {
    /// The Gaussians, world space, in the axes asked for.
    pub gaussians: GaussianSet,
    /// Format version (1..=4).
    pub version: u32,
    /// Fractional bits of the positions.
    pub fractional_bits: u8,
    /// The anti-aliased flag.
    pub antialiased: bool,
    /// The axes the file stores (`RUB` unless a coordinate-system extension names others).
    pub stored_axes: Axes,
    /// Types of the extension records that were skipped.
    pub skipped_extensions: Vec<u32>,
}

// ----------------------------------------------------------------------------------------------
// The packed arrays

/// The attribute arrays as stored.
#[derive(Clone, Debug, Default, PartialEq)]
struct Packed {
    version: u32,
    points: usize,
    sh_degree: u8,
    fractional_bits: u8,
    flags: u8,
    positions: Vec<u8>,
    alphas: Vec<u8>,
    colors: Vec<u8>,
    scales: Vec<u8>,
    rotations: Vec<u8>,
    sh: Vec<u8>,
}

/// Bytes per point of each array, in stream order.
fn stream_sizes(version: u32, sh_degree: u8) -> [u64; 6] {
    let position = if version == 1 { 6 } else { 9 };
    let rotation = if version >= 3 { 4 } else { 3 };
    let rest = 3 * (sh_coeffs_per_channel(sh_degree) as u64 - 1);
    [position, 1, 3, 3, rotation, rest]
}

const STREAM_NAMES: [&str; 6] = ["positions", "alphas", "colors", "scales", "rotations", "sh"];

fn malformed(path: &Path, element: impl Into<String>, message: impl Into<String>) -> SpzError {
    SpzError::Io(IoError::malformed(path, element, message))
}

fn unsupported(path: &Path, what: impl Into<String>) -> SpzError {
    SpzError::Io(IoError::Unsupported {
        path: path.to_path_buf(),
        what: what.into(),
    })
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

/// The header fields both layouts share, checked.
struct Header {
    version: u32,
    points: u32,
    sh_degree: u8,
    fractional_bits: u8,
    flags: u8,
}

fn check_header(path: &Path, h: &Header, file_bytes: usize) -> Result<(), SpzError> {
    if h.points > SPZ_MAX_POINTS {
        return Err(malformed(
            path,
            "header",
            format!(
                "numPoints {} is above the format's {SPZ_MAX_POINTS}",
                h.points
            ),
        ));
    }
    let backed = (file_bytes as u64).saturating_mul(MAX_COMPRESSION_RATIO) / MIN_BYTES_PER_POINT;
    if u64::from(h.points) > backed {
        return Err(malformed(
            path,
            "header",
            format!(
                "numPoints {} cannot be held by a file of {file_bytes} bytes",
                h.points
            ),
        ));
    }
    if h.sh_degree == 4 {
        return Err(unsupported(
            path,
            "SH degree 4 (3DGS files and trisplat stop at degree 3)",
        ));
    }
    if h.sh_degree > 4 {
        return Err(malformed(
            path,
            "header",
            format!("shDegree {} is above 4", h.sh_degree),
        ));
    }
    if h.fractional_bits > MAX_READ_FRACTIONAL_BITS {
        return Err(malformed(
            path,
            "header",
            format!(
                "fractionalBits {} is above {MAX_READ_FRACTIONAL_BITS}",
                h.fractional_bits
            ),
        ));
    }
    Ok(())
}

/// Reads up to `limit` bytes from `r` into a vector that grows only as bytes arrive.
fn read_limited(r: &mut dyn Read, limit: u64) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::new();
    r.take(limit).read_to_end(&mut out)?;
    Ok(out)
}

/// Decodes the gzip layout (versions 1-3).
fn unpack_legacy(path: &Path, bytes: &[u8]) -> Result<(Packed, Vec<u8>), SpzError> {
    let mut gz = flate2::read::GzDecoder::new(bytes);
    let gzip_error =
        |e: std::io::Error| malformed(path, "gzip stream", format!("cannot be decompressed: {e}"));
    let head = read_limited(&mut gz, LEGACY_HEADER as u64).map_err(gzip_error)?;
    if head.len() < LEGACY_HEADER {
        return Err(malformed(
            path,
            "header",
            format!(
                "the stream holds {} bytes, fewer than the {LEGACY_HEADER} of a header",
                head.len()
            ),
        ));
    }
    if le_u32(&head, 0) != SPZ_MAGIC {
        return Err(malformed(path, "header", "no NGSP magic: not an SPZ file"));
    }
    let h = Header {
        version: le_u32(&head, 4),
        points: le_u32(&head, 8),
        sh_degree: head[12],
        fractional_bits: head[13],
        flags: head[14],
    };
    if !(1..=3).contains(&h.version) {
        return Err(unsupported(
            path,
            format!(
                "version {} in a gzip stream (versions 1-3 are gzip, 4 is not)",
                h.version
            ),
        ));
    }
    check_header(path, &h, bytes.len())?;
    let n = u64::from(h.points);
    let sizes = stream_sizes(h.version, h.sh_degree);
    let mut arrays: Vec<Vec<u8>> = Vec::with_capacity(6);
    for (size, name) in sizes.iter().zip(STREAM_NAMES) {
        let want = n * size;
        let got = read_limited(&mut gz, want).map_err(gzip_error)?;
        if (got.len() as u64) < want {
            return Err(malformed(
                path,
                name,
                format!(
                    "{} points need {want} bytes, the stream ends after {}",
                    h.points,
                    got.len()
                ),
            ));
        }
        arrays.push(got);
    }
    // Read to the end of the stream, which checks its CRC and length (a cut or corrupted
    // trailer is an error, as in the reference's zlib).
    let trailing = read_limited(&mut gz, MAX_TRAILING_EXTENSIONS + 1).map_err(gzip_error)?;
    if trailing.len() as u64 > MAX_TRAILING_EXTENSIONS {
        return Err(malformed(
            path,
            "gzip stream",
            format!("more than {MAX_TRAILING_EXTENSIONS} bytes follow the attribute arrays"),
        ));
    }
    let trailing = if h.flags & FLAG_EXTENSIONS != 0 {
        trailing
    } else {
        Vec::new()
    };
    Ok((packed_from(h, arrays), trailing))
}

fn packed_from(h: Header, arrays: Vec<Vec<u8>>) -> Packed {
    let mut a = arrays.into_iter();
    let mut next = || a.next().unwrap_or_default();
    Packed {
        version: h.version,
        points: h.points as usize,
        sh_degree: h.sh_degree,
        fractional_bits: h.fractional_bits,
        flags: h.flags,
        positions: next(),
        alphas: next(),
        colors: next(),
        scales: next(),
        rotations: next(),
        sh: next(),
    }
}

/// Decodes the version-4 layout.
fn unpack_ngsp(path: &Path, bytes: &[u8]) -> Result<(Packed, Vec<u8>), SpzError> {
    if bytes.len() < NGSP_HEADER {
        return Err(malformed(
            path,
            "header",
            format!(
                "the file has {} bytes, fewer than the {NGSP_HEADER} of a version-4 header",
                bytes.len()
            ),
        ));
    }
    let h = Header {
        version: le_u32(bytes, 4),
        points: le_u32(bytes, 8),
        sh_degree: bytes[12],
        fractional_bits: bytes[13],
        flags: bytes[14],
    };
    if h.version != 4 {
        return Err(unsupported(
            path,
            format!(
                "version {} with a plain header (this reader knows versions 1-{SPZ_LATEST_VERSION})",
                h.version
            ),
        ));
    }
    check_header(path, &h, bytes.len())?;
    let streams = usize::from(bytes[15]);
    let toc = le_u32(bytes, 16) as usize;
    if toc < NGSP_HEADER {
        return Err(malformed(
            path,
            "header",
            format!("tocByteOffset {toc} points into the {NGSP_HEADER}-byte header"),
        ));
    }
    let toc_end = toc + streams * 16;
    if toc_end > bytes.len() {
        return Err(malformed(
            path,
            "table of contents",
            format!(
                "{streams} entries at byte {toc} run past the end of the file ({} bytes)",
                bytes.len()
            ),
        ));
    }
    let n = u64::from(h.points);
    let sizes = stream_sizes(4, h.sh_degree);
    // Empty arrays have no stream.
    let present: Vec<usize> = (0..6).filter(|&i| n * sizes[i] > 0).collect();
    if streams != present.len() {
        return Err(malformed(
            path,
            "header",
            format!(
                "numStreams {streams}; {} points of SH degree {} have {} non-empty arrays",
                h.points,
                h.sh_degree,
                present.len()
            ),
        ));
    }
    let mut arrays: Vec<Vec<u8>> = vec![Vec::new(); 6];
    let mut at = toc_end as u64;
    for (k, &i) in present.iter().enumerate() {
        let entry = toc + k * 16;
        let compressed = le_u64(bytes, entry);
        let uncompressed = le_u64(bytes, entry + 8);
        let name = STREAM_NAMES[i];
        let want = n * sizes[i];
        if uncompressed != want {
            return Err(malformed(
                path,
                format!("stream {k} ({name})"),
                format!("{uncompressed} bytes; {} points need {want}", h.points),
            ));
        }
        let end = at
            .checked_add(compressed)
            .filter(|&e| e <= bytes.len() as u64)
            .ok_or_else(|| {
                malformed(
                    path,
                    format!("stream {k} ({name})"),
                    format!(
                        "{compressed} compressed bytes at byte {at} run past the end of the file ({} bytes)",
                        bytes.len()
                    ),
                )
            })?;
        let zstd_error = |e: String| {
            malformed(
                path,
                format!("stream {k} ({name})"),
                format!("cannot be decompressed: {e}"),
            )
        };
        let source = &bytes[at as usize..end as usize];
        // The decoder reserves the window the frame asks for: at most the stream's own size
        // (rounded up) or a few MiB.
        let window = want.next_power_of_two().max(MIN_ZSTD_WINDOW_LIMIT);
        let mut decoder =
            ruzstd::decoding::StreamingDecoder::new_with_max_window_size(source, window)
                .map_err(|e| zstd_error(e.to_string()))?;
        let got = read_limited(&mut decoder, want).map_err(|e| zstd_error(e.to_string()))?;
        if (got.len() as u64) < want {
            return Err(malformed(
                path,
                format!("stream {k} ({name})"),
                format!("decompresses to {} bytes, {want} expected", got.len()),
            ));
        }
        let mut extra = [0u8; 1];
        if decoder
            .read(&mut extra)
            .map_err(|e| zstd_error(e.to_string()))?
            > 0
        {
            return Err(malformed(
                path,
                format!("stream {k} ({name})"),
                format!("decompresses to more than the {want} bytes expected"),
            ));
        }
        arrays[i] = got;
        at = end;
    }
    if at != bytes.len() as u64 {
        return Err(malformed(
            path,
            "table of contents",
            format!("the streams end at byte {at}, the file at {}", bytes.len()),
        ));
    }
    let extensions = if h.flags & FLAG_EXTENSIONS != 0 {
        bytes[NGSP_HEADER..toc].to_vec()
    } else {
        Vec::new()
    };
    Ok((packed_from(h, arrays), extensions))
}

/// Reads extension records (`type`, `byteLength`, payload): the stored axes and the skipped
/// types.
fn read_extensions(path: &Path, mut b: &[u8]) -> Result<(Axes, Vec<u32>), SpzError> {
    let mut axes = Axes::Rub;
    let mut skipped = Vec::new();
    let mut offset = 0usize;
    while !b.is_empty() {
        if b.len() < 8 {
            return Err(malformed(
                path,
                format!("extension record at byte {offset}"),
                format!("{} bytes, fewer than a record header's 8", b.len()),
            ));
        }
        let ty = le_u32(b, 0);
        let len = le_u32(b, 4) as usize;
        let Some(payload) = b.get(8..8 + len) else {
            return Err(malformed(
                path,
                format!("extension record 0x{ty:08X} at byte {offset}"),
                format!("a payload of {len} bytes runs past the extension data"),
            ));
        };
        if ty == COORDINATE_SYSTEM_EXTENSION {
            if payload.len() != 4 {
                return Err(malformed(
                    path,
                    "coordinate-system extension",
                    format!("a payload of {} bytes, 4 expected", payload.len()),
                ));
            }
            let id = le_u32(payload, 0);
            axes = match id {
                // UNSPECIFIED: the reference falls back to RUB.
                0 => Axes::Rub,
                _ => Axes::from_id(id).ok_or_else(|| {
                    malformed(
                        path,
                        "coordinate-system extension",
                        format!("unknown coordinate system {id} (1-16 are defined)"),
                    )
                })?,
            };
        } else {
            skipped.push(ty);
        }
        b = &b[8 + len..];
        offset += 8 + len;
    }
    Ok((axes, skipped))
}

// ----------------------------------------------------------------------------------------------
// Decoding values

/// A float16 bit pattern as f32 (version 1 positions).
fn half_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0f32 } else { 1.0 };
    let exponent = i32::from((h >> 10) & 0x1f);
    let mantissa = f32::from(h & 0x3ff);
    match exponent {
        0 => sign * mantissa * 2f32.powi(-24),
        31 if mantissa == 0.0 => sign * f32::INFINITY,
        31 => f32::NAN,
        e => sign * (1.0 + mantissa / 1024.0) * 2f32.powi(e - 15),
    }
}

/// The logit of a stored alpha byte (the reference's f32 formula; 0 and 255 clamped).
fn alpha_logit(a: u8) -> f32 {
    match a {
        0 => TRANSPARENT_LOGIT,
        255 => OPAQUE_LOGIT,
        _ => {
            let p = f32::from(a) / 255.0;
            (p / (1.0 - p)).ln()
        }
    }
}

/// Unpacks a smallest-three rotation into `[x, y, z, w]`.
fn smallest_three(r: &[u8]) -> [f32; 4] {
    let mut comp = u32::from_le_bytes([r[0], r[1], r[2], r[3]]);
    const MASK: u32 = (1 << 9) - 1;
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum = 0.0f32;
    for i in (0..4).rev() {
        if i != largest {
            let mag = comp & MASK;
            let negative = (comp >> 9) & 1 == 1;
            comp >>= 10;
            let v = SQRT1_2 * mag as f32 / MASK as f32;
            q[i] = if negative { -v } else { v };
            sum += q[i] * q[i];
        }
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    q
}

/// Unpacks a first-three rotation (w ≥ 0) into `[x, y, z, w]`.
fn first_three(r: &[u8]) -> [f32; 4] {
    // The reference multiplies by 1/127.5 (rounded to f32), not divides.
    let [x, y, z] = [r[0], r[1], r[2]].map(|v| f32::from(v) * (1.0 / 127.5) - 1.0);
    let w = (1.0 - (x * x + y * y + z * z)).max(0.0).sqrt();
    [x, y, z, w]
}

fn decode_values(path: &Path, p: &Packed) -> Result<GaussianSet, SpzError> {
    let n = p.points;
    let k = sh_coeffs_per_channel(p.sh_degree);
    let rest = k - 1;
    let step = 2f32.powi(-i32::from(p.fractional_bits));
    let mut means = Vec::with_capacity(n);
    if p.version == 1 {
        for c in p.positions.chunks_exact(6) {
            let h = |i: usize| half_to_f32(u16::from_le_bytes([c[2 * i], c[2 * i + 1]]));
            means.push(Vec3::new(h(0), h(1), h(2)));
        }
    } else {
        for c in p.positions.chunks_exact(9) {
            let f = |i: usize| {
                let raw = i32::from(c[3 * i])
                    | i32::from(c[3 * i + 1]) << 8
                    | i32::from(c[3 * i + 2]) << 16;
                // Sign-extend 24 bits.
                let fixed = (raw << 8) >> 8;
                fixed as f32 * step
            };
            means.push(Vec3::new(f(0), f(1), f(2)));
        }
    }
    let log_scales = p
        .scales
        .chunks_exact(3)
        .map(|s| Vec3::from(s_to_log([s[0], s[1], s[2]])))
        .collect();
    let rotations = if p.version >= 3 {
        p.rotations
            .chunks_exact(4)
            .map(smallest_three)
            .map(|[x, y, z, w]| [w, x, y, z])
            .collect()
    } else {
        p.rotations
            .chunks_exact(3)
            .map(first_three)
            .map(|[x, y, z, w]| [w, x, y, z])
            .collect()
    };
    let opacity_logits = p.alphas.iter().map(|&a| alpha_logit(a)).collect();
    let mut sh = vec![0.0f32; n * 3 * k];
    for i in 0..n {
        let out = &mut sh[i * 3 * k..(i + 1) * 3 * k];
        for (dc, &q) in out.iter_mut().zip(&p.colors[3 * i..3 * i + 3]) {
            *dc = ((f32::from(q) / 255.0) - 0.5) / COLOR_SCALE;
        }
        for j in 0..rest {
            for c in 0..3 {
                let q = f32::from(p.sh[(i * rest + j) * 3 + c]);
                out[3 + c * rest + j] = (q - 128.0) / 128.0;
            }
        }
    }
    let parts = GaussianParts {
        means,
        log_scales,
        scale_dims: ScaleDims::Three,
        rotations,
        opacity_logits,
        sh_degree: p.sh_degree,
        sh,
        binding: None,
        material: None,
        space: ParameterSpace::World,
        extras: Vec::new(),
        property_order: None,
    };
    GaussianSet::try_new(parts).map_err(|source| SpzError::Invalid {
        path: path.to_path_buf(),
        source,
    })
}

fn s_to_log(s: [u8; 3]) -> [f32; 3] {
    s.map(|v| f32::from(v) / 16.0 - 10.0)
}

/// Decodes SPZ bytes (either layout, told apart by the first bytes); `path` only names the
/// file in errors.
///
/// # Errors
/// [`SpzError::Io`] naming the header field, stream or extension record at fault,
/// [`SpzError::Invalid`] for values that make no Gaussian (a non-finite float16 position).
pub fn decode_spz(
    bytes: &[u8],
    path: &Path,
    options: &SpzReadOptions,
) -> Result<SpzFile, SpzError> {
    let (packed, extension_bytes) = if bytes.starts_with(&SPZ_MAGIC.to_le_bytes()) {
        unpack_ngsp(path, bytes)?
    } else if bytes.starts_with(&[0x1f, 0x8b]) {
        unpack_legacy(path, bytes)?
    } else {
        return Err(malformed(
            path,
            "header",
            "neither a gzip stream nor an NGSP header: not an SPZ file",
        ));
    };
    let (stored_axes, skipped_extensions) = read_extensions(path, &extension_bytes)?;
    let stored = decode_values(path, &packed)?;
    let gaussians = match options.axes {
        Some(to) => change_axes(&stored, stored_axes.to(to)),
        None => stored,
    };
    Ok(SpzFile {
        gaussians,
        version: packed.version,
        fractional_bits: packed.fractional_bits,
        antialiased: packed.flags & FLAG_ANTIALIASED != 0,
        stored_axes,
        skipped_extensions,
    })
}

/// Reads an SPZ file.
///
/// # Errors
/// As [`decode_spz`]; [`SpzError::Io`] when the file cannot be read.
pub fn read_spz(path: &Path, options: &SpzReadOptions) -> Result<SpzFile, SpzError> {
    let bytes = std::fs::read(path).map_err(|e| SpzError::Io(IoError::os(path, e)))?;
    decode_spz(&bytes, path, options)
}

// ----------------------------------------------------------------------------------------------
// Encoding

/// `clamp(round(x), 0, 255)` (round half away from zero, as C's `std::round`).
#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "clamped to 0..=255 first"
)]
fn to_u8(x: f32) -> u8 {
    if x.is_nan() {
        return 0;
    }
    x.round().clamp(0.0, 255.0) as u8
}

/// The reference's SH quantisation: 8 bits, then the nearest bucket of `bucket` values.
#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "saturating float to int, then clamped to 0..=255"
)]
fn quantize_sh(x: f32, bucket: i32) -> u8 {
    let q = ((x * 128.0).round() + 128.0) as i32;
    let q = (q.saturating_add(bucket / 2)) / bucket * bucket;
    q.clamp(0, 255) as u8
}

/// Packs a `[w, x, y, z]` quaternion as the reference does: normalised in f32 (x y z w order).
fn normalized_xyzw(q: [f32; 4]) -> [f32; 4] {
    let [w, x, y, z] = q;
    let norm = (x * x + y * y + z * z + w * w).sqrt();
    [x / norm, y / norm, z / norm, w / norm]
}

fn pack_smallest_three(q: [f32; 4]) -> [u8; 4] {
    let mut largest = 0usize;
    for i in 1..4 {
        if q[i].abs() > q[largest].abs() {
            largest = i;
        }
    }
    let negate = q[largest] < 0.0;
    let mut comp = largest as u32;
    for (i, &v) in q.iter().enumerate() {
        if i != largest {
            let negbit = u32::from((v < 0.0) ^ negate);
            #[expect(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                reason = "a non-negative value below 512 (the reference's truncation)"
            )]
            let mag = ((511.0 * (v.abs() / SQRT1_2) + 0.5) as u32).min(511);
            comp = (comp << 10) | (negbit << 9) | mag;
        }
    }
    comp.to_le_bytes()
}

fn pack_first_three(q: [f32; 4]) -> [u8; 3] {
    let s = if q[3] < 0.0 { -127.5f32 } else { 127.5 };
    [
        to_u8(q[0] * s + 127.5),
        to_u8(q[1] * s + 127.5),
        to_u8(q[2] * s + 127.5),
    ]
}

/// The sigmoid in f32 as the reference computes it (overflow gives 0, never NaN).
fn sigmoid_f32(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// The fixed-point value of `x`, if it fits 24 signed bits.
#[expect(
    clippy::cast_possible_truncation,
    reason = "range checked before the conversion"
)]
fn fixed(x: f32, scale: f32) -> Option<i32> {
    let v = (x * scale).round();
    (-8_388_608.0..=8_388_607.0)
        .contains(&v)
        .then_some(v as i32)
}

fn choose_fractional_bits(
    path: &Path,
    set: &GaussianSet,
    asked: Option<u8>,
) -> Result<u8, SpzError> {
    let fits = |bits: u8| -> Option<(usize, f32)> {
        let scale = 2f32.powi(i32::from(bits));
        set.means().iter().enumerate().find_map(|(i, p)| {
            p.to_array()
                .into_iter()
                .find(|&x| fixed(x, scale).is_none())
                .map(|x| (i, x))
        })
    };
    match asked {
        Some(bits) if bits > 23 => Err(SpzError::Unrepresentable {
            path: path.to_path_buf(),
            message: format!("{bits} fractional bits: 24-bit positions take at most 23"),
        }),
        Some(bits) => match fits(bits) {
            None => Ok(bits),
            Some((i, x)) => Err(SpzError::Unrepresentable {
                path: path.to_path_buf(),
                message: format!(
                    "Gaussian {i}: coordinate {x} does not fit 24-bit fixed point with {bits} \
                     fractional bits (|x| < {})",
                    f64::from(1u32 << 23) / f64::from(1u32 << bits)
                ),
            }),
        },
        None => {
            let mut last = None;
            for bits in (0..=DEFAULT_FRACTIONAL_BITS).rev() {
                match fits(bits) {
                    None => return Ok(bits),
                    Some(bad) => last = Some(bad),
                }
            }
            let (i, x) = last.unwrap_or((0, 0.0));
            Err(SpzError::Unrepresentable {
                path: path.to_path_buf(),
                message: format!(
                    "Gaussian {i}: coordinate {x} is beyond the ±8388608 that SPZ's 24-bit \
                     fixed point holds"
                ),
            })
        }
    }
}

/// Encodes a world-space set as SPZ bytes; `path` only names the file in errors.
///
/// # Errors
/// [`SpzError::Unrepresentable`] for a bound or empty set, a coordinate out of range or bad
/// options.
pub fn encode_spz(
    set: &GaussianSet,
    path: &Path,
    options: &SpzWriteOptions,
) -> Result<Vec<u8>, SpzError> {
    let refuse = |message: String| SpzError::Unrepresentable {
        path: path.to_path_buf(),
        message,
    };
    if set.binding().is_some() || set.space() != ParameterSpace::World {
        return Err(refuse(
            "bound Gaussians (local parameters and a binding) cannot be stored in SPZ; write \
             world-space frames (`trisplat deform`)"
                .into(),
        ));
    }
    if set.is_empty() {
        return Err(refuse(
            "an empty set cannot be stored: SPZ readers refuse files of 0 points".into(),
        ));
    }
    if !(2..=SPZ_LATEST_VERSION).contains(&options.version) {
        return Err(refuse(format!(
            "version {} cannot be written (2, 3 or 4)",
            options.version
        )));
    }
    for (name, bits) in [
        ("sh1_bits", options.sh1_bits),
        ("sh_rest_bits", options.sh_rest_bits),
    ] {
        if !(1..=8).contains(&bits) {
            return Err(refuse(format!("{name} {bits} is outside 1..=8")));
        }
    }
    let n = set.len();
    let points = u32::try_from(n)
        .ok()
        .filter(|&p| p <= SPZ_MAX_POINTS)
        .ok_or_else(|| refuse(format!("{n} Gaussians; SPZ holds at most {SPZ_MAX_POINTS}")))?;
    let stored = match options.axes {
        Some(from) => change_axes(set, from.to(Axes::Rub)),
        None => set.clone(),
    };
    let bits = choose_fractional_bits(path, &stored, options.fractional_bits)?;
    let packed = pack(&stored, options, bits);
    let flags = if options.antialiased {
        FLAG_ANTIALIASED
    } else {
        0
    };
    let arrays = [
        &packed.positions,
        &packed.alphas,
        &packed.colors,
        &packed.scales,
        &packed.rotations,
        &packed.sh,
    ];
    let mut out = Vec::new();
    if options.version < 4 {
        let mut raw =
            Vec::with_capacity(LEGACY_HEADER + arrays.iter().map(|a| a.len()).sum::<usize>());
        raw.extend_from_slice(&SPZ_MAGIC.to_le_bytes());
        raw.extend_from_slice(&options.version.to_le_bytes());
        raw.extend_from_slice(&points.to_le_bytes());
        raw.extend_from_slice(&[set.sh_degree(), bits, flags, 0]);
        for a in arrays {
            raw.extend_from_slice(a);
        }
        let mut gz = flate2::write::GzEncoder::new(&mut out, flate2::Compression::default());
        std::io::Write::write_all(&mut gz, &raw)
            .and_then(|()| gz.finish().map(|_| ()))
            .map_err(|e| SpzError::Io(IoError::os(path, e)))?;
    } else {
        let chunks: Vec<(usize, Vec<u8>)> = arrays
            .iter()
            .filter(|a| !a.is_empty())
            .map(|a| {
                (
                    a.len(),
                    ruzstd::encoding::compress_to_vec(
                        a.as_slice(),
                        ruzstd::encoding::CompressionLevel::Fastest,
                    ),
                )
            })
            .collect();
        out.extend_from_slice(&SPZ_MAGIC.to_le_bytes());
        out.extend_from_slice(&4u32.to_le_bytes());
        out.extend_from_slice(&points.to_le_bytes());
        #[expect(clippy::cast_possible_truncation, reason = "at most 6 streams")]
        out.extend_from_slice(&[set.sh_degree(), bits, flags, chunks.len() as u8]);
        out.extend_from_slice(&(NGSP_HEADER as u32).to_le_bytes());
        out.extend_from_slice(&[0u8; 12]);
        for (size, chunk) in &chunks {
            out.extend_from_slice(&(chunk.len() as u64).to_le_bytes());
            out.extend_from_slice(&(*size as u64).to_le_bytes());
        }
        for (_, chunk) in &chunks {
            out.extend_from_slice(chunk);
        }
    }
    Ok(out)
}

/// Quantises the (already re-axed) set.
fn pack(set: &GaussianSet, options: &SpzWriteOptions, bits: u8) -> Packed {
    let n = set.len();
    let degree = set.sh_degree();
    let k = sh_coeffs_per_channel(degree);
    let rest = k - 1;
    let scale = 2f32.powi(i32::from(bits));
    let mut p = Packed {
        version: options.version,
        points: n,
        sh_degree: degree,
        fractional_bits: bits,
        ..Packed::default()
    };
    p.positions.reserve(9 * n);
    for m in set.means() {
        for x in m.to_array() {
            let v = fixed(x, scale).unwrap_or(0);
            p.positions.extend_from_slice(&v.to_le_bytes()[..3]);
        }
    }
    p.alphas = set
        .opacity_logits()
        .iter()
        .map(|&a| to_u8(sigmoid_f32(a) * 255.0))
        .collect();
    let dims = set.scale_dims().count();
    for s in set.log_scales() {
        for (axis, v) in s.to_array().into_iter().enumerate() {
            // A surfel's missing axis: the smallest scale SPZ stores.
            p.scales.push(if axis < dims {
                to_u8((v + 10.0) * 16.0)
            } else {
                0
            });
        }
    }
    let three = options.version >= 3;
    for &q in set.rotations() {
        let q = normalized_xyzw(q);
        if three {
            p.rotations.extend_from_slice(&pack_smallest_three(q));
        } else {
            p.rotations.extend_from_slice(&pack_first_three(q));
        }
    }
    let b1 = 1i32 << (8 - options.sh1_bits);
    let brest = 1i32 << (8 - options.sh_rest_bits);
    p.colors.reserve(3 * n);
    p.sh.reserve(3 * rest * n);
    for i in 0..n {
        let c = set.sh_coeffs(i);
        for &dc in &c[..3] {
            p.colors
                .push(to_u8(dc * (COLOR_SCALE * 255.0) + 0.5 * 255.0));
        }
        for j in 0..rest {
            let bucket = if j < 3 { b1 } else { brest };
            for ch in 0..3 {
                p.sh.push(quantize_sh(c[3 + ch * rest + j], bucket));
            }
        }
    }
    p
}

/// Writes `set` as SPZ, atomically.
///
/// # Errors
/// As [`encode_spz`]; [`SpzError::Io`] when the file cannot be written (the target is then
/// untouched).
pub fn write_spz(
    path: &Path,
    set: &GaussianSet,
    options: &SpzWriteOptions,
) -> Result<(), SpzError> {
    let bytes = encode_spz(set, path, options)?;
    write_atomically(path, |w| {
        w.write_all(&bytes).map_err(|e| IoError::os(path, e))
    })?;
    Ok(())
}
