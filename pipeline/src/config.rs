//! What the main job is asked to do: inputs, methods, options and their defaults.

use crate::avatar::GaussianLayout;
use std::fmt;
use std::path::PathBuf;

use trisplat_extract::incremental_delaunay::DEFAULT_HOP_THRESHOLD;
use trisplat_geometry::animation::DEFAULT_FPS;
use trisplat_geometry::metrics::Tau;

/// Default Gaussians per triangle when the pipeline binds them itself.
pub const DEFAULT_PER_TRIANGLE: u32 = 4;
/// Finest default TSDF voxel as a fraction of the template's bounding radius (radius / 128: on
/// the demo avatar, radius / 256 is 4x slower for a 7% lower Chamfer distance). The default
/// voxel is the mean spacing of the Gaussians when that is coarser (a finer grid only follows
/// the rendered discs), at most radius / [`COARSEST_VOXELS_PER_RADIUS`].
pub const DEFAULT_VOXELS_PER_RADIUS: f64 = 128.0;
/// Coarsest default TSDF voxel as a fraction of the template's bounding radius (sparse
/// Gaussians still get a grid of 32 voxels per radius).
pub const COARSEST_VOXELS_PER_RADIUS: f64 = 32.0;
/// Default number of views of the TSDF camera rig (a Fibonacci sphere around each frame).
pub const DEFAULT_VIEWS: usize = 24;
/// Default side of the square TSDF depth images, in pixels.
pub const DEFAULT_RESOLUTION: u32 = 256;
/// Vertical field of view of the TSDF rig, degrees (as `trisplat cameras`).
pub const DEFAULT_FOV_DEG: f64 = 40.0;
/// Default alpha of the alpha-shape method, in multiples of the mean spacing of the Gaussians
/// (mean distance from each rest-pose mean to its nearest other mean). 6, not 3: with the
/// pipeline's self-bound Gaussians (4 per triangle) 3 spacings leaves holes on real templates,
/// while 6 lowers Chamfer L1 against the deformed template at the same cost (docs/benchmarks.md,
/// "Main job (`sweep`)": CesiumMan 6.6e-3 -> 3.4e-3, F-score 0.55 -> 0.72; the LAM head
/// 8.7e-3 -> 1.4e-3, F-score 0.43 -> 0.75; the time is the tetrahedralisation's either way).
pub const DEFAULT_ALPHA_SPACINGS: f64 = 6.0;
/// Default points sampled on each mesh for the metrics.
pub const DEFAULT_SAMPLES: usize = 20_000;
/// Absolute F-score threshold when one is asked for without a value of its own (`--tau`
/// given replaces the fraction; input units, 2.5 mm for metres: "Recall@2.5mm"). Library
/// callers that pass [`ExtractOptions::tau`] to [`crate::report::measure`] get it.
pub const DEFAULT_TAU: f64 = 0.0025;
/// Default F-score threshold of the report as a fraction of each frame's ground-truth
/// bounding-box diagonal (0.5%: 1 cm on a 2 m body, 1 mm on a 20 cm head).
pub const DEFAULT_TAU_FRACTION: f64 = 0.005;
/// [`DEFAULT_TAU_FRACTION`] as the command line's default text (clap's `default_value_t`
/// cannot give an `Option` field a default that `--tau` then unsets).
#[cfg(feature = "cli")]
const DEFAULT_TAU_FRACTION_ARG: &str = "0.005";
/// Opacity of the Gaussians the pipeline binds itself: opaque enough that the rendered
/// alpha passes the TSDF's 0.5 mask on the surface (GaussianAvatars' 0.1 is a starting
/// point for training, not a surface).
pub const BIND_OPACITY: f32 = 0.9;
/// Scale of self-bound Gaussians along their triangle's normal, relative to `bind`'s initial
/// scale: flat discs, so that rendered depth lies on the surface.
pub const BIND_NORMAL_SCALE: f32 = 0.04;
/// In-plane scale of self-bound Gaussians relative to `bind`'s initial scale (which makes
/// neighbours overlap widely): smaller discs fatten silhouettes less, which otherwise pushes
/// the fused surface outward (CesiumMan, 4 per triangle: Chamfer L1 1.6e-2 at 1, 5.8e-3 at
/// 0.4, holes at 0.25).
pub const BIND_TANGENT_SCALE: f32 = 0.4;

/// Parses a positive integer (a count).
#[cfg(feature = "cli")]
fn parse_positive(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("expected a positive integer, got '{s}'")),
    }
}

/// An extraction method.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Render depth maps of the deformed Gaussians from a camera rig and fuse them (TSDF +
    /// marching cubes).
    Tsdf,
    /// Incremental Delaunay of the bound Gaussians: per-chart triangulations in the canonical
    /// domain, lifted each frame.
    Delaunay,
    /// Alpha shape of the deformed Gaussian means.
    Alpha,
}

impl Method {
    /// Every method, in report order.
    pub const ALL: [Self; 3] = [Self::Tsdf, Self::Delaunay, Self::Alpha];

    /// The method's name on the command line and in output file names.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Tsdf => "tsdf",
            Self::Delaunay => "delaunay",
            Self::Alpha => "alpha",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How bound Gaussians follow the template (docs/conventions.md §4).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// GaussianAvatars: rigid frame of the posed triangle plus its scale.
    #[default]
    Binding,
    /// SurFhead/TGA: per-triangle deformation gradient.
    Jacobian,
    /// Linear blend skinning with the glTF skin's weights (the animation must be a skinned
    /// glTF whose rest shape is the template).
    Lbs,
}

impl Mode {
    /// The mode's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Binding => "binding",
            Self::Jacobian => "jacobian",
            Self::Lbs => "lbs",
        }
    }
}

/// Which depth of the rendered Gaussians TSDF fuses (`extract --tsdf-depth`, `tsdf
/// --depth-kind`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum DepthKind {
    /// Alpha-weighted mean depth, normalised by the alpha (3DGS "expected" depth): a blend of
    /// every Gaussian along the ray, pulled toward the ones behind the surface.
    Expected,
    /// The depth of the Gaussian at which the accumulated alpha reaches ½ (2DGS/GOF "median"
    /// depth): the first surface the ray meets. The default: on the LAM head it brings the
    /// TSDF's Chamfer distance to the Gaussians' surface from 7.4 to 5.2 mm.
    #[default]
    Median,
}

impl DepthKind {
    /// The kind's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Expected => "expected",
            Self::Median => "median",
        }
    }
}

/// How each Gaussian's depth varies over its footprint in the depth maps TSDF fuses
/// (`extract --tsdf-splat-depth`, `tsdf --splat-depth`; the renderer's
/// [`trisplat_splat::render::SplatDepth`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum SplatDepthRule {
    /// The camera z of the Gaussian's mean over its whole footprint (3DGS): stepped surfaces.
    Mean,
    /// The depth of the point of highest density on each pixel's ray (RaDe-GS, GOF): a flat
    /// Gaussian gives its own plane. The default: on CesiumMan it brings the TSDF's Chamfer
    /// distance to the deformed template from 5.9 to 3.1 mm.
    #[default]
    Ray,
}

impl SplatDepthRule {
    /// The rule's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Mean => "mean",
            Self::Ray => "ray",
        }
    }
}

impl From<SplatDepthRule> for trisplat_splat::render::SplatDepth {
    fn from(rule: SplatDepthRule) -> Self {
        match rule {
            SplatDepthRule::Mean => Self::Mean,
            SplatDepthRule::Ray => Self::Ray,
        }
    }
}

/// Default of `--max-views`: most TSDF views per frame (each is a depth image rendered and
/// fused every frame: 4,096 of 256² are 1 GiB of depth).
pub const DEFAULT_MAX_VIEWS: usize = 4096;
/// Default of `--max-samples`: most metric samples per mesh (as `sample --max-points`).
pub const DEFAULT_MAX_SAMPLES: usize = 100_000_000;
/// Default of `--max-voxels`: most TSDF voxels across the template's bounding sphere.
pub const DEFAULT_MAX_VOXELS: u64 = 65_536;

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

/// The ground truth of the metrics.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GroundTruth {
    /// Each frame's deformed template (`--gt template`).
    Template,
    /// Each frame's surface of the Gaussians' centres (`--gt gaussians`): the template as
    /// stored with vertex `i` at the deformed centre of Gaussian `i`, for avatars with one
    /// Gaussian per template vertex (LAM's layout), where the centres sit up to centimetres
    /// off the skin.
    Gaussians,
    /// One static mesh for every frame.
    Mesh(PathBuf),
    /// One mesh per frame (`--gt-sequence`): a folder or pattern of OBJ/PLY files, taken in
    /// order, the file at position `i` being the ground truth of animation frame `i`; their
    /// topologies may differ (scans).
    Sequence(String),
}

impl GroundTruth {
    /// Parses a `--gt` value: the word `template`, else a mesh file.
    #[must_use]
    pub fn parse(value: &str) -> Self {
        if value == "template" {
            Self::Template
        } else if value == "gaussians" {
            Self::Gaussians
        } else {
            Self::Mesh(PathBuf::from(value))
        }
    }

    /// The value as given (`template` or the path).
    #[must_use]
    pub fn label(&self) -> String {
        match self {
            Self::Template => "template".to_owned(),
            Self::Gaussians => "gaussians".to_owned(),
            Self::Mesh(p) => p.display().to_string(),
            Self::Sequence(spec) => spec.clone(),
        }
    }
}

/// The knobs of the main job; unset values are derived from the template (see each field).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct ExtractOptions {
    /// How the Gaussians follow the template (as `trisplat deform`).
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = Mode::Binding))]
    pub mode: Mode,
    /// glTF animation clip by name or index [default: the first].
    #[cfg_attr(feature = "cli", arg(long, value_name = "NAME|INDEX"))]
    pub clip: Option<String>,
    /// Play --clip of this glTF (e.g. LAM's animation.glb) on the template's joints, matched
    /// by name; with a weights JSON animation both play together (the clip looped).
    #[cfg_attr(feature = "cli", arg(long, value_name = "A.glb"))]
    pub clip_from: Option<PathBuf>,
    /// Sampling rate of a glTF clip, frames per second.
    #[cfg_attr(feature = "cli", arg(long, value_name = "F", default_value_t = DEFAULT_FPS))]
    pub fps: f64,
    /// How the --gaussians file relates to the template: bound (binding_0, local
    /// parameters) or lam (LAM's per-vertex offsets, bound here; set by --avatar).
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = GaussianLayout::Bound,
        value_name = "LAYOUT"))]
    pub layout: GaussianLayout,
    /// Gaussians per triangle when the pipeline binds them itself (no --gaussians).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", default_value_t = DEFAULT_PER_TRIANGLE,
        value_parser = clap::value_parser!(u32).range(1..)))]
    pub per_triangle: u32,
    /// TSDF voxel size in scene units [default: the Gaussians' mean nearest-neighbour spacing,
    /// clamped to template bounding radius / 128 ..= / 32].
    #[cfg_attr(feature = "cli", arg(long, value_name = "V"))]
    pub voxel: Option<f64>,
    /// TSDF camera views per frame (a Fibonacci sphere around the frame's bounding sphere).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", default_value_t = DEFAULT_VIEWS,
        value_parser = parse_positive))]
    pub views: usize,
    /// Side of the square TSDF depth images, pixels.
    #[cfg_attr(feature = "cli", arg(long, value_name = "PX", default_value_t = DEFAULT_RESOLUTION,
        value_parser = clap::value_parser!(u32).range(8..=8192)))]
    pub resolution: u32,
    /// Which rendered depth TSDF fuses: median (the depth where the accumulated alpha reaches
    /// 1/2: the first surface a ray meets, as 2DGS and GOF extract meshes) or expected (the
    /// alpha-weighted mean depth, pulled toward the Gaussians behind the surface).
    #[cfg_attr(feature = "cli", arg(long, value_enum, value_name = "KIND",
        default_value_t = DepthKind::default()))]
    pub tsdf_depth: DepthKind,
    /// How each Gaussian's depth varies over its footprint in those depth maps: ray (the
    /// point of highest density on the pixel's ray, RaDe-GS/GOF; a flat Gaussian gives its
    /// own plane) or mean (its centre's depth over the whole footprint, as 3DGS renders
    /// depth).
    #[cfg_attr(feature = "cli", arg(long, value_enum, value_name = "RULE",
        default_value_t = SplatDepthRule::default()))]
    pub tsdf_splat_depth: SplatDepthRule,
    /// TSDF: also render the Gaussians' colours and fuse them into vertex colours (in the
    /// frame PLYs and the glTF's COLOR_0); slower and 2.5x the volume's memory.
    #[cfg_attr(feature = "cli", arg(long))]
    pub tsdf_colors: bool,
    /// Alpha-shape radius in scene units [default: 6 x the mean nearest-neighbour spacing of
    /// the rest-pose Gaussian means].
    #[cfg_attr(feature = "cli", arg(long, value_name = "A"))]
    pub alpha: Option<f64>,
    /// Alpha: keep the edge-connected pieces at least as large (in triangles) as the K-th
    /// largest, as tsdf keeps its largest (0: keep every piece; the report counts them).
    #[cfg_attr(feature = "cli", arg(long, value_name = "K", default_value_t = 0))]
    pub alpha_keep_clusters: usize,
    /// TSDF: pixels whose rendered alpha is below A carry no depth (0 < A <= 1; 2DGS and GOF
    /// cut at 1/2).
    #[cfg_attr(feature = "cli", arg(long, value_name = "A",
        default_value_t = crate::methods::RENDERED_ALPHA_MIN))]
    pub tsdf_alpha_cut: f32,
    /// Delaunay and alpha: leave out the Gaussians whose largest blending weight (alpha x
    /// transmittance) at any pixel of the tsdf rig's views of the rest pose and of 4 frames
    /// spread over the run is below W: they change no pixel by that much, such as those
    /// inside the closed mouth (the default is one 8-bit step; 0 keeps them all; tsdf renders
    /// every Gaussian in each frame anyway; docs/conventions.md §6).
    #[cfg_attr(feature = "cli", arg(long, value_name = "W",
        default_value_t = crate::visibility::DEFAULT_MIN_CONTRIBUTION))]
    pub min_contribution: f32,
    /// Delaunay and alpha: leave out floating Gaussians, Open3D's statistical outliers among the
    /// rest-pose means of the others: mean distance to the K nearest (K = --floater-neighbors)
    /// above the mean of those distances plus R standard deviations. Off unless given: on a
    /// bound avatar it also takes the sparse parts of the surface (docs/conventions.md §6).
    #[cfg_attr(feature = "cli", arg(long, value_name = "R"))]
    pub floater_std_ratio: Option<f64>,
    /// Neighbours K of the floater rule.
    #[cfg_attr(feature = "cli", arg(long, value_name = "K",
        default_value_t = crate::visibility::DEFAULT_FLOATER_NEIGHBORS,
        value_parser = parse_positive, requires = "floater_std_ratio"))]
    pub floater_neighbors: usize,
    /// Delaunay: rebuild from scratch every N frames (0: never; 1: every frame).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", default_value_t = 0))]
    pub rebuild_every: usize,
    /// Delaunay: keep updating incrementally even when updates cost more than rebuilds (by
    /// default an update dearer than a rebuild is followed by rebuilds from scratch and the
    /// update path probed again later; docs/conventions.md §6).
    #[cfg_attr(feature = "cli", arg(long))]
    pub no_auto_rebuild: bool,
    /// Delaunay hop threshold T, relative to the mean template edge: a Gaussian moves to
    /// another triangle's chart only when that triangle is nearer than its own by more than
    /// T x the mean edge. 0: every frame equals a from-scratch triangulation; T > 0 redoes
    /// fewer charts per frame (faster: CesiumMan's charts redone 4.1% -> 0.3% per frame at
    /// 0.1), but a frame may then differ from a from-scratch triangulation (Gaussians stay in
    /// charts they drifted out of by less than T edges) until the next rebuild.
    #[cfg_attr(feature = "cli", arg(long, value_name = "T",
        default_value_t = DEFAULT_HOP_THRESHOLD))]
    pub hop_threshold: f64,
    /// Points sampled on each mesh for the metrics (with --gt).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", default_value_t = DEFAULT_SAMPLES,
        value_parser = parse_positive))]
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
    /// Refuse a weights track with channels that drive nothing (without it they are listed
    /// once on stderr and in the report, and ignored).
    #[cfg_attr(feature = "cli", arg(long))]
    pub strict: bool,
    /// What to write, comma-separated: meshes (per-frame PLYs), glb (the animated sequence;
    /// its frames are written to assemble it and removed after unless meshes is asked too),
    /// report (report.json, report.md, report.html with its thumbnails, the plot as SVG and
    /// PNG). The run journal is always written.
    #[cfg_attr(feature = "cli", arg(long, value_enum, value_delimiter = ',', value_name = "LIST",
        num_args = 1.., default_values_t = OutputTarget::ALL))]
    pub targets: Vec<OutputTarget>,
    /// Resource limits.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub limits: Limits,
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
}

impl OutputTarget {
    /// Every output, the default.
    pub const ALL: [Self; 3] = [Self::Meshes, Self::Glb, Self::Report];
}

impl std::fmt::Display for OutputTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Meshes => "meshes",
            Self::Glb => "glb",
            Self::Report => "report",
        })
    }
}

impl ExtractOptions {
    /// Which Gaussians the point methods (delaunay, alpha) use ([`crate::visibility`]).
    #[must_use]
    pub fn visibility_rule(&self) -> crate::visibility::VisibilityRule {
        crate::visibility::VisibilityRule {
            min_contribution: self.min_contribution,
            floater_neighbors: self.floater_neighbors,
            floater_std_ratio: self.floater_std_ratio,
        }
    }

    /// The report's F-score threshold: the fraction of each frame's ground-truth diagonal,
    /// or the absolute `tau` when no fraction is set.
    #[must_use]
    pub fn threshold(&self) -> Tau {
        self.tau_fraction
            .map_or(Tau::Absolute(self.tau), Tau::Fraction)
    }

    /// Whether `target` is among the outputs asked for.
    #[must_use]
    pub fn writes(&self, target: OutputTarget) -> bool {
        self.targets.contains(&target)
    }
}

impl Default for ExtractOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Binding,
            clip: None,
            clip_from: None,
            fps: DEFAULT_FPS,
            layout: GaussianLayout::Bound,
            per_triangle: DEFAULT_PER_TRIANGLE,
            voxel: None,
            views: DEFAULT_VIEWS,
            resolution: DEFAULT_RESOLUTION,
            tsdf_depth: DepthKind::default(),
            tsdf_splat_depth: SplatDepthRule::default(),
            tsdf_colors: false,
            alpha: None,
            alpha_keep_clusters: 0,
            tsdf_alpha_cut: crate::methods::RENDERED_ALPHA_MIN,
            min_contribution: crate::visibility::DEFAULT_MIN_CONTRIBUTION,
            floater_std_ratio: None,
            floater_neighbors: crate::visibility::DEFAULT_FLOATER_NEIGHBORS,
            rebuild_every: 0,
            no_auto_rebuild: false,
            hop_threshold: DEFAULT_HOP_THRESHOLD,
            samples: DEFAULT_SAMPLES,
            tau: DEFAULT_TAU,
            tau_fraction: Some(DEFAULT_TAU_FRACTION),
            strict: false,
            error_colors: false,
            view_axes: trisplat_splat::Axes::Luf,
            targets: OutputTarget::ALL.to_vec(),
            limits: Limits::default(),
        }
    }
}

/// How a run treats an output folder that already holds a run, and frames that fail.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct RunControl {
    /// Continue the run in the output folder: frames its journal lists as done are kept, the
    /// others (and failed ones) are run. Refused if the inputs or options changed.
    #[cfg_attr(feature = "cli", arg(long, conflicts_with = "force"))]
    pub resume: bool,
    /// Start over in an output folder that holds a previous run (its outputs are removed).
    #[cfg_attr(feature = "cli", arg(long))]
    pub force: bool,
    /// Stop at the first frame that fails (completed frames are kept) instead of recording it
    /// and going on.
    #[cfg_attr(feature = "cli", arg(long))]
    pub fail_fast: bool,
    /// Run the methods of each frame one after another, so that each method's ms/frame is its
    /// time alone; by default they run side by side (a shorter run; each method's time then
    /// includes waiting for cores the others hold). The meshes are the same either way.
    #[cfg_attr(feature = "cli", arg(long))]
    pub serial_methods: bool,
}

/// A whole `trisplat extract` run.
#[derive(Clone, Debug, PartialEq)]
pub struct ExtractConfig {
    /// The template mesh (rest shape; a glTF may carry its own animation).
    pub template: PathBuf,
    /// The animation: a glTF, a folder or pattern of OBJ/PLY frames; `None`: the template's
    /// own glTF clip, or the template alone as one frame.
    pub animation: Option<String>,
    /// Bound Gaussians; `None`: the pipeline binds new ones.
    pub gaussians: Option<PathBuf>,
    /// Methods, each run on every frame (duplicates are ignored).
    pub methods: Vec<Method>,
    /// Output folder.
    pub output: PathBuf,
    /// Frame selection `A..B`, `A..=B`, `A..`, `..B` or `A` (animation frame indices).
    pub frames: Option<String>,
    /// Ground truth of the metrics; `None`: no metrics.
    pub gt: Option<GroundTruth>,
    /// The knobs.
    pub options: ExtractOptions,
}

impl ExtractConfig {
    /// The methods asked for, without duplicates, in report order (tsdf, delaunay, alpha).
    #[must_use]
    pub fn methods(&self) -> Vec<Method> {
        Method::ALL
            .into_iter()
            .filter(|m| self.methods.contains(m))
            .collect()
    }
}

#[cfg(all(test, feature = "cli"))]
mod tests {
    use super::*;
    use clap::Parser as _;

    #[derive(clap::Parser)]
    struct Args {
        #[command(flatten)]
        options: ExtractOptions,
    }

    fn parse(args: &[&str]) -> Result<ExtractOptions, clap::Error> {
        Args::try_parse_from(std::iter::once("extract").chain(args.iter().copied()))
            .map(|a| a.options)
    }

    #[test]
    fn tau_is_relative_by_default_absolute_when_given() {
        let default = parse(&[]).expect("defaults");
        assert_eq!(default, ExtractOptions::default());
        assert_eq!(default.tau_fraction, Some(DEFAULT_TAU_FRACTION));
        assert_eq!(DEFAULT_TAU_FRACTION_ARG.parse(), Ok(DEFAULT_TAU_FRACTION));
        assert_eq!(default.threshold(), Tau::Fraction(DEFAULT_TAU_FRACTION));
        let absolute = parse(&["--tau", "0.01"]).expect("absolute");
        assert_eq!(absolute.tau_fraction, None);
        assert_eq!(absolute.threshold(), Tau::Absolute(0.01));
        let relative = parse(&["--tau-fraction", "0.02"]).expect("relative");
        assert_eq!(relative.threshold(), Tau::Fraction(0.02));
        assert!(parse(&["--tau", "0.01", "--tau-fraction", "0.02"]).is_err());
    }
}
