//! Options of the first stages (docs/conventions.md §1): how the template is animated, how the
//! Gaussians are read or bound, and how they follow the template; with their defaults.

use std::path::PathBuf;

use trisplat_geometry::animation::DEFAULT_FPS;

/// Default Gaussians per triangle when the pipeline binds them itself.
pub const DEFAULT_PER_TRIANGLE: u32 = 4;
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

/// How a Gaussian file relates to its template.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum GaussianLayout {
    /// Bound to triangles (`binding_0`), local parameters (GaussianAvatars, `trisplat bind`).
    #[default]
    Bound,
    /// LAM's per-vertex layout: one row per template vertex, positions are offsets from
    /// the vertex, colours are RGB; bound here to the triangles around each vertex.
    Lam,
}

impl GaussianLayout {
    /// The name used on the command line.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Bound => "bound",
            Self::Lam => "lam",
        }
    }
}

/// The animation stage: which clip plays, at what rate, and how the Gaussians follow it.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct AnimationOptions {
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
    /// Refuse a weights track with channels that drive nothing (without it they are listed
    /// once on stderr and in the report, and ignored).
    #[cfg_attr(feature = "cli", arg(long))]
    pub strict: bool,
}

impl Default for AnimationOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Binding,
            clip: None,
            clip_from: None,
            fps: DEFAULT_FPS,
            strict: false,
        }
    }
}

/// The bind stage: how the `--gaussians` file is read, or how many Gaussians are bound here.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct BindOptions {
    /// How the --gaussians file relates to the template: bound (binding_0, local
    /// parameters) or lam (LAM's per-vertex offsets, bound here; set by --avatar).
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = GaussianLayout::Bound,
        value_name = "LAYOUT"))]
    pub layout: GaussianLayout,
    /// Gaussians per triangle when the pipeline binds them itself (no --gaussians).
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", default_value_t = DEFAULT_PER_TRIANGLE,
        value_parser = clap::value_parser!(u32).range(1..)))]
    pub per_triangle: u32,
}

impl Default for BindOptions {
    fn default() -> Self {
        Self {
            layout: GaussianLayout::Bound,
            per_triangle: DEFAULT_PER_TRIANGLE,
        }
    }
}
