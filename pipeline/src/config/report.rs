//! Options of the metrics and of what a run writes, with their defaults and the resource
//! limits checked before anything is allocated.

use trisplat_geometry::io::{DEFAULT_MORPH_BASIS_MIN_PAYLOAD, GltfCompression, MorphBasis};
use trisplat_geometry::metrics::Tau;

/// Default points sampled on each mesh for the metrics.
pub const DEFAULT_SAMPLES: usize = 20_000;
/// Absolute F-score threshold when one is asked for without a value of its own (`--tau`
/// given replaces the fraction; input units, 2.5 mm for metres: "Recall@2.5mm"). Library
/// callers that pass [`MetricOptions::tau`] to the metrics' `measure` get it.
pub const DEFAULT_TAU: f64 = 0.0025;
/// Default F-score threshold of the report as a fraction of each frame's ground-truth
/// bounding-box diagonal (0.5%: 1 cm on a 2 m body, 1 mm on a 20 cm head).
pub const DEFAULT_TAU_FRACTION: f64 = 0.005;
/// [`DEFAULT_TAU_FRACTION`] as the command line's default text (clap's `default_value_t`
/// cannot give an `Option` field a default that `--tau` then unsets).
#[cfg(feature = "cli")]
pub(crate) const DEFAULT_TAU_FRACTION_ARG: &str = "0.005";
/// Default of `--max-views`: most TSDF views per frame (each is a depth image rendered and
/// fused every frame: 4,096 of 256² are 1 GiB of depth).
pub const DEFAULT_MAX_VIEWS: usize = 4096;
/// Default of `--max-samples`: most metric samples per mesh (as `sample --max-points`).
pub const DEFAULT_MAX_SAMPLES: usize = 100_000_000;
/// Default of `--max-voxels`: most TSDF voxels across the template's bounding sphere.
pub const DEFAULT_MAX_VOXELS: u64 = 65_536;

/// The metrics against a ground truth (docs/conventions.md §8).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct MetricOptions {
    /// Points sampled on each mesh for the metrics (with --gt).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", default_value_t = DEFAULT_SAMPLES,
        value_parser = super::arg::parse_positive))]
    pub samples: usize,
    /// F-score threshold of the report as a fraction of each frame's ground-truth
    /// bounding-box diagonal [default: 0.005 unless --tau is given]; unset, the absolute
    /// --tau is used.
    // Declared before `tau`: clap adds defaults in declaration order, so `tau`'s (hidden)
    // default is not there yet when this default looks whether --tau was given.
    #[cfg_attr(feature = "cli", arg(long, value_name = "F",
        default_value = DEFAULT_TAU_FRACTION_ARG,
        default_value_if("tau", clap::builder::ArgPredicate::IsPresent, None),
        hide_default_value = true))]
    pub tau_fraction: Option<f64>,
    /// Absolute F-score threshold of the report, in scene units, instead of --tau-fraction
    /// (used only while the fraction is unset).
    #[cfg_attr(feature = "cli", arg(long, value_name = "T", default_value_t = DEFAULT_TAU,
        hide_default_value = true, conflicts_with = "tau_fraction"))]
    pub tau: f64,
    /// Views of each frame's render consistency: every mesh against that frame's Gaussians
    /// from a held-out sphere rig (silhouette IoU, depth error, normal angle; 0: not measured).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N",
        default_value_t = DEFAULT_CONSISTENCY_VIEWS))]
    pub consistency_views: usize,
    /// Width and height of the render-consistency views, pixels.
    #[cfg_attr(feature = "cli", arg(long, value_name = "PX",
        default_value_t = DEFAULT_CONSISTENCY_RESOLUTION,
        value_parser = clap::value_parser!(u32).range(8..=4096)))]
    pub consistency_resolution: u32,
}

/// Views of the main job's per-frame render consistency (`--consistency-views`): fewer and
/// smaller than `trisplat eval`'s 16 of 384², so that a long run pays less for it (its cost
/// and its agreement with eval's rig on the LAM avatar are in docs/benchmarks.md).
pub const DEFAULT_CONSISTENCY_VIEWS: usize = 8;
/// Pixels across of those views (`--consistency-resolution`).
pub const DEFAULT_CONSISTENCY_RESOLUTION: u32 = 192;

impl Default for MetricOptions {
    fn default() -> Self {
        Self {
            samples: DEFAULT_SAMPLES,
            tau_fraction: Some(DEFAULT_TAU_FRACTION),
            tau: DEFAULT_TAU,
            consistency_views: DEFAULT_CONSISTENCY_VIEWS,
            consistency_resolution: DEFAULT_CONSISTENCY_RESOLUTION,
        }
    }
}

impl MetricOptions {
    /// The report's F-score threshold: the fraction of each frame's ground-truth diagonal,
    /// or the absolute `tau` when no fraction is set.
    #[must_use]
    pub fn threshold(&self) -> Tau {
        self.tau_fraction
            .map_or(Tau::Absolute(self.tau), Tau::Fraction)
    }
}

/// One kind of output of the main job (`extract --targets`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum OutputTarget {
    /// `<method>/frame_NNNNNN.ply`, one per frame and method.
    Meshes,
    /// `<method>.glb` (or its parts), the animated sequence.
    Glb,
    /// `report.json`, `report.md`, `report.html` with `thumbnails/`, `error_vs_time.svg` and
    /// `error_vs_time.png`.
    Report,
    /// `<method>.usda`, the sequence as a USD mesh cache (not in the default: text, large).
    Usd,
    /// `<method>_rig.glb`, the template's skin and morph targets moved onto the method's first
    /// key mesh, played by the track (`--topology fixed|adaptive`, a glTF template with a
    /// rig; not in the default: it re-evaluates every frame to measure the rig).
    Rig,
}

impl OutputTarget {
    /// The default outputs (every one but the USD cache).
    pub const ALL: [Self; 3] = [Self::Meshes, Self::Glb, Self::Report];

    /// Whether this output is assembled from the frame files (written for it, then removed
    /// unless [`OutputTarget::Meshes`] is asked too).
    #[must_use]
    pub fn assembled_from_frames(self) -> bool {
        matches!(self, Self::Glb | Self::Usd)
    }
}

impl std::fmt::Display for OutputTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Meshes => "meshes",
            Self::Glb => "glb",
            Self::Report => "report",
            Self::Usd => "usd",
            Self::Rig => "rig",
        })
    }
}

/// What a run writes besides its journal, and how its pictures look.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct OutputOptions {
    /// Colour the vertices of the frame meshes (PLYs and glTF) by their distance to the
    /// ground truth: viridis from 0 (dark purple) to 2 x the frame's F-score threshold tau
    /// (yellow, and beyond). Needs --gt or --gt-sequence; not with --tsdf-colors.
    #[cfg_attr(feature = "cli", arg(long, conflicts_with = "tsdf_colors"))]
    pub error_colors: bool,
    /// The template's axes, for the camera of report.html's pictures (which look at the model
    /// from its front, a little to one side and above): three letters for the directions of x,
    /// y and z as the model sees them, Right/Left, Up/Down, Back/Front (docs/conventions.md
    /// §3 "Axes"). glTF's frame (+Y up, facing +Z) is luf; a Z-up mesh facing -Y (Blender's
    /// front) is lbu. Only the pictures use it.
    #[cfg_attr(feature = "cli", arg(long, value_name = "AXES", default_value = "luf"))]
    pub view_axes: trisplat_splat::Axes,
    /// What to write, comma-separated: meshes (per-frame PLYs), glb (the animated sequence;
    /// its frames are written to assemble it and removed after unless meshes is asked too),
    /// report (report.json, report.md, report.html with its thumbnails, the plot as SVG and
    /// PNG), usd (<method>.usda, a USD mesh cache; not in the default; its frames are written
    /// and removed as for glb), rig (<method>_rig.glb: the template's skin and morph targets
    /// moved onto the first key mesh, animated by the track; needs --topology fixed or
    /// adaptive and a glTF template with a skin or morph targets; not in the default). The run
    /// journal is always written.
    #[cfg_attr(feature = "cli", arg(long, value_enum, value_delimiter = ',', value_name = "LIST",
        num_args = 1.., default_values_t = OutputTarget::ALL))]
    pub targets: Vec<OutputTarget>,
    /// How the glb stores its data: meshopt (the default: positions and morph deltas as
    /// 16-bit integers within 5.3e-5 of the sequence's bounding-box diagonal, normals as
    /// bytes, KHR_mesh_quantization, and every buffer compressed with EXT_meshopt_compression;
    /// three.js and Babylon.js read it), quantize (the integers, uncompressed),
    /// none (plain f32 glTF that every reader plays, about 10-50x larger).
    #[cfg_attr(feature = "cli", arg(long, value_enum, value_name = "KIND",
        default_value_t = GltfCompression::Meshopt))]
    pub gltf_compression: GltfCompression,
    /// The glb's morph basis (meshopt and quantize): each run of frames between key frames
    /// is stored as a few basis shapes and a weight per shape and frame, the fewest (up to
    /// 192, fewer than the run's frames) that put every vertex of every frame within E of its
    /// frame's bounding-box diagonal of its place; a run that needs more keeps one morph
    /// target per frame. 8e-5 (the default; the glTF clients are checked to 1e-4); 0: one
    /// morph target per frame. Fitted only for a glb over --gltf-morph-above. The report
    /// records the basis sizes and the largest error (glb_storage).
    #[cfg_attr(feature = "cli", arg(long, value_name = "E",
        default_value_t = trisplat_geometry::io::DEFAULT_MORPH_BASIS_TOLERANCE,
        value_parser = super::arg::parse_share))]
    pub gltf_morph_tolerance: f64,
    /// The morph basis is fitted only for a glb whose one-morph-target-per-frame position
    /// deltas (quantised, 8 bytes per vertex and frame, before compression) exceed MB
    /// megabytes (default 300: about 100 MB compressed at the worst ratio measured, 3x; on
    /// LAM's track the TSDF glb's 1.2 GB gets a basis, delaunay's 0.28 GB and alpha's do not);
    /// 0: every glb.
    #[cfg_attr(feature = "cli", arg(long, value_name = "MB", default_value_t = DEFAULT_MORPH_ABOVE_MB,
        value_parser = super::arg::parse_share))]
    pub gltf_morph_above: f64,
}

/// The default of `--gltf-morph-above` (megabytes): [`DEFAULT_MORPH_BASIS_MIN_PAYLOAD`].
#[expect(clippy::cast_precision_loss, reason = "300 MB, exact")]
pub const DEFAULT_MORPH_ABOVE_MB: f64 = DEFAULT_MORPH_BASIS_MIN_PAYLOAD as f64 / 1e6;

/// The morph basis of tolerance `tolerance` for glbs over `above_mb` megabytes of
/// one-target-per-frame deltas (`--gltf-morph-tolerance`, `--gltf-morph-above`).
#[must_use]
pub fn morph_basis(tolerance: f64, above_mb: f64) -> MorphBasis {
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "finite and non-negative (parse_share); saturates"
    )]
    let min_payload = (above_mb * 1e6).round() as u64;
    MorphBasis {
        tolerance,
        min_payload,
        ..MorphBasis::default()
    }
}

impl Default for OutputOptions {
    fn default() -> Self {
        Self {
            error_colors: false,
            view_axes: trisplat_splat::Axes::Luf,
            targets: OutputTarget::ALL.to_vec(),
            gltf_compression: GltfCompression::default(),
            gltf_morph_tolerance: trisplat_geometry::io::DEFAULT_MORPH_BASIS_TOLERANCE,
            gltf_morph_above: DEFAULT_MORPH_ABOVE_MB,
        }
    }
}

impl OutputOptions {
    /// The glb's morph basis ([`Self::gltf_morph_tolerance`], [`Self::gltf_morph_above`],
    /// the default vector limit).
    #[must_use]
    pub fn morph_basis(&self) -> MorphBasis {
        morph_basis(self.gltf_morph_tolerance, self.gltf_morph_above)
    }

    /// Whether `target` is among the outputs asked for.
    #[must_use]
    pub fn writes(&self, target: OutputTarget) -> bool {
        self.targets.contains(&target)
    }

    /// Whether the frame files are written: asked for, or an output is assembled from them.
    #[must_use]
    pub fn writes_frame_files(&self) -> bool {
        self.targets
            .iter()
            .any(|t| *t == OutputTarget::Meshes || t.assembled_from_frames())
    }
}

/// Resource limits of the main job, checked before anything is allocated; each raised by its
/// option. They do not change the outputs (a run resumes under other limits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct Limits {
    /// Most TSDF views per frame (--views).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N",
        default_value_t = DEFAULT_MAX_VIEWS))]
    pub max_views: usize,
    /// Most metric samples per mesh (--samples).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N",
        default_value_t = DEFAULT_MAX_SAMPLES))]
    pub max_samples: usize,
    /// Most TSDF voxels across the template's bounding sphere (--voxel).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N",
        default_value_t = DEFAULT_MAX_VOXELS))]
    pub max_voxels: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_views: DEFAULT_MAX_VIEWS,
            max_samples: DEFAULT_MAX_SAMPLES,
            max_voxels: DEFAULT_MAX_VOXELS,
        }
    }
}
