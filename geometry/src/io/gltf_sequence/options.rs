//! What the caller chooses: the layout of a sequence and how its buffer data is stored.

/// Name of the animation, of the morph-target mesh and of the node-per-frame root.
pub(super) const SEQUENCE_NAME: &str = "sequence";

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

/// How the vertex, index and animation data of a sequence is stored (see the module docs,
/// "Quantisation and compression").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum GltfCompression {
    /// Plain glTF 2.0: `f32` positions, normals and morph deltas, `u32` indices. Every glTF
    /// reader plays it; it is the largest (12 bytes per vertex per frame for positions).
    None,
    /// `KHR_mesh_quantization` (required): positions and position deltas as `SHORT` on a grid
    /// of 1/16384 of the sequence's bounding-box diagonal, normals and normal deltas as
    /// normalised `BYTE`; the grid's scale and offset are a leaf node's transform.
    Quantize,
    /// As `Quantize`, and every buffer view compressed with `EXT_meshopt_compression`
    /// (required; vertex and animation data in ATTRIBUTES mode, indices in TRIANGLES mode).
    /// The default: three.js, Babylon.js and gltfpack read it (for a reader without the
    /// extension, such as Blender's importer, write `None`).
    #[default]
    Meshopt,
}

impl GltfCompression {
    /// Whether positions and normals are stored as integers (`KHR_mesh_quantization`).
    #[must_use]
    pub fn quantizes(self) -> bool {
        !matches!(self, Self::None)
    }
}

/// The default [`MorphBasis::tolerance`]: 8e-5 of a frame's bounding-box diagonal. The error
/// is measured on the data as stored (base and vectors quantised, `f32` weights), so the 20%
/// left to the `1e-4` the glTF clients are checked against covers only a viewer's own `f32`
/// evaluation (about 1e-7 of the size).
pub const DEFAULT_MORPH_BASIS_TOLERANCE: f64 = 8e-5;

/// The default [`MorphBasis::max_components`]: 192 (the LAM track's TSDF run needs 110; a
/// vector of a 157,580-vertex mesh holds 1.9 MB while it is built, 0.95 MB as stored).
pub const DEFAULT_MORPH_BASIS_MAX_COMPONENTS: usize = 192;

/// A compact morph basis per run of frames of one topology (see the module docs, "Morph
/// basis"): the run's morph targets are a few basis shapes and each frame is a weighted sum of
/// them, instead of one target per frame. Quantised storage only (`Quantize`, `Meshopt`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MorphBasis {
    /// The largest distance a vertex of any frame may lie from its true place, as a fraction
    /// of the smallest bounding-box diagonal of the run's frames; 0 turns the basis off (one
    /// target per frame). A run whose basis would not meet it within `max_components`
    /// vectors keeps one target per frame.
    pub tolerance: f64,
    /// The most basis vectors a run may have; a run needing more, or as many as it has frames
    /// after its first, keeps one target per frame.
    pub max_components: usize,
    /// A file whose one-target-per-frame position deltas (quantised: 8 bytes per vertex and
    /// frame after a run's first, before compression) are at most this many bytes keeps one
    /// target per frame: the basis is fitted only where that payload is larger (0: wherever
    /// it can be). See [`DEFAULT_MORPH_BASIS_MIN_PAYLOAD`].
    pub min_payload: u64,
}

/// The [`MorphBasis::min_payload`] of `extract` and `merge` (`--gltf-morph-above`): 300 MB.
/// meshoptimizer's codec compressed the LAM track's quantised deltas 3.1x (alpha, 45 MB to
/// 14.7), 3.9x (delaunay) and 6.8x (tsdf), so a file at most this large stays within about
/// 100 MB with one target per frame at the worst of these ratios; a larger one (the TSDF
/// mesh's 1.2 GB) gets the basis (docs/benchmarks.md, "One command").
pub const DEFAULT_MORPH_BASIS_MIN_PAYLOAD: u64 = 300_000_000;

impl Default for MorphBasis {
    fn default() -> Self {
        Self {
            tolerance: DEFAULT_MORPH_BASIS_TOLERANCE,
            max_components: DEFAULT_MORPH_BASIS_MAX_COMPONENTS,
            min_payload: 0,
        }
    }
}

impl MorphBasis {
    /// One morph target per frame (no basis).
    pub const OFF: Self = Self {
        tolerance: 0.0,
        max_components: 0,
        min_payload: 0,
    };

    /// Whether a basis is tried at all.
    #[must_use]
    pub fn enabled(&self) -> bool {
        self.tolerance > 0.0 && self.tolerance.is_finite() && self.max_components > 0
    }

    /// Whether a basis is tried for a file whose one-target-per-frame position deltas take
    /// `payload` bytes ([`Self::min_payload`]).
    #[must_use]
    pub fn applies_to(&self, payload: u64) -> bool {
        self.enabled() && payload > self.min_payload
    }
}

/// Everything [`super::write_sequence_with`] takes besides the frames and their times.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SequenceOptions {
    /// Morph targets, one node per run of one topology, or one node per frame.
    pub layout: SequenceLayout,
    /// Plain, quantised, or quantised and compressed.
    pub compression: GltfCompression,
    /// Quantised storage: a morph basis per run instead of one target per frame (the
    /// default; [`MorphBasis::OFF`] for one target per frame).
    pub morph_basis: MorphBasis,
}

/// What one run of frames of one topology became in the file.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentSummary {
    /// Its frames (indices into the written sequence).
    pub frames: std::ops::Range<usize>,
    /// Its number of basis vectors (morph targets), or `None` when it holds one target per
    /// frame after its first (a run of one frame has none).
    pub basis: Option<usize>,
    /// The largest distance of a vertex of one of its frames from its true place, in the
    /// frames' units: measured for a basis (as stored, `f32` weights), the grid's bound
    /// (half a step per axis) for quantised targets, 0 for plain `f32` storage.
    pub max_error: f64,
    /// Per frame of the run, the largest such distance (measured for a basis, else the bound).
    pub frame_errors: Vec<f64>,
    /// The smallest bounding-box diagonal of its frames (the tolerance's unit).
    pub diagonal: f64,
}

/// What [`super::write_sequence_parts_summarised`] wrote.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SequenceSummary {
    /// The files written, in order.
    pub parts: Vec<std::path::PathBuf>,
    /// Each run of one topology, in frame order (of the whole sequence).
    pub segments: Vec<SegmentSummary>,
    /// The quantised position deltas one morph target per frame would take (8 bytes per
    /// vertex and frame after a run's first): what [`MorphBasis::min_payload`] is compared
    /// with ([`MorphBasis::applies_to`]).
    pub target_payload: u64,
}
