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

/// Everything [`super::write_sequence_with`] takes besides the frames and their times.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SequenceOptions {
    /// Morph targets, one node per run of one topology, or one node per frame.
    pub layout: SequenceLayout,
    /// Plain, quantised, or quantised and compressed.
    pub compression: GltfCompression,
}
