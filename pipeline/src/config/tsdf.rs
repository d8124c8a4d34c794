//! Options of the tsdf method (render depth maps of each frame's Gaussians from a rig, fuse
//! them), with their defaults.

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
/// Rendered alpha below which a pixel carries no depth (the default of `--tsdf-alpha-cut`):
/// the Gaussians barely cover it (2DGS and GOF cut at 1/2).
pub const RENDERED_ALPHA_MIN: f32 = 0.5;

/// Accumulated alpha at which a view's free space ends (the default of `--tsdf-front-alpha`):
/// a voxel between the depth where a pixel's alpha first reaches it and the pixel's median
/// depth is not carved by that view (semi-transparent hair in front of the skull stays for
/// the views that see it edge-on); 0 carves up to the median depth.
pub const DEFAULT_FRONT_ALPHA: f32 = 0.0;

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
    /// The depth of the Gaussian at which the accumulated alpha first reaches
    /// `--tsdf-front-alpha` (the outer edge of semi-transparent layers).
    Front,
}

impl DepthKind {
    /// The kind's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Expected => "expected",
            Self::Median => "median",
            Self::Front => "front",
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

/// Where the tsdf method's voxel grid and camera rig sit (`extract --tsdf-anchor`,
/// docs/conventions.md §6, "The tsdf method's anchor").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum TsdfAnchor {
    /// Moving rigidly with the avatar (the rigid motion that best maps the rest template onto
    /// the frame's): a rigidly moving surface is sampled alike in every frame, so a frame's
    /// own extraction agrees with a mesh carried from a key. The default.
    #[default]
    Rigid,
    /// Fixed in world space around each frame's bounding sphere (the rule before issue #31):
    /// a moving surface is resampled every frame.
    World,
}

impl TsdfAnchor {
    /// The anchor's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Rigid => "rigid",
            Self::World => "world",
        }
    }
}

/// The tsdf method's rig, depth maps and fusion.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct TsdfOptions {
    /// TSDF voxel size in scene units [default: the Gaussians' mean nearest-neighbour spacing,
    /// clamped to template bounding radius / 128 ..= / 32].
    #[cfg_attr(feature = "cli", arg(long, value_name = "V"))]
    pub voxel: Option<f64>,
    /// TSDF camera views per frame (a Fibonacci sphere around the frame's bounding sphere).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", default_value_t = DEFAULT_VIEWS,
        value_parser = super::arg::parse_positive))]
    pub views: usize,
    /// Side of the square TSDF depth images, pixels.
    #[cfg_attr(feature = "cli", arg(long, value_name = "PX", default_value_t = DEFAULT_RESOLUTION,
        value_parser = clap::value_parser!(u32).range(8..=8192)))]
    pub resolution: u32,
    /// Which rendered depth TSDF fuses: median (the depth where the accumulated alpha reaches
    /// 1/2: the first surface a ray meets, as 2DGS and GOF extract meshes) or expected (the
    /// alpha-weighted mean depth, pulled toward the Gaussians behind the surface).
    #[cfg_attr(feature = "cli", arg(id = "tsdf_depth", long = "tsdf-depth", value_enum,
        value_name = "KIND", default_value_t = DepthKind::default()))]
    pub depth: DepthKind,
    /// How each Gaussian's depth varies over its footprint in those depth maps: ray (the
    /// point of highest density on the pixel's ray, RaDe-GS/GOF; a flat Gaussian gives its
    /// own plane) or mean (its centre's depth over the whole footprint, as 3DGS renders
    /// depth).
    #[cfg_attr(feature = "cli", arg(id = "tsdf_splat_depth", long = "tsdf-splat-depth",
        value_enum, value_name = "RULE", default_value_t = SplatDepthRule::default()))]
    pub splat_depth: SplatDepthRule,
    /// TSDF: also render the Gaussians' colours and fuse them into vertex colours (in the
    /// frame PLYs and the glTF's COLOR_0); slower and 2.5x the volume's memory.
    #[cfg_attr(feature = "cli", arg(id = "tsdf_colors", long = "tsdf-colors"))]
    pub colors: bool,
    /// TSDF: pixels whose rendered alpha is below A carry no depth (0 < A <= 1; 2DGS and GOF
    /// cut at 1/2).
    #[cfg_attr(feature = "cli", arg(id = "tsdf_alpha_cut", long = "tsdf-alpha-cut",
        value_name = "A", default_value_t = RENDERED_ALPHA_MIN))]
    pub alpha_cut: f32,
    /// TSDF: a view marks free space only in front of the depth where a pixel's accumulated
    /// alpha first reaches A (0 <= A < 1; 0: up to the fused depth), so that semi-transparent
    /// layers (fuzzy hair) that a view sees through are not carved by it.
    #[cfg_attr(feature = "cli", arg(id = "tsdf_front_alpha", long = "tsdf-front-alpha",
        value_name = "A", default_value_t = DEFAULT_FRONT_ALPHA))]
    pub front_alpha: f32,
    /// TSDF: where the voxel grid and camera rig sit: rigid (they move with the avatar's
    /// best-fitting rigid motion from the rest template, so a turning head is sampled alike
    /// in every frame) or world (fixed in space around each frame, the earlier rule).
    #[cfg_attr(feature = "cli", arg(id = "tsdf_anchor", long = "tsdf-anchor", value_enum,
        value_name = "ANCHOR", default_value_t = TsdfAnchor::default()))]
    pub anchor: TsdfAnchor,
}

impl Default for TsdfOptions {
    fn default() -> Self {
        Self {
            voxel: None,
            views: DEFAULT_VIEWS,
            resolution: DEFAULT_RESOLUTION,
            depth: DepthKind::default(),
            splat_depth: SplatDepthRule::default(),
            colors: false,
            alpha_cut: RENDERED_ALPHA_MIN,
            front_alpha: DEFAULT_FRONT_ALPHA,
            anchor: TsdfAnchor::default(),
        }
    }
}
