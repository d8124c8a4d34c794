//! Options of the opacity method (`extract --method opacity`): which field decides each
//! point's side, and which pieces of the surface are kept, with their defaults.

/// The field the opacity method meshes (`extract --opacity-field`, `opacity-mesh --field`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum OpacityField {
    /// Gaussian Opacity Fields' field: the smallest over views of the opacity accumulated along
    /// each view's ray up to the point (walks along rays; ~9x the median field's time on LAM).
    Gof,
    /// The views' rendered median-depth maps decide each point's side, and the vertices lie on
    /// the median depth (the default: on LAM better than GOF's field on every
    /// render-consistency score at a ninth of its time, docs/benchmarks.md).
    #[default]
    Median,
    /// The median field for a template avatar's flat Gaussians (discs on the surface, whose box
    /// corners do not leave it): points on both sides of every 4th pixel's median depth
    /// ([`TEMPLATE_DEPTH_SAMPLES`]), every vertex of a thick part settled, rims included, and
    /// the settled vertices Taubin-smoothed ([`TEMPLATE_SMOOTHING`] iterations). On CesiumMan
    /// and the Spot walk it meets issue #34's per-frame ground-truth goals where `median` does
    /// not; on LAM it costs 0.005 IoU, so it is not the default (docs/benchmarks.md).
    Template,
}

/// Depth-sample stride of [`OpacityField::Template`] (`DepthRules::sample_stride`).
pub const TEMPLATE_DEPTH_SAMPLES: u32 = 4;
/// Taubin iterations of [`OpacityField::Template`] (`OpacityOptions::smoothing`).
pub const TEMPLATE_SMOOTHING: u32 = 10;

impl OpacityField {
    /// The field's name.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Gof => "gof",
            Self::Median => "median",
            Self::Template => "template",
        }
    }
}

/// Which connected pieces of the opacity surface are kept (`extract --opacity-pieces`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum OpacityPieces {
    /// Every piece.
    All,
    /// Every piece with at least 1% of the surface's area.
    Major,
    /// The largest piece by area (the default: one piece, as issue #34 asks).
    #[default]
    Largest,
}

/// The opacity method's field and pieces.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct OpacityMethodOptions {
    /// Opacity method: which field decides a point's side: median (the rig's rendered
    /// median-depth maps; vertices on the median depth), template (the median field for a
    /// template avatar's flat Gaussians: depth samples, rims settled, smoothed) or gof
    /// (Gaussian Opacity Fields' opacity along rays).
    #[cfg_attr(feature = "cli", arg(id = "opacity_field", long = "opacity-field",
        value_enum, value_name = "FIELD", default_value_t = OpacityField::default()))]
    pub field: OpacityField,
    /// Opacity method: which connected pieces of the surface are kept: the largest by area,
    /// every piece with at least 1% of the area (major), or all.
    #[cfg_attr(feature = "cli", arg(id = "opacity_pieces", long = "opacity-pieces",
        value_enum, value_name = "PIECES", default_value_t = OpacityPieces::default()))]
    pub pieces: OpacityPieces,
}
