//! Radiance HDR (`.hdr`, RGBE) images: the reader (and a flat writer, [`write_hdr`]) of
//! environment maps (docs/conventions.md §5
//! "Relighting").
//!
//! - Header: the magic `#?RADIANCE` or `#?RGBE`, variable lines up to an empty line (only
//!   `FORMAT=32-bit_rle_rgbe` is accepted; `EXPOSURE` and other variables are ignored, as
//!   OpenCV and stb_image do), then the resolution line, which must be `-Y H +X W` (rows top to
//!   bottom, columns left to right: the common orientation). Other orientations and the XYZE
//!   format are refused with an error naming them.
//! - Scanlines: new-style run-length encoded (`2 2 hi lo`, four channels one after the other,
//!   runs of `count - 128` copies or `count` literals), flat RGBE, or old-style runs
//!   (`1 1 1 n` repeats the previous pixel, shifts of 8 bits for consecutive runs).
//! - A texel `(r, g, b, e)` is `c · 2^(e - 136)` per channel (Greg Ward's reference code as
//!   OpenCV and stb_image decode it, no half-step offset), and 0 when `e = 0`.
//! - Never trusted: header sizes. A file whose pixel count its bytes cannot hold (16 pixels a
//!   byte is the densest run-length code) is refused before anything is allocated.

use std::path::Path;

use super::error::IoError;

/// Largest image read, in pixels (16384 × 8192).
pub const MAX_HDR_PIXELS: u64 = 1 << 27;

/// A decoded Radiance image: linear RGB radiance, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct HdrImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height` RGB triples.
    pub rgb: Vec<[f32; 3]>,
}

/// Reads a Radiance `.hdr` file.
///
/// # Errors
/// [`IoError`] naming the file: unreadable, not a Radiance file (magic), an unsupported format
/// or orientation, a truncated or malformed scanline (naming the row).
pub fn read_hdr(path: &Path) -> Result<HdrImage, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::os(path, e))?;
    parse_hdr(path, &bytes)
}

/// Decodes the bytes of a Radiance `.hdr` file (`path` names it in errors).
///
/// # Errors
/// See [`read_hdr`].
pub fn parse_hdr(path: &Path, bytes: &[u8]) -> Result<HdrImage, IoError> {
    let (width, height, body) = parse_header(path, bytes)?;
    let pixels = u64::from(width) * u64::from(height);
    if pixels > MAX_HDR_PIXELS {
        return Err(IoError::Unsupported {
            path: path.into(),
            what: format!("{width}x{height} exceeds the {MAX_HDR_PIXELS}-pixel limit"),
        });
    }
    if pixels > 16 * body.len() as u64 + 16 {
        return Err(IoError::malformed(
            path,
            "pixel data",
            format!(
                "{} bytes cannot hold {width}x{height} pixels (truncated file?)",
                body.len()
            ),
        ));
    }
    let w = width as usize;
    let scale: Vec<f32> = (0..256u32)
        .map(|e| {
            if e == 0 {
                0.0
            } else {
                (f64::from(e) - 136.0).exp2() as f32
            }
        })
        .collect();
    let mut rgb = Vec::with_capacity(w * height as usize);
    let mut line = vec![[0u8; 4]; w];
    let mut at = 0usize;
    for row in 0..height as usize {
        at = read_scanline(body, at, &mut line)
            .map_err(|message| IoError::malformed(path, format!("scanline {row}"), message))?;
        // c · 2^(e - 136) is exact in f32 for every byte pair: the same values as `rgbe_to_rgb`.
        rgb.extend(line.iter().map(|&[r, g, b, e]| {
            let f = scale[usize::from(e)];
            [f32::from(r) * f, f32::from(g) * f, f32::from(b) * f]
        }));
    }
    Ok(HdrImage { width, height, rgb })
}

/// Writes linear RGB radiance (`width × height`, row 0 at the top) as a Radiance `.hdr` file:
/// `#?RADIANCE`, `FORMAT=32-bit_rle_rgbe`, `-Y H +X W`, flat RGBE scanlines (what
/// [`read_hdr`], OpenCV and stb_image read). A texel is stored as [`rgb_to_rgbe`]. Written
/// atomically (temporary file, then rename).
///
/// # Errors
/// [`IoError`] naming the file: a size that does not match `rgb`, a negative or non-finite
/// value (naming the texel), or the write failing.
pub fn write_hdr(path: &Path, width: u32, height: u32, rgb: &[[f32; 3]]) -> Result<(), IoError> {
    if u64::from(width) * u64::from(height) != rgb.len() as u64 {
        return Err(IoError::malformed(
            path,
            "pixel data",
            format!("{} texels for a {width}x{height} image", rgb.len()),
        ));
    }
    if let Some(k) = rgb
        .iter()
        .position(|t| t.iter().any(|v| !(v.is_finite() && *v >= 0.0)))
    {
        return Err(IoError::malformed(
            path,
            format!("texel {k}"),
            format!("radiance {:?} is not finite and >= 0", rgb[k]),
        ));
    }
    super::atomic::write_atomically(path, |out| {
        let os = |e| IoError::os(path, e);
        write!(
            out,
            "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {height} +X {width}\n"
        )
        .map_err(os)?;
        let bytes: Vec<u8> = rgb.iter().flat_map(|&t| rgb_to_rgbe(t)).collect();
        out.write_all(&bytes).map_err(os)
    })
}

/// Linear RGB as one RGBE texel (Greg Ward's encoding: the largest channel's exponent `e`,
/// each channel `⌊c / 2^(e − 136)⌋`; 0 below 1e-32). [`rgbe_to_rgb`] gives each channel back
/// less than one step `2^(e − 8)` below it, within `2^-7` of the largest channel.
#[must_use]
pub fn rgb_to_rgbe(rgb: [f32; 3]) -> [u8; 4] {
    let m = rgb[0].max(rgb[1]).max(rgb[2]);
    if m.is_nan() || m < 1e-32 || m.is_infinite() {
        return [0; 4];
    }
    // m = f · 2^e with f in [0.5, 1): e = ⌊log2 m⌋ + 1.
    let mut e = f64::from(m).log2().floor() as i32 + 1;
    if f64::from(m) >= f64::from(e).exp2() {
        e += 1;
    }
    let e = e.clamp(-128, 127);
    let scale = 256.0 / f64::from(e).exp2();
    let c = rgb.map(|v| (f64::from(v.max(0.0)) * scale).floor().clamp(0.0, 255.0) as u8);
    [c[0], c[1], c[2], (e + 128) as u8]
}

/// One RGBE texel as linear RGB.
#[must_use]
pub fn rgbe_to_rgb([r, g, b, e]: [u8; 4]) -> [f32; 3] {
    if e == 0 {
        return [0.0; 3];
    }
    let f = (f64::from(e) - 136.0).exp2();
    [r, g, b].map(|c| (f64::from(c) * f) as f32)
}

/// The header: magic, variables, resolution line. Returns width, height and the pixel bytes.
fn parse_header<'a>(path: &Path, bytes: &'a [u8]) -> Result<(u32, u32, &'a [u8]), IoError> {
    let bad = |element: &str, message: String| IoError::malformed(path, element, message);
    if !(bytes.starts_with(b"#?RADIANCE") || bytes.starts_with(b"#?RGBE")) {
        return Err(bad(
            "header",
            "not a Radiance HDR file (no #?RADIANCE or #?RGBE magic)".into(),
        ));
    }
    let mut at = 0usize;
    let next_line = |at: &mut usize| -> Option<&'a [u8]> {
        let rest = bytes.get(*at..)?;
        let end = rest.iter().position(|&b| b == b'\n')?;
        *at += end + 1;
        Some(&rest[..end])
    };
    let _magic = next_line(&mut at);
    let mut line_no = 1usize;
    loop {
        line_no += 1;
        let Some(line) = next_line(&mut at) else {
            return Err(bad(
                "header",
                "ends before the empty line that closes it".into(),
            ));
        };
        let line = String::from_utf8_lossy(line);
        let line = line.trim_end_matches('\r');
        if line.is_empty() {
            break;
        }
        if let Some(format) = line
            .strip_prefix("FORMAT=")
            .filter(|f| f.trim() != "32-bit_rle_rgbe")
        {
            return Err(IoError::Unsupported {
                path: path.into(),
                what: format!(
                    "header line {line_no}: FORMAT={format} (only 32-bit_rle_rgbe is read)"
                ),
            });
        }
    }
    line_no += 1;
    let Some(resolution) = next_line(&mut at) else {
        return Err(bad("resolution line", "missing".into()));
    };
    let resolution = String::from_utf8_lossy(resolution);
    let words: Vec<&str> = resolution.split_whitespace().collect();
    let size = |s: &str| s.parse::<u32>().ok().filter(|&v| v > 0);
    match words.as_slice() {
        ["-Y", h, "+X", w] => match (size(w), size(h)) {
            (Some(w), Some(h)) => Ok((w, h, &bytes[at..])),
            _ => Err(bad(
                &format!("resolution line (header line {line_no})"),
                format!("'{}' does not give a positive size", resolution.trim()),
            )),
        },
        [a, _, b, _]
            if matches!(*a, "-Y" | "+Y" | "-X" | "+X")
                && matches!(*b, "-Y" | "+Y" | "-X" | "+X") =>
        {
            Err(IoError::Unsupported {
                path: path.into(),
                what: format!(
                    "orientation '{}' (only '-Y H +X W', rows top to bottom, is read)",
                    resolution.trim()
                ),
            })
        }
        _ => Err(bad(
            &format!("resolution line (header line {line_no})"),
            format!("'{}' is not '-Y H +X W'", resolution.trim()),
        )),
    }
}

/// Decodes one scanline starting at byte `at` into `line`; returns the byte after it.
fn read_scanline(body: &[u8], at: usize, line: &mut [[u8; 4]]) -> Result<usize, String> {
    let w = line.len();
    let head = body.get(at..at + 4);
    let new_rle = (8..=0x7fff).contains(&w)
        && head.is_some_and(|h| h[0] == 2 && h[1] == 2 && h[2] & 0x80 == 0);
    if !new_rle {
        return read_flat(body, at, line);
    }
    let h = head.unwrap_or(&[0; 4]);
    let declared = usize::from(h[2]) << 8 | usize::from(h[3]);
    if declared != w {
        return Err(format!(
            "run-length scanline of width {declared}, the image is {w} wide"
        ));
    }
    let mut at = at + 4;
    let truncated = || "truncated (the file ends inside it)".to_string();
    for channel in 0..4 {
        let mut x = 0usize;
        while x < w {
            let &count = body.get(at).ok_or_else(truncated)?;
            at += 1;
            if count > 128 {
                let run = usize::from(count - 128);
                let &value = body.get(at).ok_or_else(truncated)?;
                at += 1;
                if x + run > w {
                    return Err(format!("a run of {run} passes the end of the row at {x}"));
                }
                for p in &mut line[x..x + run] {
                    p[channel] = value;
                }
                x += run;
            } else {
                let run = usize::from(count);
                if run == 0 {
                    return Err("a run of length 0".into());
                }
                if x + run > w {
                    return Err(format!("{run} literals pass the end of the row at {x}"));
                }
                let values = body.get(at..at + run).ok_or_else(truncated)?;
                at += run;
                for (p, &v) in line[x..x + run].iter_mut().zip(values) {
                    p[channel] = v;
                }
                x += run;
            }
        }
    }
    Ok(at)
}

/// A flat (or old-style run-length) scanline.
fn read_flat(body: &[u8], mut at: usize, line: &mut [[u8; 4]]) -> Result<usize, String> {
    let w = line.len();
    let mut x = 0usize;
    let mut shift = 0u32;
    while x < w {
        let p = body
            .get(at..at + 4)
            .ok_or_else(|| "truncated (the file ends inside it)".to_string())?;
        at += 4;
        if p[0] == 1 && p[1] == 1 && p[2] == 1 {
            if x == 0 {
                return Err("an old-style run with no pixel before it".into());
            }
            let run = usize::from(p[3]).checked_shl(shift).unwrap_or(usize::MAX);
            if shift > 16 || x + run > w {
                return Err(format!(
                    "an old-style run of {run} passes the end of the row"
                ));
            }
            let previous = line[x - 1];
            line[x..x + run].fill(previous);
            x += run;
            shift += 8;
        } else {
            line[x] = [p[0], p[1], p[2], p[3]];
            x += 1;
            shift = 0;
        }
    }
    Ok(at)
}

#[cfg(test)]
mod tests {

    /// Written then read: every channel within `2^-7` of the texel's largest, never above it,
    /// zeros kept;
    /// negative or NaN radiance refused with the texel named, nothing written.
    #[test]
    fn write_then_read_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.hdr");
        let rgb: Vec<[f32; 3]> = (0..32)
            .map(|k| {
                let k = k as f32;
                [
                    0.01 * k * k,
                    3.0 + k,
                    if (k as u32).is_multiple_of(5) {
                        0.0
                    } else {
                        1e3 / (k + 1.0)
                    },
                ]
            })
            .chain([[0.0; 3], [1.0, 0.5, 0.25], [65_000.0, 1.0, 0.0]])
            .chain(std::iter::repeat_n([0.2; 3], 15))
            .collect();
        write_hdr(&path, 10, 5, &rgb).unwrap();
        let back = read_hdr(&path).unwrap();
        assert_eq!((back.width, back.height), (10, 5));
        for (a, b) in rgb.iter().zip(&back.rgb) {
            let m = a[0].max(a[1]).max(a[2]);
            for c in 0..3 {
                assert!(b[c] <= a[c] && a[c] - b[c] <= m / 128.0, "{a:?} {b:?}");
            }
        }
        let mut bad = rgb.clone();
        bad[7][1] = f32::NAN;
        let other = dir.path().join("bad.hdr");
        let err = write_hdr(&other, 10, 5, &bad).unwrap_err().to_string();
        assert!(err.contains("texel 7"), "{err}");
        assert!(!other.exists());
        assert!(write_hdr(&other, 10, 4, &rgb).is_err());
    }
    use super::*;

    fn header(res: &str) -> Vec<u8> {
        format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n{res}\n").into_bytes()
    }

    #[test]
    fn flat_and_rle_scanlines_decode_alike() {
        let w = 8usize;
        let pixels: Vec<[u8; 4]> = (0..w)
            .map(|i| [i as u8 * 10, 3, 200, 128 + i as u8])
            .collect();
        let mut flat = header("-Y 1 +X 8");
        flat.extend(pixels.iter().flatten());
        let mut rle = header("-Y 1 +X 8");
        rle.extend([2, 2, 0, 8]);
        // Red: 8 literals; green: a run of 8; blue: a run of 8; exponent: 8 literals.
        rle.push(8);
        rle.extend(pixels.iter().map(|p| p[0]));
        rle.extend([128 + 8, 3, 128 + 8, 200, 8]);
        rle.extend(pixels.iter().map(|p| p[3]));
        let a = parse_hdr(Path::new("a.hdr"), &flat).unwrap();
        let b = parse_hdr(Path::new("b.hdr"), &rle).unwrap();
        assert_eq!(a, b);
        // (10, 3, 200, 129): 10 · 2^-7.
        assert_eq!(a.rgb[1][0], 10.0 / 128.0);
        assert_eq!(rgbe_to_rgb([5, 5, 5, 0]), [0.0; 3]);
    }

    #[test]
    fn old_style_runs_repeat_the_previous_pixel() {
        let mut bytes = header("-Y 1 +X 4");
        bytes.extend([64, 64, 64, 129, 1, 1, 1, 3]);
        let img = parse_hdr(Path::new("o.hdr"), &bytes).unwrap();
        assert!(img.rgb.iter().all(|p| *p == [0.5; 3]));
    }

    #[test]
    fn bad_files_are_refused_by_name() {
        let p = Path::new("bad.hdr");
        let msg = |b: &[u8]| parse_hdr(p, b).unwrap_err().to_string();
        assert!(msg(b"P6\n1 1\n255\n").contains("not a Radiance HDR file"));
        assert!(msg(&header("+Y 1 +X 8")).contains("orientation '+Y 1 +X 8'"));
        assert!(msg(b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n").contains("xyze"));
        assert!(msg(&header("-Y 1 +X 8")).contains("bad.hdr"));
        let mut rle = header("-Y 1 +X 8");
        rle.extend([2, 2, 0, 8, 128 + 9, 1]);
        assert!(msg(&rle).contains("scanline 0"), "{}", msg(&rle));
        // A header that claims more pixels than its bytes can hold allocates nothing.
        assert!(msg(&header("-Y 60000 +X 60000")).contains("limit"));
        assert!(msg(&header("-Y 100 +X 100")).contains("cannot hold"));
    }
}
