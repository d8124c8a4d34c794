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
//! error). The main job assembles each method's `.glb` this way from its per-frame PLY
//! files, or, for a carried mesh, from a source that places each frame again from its key
//! (`pipeline`'s `carried_frames`), so no frame file is read.
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
//! **Quantisation and compression** ([`GltfCompression`], [`write_sequence_with`]; the plain
//! functions above write [`GltfCompression::None`], the form every glTF reader plays):
//!
//! - `Quantize` (`KHR_mesh_quantization`, required): each mesh's positions are integers `q` on
//!   a grid, `SHORT` (not normalised), each element padded to 8 bytes (`byteStride` 8, the 4-byte
//!   vertex alignment); its morph targets' `POSITION` deltas are differences of those integers,
//!   `SHORT` too, so base + delta is exactly frame k's grid point. The grid's step is the
//!   bounding-box diagonal of every vertex of every frame divided by
//!   [`POSITION_STEPS_PER_DIAGONAL`] (16384), its origin the centre of the segment's own box
//!   over its frames; the mesh sits on a leaf node (`<name>_mesh`) whose `translation` is that
//!   origin and whose uniform `scale` is the step (both exactly the `f32` values quantised
//!   against), under the node the scale (visibility) track animates; the `weights` track
//!   targets the leaf. A vertex is within half a step per axis of its true place: at most
//!   `sqrt(3) / 2 / 16384 = 5.3e-5` of the diagonal (0.016 mm on a 0.3 m head), below the
//!   1e-4 asked; three.js measured 5.1-5.5e-5 of each frame's own diagonal on the LAM fixture.
//!   A segment's box is at most one diagonal across, so `|q| ≤ 8193` and deltas fit `SHORT`
//!   with room to spare. Normals are normalised `BYTE` (`round(127 n)`, stride 4), normal
//!   deltas the difference of two such, clamped to ±127 (a component that changes by more than
//!   1 is cut; viewers normalise the morphed normal). Indices are `u16` below 65,535 vertices,
//!   else `u32`. Texture coordinates, colours and animation data stay `f32`.
//! - `Meshopt` (`EXT_meshopt_compression` and `KHR_mesh_quantization`, both required; the
//!   default of `extract` and `convert`): the same views, each compressed by meshoptimizer
//!   (the `meshopt` crate) in isolation: vertex attributes, morph deltas and animation key
//!   times and values in ATTRIBUTES mode (vertex codec version 0, header `0xa0`, as the
//!   extension specifies; filter NONE), indices in TRIANGLES mode (index codec version 1,
//!   header `0xe1`; the codec keeps each triangle and its winding, not always its first
//!   corner). The compressed bytes are buffer 0 (the GLB binary chunk, or the `.gltf` data
//!   URI), each view 4-byte aligned; the views point at buffer 1, a fallback buffer with no data
//!   (`byteLength` of the uncompressed layout, `"fallback": true`), which the extension allows
//!   only when it is required, so no uncompressed copy is stored. A compressed `.glb` is
//!   built in one pass into an unnamed spool file beside the output (its length is known only
//!   at the end), then copied after the JSON chunk: frames are read twice (survey, bytes), not
//!   three times.
//!
//! **Morph basis** ([`MorphBasis`], the library's default with quantised storage; on the
//! command line the default of `extract` and `merge` for a file whose one-target-per-frame
//! deltas exceed [`MorphBasis::min_payload`], 300 MB there; module `basis`): a
//! run of three frames or more without normal targets is stored as a few basis shapes
//! instead of one target per frame. Its base is its first frame on a grid twice as fine
//! (60,000 steps per diagonal: the base is its only position data), its morph targets
//! `basis_000`, ... are `SHORT` vectors (each in 1/16 grid steps at its largest weight), and its
//! STEP `weights` track gives each frame a weight per vector (`f32`). The vectors are the run's
//! principal components (module `pca`: a sketch of every frame, its frames × frames Gram matrix
//! and leading eigenvectors, the vectors built from the full frames, three streaming passes),
//! truncated at the smallest of a few ranks whose every frame, weighted by least squares on the
//! vectors as stored (`f32` weights), has every vertex within the tolerance; a frame still over
//! it adds its residual as a vector. The
//! tolerance is a fraction of the run's smallest frame diagonal ([`MorphBasis::tolerance`],
//! default 8e-5, measured as stored, against the 1e-4 the glTF clients are checked with); a run whose basis
//! would need more than [`MorphBasis::max_components`] vectors (default 128) or as many as
//! it has frames after its first keeps one target per frame. Every run's basis size and
//! measured largest error are returned by [`write_sequence_parts_summarised`]. On LAM's
//! 973-frame track it makes the TSDF `.glb` 26.5 MB instead of 178.1 (110 vectors;
//! docs/benchmarks.md). `Quantize` lays the buffer out
//! in two passes, so it fits each basis twice; `None` keeps one `f32` target per frame.
//!
//! Validity: outputs of both layouts (`.glb` and `.gltf`, with and without normals, one and
//! many frames) were checked with the Khronos glTF-Validator 2.0.0-dev.3.10 (npm
//! `gltf-validator`): 0 errors, 0 warnings; the only message is an info, `NODE_EMPTY`, for
//! the node of a frame without triangles. `trisplat convert` output of 100 frames of 20,000
//! vertices, `.glb` and `.gltf`: 0 errors, 0 warnings, 0 infos. Compressed files: 0 errors,
//! 0 warnings, two infos (the validator cannot decode `EXT_meshopt_compression`, and sees
//! buffer 0 referenced only from the extension). CI runs that validator and three.js's
//! GLTFLoader + AnimationMixer on extract's files (`tests/reference/gltf_clients`);
//! `tests/tests/io_gltf_quantized.rs` decodes the compressed views with meshoptimizer's own
//! decoder and evaluates every frame; `tests/tests/io_gltf_sequence.rs` checks the structural
//! rules that validator enforces
//! and these files could break: views inside the buffer and 4-byte aligned, accessors inside
//! their views, exact `min`/`max` where required, view targets, index ranges, unit normals,
//! morph target counts, the node tree, key times and sampler output sizes.

mod basis;
mod blocks;
mod builder;
mod codec;
mod container;
mod eigen;
mod layouts;
mod options;
mod pca;
mod quantize;
mod sink;
mod source;
mod survey;

use std::path::{Path, PathBuf};

use self::builder::{Builder, Document};
use self::container::{write_glb, write_glb_spooled, write_gltf};
use self::layouts::{Context, Segment, build_morph_targets, build_segments};
pub use self::options::{
    DEFAULT_MORPH_BASIS_MAX_COMPONENTS, DEFAULT_MORPH_BASIS_MIN_PAYLOAD,
    DEFAULT_MORPH_BASIS_TOLERANCE, GltfCompression, MorphBasis, SegmentSummary, SequenceLayout,
    SequenceOptions, SequenceSummary,
};
pub use self::quantize::POSITION_STEPS_PER_DIAGONAL;
use self::sink::{Counted, Sink, Spool};
use self::source::FrameRun;
pub use self::source::{FrameFiles, FrameSource};
pub(crate) use self::survey::key_times;
use self::survey::{Survey, split};
use super::error::IoError;
use super::format::Format;
use crate::mesh::TriMesh;

/// Writes `frames` (shown at `frame_times` seconds, strictly increasing, same length) as one
/// animated glTF/GLB (format from the extension), atomically, as plain glTF 2.0
/// ([`GltfCompression::None`]). See the module docs for the layouts; [`write_sequence_with`]
/// chooses the storage too.
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
/// frames (a `.gltf` embeds its buffer as base64 text and holds it in memory). Plain glTF 2.0
/// ([`GltfCompression::None`]).
///
/// # Errors
/// As [`write_mesh_sequence`], and the source's errors.
pub fn write_sequence(
    path: &Path,
    frames: &dyn FrameSource,
    frame_times: &[f64],
    layout: SequenceLayout,
) -> Result<(), IoError> {
    let options = SequenceOptions {
        layout,
        compression: GltfCompression::None,
        morph_basis: MorphBasis::OFF,
    };
    write_sequence_with(path, frames, frame_times, &options)
}

/// [`write_sequence`] with the storage chosen too (quantised, compressed).
///
/// # Errors
/// As [`write_mesh_sequence`], and the source's errors.
pub fn write_sequence_with(
    path: &Path,
    frames: &dyn FrameSource,
    frame_times: &[f64],
    options: &SequenceOptions,
) -> Result<(), IoError> {
    let format = Format::from_path(path)?;
    if !matches!(format, Format::Glb | Format::Gltf) {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: "a mesh sequence is written as .glb or .gltf".into(),
        });
    }
    let keys = key_times(path, frames.frame_count(), frame_times)?;
    let mut survey = survey(path, frames, options)?;
    let segments = segments(&mut survey, 0..frames.frame_count());
    let job = Job {
        path,
        frames,
        keys: &keys,
        survey: &survey,
        segments: &segments,
        options,
    };
    match format {
        Format::Glb => job.write_glb(None).map(|_| ()),
        _ => job.write_gltf().map(|_| ()),
    }
}

/// The survey of `frames` for `options`: with the morph basis's sketch when a basis is
/// fitted (asked for, quantised, over its payload, no normal targets).
fn survey(
    path: &Path,
    frames: &dyn FrameSource,
    options: &SequenceOptions,
) -> Result<Survey, IoError> {
    let sketch = options.morph_basis.enabled()
        && options.compression.quantizes()
        && options.layout != SequenceLayout::NodePerFrame;
    let mut survey = Survey::of(path, frames, options.layout, sketch)?;
    if survey.normals || !options.morph_basis.applies_to(survey.target_payload) {
        survey.sketch = Vec::new();
    }
    Ok(survey)
}

/// The segments of `survey` within frames `run`, counted from its first frame; they take the
/// survey's sketch of their frames (left empty there).
fn segments(survey: &mut Survey, run: std::ops::Range<usize>) -> Vec<Segment> {
    let spans = survey.segments_in(&run);
    spans
        .into_iter()
        .map(|(frames, bounds, diagonal)| {
            let sketch = survey
                .sketch
                .get_mut(frames.start + run.start..frames.end + run.start)
                .map(|s| s.iter_mut().map(std::mem::take).collect())
                .unwrap_or_default();
            Segment {
                frames,
                bounds,
                diagonal,
                sketch: std::cell::Cell::new(sketch),
            }
        })
        .collect()
}

/// One file to write: frames, their keys and segments, the storage.
struct Job<'a> {
    path: &'a Path,
    frames: &'a dyn FrameSource,
    keys: &'a [f32],
    survey: &'a Survey,
    segments: &'a [Segment],
    options: &'a SequenceOptions,
}

impl Job<'_> {
    /// The document, its buffer going to `sink`, and each segment's summary.
    fn build(&self, sink: &mut dyn Sink) -> Result<(Document, Vec<SegmentSummary>), IoError> {
        let builder = Builder::new(sink, self.path, self.options.compression);
        let mut ctx = Context {
            path: self.path,
            frames: self.frames,
            keys: self.keys,
            diagonal: self.survey.diagonal,
            with_normals: self.survey.normals,
            basis: self.options.morph_basis,
            basis_applies: self
                .options
                .morph_basis
                .applies_to(self.survey.target_payload),
            summaries: Vec::with_capacity(self.segments.len()),
        };
        let doc = match (self.survey.morph, self.segments.first()) {
            (true, Some(segment)) => build_morph_targets(&mut ctx, segment, builder),
            _ => build_segments(&mut ctx, self.segments, builder),
        }?;
        Ok((doc, ctx.summaries))
    }

    /// Writes the `.glb`: plain or quantised in two passes (lay out, then stream; a basis is
    /// fitted in each), compressed through a spool. With `limit`, a compressed buffer over it
    /// is not written and `None` is returned; else the segments' summaries.
    fn write_glb(&self, limit: Option<u64>) -> Result<Option<Vec<SegmentSummary>>, IoError> {
        if self.options.compression == GltfCompression::Meshopt {
            let mut spool = Spool::beside(self.path)?;
            let (doc, summaries) = self.build(&mut spool)?;
            if limit.is_some_and(|limit| spool.len as u64 > limit) {
                return Ok(None);
            }
            write_glb_spooled(self.path, &doc, spool)?;
            Ok(Some(summaries))
        } else {
            let mut counted = Counted(0);
            let (doc, summaries) = self.build(&mut counted)?;
            write_glb(self.path, &doc, counted.0, |sink| {
                self.build(sink).map(|_| ())
            })?;
            Ok(Some(summaries))
        }
    }

    /// Writes the `.gltf` (its buffer in memory); returns the segments' summaries.
    fn write_gltf(&self) -> Result<Vec<SegmentSummary>, IoError> {
        let mut bin = Vec::new();
        let (doc, summaries) = self.build(&mut bin)?;
        write_gltf(self.path, doc, &bin)?;
        Ok(summaries)
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
/// Plain glTF 2.0 ([`GltfCompression::None`]).
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
    let options = SequenceOptions {
        layout,
        compression: GltfCompression::None,
        morph_basis: MorphBasis::OFF,
    };
    write_sequence_parts_with(path, frames, frame_times, &options, max_bytes)
}

/// [`write_sequence_parts`] with the storage chosen too. Parts are cut by each frame's plain
/// size (a bound of its quantised and compressed size); compressed, the whole sequence is
/// first tried as one file, which is kept when its buffer fits in `max_bytes`.
///
/// # Errors
/// As [`write_sequence_parts`].
pub fn write_sequence_parts_with(
    path: &Path,
    frames: &dyn FrameSource,
    frame_times: &[f64],
    options: &SequenceOptions,
    max_bytes: u64,
) -> Result<Vec<PathBuf>, IoError> {
    write_sequence_parts_summarised(path, frames, frame_times, options, max_bytes)
        .map(|summary| summary.parts)
}

/// [`write_sequence_parts_with`], returning what each run of one topology became too (its
/// morph basis, its largest error; [`SequenceSummary`]), for a report.
///
/// # Errors
/// As [`write_sequence_parts`].
pub fn write_sequence_parts_summarised(
    path: &Path,
    frames: &dyn FrameSource,
    frame_times: &[f64],
    options: &SequenceOptions,
    max_bytes: u64,
) -> Result<SequenceSummary, IoError> {
    if Format::from_path(path)? != Format::Glb {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: "a sequence split into parts is written as .glb".into(),
        });
    }
    let keys = key_times(path, frames.frame_count(), frame_times)?;
    let mut survey = survey(path, frames, options)?;
    let runs = split(path, &survey.sizes, max_bytes)?;
    let whole = segments(&mut survey, 0..frames.frame_count());
    let job = Job {
        path,
        frames,
        keys: &keys,
        survey: &survey,
        segments: &whole,
        options,
    };
    let one_file = if runs.len() == 1 {
        job.write_glb(None)?
    } else if options.compression == GltfCompression::Meshopt {
        // The compressed buffer is usually far below the plain bound: try one file first.
        job.write_glb(Some(max_bytes))?
    } else {
        None
    };
    if let Some(segments) = one_file {
        return Ok(SequenceSummary {
            parts: vec![path.to_path_buf()],
            segments,
            target_payload: survey.target_payload,
        });
    }
    let stem = path
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let mut written = Vec::with_capacity(runs.len());
    let mut summaries = Vec::new();
    for (i, run) in runs.into_iter().enumerate() {
        let part = path.with_file_name(format!("{stem}_part{:03}.glb", i + 1));
        let part_segments = segments(&mut survey, run.clone());
        let part_frames = FrameRun {
            frames,
            run: run.clone(),
        };
        let part_summaries = Job {
            path: &part,
            frames: &part_frames,
            keys: &keys[run.clone()],
            survey: &survey,
            segments: &part_segments,
            options,
        }
        .write_glb(None)?
        .unwrap_or_default();
        summaries.extend(part_summaries.into_iter().map(|mut s| {
            s.frames = s.frames.start + run.start..s.frames.end + run.start;
            s
        }));
        written.push(part);
    }
    Ok(SequenceSummary {
        parts: written,
        segments: summaries,
        target_payload: survey.target_payload,
    })
}
