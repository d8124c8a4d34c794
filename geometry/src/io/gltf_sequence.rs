//! A mesh sequence written as one animated glTF 2.0 file (`.glb` or `.gltf`).
//!
//! [`write_mesh_sequence`] stores frames shown at given times (seconds) in one of two layouts
//! ([`SequenceLayout`]):
//!
//! - **Morph targets** (frames that share the first frame's vertex count and triangles): one
//!   node with one mesh whose base is frame 0 and whose morph target `k − 1` holds frame `k`
//!   as `POSITION` deltas (and `NORMAL` deltas when every frame has normals). A `weights`
//!   channel with **STEP** interpolation has one key per frame: at `frame_times[k]` target
//!   `k − 1` has weight 1 and every other weight is 0 (at `frame_times[0]` all are 0). STEP
//!   and not LINEAR because a viewer then shows the frames exactly as given, never a blend of
//!   two, and at most one target is active at a time (viewers that cap the number of active
//!   morph targets, e.g. to 8, still play it). Texture coordinates and colours are those of
//!   frame 0. Target deltas are stored dense, not as sparse accessors: frames of a captured or
//!   extracted sequence move nearly every vertex, where a sparse accessor (an index plus a
//!   value per moved vertex) is larger. Targets are named `frame_000001`, ... in
//!   `mesh.extras.targetNames`.
//! - **One node per run** (any topology): a root node `sequence` with one child node per run
//!   of consecutive frames that share a vertex count and triangles (a mesh carried between
//!   keys), named by its first frame (`frame_000000`, ...). A run of one frame is a plain
//!   mesh; a longer run is a mesh whose base is its first frame with one morph target per
//!   later frame (as above, its own STEP `weights` channel keyed at its frames' times). Every
//!   child has a `scale` channel with **STEP** interpolation that is 1 from its run's first
//!   time until the next run's first time and 0 otherwise, so exactly one frame is visible at
//!   any time (before the first time the first frame, after the last time the last frame).
//!   Each scale channel has at most three keys (the first frame's time, its own, the next
//!   run's), so for runs of one frame the animation data grows linearly with the number of
//!   frames. In the static scene (no animation applied) the first run has scale 1 and the
//!   others 0. A frame without triangles is a run of its own, a child node without a mesh.
//!   [`SequenceLayout::NodePerFrame`] makes every frame a run of its own.
//!
//! **Streaming.** The writer takes its frames from a [`FrameSource`] one at a time: in memory
//! ([`write_mesh_sequence`]) or read from one mesh file per frame ([`FrameFiles`],
//! [`write_sequence`]). It reads every frame up to three times: once to check it and choose
//! the layout, once to lay the buffer out (lengths and `min`/`max`, nothing kept), once to
//! stream the bytes into the `.glb`, so it holds only the first frame, the previous frame's
//! triangles and the frame at hand, whatever the length of the sequence (`.gltf` holds its
//! base64 buffer in memory). Both readings must agree (a frame file changed in between is an
//! error). The main job writes its per-frame PLY files first and assembles each method's
//! `.glb` from them this way.
//!
//! Both layouts put everything in one animation named `sequence` whose duration is the last
//! frame time; a one-frame sequence gets a single-key scale channel so that every file has
//! that animation. Key times are `f32` in glTF: each time is stored as the largest `f32` not
//! above it, so evaluating at the `f64` frame time itself selects that frame; times that
//! collapse to the same `f32` are an error.
//!
//! Vertex data is `f32` (`POSITION` with `min`/`max` as the specification requires, morph
//! target `POSITION` deltas with `min`/`max` too, unit `NORMAL`s — zero ones become +z as in
//! the static writer — `TEXCOORD_0`, `COLOR_0` as float RGBA), indices `u32`, animation
//! inputs with `min`/`max`. Every buffer view starts on a 4-byte boundary. `.glb` holds the
//! one buffer in its binary chunk; `.gltf` embeds it as a base64 data URI, so the output is
//! one self-contained file written atomically.
//!
//! Size: vertex data is 12 bytes per vertex per frame for positions, 12 more with normals, in
//! either layout; indices (12 bytes per triangle) are written once for morph targets and, for
//! one node per frame, once per run of frames with identical triangles (consecutive frames
//! share the accessor). 100 frames of a 20,000-vertex, 39,402-triangle grid without normals
//! make a 24.5 MB `.glb` as morph targets (measured), and about 71 MB as one node per frame
//! if every frame had other triangles (100 × (240,000 + 472,824) bytes);
//! `trisplat convert` checks those 100 PLY frames and streams the `.glb` in 1.15-1.17 s
//! (2 cores) with 15 MB peak memory; holding the frames in memory instead, it took about
//! 0.4 s and 115 MB, a peak that grew with every frame.
//!
//! Validity: outputs of both layouts (`.glb` and `.gltf`, with and without normals, one and
//! many frames) were checked with the Khronos glTF-Validator 2.0.0-dev.3.10 (npm
//! `gltf-validator`): 0 errors, 0 warnings; the only message is an info, `NODE_EMPTY`, for
//! the node of a frame without triangles. `trisplat convert` output of 100 frames of 20,000
//! vertices, `.glb` and `.gltf`: 0 errors, 0 warnings, 0 infos. CI has no node, so the tests
//! (`tests/tests/io_gltf_sequence.rs`) check the structural rules that validator enforces
//! and these files could break: views inside the buffer and 4-byte aligned, accessors inside
//! their views, exact `min`/`max` where required, view targets, index ranges, unit normals,
//! morph target counts, the node tree, key times and sampler output sizes.

use std::borrow::Cow;
use std::io::Write;
use std::ops::Range;
use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::Vec3;
use rayon::prelude::*;
use serde_json::{Map, Value, json};

use super::atomic::write_atomically;
use super::error::IoError;
use super::files::read_mesh;
use super::format::Format;
use super::gltf_codes::{ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, TRIANGLES, UNSIGNED_INT};
use crate::mesh::TriMesh;

/// Name of the animation, of the morph-target mesh and of the node-per-frame root.
const SEQUENCE_NAME: &str = "sequence";

/// How a sequence is stored in glTF.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SequenceLayout {
    /// Morph targets when every frame has the first frame's vertex count and triangles (and
    /// the first frame has triangles), else one node per run of frames that share their
    /// topology (morph targets within a run).
    #[default]
    Auto,
    /// One mesh: frame 0 as the base, one morph target per later frame, a STEP weights
    /// track. Every frame must have the vertex count and triangles of frame 0.
    MorphTargets,
    /// One mesh and node per frame under a root node, shown one at a time by STEP scale
    /// tracks (scale 1 for the current frame, 0 for the others). (`Auto` with frames of
    /// several topologies gives one node per run of frames with the same topology instead.)
    NodePerFrame,
}

/// The frames of a sequence, handed to the writer one at a time: the writer reads each frame
/// up to three times (checks, sizes, bytes) and never holds more than the first frame, the
/// previous frame's triangles and the frame at hand, so a sequence read from files is written
/// in memory independent of its length.
pub trait FrameSource {
    /// Number of frames.
    fn frame_count(&self) -> usize;

    /// Frame `k` (`k < frame_count()`).
    ///
    /// # Errors
    /// The source's own (an unreadable frame file, named).
    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError>;
}

impl FrameSource for &[TriMesh] {
    fn frame_count(&self) -> usize {
        self.len()
    }

    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError> {
        self.get(k)
            .map(Cow::Borrowed)
            .ok_or_else(|| IoError::malformed(Path::new(""), format!("frame {k}"), "no such frame"))
    }
}

/// Frames stored one per mesh file (any format [`super::read_mesh`] reads), read when needed.
#[derive(Clone, Copy, Debug)]
pub struct FrameFiles<'a>(pub &'a [PathBuf]);

impl FrameSource for FrameFiles<'_> {
    fn frame_count(&self) -> usize {
        self.0.len()
    }

    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError> {
        let path = self.0.get(k).ok_or_else(|| {
            IoError::malformed(Path::new(""), format!("frame {k}"), "no such frame file")
        })?;
        read_mesh(path).map(Cow::Owned)
    }
}

/// Writes `frames` (shown at `frame_times` seconds, strictly increasing, same length) as one
/// animated glTF/GLB (format from the extension), atomically. See the module docs for the
/// layouts; [`write_sequence`] does the same for frames read one at a time.
///
/// # Errors
/// [`IoError::UnknownFormat`] or [`IoError::Unsupported`] for a path that is not `.glb` or
/// `.gltf`; [`IoError::Malformed`] naming the output file and the element for an empty
/// sequence, a length mismatch, a frame time that is negative, not finite, not increasing or
/// not distinct as `f32`, a non-finite vertex or morph delta, and (with
/// [`SequenceLayout::MorphTargets`]) a frame whose topology differs from frame 0;
/// [`IoError::Unsupported`] for a `.glb` over 4 GiB; [`IoError::Os`] when the file cannot be
/// written.
pub fn write_mesh_sequence(
    path: &Path,
    frames: &[TriMesh],
    frame_times: &[f64],
    layout: SequenceLayout,
) -> Result<(), IoError> {
    write_sequence(path, &frames, frame_times, layout)
}

/// [`write_mesh_sequence`] for frames handed over one at a time by `frames` (for example
/// [`FrameFiles`]): a `.glb` is streamed to disk, so memory does not grow with the number of
/// frames (a `.gltf` embeds its buffer as base64 text and holds it in memory).
///
/// # Errors
/// As [`write_mesh_sequence`], and the source's errors.
pub fn write_sequence(
    path: &Path,
    frames: &dyn FrameSource,
    frame_times: &[f64],
    layout: SequenceLayout,
) -> Result<(), IoError> {
    let format = Format::from_path(path)?;
    if !matches!(format, Format::Glb | Format::Gltf) {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: "a mesh sequence is written as .glb or .gltf".into(),
        });
    }
    let keys = key_times(path, frames.frame_count(), frame_times)?;
    let survey = Survey::of(path, frames, layout)?;
    write_surveyed(path, format, frames, &keys, &survey, &survey.segments)
}

/// Writes `frames` at `keys` in the layout `survey` chose, `segments` being its runs of one
/// topology among `frames`.
fn write_surveyed(
    path: &Path,
    format: Format,
    frames: &dyn FrameSource,
    keys: &[f32],
    survey: &Survey,
    segments: &[Range<usize>],
) -> Result<(), IoError> {
    let build = |sink: &mut dyn Sink| -> Result<Document, IoError> {
        if survey.morph {
            build_morph_targets(path, frames, keys, survey.normals, sink)
        } else {
            build_segments(path, frames, keys, segments, survey.normals, sink)
        }
    };
    match format {
        Format::Glb => {
            // Pass 1 lays the buffer out (lengths only), pass 2 streams its bytes.
            let mut counted = Counted(0);
            let doc = build(&mut counted)?;
            write_glb(path, &doc, counted.0, |sink| build(sink).map(|_| ()))
        }
        _ => {
            let mut bin = Vec::new();
            let doc = build(&mut bin)?;
            write_gltf(path, doc, &bin)
        }
    }
}

/// The largest `.glb` [`write_sequence_parts`] writes as one file: the format's 4 GiB limit
/// less room for the JSON chunk.
pub const GLB_PART_LIMIT: u64 = (1 << 32) - (64 << 20);

/// [`write_sequence`] into as many `.glb` files as glTF's 4 GiB limit needs: one file at
/// `path` when the sequence fits in `max_bytes` of buffer, else consecutive runs of frames in
/// `STEM_part001.glb`, `STEM_part002.glb`, ... beside it, each a complete animated glTF that
/// keeps the frames' own times (part 2 starts at its first frame's time). Returns the files
/// written, in order. Use [`GLB_PART_LIMIT`] for `max_bytes` unless a smaller part is wanted.
///
/// # Errors
/// As [`write_sequence`]; [`IoError::Unsupported`] when a single frame exceeds `max_bytes`,
/// or for a `.gltf` path (parts are `.glb`). Parts already written stay when a later one
/// fails (each is complete).
pub fn write_sequence_parts(
    path: &Path,
    frames: &dyn FrameSource,
    frame_times: &[f64],
    layout: SequenceLayout,
    max_bytes: u64,
) -> Result<Vec<PathBuf>, IoError> {
    if Format::from_path(path)? != Format::Glb {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: "a sequence split into parts is written as .glb".into(),
        });
    }
    let keys = key_times(path, frames.frame_count(), frame_times)?;
    let survey = Survey::of(path, frames, layout)?;
    let runs = split(path, &survey.sizes, max_bytes)?;
    if runs.len() == 1 {
        write_surveyed(path, Format::Glb, frames, &keys, &survey, &survey.segments)?;
        return Ok(vec![path.to_path_buf()]);
    }
    let stem = path
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let mut written = Vec::with_capacity(runs.len());
    for (i, run) in runs.into_iter().enumerate() {
        let part = path.with_file_name(format!("{stem}_part{:03}.glb", i + 1));
        let part_keys = &keys[run.clone()];
        let segments = survey.segments_in(&run);
        write_surveyed(
            &part,
            Format::Glb,
            &FrameRun { frames, run },
            part_keys,
            &survey,
            &segments,
        )?;
        written.push(part);
    }
    Ok(written)
}

/// Consecutive runs of frames whose buffers stay within `max_bytes`: each frame's bound from
/// `sizes`, plus the morph layout's weights track (4 bytes per frame and target, quadratic in
/// the frames of a part).
fn split(
    path: &Path,
    sizes: &[u64],
    max_bytes: u64,
) -> Result<Vec<std::ops::Range<usize>>, IoError> {
    let fits = |frames: u64, bytes: u64| bytes.saturating_add(4 * frames * frames) <= max_bytes;
    let mut runs = Vec::new();
    let (mut start, mut bytes) = (0, 0u64);
    for (k, &size) in sizes.iter().enumerate() {
        if !fits(1, size) {
            return Err(IoError::Unsupported {
                path: path.to_path_buf(),
                what: format!("frame {k} alone needs {size} bytes, over the {max_bytes}-byte part"),
            });
        }
        if !fits((k + 1 - start) as u64, bytes + size) {
            runs.push(start..k);
            (start, bytes) = (k, 0);
        }
        bytes += size;
    }
    runs.push(start..sizes.len());
    Ok(runs)
}

/// Frames `run` of another source.
struct FrameRun<'a> {
    frames: &'a dyn FrameSource,
    run: std::ops::Range<usize>,
}

impl FrameSource for FrameRun<'_> {
    fn frame_count(&self) -> usize {
        self.run.len()
    }

    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError> {
        self.frames.frame(self.run.start + k)
    }
}

/// What one read of every frame tells before anything is written.
struct Survey {
    /// Whether the morph-target layout is used.
    morph: bool,
    /// Morph targets carry normal deltas (every frame has normals).
    normals: bool,
    /// Per frame, an upper bound of the buffer bytes it adds in either layout (its vertex
    /// data, its own indices and its animation keys).
    sizes: Vec<u64>,
    /// Runs of consecutive frames with one vertex count and the same triangles (a frame
    /// without triangles is a run of its own; one run per frame for
    /// [`SequenceLayout::NodePerFrame`]).
    segments: Vec<Range<usize>>,
}

impl Survey {
    /// Checks every frame (finite positions; for morph targets the topology of frame 0) and
    /// decides the layout.
    fn of(path: &Path, frames: &dyn FrameSource, layout: SequenceLayout) -> Result<Self, IoError> {
        let base = frames.frame(0)?;
        let mut same = base.triangle_count() > 0;
        let mut segments: Vec<Range<usize>> = Vec::new();
        segments.push(0..1);
        // The first frame of the current segment (frame 0 is `base`).
        let mut segment_base: Option<TriMesh> = None;
        if layout == SequenceLayout::MorphTargets && !same {
            return Err(IoError::malformed(
                path,
                "frame 0",
                "has no triangles (morph targets need a base mesh)",
            ));
        }
        let mut normals = base.normals().is_some();
        let mut sizes = Vec::with_capacity(frames.frame_count());
        for k in 0..frames.frame_count() {
            let frame = if k == 0 {
                Cow::Borrowed(base.as_ref())
            } else {
                frames.frame(k)?
            };
            if let Some(v) = frame.positions().iter().position(|p| !p.is_finite()) {
                return Err(IoError::malformed(
                    path,
                    format!("frame {k} vertex {v}"),
                    "position is not finite",
                ));
            }
            normals &= frame.normals().is_some();
            let per_vertex = 12
                + if frame.normals().is_some() { 12 } else { 0 }
                + if frame.uvs().is_some() { 8 } else { 0 }
                + if frame.colors().is_some() { 16 } else { 0 };
            sizes.push(
                (per_vertex * frame.vertex_count() + 12 * frame.triangle_count() + 64) as u64,
            );
            if k == 0 {
                continue;
            }
            let current = segment_base.as_ref().unwrap_or(&base);
            let joins = layout != SequenceLayout::NodePerFrame
                && current.triangle_count() > 0
                && topology_difference(current, &frame).is_none();
            match segments.last_mut() {
                Some(segment) if joins => segment.end = k + 1,
                _ => {
                    segments.push(k..k + 1);
                    segment_base = Some(frame.clone().into_owned());
                }
            }
            if layout == SequenceLayout::NodePerFrame || !same {
                continue;
            }
            if let Some(message) = topology_difference(&base, &frame) {
                if layout == SequenceLayout::MorphTargets {
                    return Err(IoError::malformed(
                        path,
                        format!("frame {k}"),
                        format!("{message} (morph targets need the topology of frame 0)"),
                    ));
                }
                same = false;
            }
        }
        Ok(Self {
            morph: layout != SequenceLayout::NodePerFrame && same,
            normals,
            sizes,
            segments,
        })
    }

    /// The segments of frames `run`, cut to it and counted from its first frame.
    fn segments_in(&self, run: &Range<usize>) -> Vec<Range<usize>> {
        self.segments
            .iter()
            .filter(|s| s.start < run.end && s.end > run.start)
            .map(|s| s.start.max(run.start) - run.start..s.end.min(run.end) - run.start)
            .collect()
    }
}

/// The glTF key time of every frame: the largest `f32` not above it, checked to be finite,
/// non-negative and strictly increasing (in `f64` and as `f32`).
fn key_times(path: &Path, frames: usize, times: &[f64]) -> Result<Vec<f32>, IoError> {
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
    let mut keys = Vec::with_capacity(frames);
    for (k, &t) in times.iter().enumerate() {
        let element = || format!("frame time {k}");
        if !(t.is_finite() && t >= 0.0) {
            return Err(IoError::malformed(
                path,
                element(),
                format!("{t} is not a finite, non-negative number of seconds"),
            ));
        }
        if k > 0 && t <= times[k - 1] {
            return Err(IoError::malformed(
                path,
                element(),
                format!(
                    "{t} s does not come after frame time {} ({} s): times must increase strictly",
                    k - 1,
                    times[k - 1]
                ),
            ));
        }
        #[expect(clippy::cast_possible_truncation, reason = "rounded down just below")]
        let mut key = t as f32;
        if f64::from(key) > t {
            key = key.next_down();
        }
        if let Some(&previous) = keys.last()
            && key <= previous
        {
            return Err(IoError::malformed(
                path,
                element(),
                format!(
                    "{t} s is too close to frame time {} to be a distinct glTF (f32) key time",
                    k - 1
                ),
            ));
        }
        keys.push(key);
    }
    Ok(keys)
}

/// What differs between the topology of `frame` and `base`, if anything.
fn topology_difference(base: &TriMesh, frame: &TriMesh) -> Option<String> {
    if frame.vertex_count() != base.vertex_count() {
        return Some(format!(
            "has {} vertices, frame 0 has {}",
            frame.vertex_count(),
            base.vertex_count()
        ));
    }
    if frame.triangle_count() != base.triangle_count() {
        return Some(format!(
            "has {} triangles, frame 0 has {}",
            frame.triangle_count(),
            base.triangle_count()
        ));
    }
    frame
        .triangles()
        .iter()
        .zip(base.triangles())
        .position(|(a, b)| a != b)
        .map(|t| {
            format!(
                "triangle {t} is {:?}, in frame 0 {:?}",
                frame.triangles()[t],
                base.triangles()[t]
            )
        })
}

/// The name of frame `k`'s node (node per frame) or morph target (`k ≥ 1`).
fn frame_name(k: usize) -> String {
    format!("frame_{k:06}")
}

/// One accessor's data, ready to be appended to the buffer.
struct Block {
    bytes: Vec<u8>,
    count: usize,
    kind: &'static str,
    component_type: u32,
    target: Option<u32>,
    bounds: Option<(Vec<f32>, Vec<f32>)>,
}

/// `values` (`width` floats per element) as a float accessor block, with per-component
/// `min`/`max` when `bounds`.
fn float_block(values: &[f32], width: usize, target: Option<u32>, bounds: bool) -> Block {
    let kind = match width {
        1 => "SCALAR",
        2 => "VEC2",
        3 => "VEC3",
        _ => "VEC4",
    };
    let bounds = bounds.then(|| {
        let mut min = vec![f32::INFINITY; width];
        let mut max = vec![f32::NEG_INFINITY; width];
        for element in values.chunks_exact(width) {
            for (c, &x) in element.iter().enumerate() {
                min[c] = min[c].min(x);
                max[c] = max[c].max(x);
            }
        }
        (min, max)
    });
    Block {
        bytes: values.iter().flat_map(|x| x.to_le_bytes()).collect(),
        count: values.len() / width,
        kind,
        component_type: FLOAT,
        target,
        bounds,
    }
}

fn vec3_block(values: &[Vec3], target: Option<u32>, bounds: bool) -> Block {
    let flat: Vec<f32> = values.iter().flat_map(|v| v.to_array()).collect();
    float_block(&flat, 3, target, bounds)
}

fn index_block(triangles: &[[u32; 3]]) -> Block {
    Block {
        bytes: triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect(),
        count: triangles.len() * 3,
        kind: "SCALAR",
        component_type: UNSIGNED_INT,
        target: Some(ELEMENT_ARRAY_BUFFER),
        bounds: None,
    }
}

/// glTF wants unit normals: zero or non-finite ones become +z (as in the static writer).
fn unit_normals(normals: &[Vec3]) -> Vec<Vec3> {
    normals
        .iter()
        .map(|v| v.try_normalize().unwrap_or(Vec3::Z))
        .collect()
}

/// Where the buffer's bytes go: nowhere (the layout pass), a vector, or the output file.
trait Sink {
    /// Appends `bytes`.
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError>;
}

/// Counts the bytes (the layout pass).
struct Counted(usize);

impl Sink for Counted {
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.0 += bytes.len();
        Ok(())
    }
}

impl Sink for Vec<u8> {
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.extend_from_slice(bytes);
        Ok(())
    }
}

/// Writes straight into the output (the byte pass of a `.glb`).
struct Stream<'a> {
    out: &'a mut dyn Write,
    path: &'a Path,
    written: usize,
}

impl Sink for Stream<'_> {
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.written += bytes.len();
        self.out
            .write_all(bytes)
            .map_err(|e| IoError::os(self.path, e))
    }
}

/// A buffer view of the document (buffer 0), kept compact until the JSON is written: a long
/// sequence has several per frame, and a `serde_json::Value` map each would grow the run's
/// memory with its length.
#[derive(serde::Serialize)]
#[serde(rename_all = "camelCase")]
struct ViewJson {
    buffer: u32,
    byte_offset: usize,
    byte_length: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    target: Option<u32>,
}

/// An accessor of the document (one per buffer view), compact as [`ViewJson`].
#[derive(serde::Serialize)]
#[serde(rename_all = "camelCase")]
struct AccessorJson {
    buffer_view: usize,
    component_type: u32,
    count: usize,
    #[serde(rename = "type")]
    kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    min: Option<Vec<f32>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    max: Option<Vec<f32>>,
}

/// The buffer views and accessors under construction (one buffer, 4-byte aligned views: every
/// component is 4 bytes); the bytes go to a [`Sink`].
struct Builder<'s> {
    sink: &'s mut dyn Sink,
    len: usize,
    views: Vec<ViewJson>,
    accessors: Vec<AccessorJson>,
}

impl<'s> Builder<'s> {
    fn new(sink: &'s mut dyn Sink) -> Self {
        Self {
            sink,
            len: 0,
            views: Vec::new(),
            accessors: Vec::new(),
        }
    }

    /// Appends `block` as a buffer view and an accessor; returns the accessor index.
    fn push(&mut self, block: Block) -> Result<usize, IoError> {
        let offset = self.len;
        self.sink.put(&block.bytes)?;
        self.len += block.bytes.len();
        self.views.push(ViewJson {
            buffer: 0,
            byte_offset: offset,
            byte_length: block.bytes.len(),
            target: block.target,
        });
        let (min, max) = block.bounds.unzip();
        self.accessors.push(AccessorJson {
            buffer_view: self.views.len() - 1,
            component_type: block.component_type,
            count: block.count,
            kind: block.kind,
            min,
            max,
        });
        Ok(self.accessors.len() - 1)
    }

    /// Appends the attributes of `mesh` and its indices (unless `shared_indices` names an
    /// accessor holding the same triangles); returns the primitive's JSON and its index
    /// accessor.
    fn primitive(
        &mut self,
        mesh: &TriMesh,
        with_normals: bool,
        shared_indices: Option<usize>,
    ) -> Result<(Value, usize), IoError> {
        let mut attributes = Map::new();
        let position = self.push(vec3_block(&mesh.positions_f32(), Some(ARRAY_BUFFER), true))?;
        attributes.insert("POSITION".into(), json!(position));
        if with_normals && let Some(normals) = mesh.normals() {
            let normal = self.push(vec3_block(
                &unit_normals(normals),
                Some(ARRAY_BUFFER),
                false,
            ))?;
            attributes.insert("NORMAL".into(), json!(normal));
        }
        if let Some(uvs) = mesh.uvs() {
            let flat: Vec<f32> = uvs.iter().flat_map(|v| v.to_array()).collect();
            let uv = self.push(float_block(&flat, 2, Some(ARRAY_BUFFER), false))?;
            attributes.insert("TEXCOORD_0".into(), json!(uv));
        }
        if let Some(colors) = mesh.colors() {
            let flat: Vec<f32> = colors
                .iter()
                .flat_map(|c| c.map(|x| x.clamp(0.0, 1.0)))
                .collect();
            let color = self.push(float_block(&flat, 4, Some(ARRAY_BUFFER), false))?;
            attributes.insert("COLOR_0".into(), json!(color));
        }
        let indices = match shared_indices {
            Some(i) => i,
            None => self.push(index_block(mesh.triangles()))?,
        };
        Ok((
            json!({"attributes": attributes, "indices": indices, "mode": TRIANGLES}),
            indices,
        ))
    }

    /// Appends an animation sampler's key times and values; returns the sampler's JSON.
    fn sampler(&mut self, keys: &[f32], values: &[f32], width: usize) -> Result<Value, IoError> {
        let input = self.push(float_block(keys, 1, None, true))?;
        let output = self.push(float_block(values, width, None, false))?;
        Ok(json!({"input": input, "output": output, "interpolation": "STEP"}))
    }

    /// The document around `nodes`, `meshes` and one animation.
    fn document(
        self,
        nodes: Vec<Value>,
        meshes: Vec<Value>,
        samplers: Vec<Value>,
        channels: Vec<Value>,
    ) -> Document {
        Document {
            asset: json!({"version": "2.0", "generator": "trisplat"}),
            scene: 0,
            scenes: json!([{"nodes": [0]}]),
            nodes,
            meshes,
            animations: json!([{"name": SEQUENCE_NAME, "samplers": samplers, "channels": channels}]),
            accessors: self.accessors,
            buffer_views: self.views,
            buffers: json!([{"byteLength": self.len}]),
        }
    }
}

/// The glTF JSON of a sequence, serialised straight from its parts: the accessors and buffer
/// views (several per frame) stay compact structs instead of becoming one `Value` tree.
#[derive(serde::Serialize)]
#[serde(rename_all = "camelCase")]
struct Document {
    asset: Value,
    scene: u32,
    scenes: Value,
    nodes: Vec<Value>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    meshes: Vec<Value>,
    animations: Value,
    accessors: Vec<AccessorJson>,
    buffer_views: Vec<ViewJson>,
    buffers: Value,
}

/// The morph targets of frames `run` against `base` (their topology already checked): each
/// frame's `POSITION` deltas (relative to the base as stored in f32, so base + delta is the
/// frame), and `NORMAL` deltas when `base_normals` is given.
fn morph_targets(
    builder: &mut Builder<'_>,
    path: &Path,
    frames: &dyn FrameSource,
    base: &TriMesh,
    run: Range<usize>,
    base_normals: Option<&[Vec3]>,
) -> Result<Vec<Value>, IoError> {
    let mut targets = Vec::with_capacity(run.len());
    for k in run {
        let frame = frames.frame(k)?;
        let flat: Vec<f32> = frame
            .positions()
            .par_iter()
            .zip(base.positions())
            .flat_map_iter(|(p, q)| {
                (0..3).map(move |c| {
                    #[expect(
                        clippy::cast_possible_truncation,
                        reason = "f32 storage; overflow is checked below"
                    )]
                    let d = (p[c] - f64::from(q[c] as f32)) as f32;
                    d
                })
            })
            .collect();
        if let Some(i) = flat.iter().position(|d| !d.is_finite()) {
            return Err(IoError::malformed(
                path,
                format!("frame {k} vertex {}", i / 3),
                "the offset from its base frame overflows f32",
            ));
        }
        let mut target = Map::new();
        let positions = builder.push(float_block(&flat, 3, Some(ARRAY_BUFFER), true))?;
        target.insert("POSITION".into(), json!(positions));
        if let (Some(n0), Some(nk)) = (base_normals, frame.normals()) {
            let d: Vec<Vec3> = unit_normals(nk)
                .iter()
                .zip(n0)
                .map(|(a, b)| *a - *b)
                .collect();
            let normals = builder.push(vec3_block(&d, Some(ARRAY_BUFFER), false))?;
            target.insert("NORMAL".into(), json!(normals));
        }
        targets.push(Value::Object(target));
    }
    Ok(targets)
}

/// Gives `mesh` (whose primitive is `primitive`) the morph targets of frames `first + 1..`
/// (`targets` of them), named by frame; returns the STEP weights of keys `first..`: all 0 at
/// the first, then target `j - 1` alone at weight 1 at key `first + j`.
fn with_targets(
    mesh: &mut Value,
    primitive: &mut Value,
    targets: Vec<Value>,
    first: usize,
) -> Vec<f32> {
    let n = targets.len();
    primitive["targets"] = json!(targets);
    mesh["weights"] = json!(vec![0.0f32; n]);
    mesh["extras"] =
        json!({"targetNames": (first + 1..=first + n).map(frame_name).collect::<Vec<_>>()});
    let mut weights = vec![0.0f32; (n + 1) * n];
    for j in 1..=n {
        weights[j * n + (j - 1)] = 1.0;
    }
    weights
}

/// The morph-target layout (topology already checked), frame by frame.
fn build_morph_targets(
    path: &Path,
    frames: &dyn FrameSource,
    keys: &[f32],
    with_normals: bool,
    sink: &mut dyn Sink,
) -> Result<Document, IoError> {
    let base = frames.frame(0)?;
    let mut builder = Builder::new(sink);
    let (mut primitive, _) = builder.primitive(&base, with_normals, None)?;
    let base_normals = if with_normals {
        base.normals().map(unit_normals)
    } else {
        None
    };
    let count = frames.frame_count();
    let targets = morph_targets(
        &mut builder,
        path,
        frames,
        &base,
        1..count,
        base_normals.as_deref(),
    )?;
    let mut mesh = json!({"name": SEQUENCE_NAME});
    let (sampler, channel) = if targets.is_empty() {
        let sampler = builder.sampler(keys, &[1.0; 3], 3)?;
        (
            sampler,
            json!({"sampler": 0, "target": {"node": 0, "path": "scale"}}),
        )
    } else {
        let weights = with_targets(&mut mesh, &mut primitive, targets, 0);
        let sampler = builder.sampler(keys, &weights, 1)?;
        (
            sampler,
            json!({"sampler": 0, "target": {"node": 0, "path": "weights"}}),
        )
    };
    mesh["primitives"] = json!([primitive]);
    let node = json!({"name": SEQUENCE_NAME, "mesh": 0});
    Ok(builder.document(vec![node], vec![mesh], vec![sampler], vec![channel]))
}

/// The node-per-segment layout (one node per frame when every segment is one frame), segment
/// by segment.
fn build_segments(
    path: &Path,
    frames: &dyn FrameSource,
    keys: &[f32],
    segments: &[Range<usize>],
    with_normals: bool,
    sink: &mut dyn Sink,
) -> Result<Document, IoError> {
    let mut builder = Builder::new(sink);
    let mut nodes =
        vec![json!({"name": SEQUENCE_NAME, "children": (1..=segments.len()).collect::<Vec<_>>()})];
    let mut meshes = Vec::new();
    let mut samplers = Vec::with_capacity(segments.len());
    let mut channels = Vec::with_capacity(segments.len());
    // The index accessor of the last segment with a mesh, shared while the triangles repeat.
    let mut last_indices: Option<(Vec<[u32; 3]>, usize)> = None;
    for (s, segment) in segments.iter().enumerate() {
        let base = frames.frame(segment.start)?;
        let mut node = json!({"name": frame_name(segment.start)});
        let mut weights = None;
        if base.triangle_count() > 0 {
            let shared = last_indices
                .as_ref()
                .filter(|(triangles, _)| triangles.as_slice() == base.triangles())
                .map(|(_, accessor)| *accessor);
            // A one-frame segment keeps its normals; a longer one only when every frame
            // has them (its targets carry their deltas).
            let normals = segment.len() == 1 || with_normals;
            let (mut primitive, indices) = builder.primitive(&base, normals, shared)?;
            if shared.is_none() {
                last_indices = Some((base.triangles().to_vec(), indices));
            }
            let mut mesh = json!({"name": frame_name(segment.start)});
            if segment.len() > 1 {
                let base_normals = if with_normals {
                    base.normals().map(unit_normals)
                } else {
                    None
                };
                let targets = morph_targets(
                    &mut builder,
                    path,
                    frames,
                    &base,
                    segment.start + 1..segment.end,
                    base_normals.as_deref(),
                )?;
                weights = Some(with_targets(
                    &mut mesh,
                    &mut primitive,
                    targets,
                    segment.start,
                ));
            }
            mesh["primitives"] = json!([primitive]);
            meshes.push(mesh);
            node["mesh"] = json!(meshes.len() - 1);
        }
        let shown = if s == 0 { 1.0f32 } else { 0.0 };
        node["scale"] = json!([shown, shown, shown]);
        nodes.push(node);
        // Visible (1) from its first key to the next segment's, hidden (0) elsewhere.
        let mut times = Vec::with_capacity(3);
        let mut scales: Vec<f32> = Vec::with_capacity(9);
        if segment.start > 0 {
            times.push(keys[0]);
            scales.extend([0.0; 3]);
        }
        times.push(keys[segment.start]);
        scales.extend([1.0; 3]);
        if let Some(&next) = keys.get(segment.end) {
            times.push(next);
            scales.extend([0.0; 3]);
        }
        samplers.push(builder.sampler(&times, &scales, 3)?);
        channels.push(
            json!({"sampler": samplers.len() - 1, "target": {"node": s + 1, "path": "scale"}}),
        );
        if let Some(weights) = weights {
            samplers.push(builder.sampler(&keys[segment.clone()], &weights, 1)?);
            channels.push(
                json!({"sampler": samplers.len() - 1, "target": {"node": s + 1, "path": "weights"}}),
            );
        }
    }
    Ok(builder.document(nodes, meshes, samplers, channels))
}

/// Writes the document and a buffer of `bin_len` bytes, produced by `fill` into the sink it is
/// given, as `.glb` (JSON chunk padded with spaces, binary chunk with zeros, both to 4 bytes).
fn write_glb(
    path: &Path,
    doc: &Document,
    bin_len: usize,
    fill: impl Fn(&mut dyn Sink) -> Result<(), IoError>,
) -> Result<(), IoError> {
    let mut json = serde_json::to_vec(doc).map_err(|e| IoError::os(path, e.into()))?;
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let padding = (4 - bin_len % 4) % 4;
    let padded = bin_len + padding;
    let total = 12 + 8 + json.len() + 8 + padded;
    let too_big = || IoError::Unsupported {
        path: path.to_path_buf(),
        what: format!("a {total}-byte GLB (the format holds at most 4 GiB)"),
    };
    let total32 = u32::try_from(total).map_err(|_| too_big())?;
    let json_len = u32::try_from(json.len()).map_err(|_| too_big())?;
    let bin_len32 = u32::try_from(padded).map_err(|_| too_big())?;
    write_atomically(path, |w| {
        let mut put = |bytes: &[u8]| w.write_all(bytes).map_err(|e| IoError::os(path, e));
        put(b"glTF")?;
        put(&2u32.to_le_bytes())?;
        put(&total32.to_le_bytes())?;
        put(&json_len.to_le_bytes())?;
        put(b"JSON")?;
        put(&json)?;
        put(&bin_len32.to_le_bytes())?;
        put(b"BIN\0")?;
        let mut stream = Stream {
            out: &mut *w,
            path,
            written: 0,
        };
        fill(&mut stream)?;
        if stream.written != bin_len {
            return Err(IoError::malformed(
                path,
                "buffer",
                format!(
                    "the frames gave {} bytes on the second reading, {bin_len} on the first \
                     (a frame changed while the sequence was written)",
                    stream.written
                ),
            ));
        }
        w.write_all(&[0u8; 3][..padding])
            .map_err(|e| IoError::os(path, e))
    })
}

/// Writes the document as `.gltf` text with the buffer embedded as a base64 data URI.
fn write_gltf(path: &Path, mut doc: Document, bin: &[u8]) -> Result<(), IoError> {
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bin)
    );
    doc.buffers = json!([{"byteLength": bin.len(), "uri": uri}]);
    write_atomically(path, |w| {
        serde_json::to_writer(&mut *w, &doc).map_err(|e| IoError::os(path, e.into()))
    })
}
