//! What is done to each mesh a method makes before it is carried or written
//! (docs/conventions.md §10): decimation through meshoptimizer (`--faces`,
//! `--simplify-error`, `--simplify-border`) and vertex colours from the Gaussians
//! (`--vertex-colors`).

use std::fmt;

/// Whether the meshes get vertex colours.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum VertexColors {
    /// Each vertex the colour of the Gaussians near it (their SH degree-0 colours weighted by
    /// opacity times density at the vertex); the opacity method keeps its own composited
    /// colours, and tsdf its fused ones with `--tsdf-colors`.
    #[default]
    Gaussians,
    /// No vertex colours (the opacity method does not composite them either).
    Off,
}

impl VertexColors {
    /// The name on the command line and in the report.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Gaussians => "gaussians",
            Self::Off => "off",
        }
    }
}

impl fmt::Display for VertexColors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Whether the simplifier may move an open mesh's border.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum SimplifyBorder {
    /// Border vertices stay where the method put them (meshoptimizer's `LockBorder`).
    #[default]
    Locked,
    /// Border vertices may collapse along the border (more collapses near rims).
    Free,
}

/// Decimation and vertex colours of every method's meshes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct FinishOptions {
    /// Decimate each mesh (with --topology fixed|adaptive: each key mesh, before it is bound)
    /// to at most N triangles through meshoptimizer's simplifier; a mesh with no more is kept
    /// as it is. The report gives the faces before and after and the error it cost.
    #[cfg_attr(feature = "cli", arg(long, value_name = "N", conflicts_with = "simplify_error",
        value_parser = super::arg::parse_positive))]
    pub faces: Option<usize>,
    /// Decimate each mesh while meshoptimizer's error stays within E times the mesh's extent
    /// (the largest side of its bounding box; 0.001 = 0.1%).
    #[cfg_attr(feature = "cli", arg(long, value_name = "E",
        value_parser = super::arg::parse_share))]
    pub simplify_error: Option<f64>,
    /// Decimation: whether an open mesh's border vertices stay in place.
    #[cfg_attr(feature = "cli", arg(long, value_enum, value_name = "RULE",
        default_value_t = SimplifyBorder::Locked))]
    pub simplify_border: SimplifyBorder,
    /// Vertex colours of the meshes (PLY red green blue, glTF COLOR_0; a carried mesh keeps
    /// its key's): gaussians (the colour of the Gaussians near each vertex) or off.
    #[cfg_attr(feature = "cli", arg(long, value_enum, value_name = "KIND",
        default_value_t = VertexColors::Gaussians))]
    pub vertex_colors: VertexColors,
}

impl FinishOptions {
    /// Whether any mesh is decimated.
    #[must_use]
    pub fn decimates(&self) -> bool {
        self.faces.is_some() || self.simplify_error.is_some()
    }
}
