//! Whether each frame is meshed from scratch or one mesh is carried through the track
//! (`--topology`), with the thresholds that start a new key mesh.

use std::fmt;

/// How the meshes of a track relate from frame to frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Topology {
    /// Every frame meshed from scratch: its own vertices and triangles.
    PerFrame,
    /// The track's first frame meshed once (the key); every other frame is that mesh with its
    /// vertices carried by the template's triangles.
    Fixed,
    /// As `fixed`, and a frame whose Gaussians have drifted off the carried mesh
    /// (`--key-hops`) or whose carried triangles are stretched (`--key-stretch`) is meshed
    /// again and starts a new key. The default (docs/conventions.md §10 says why).
    #[default]
    Adaptive,
}

impl Topology {
    /// The name on the command line and in the report.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::PerFrame => "per-frame",
            Self::Fixed => "fixed",
            Self::Adaptive => "adaptive",
        }
    }

    /// Whether a mesh is carried from frame to frame.
    #[must_use]
    pub fn carries(self) -> bool {
        self != Self::PerFrame
    }
}

impl fmt::Display for Topology {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Default [`TopologyOptions::key_hops`]: a new key once 5% of the probe Gaussians hop.
pub const DEFAULT_KEY_HOPS: f64 = 0.05;
/// Default [`TopologyOptions::key_stretch`]: a new key once 2% of the key mesh's area sits in
/// triangles stretched or shrunk more than twofold.
pub const DEFAULT_KEY_STRETCH: f64 = 0.02;
/// Default [`TopologyOptions::key_offset`], in multiples of the mean template edge: a new key
/// once the probe Gaussians' distances to the carried mesh have changed by this much on average.
pub const DEFAULT_KEY_OFFSET: f64 = 0.1;
/// Default [`TopologyOptions::hop_distance`], in multiples of the mean template edge. On LAM
/// (mean edge about 3 mm) 0.1 edges started a key every 3-4 frames for delaunay and alpha
/// although frame 0's meshes carried to frame 300 stayed within 0.07 and 0.13 mm (Chamfer L1)
/// of that frame's own extraction (docs/benchmarks.md, "One mesh through the track").
pub const DEFAULT_HOP_DISTANCE: f64 = 0.5;

/// The topology of a run's meshes and when `adaptive` starts a new key.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct TopologyOptions {
    /// per-frame: mesh every frame from scratch; fixed: mesh the track's first frame and carry
    /// that mesh through every frame (each vertex bound to the template triangle of its
    /// nearest Gaussian: barycentric position and offset along the normal); adaptive (the
    /// default): as fixed, meshing again where the carried mesh drifts from the frame's
    /// Gaussians (docs/conventions.md §10).
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = Topology::Adaptive))]
    pub topology: Topology,
    /// adaptive: start a new key when more than this share of the probe Gaussians hop (move
    /// more than --hop-distance off the carried mesh's triangle they were nearest at the key).
    #[cfg_attr(feature = "cli", arg(long, value_name = "SHARE",
        default_value_t = DEFAULT_KEY_HOPS))]
    pub key_hops: f64,
    /// adaptive: start a new key when more than this share of the key mesh's area is in
    /// triangles whose area grew or shrank more than twofold.
    #[cfg_attr(feature = "cli", arg(long, value_name = "SHARE",
        default_value_t = DEFAULT_KEY_STRETCH))]
    pub key_stretch: f64,
    /// adaptive: start a new key when the probe Gaussians' distances to the carried mesh have
    /// changed since the key by more than this many mean template edges on average (the
    /// surface they make moving off the carried mesh, hop or not).
    #[cfg_attr(feature = "cli", arg(long, value_name = "EDGES",
        default_value_t = DEFAULT_KEY_OFFSET))]
    pub key_offset: f64,
    /// adaptive, tsdf only: start a new key when the probe Gaussians have moved more than this
    /// many mean template edges on average since the key (off unless given). For
    /// `--tsdf-anchor world`, whose voxel grid and camera rig stay fixed in space so that a
    /// frame's own extraction is a new sampling of a surface that moved through them: 0.3
    /// keeps LAM's tsdf within 0.5 mm of each frame's own extraction at a key every 5-10
    /// frames. The default rigid anchor does not need it.
    #[cfg_attr(feature = "cli", arg(long, value_name = "EDGES"))]
    pub key_motion: Option<f64>,
    /// How far (multiples of the mean template edge) a Gaussian's distance to its carried
    /// triangle may change before it counts as hopping.
    #[cfg_attr(feature = "cli", arg(long, value_name = "EDGES",
        default_value_t = DEFAULT_HOP_DISTANCE))]
    pub hop_distance: f64,
}

impl Default for TopologyOptions {
    fn default() -> Self {
        Self {
            topology: Topology::Adaptive,
            key_hops: DEFAULT_KEY_HOPS,
            key_stretch: DEFAULT_KEY_STRETCH,
            key_offset: DEFAULT_KEY_OFFSET,
            key_motion: None,
            hop_distance: DEFAULT_HOP_DISTANCE,
        }
    }
}
