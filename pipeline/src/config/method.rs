//! The extraction methods, by name.

use std::fmt;

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
    /// Boundary of the solid the alpha complex of the deformed Gaussian means encloses (at the
    /// smallest alpha that makes it at most `--alpha-pieces` pieces).
    Alpha,
    /// The deformed Gaussians' opacity field (Gaussian Opacity Fields): centres and 3-sigma
    /// box corners tetrahedralised, the field the minimum over the tsdf rig's views, marching
    /// tetrahedra at 1/2.
    Opacity,
}

impl Method {
    /// Every method, in report order.
    pub const ALL: [Self; 4] = [Self::Tsdf, Self::Delaunay, Self::Alpha, Self::Opacity];

    /// The method's name on the command line and in output file names.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Tsdf => "tsdf",
            Self::Delaunay => "delaunay",
            Self::Alpha => "alpha",
            Self::Opacity => "opacity",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}
