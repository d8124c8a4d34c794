//! A mesh sequence written as a USD mesh cache: one `.usda` layer (USD's text format) holding
//! one `Mesh` prim whose points are sampled at every frame and whose topology is sampled where
//! it changes (docs/conventions.md §9 "USD mesh cache").
//!
//! The layer, for frames `0..n` shown at `frame_times` seconds:
//!
//! ```text
//! #usda 1.0
//! (
//!     defaultPrim = "sequence"
//!     startTimeCode = c_0   endTimeCode = c_{n-1}   timeCodesPerSecond = r
//!     metersPerUnit = 1   upAxis = "Y"
//! )
//! def Xform "sequence" (kind = "component")
//! {
//!     def Mesh "mesh"
//!     {
//!         uniform token subdivisionScheme = "none"
//!         point3f[] points.timeSamples = { c_0: [...], c_1: [...], ... }
//!         float3[] extent.timeSamples = { ... }
//!         int[] faceVertexCounts.timeSamples = { c_0: [3, ...], c_k: [...] }
//!         int[] faceVertexIndices.timeSamples = { c_0: [...], c_k: [...] }
//!         normal3f[] normals (interpolation = "vertex")      (when every frame has normals)
//!         normal3f[] normals.timeSamples = { ... }
//!     }
//! }
//! ```
//!
//! - **Time codes.** Frame `k` is at time code `c_k = t_k · r`. The rate `r`
//!   (`timeCodesPerSecond`) is the track's frame rate when its times are a whole number of
//!   frames apart (`t_k = t_0 + j/r` with an integer `r ≤ 1000` found from the shortest
//!   interval), so time codes are frame numbers as DCC tools expect; otherwise `r` is 1000 and
//!   time codes are milliseconds. A one-frame sequence has `r` = 24 (USD's default).
//! - **Topology.** `faceVertexCounts` and `faceVertexIndices` get a sample at frame 0 and at
//!   every frame whose vertex count or triangles differ from the previous frame's (a new key
//!   of a carried mesh, or every frame of meshes extracted from scratch). USD holds a sample
//!   until the next one, so each frame reads its own topology.
//! - **Values.** Points are `float` (USD's `point3f`, as every `UsdGeomMesh`), written in the
//!   shortest decimal that reads back to the same `f32`; `extent` is each frame's bounding box
//!   of those `f32` points. Normals are written only when every frame has them. Texture
//!   coordinates and vertex colours are not written.
//! - **Streaming.** Frames are read once, one at a time: points go straight to the output and
//!   the topology, extent and normal samples to anonymous temporary files in the output's
//!   folder, appended at the end, so memory does not grow with the number of frames. The
//!   output is written atomically (temporary file, then rename).
//!
//! `.usdc` (USD's binary crate format) is not written; USD converts:
//! `usdcat cache.usda -o cache.usdc`, or with PyPI's `usd-core` (which has no `usdcat`)
//! `Sdf.Layer.FindOrOpen("cache.usda").Export("cache.usdc")`. On LAM's tsdf meshes
//! (172,751 vertices) a frame takes 6.9 MB as `.usda` and 2.1 MB as `.usdc`.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Read, Seek, Write};
use std::path::Path;

use rayon::prelude::*;

use super::atomic::write_atomically;
use super::error::IoError;
use super::gltf_sequence::FrameSource;
use crate::mesh::TriMesh;

/// Name of the root prim (the layer's `defaultPrim`).
const ROOT: &str = "sequence";

/// The largest frame rate read as frames per second; slower or irregular tracks use
/// milliseconds.
const MAX_RATE: f64 = 1000.0;

/// What [`write_usd_sequence`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct UsdCacheSummary {
    /// Number of time samples of `points` (the number of frames).
    pub samples: usize,
    /// Frames where a topology sample starts (always frame 0).
    pub topology_keys: Vec<usize>,
    /// `timeCodesPerSecond`.
    pub time_codes_per_second: f64,
    /// Whether normals were written.
    pub normals: bool,
}

/// Writes `frames`, shown at `frame_times` seconds (strictly increasing, one per frame), as a
/// USD mesh cache in `.usda` text (module docs), atomically.
///
/// # Errors
/// [`IoError::Unsupported`] for an output that is not `.usda`; [`IoError::Malformed`] naming
/// the output and the element for no frames, a length mismatch, a frame time that is not a
/// finite, non-negative, strictly increasing number of seconds, and a vertex that is not
/// finite in `f32`; the source's errors (an unreadable frame, named); [`IoError::Os`] when
/// the file cannot be written.
pub fn write_usd_sequence(
    path: &Path,
    frames: &dyn FrameSource,
    frame_times: &[f64],
) -> Result<UsdCacheSummary, IoError> {
    let is_usda = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("usda"));
    if !is_usda {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: "a USD mesh cache is written as .usda text (USD converts it to .usdc: \
                   `usdcat IN.usda -o OUT.usdc`)"
                .into(),
        });
    }
    let (rate, codes) = time_codes(path, frames.frame_count(), frame_times)?;
    let mut summary = None;
    write_atomically(path, |out| {
        summary = Some(write_layer(path, out, frames, rate, &codes)?);
        Ok(())
    })?;
    Ok(summary.expect("set by the write"))
}

/// The rate (`timeCodesPerSecond`) and each frame's time code, after checking the times.
fn time_codes(path: &Path, frames: usize, times: &[f64]) -> Result<(f64, Vec<f64>), IoError> {
    if frames == 0 {
        return Err(IoError::malformed(path, "frames", "no frames to write"));
    }
    if times.len() != frames {
        return Err(IoError::malformed(
            path,
            "frame times",
            format!("{} times for {frames} frames", times.len()),
        ));
    }
    for (k, &t) in times.iter().enumerate() {
        if !(t.is_finite() && t >= 0.0) {
            return Err(IoError::malformed(
                path,
                format!("frame time {k}"),
                format!("{t} is not a finite, non-negative number of seconds"),
            ));
        }
        if k > 0 && t <= times[k - 1] {
            return Err(IoError::malformed(
                path,
                format!("frame time {k}"),
                format!(
                    "{t} s does not come after frame time {} ({} s): times must increase \
                     strictly",
                    k - 1,
                    times[k - 1]
                ),
            ));
        }
    }
    let rate = frame_rate(times);
    let codes = times
        .iter()
        .map(|&t| {
            let c = t * rate;
            let whole = c.round();
            if (c - whole).abs() <= 1e-6 * whole.abs().max(1.0) {
                whole
            } else {
                c
            }
        })
        .collect();
    Ok((rate, codes))
}

/// The whole frame rate whose frames the times fall on, else [`MAX_RATE`] (module docs).
fn frame_rate(times: &[f64]) -> f64 {
    let Some(shortest) = times.windows(2).map(|w| w[1] - w[0]).min_by(f64::total_cmp) else {
        return 24.0;
    };
    let rate = (1.0 / shortest).round();
    let on_grid = (1.0..=MAX_RATE).contains(&rate)
        && times.iter().all(|&t| {
            let frames = (t - times[0]) * rate;
            (frames - frames.round()).abs() <= 1e-6 * frames.abs().max(1.0)
        });
    if on_grid { rate } else { MAX_RATE }
}

/// An anonymous temporary file in `path`'s folder, for one attribute's samples.
fn side_file(path: &Path) -> Result<BufWriter<File>, IoError> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    tempfile::tempfile_in(dir)
        .map(|f| BufWriter::with_capacity(1 << 20, f))
        .map_err(|e| IoError::os(path, e))
}

/// Appends the samples gathered in `side` to `out`.
fn append(path: &Path, out: &mut dyn Write, side: BufWriter<File>) -> Result<(), IoError> {
    let mut file = side
        .into_inner()
        .map_err(|e| IoError::os(path, e.into_error()))?;
    file.rewind().map_err(|e| IoError::os(path, e))?;
    let mut buffer = vec![0_u8; 1 << 20];
    loop {
        let n = file.read(&mut buffer).map_err(|e| IoError::os(path, e))?;
        if n == 0 {
            return Ok(());
        }
        out.write_all(&buffer[..n])
            .map_err(|e| IoError::os(path, e))?;
    }
}

/// Writes the whole layer to `out`, reading each frame once.
fn write_layer(
    path: &Path,
    out: &mut dyn Write,
    frames: &dyn FrameSource,
    rate: f64,
    codes: &[f64],
) -> Result<UsdCacheSummary, IoError> {
    let io = |e: std::io::Error| IoError::os(path, e);
    let first = codes[0];
    let last = codes[codes.len() - 1];
    write!(
        out,
        "#usda 1.0\n(\n    defaultPrim = \"{ROOT}\"\n    doc = \"A mesh cache written by \
         trisplat: points at every frame, topology where it changes\"\n    endTimeCode = \
         {last}\n    metersPerUnit = 1\n    startTimeCode = {first}\n    timeCodesPerSecond = \
         {rate}\n    upAxis = \"Y\"\n)\n\ndef Xform \"{ROOT}\" (\n    kind = \"component\"\n)\n\
         {{\n    def Mesh \"mesh\"\n    {{\n        uniform token subdivisionScheme = \
         \"none\"\n        point3f[] points.timeSamples = {{\n"
    )
    .map_err(io)?;
    let mut extent = side_file(path)?;
    let mut counts = side_file(path)?;
    let mut indices = side_file(path)?;
    let mut normals = side_file(path)?;
    let mut all_normals = true;
    let mut topology_keys = Vec::new();
    let mut previous: Option<TriMesh> = None;
    let mut text = String::new();
    for (k, &code) in codes.iter().enumerate() {
        let mesh = frames.frame(k)?;
        let points = finite_points(path, k, &mesh)?;
        write!(out, "            {code}: ").map_err(io)?;
        vec3_array(&points, &mut text);
        out.write_all(text.as_bytes()).map_err(io)?;
        out.write_all(b",\n").map_err(io)?;
        let (lo, hi) = bounds(&points);
        writeln!(
            extent,
            "            {code}: [({}, {}, {}), ({}, {}, {})],",
            lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
        )
        .map_err(io)?;
        let changed = previous.as_ref().is_none_or(|p| {
            p.vertex_count() != mesh.vertex_count() || p.triangles() != mesh.triangles()
        });
        if changed {
            topology_keys.push(k);
            write!(counts, "            {code}: [").map_err(io)?;
            let threes = vec!["3"; mesh.triangle_count()].join(", ");
            counts.write_all(threes.as_bytes()).map_err(io)?;
            counts.write_all(b"],\n").map_err(io)?;
            write!(indices, "            {code}: ").map_err(io)?;
            index_array(mesh.triangles(), &mut text);
            indices.write_all(text.as_bytes()).map_err(io)?;
            indices.write_all(b",\n").map_err(io)?;
        }
        match mesh.normals() {
            Some(n) if all_normals => {
                let n: Vec<[f32; 3]> = n.iter().map(|v| v.to_array()).collect();
                write!(normals, "            {code}: ").map_err(io)?;
                vec3_array(&n, &mut text);
                normals.write_all(text.as_bytes()).map_err(io)?;
                normals.write_all(b",\n").map_err(io)?;
            }
            _ => all_normals = false,
        }
        if changed {
            previous = Some(mesh.into_owned());
        }
    }
    out.write_all(b"        }\n        float3[] extent.timeSamples = {\n")
        .map_err(io)?;
    append(path, out, extent)?;
    out.write_all(b"        }\n        int[] faceVertexCounts.timeSamples = {\n")
        .map_err(io)?;
    append(path, out, counts)?;
    out.write_all(b"        }\n        int[] faceVertexIndices.timeSamples = {\n")
        .map_err(io)?;
    append(path, out, indices)?;
    out.write_all(b"        }\n").map_err(io)?;
    if all_normals {
        out.write_all(
            b"        normal3f[] normals (\n            interpolation = \"vertex\"\n        \
              )\n        normal3f[] normals.timeSamples = {\n",
        )
        .map_err(io)?;
        append(path, out, normals)?;
        out.write_all(b"        }\n").map_err(io)?;
    }
    out.write_all(b"    }\n}\n").map_err(io)?;
    Ok(UsdCacheSummary {
        samples: codes.len(),
        topology_keys,
        time_codes_per_second: rate,
        normals: all_normals,
    })
}

/// Frame `k`'s vertices as `f32`, every coordinate finite.
fn finite_points(path: &Path, k: usize, mesh: &TriMesh) -> Result<Vec<[f32; 3]>, IoError> {
    #[expect(clippy::cast_possible_truncation, reason = "USD points are float")]
    let points: Vec<[f32; 3]> = mesh
        .positions()
        .iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    if let Some(v) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(IoError::malformed(
            path,
            format!("frame {k}, vertex {v}"),
            format!(
                "{:?} is not finite as a 32-bit float",
                mesh.positions()[v].to_array()
            ),
        ));
    }
    Ok(points)
}

/// The bounding box of `points` (zeros for none).
fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    if points.is_empty() {
        return ([0.0; 3], [0.0; 3]);
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// Vertices per formatting task.
const CHUNK: usize = 8192;

/// `[(x, y, z), ...]` into `text` (cleared first), each value the shortest decimal that reads
/// back to the same `f32`; chunks formatted in parallel.
fn vec3_array(values: &[[f32; 3]], text: &mut String) {
    text.clear();
    text.push('[');
    let parts: Vec<String> = values
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut s = String::with_capacity(chunk.len() * 36);
            for (i, v) in chunk.iter().enumerate() {
                if i > 0 {
                    s.push_str(", ");
                }
                let _ = write!(s, "({}, {}, {})", v[0], v[1], v[2]);
            }
            s
        })
        .collect();
    text.push_str(&parts.join(", "));
    text.push(']');
}

/// `[a, b, c, ...]`, the triangles' corners in order, into `text` (cleared first).
fn index_array(triangles: &[[u32; 3]], text: &mut String) {
    text.clear();
    text.push('[');
    let parts: Vec<String> = triangles
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut s = String::with_capacity(chunk.len() * 24);
            for (i, t) in chunk.iter().enumerate() {
                if i > 0 {
                    s.push_str(", ");
                }
                let _ = write!(s, "{}, {}, {}", t[0], t[1], t[2]);
            }
            s
        })
        .collect();
    text.push_str(&parts.join(", "));
    text.push(']');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_rate_is_the_grid_the_times_fall_on() {
        let at_30: Vec<f64> = (0..10).map(|k| f64::from(k) / 30.0).collect();
        assert_eq!(frame_rate(&at_30), 30.0);
        let gaps = [0.0, 1.0 / 30.0, 3.0 / 30.0, 4.0 / 30.0];
        assert_eq!(frame_rate(&gaps), 30.0);
        let irregular = [0.0, 0.013, 0.05];
        assert_eq!(frame_rate(&irregular), MAX_RATE);
        assert_eq!(frame_rate(&[0.5]), 24.0);
        let (rate, codes) =
            time_codes(Path::new("x.usda"), 3, &[1.0, 1.0 + 1.0 / 30.0, 1.1]).expect("valid times");
        assert_eq!(rate, 30.0);
        assert_eq!(codes, vec![30.0, 31.0, 33.0]);
    }

    #[test]
    fn arrays_are_written_in_usd_syntax() {
        let mut text = String::new();
        vec3_array(&[[0.0, 1.5, -2.0], [0.1, 1e-7, 3.0]], &mut text);
        assert_eq!(text, "[(0, 1.5, -2), (0.1, 0.0000001, 3)]");
        index_array(&[[0, 1, 2], [2, 1, 3]], &mut text);
        assert_eq!(text, "[0, 1, 2, 2, 1, 3]");
        vec3_array(&[], &mut text);
        assert_eq!(text, "[]");
    }
}
