//! Options of the point methods (delaunay, alpha) and of the rule that decides which
//! Gaussians they mesh, with their defaults.

use trisplat_extract::alpha_complex::Surface;
use trisplat_extract::incremental_delaunay::DEFAULT_HOP_THRESHOLD;

/// Default alpha of the alpha-shape method, in multiples of the mean spacing of the Gaussians
/// (mean distance from each rest-pose mean to its nearest other mean). 6, not 3: with the
/// pipeline's self-bound Gaussians (4 per triangle) 3 spacings leaves holes on real templates,
/// while 6 lowers Chamfer L1 against the deformed template at the same cost (docs/benchmarks.md,
/// "Main job (`sweep`)": CesiumMan 6.6e-3 -> 3.4e-3, F-score 0.55 -> 0.72; the LAM head
/// 8.7e-3 -> 1.4e-3, F-score 0.43 -> 0.75; the time is the tetrahedralisation's either way).
/// Since issue #34 this is the radius of `--alpha-rule open3d` only; the default rule searches
/// α itself ([`DEFAULT_ALPHA_FLOOR_SPACINGS`]).
pub const DEFAULT_ALPHA_SPACINGS: f64 = 6.0;
/// The smallest α the default alpha search tries, in mean spacings (below about 2 spacings the
/// alpha complex of 4 Gaussians per triangle is hundreds of pieces on every template measured).
pub const DEFAULT_ALPHA_FLOOR_SPACINGS: f64 = 1.5;
/// The largest α the default alpha search tries, in mean spacings.
pub const DEFAULT_ALPHA_CEILING_SPACINGS: f64 = 12.0;
/// Steps of the default alpha search per doubling of α.
pub const ALPHA_STEPS_PER_DOUBLING: u32 = 4;
/// Default `--alpha-pieces`: the alpha search stops at the first α whose mesh has at most 10
/// pieces. 10, not 1: on the LAM head one piece needs a coarse α (F-score against its Gaussians'
/// surface 0.65 -> 0.60), while 10 improves every accuracy score over Open3D's shape on LAM,
/// CesiumMan and a Spot walk (docs/benchmarks.md, "Alpha shapes: one piece"); `--alpha-pieces 1`
/// asks for one piece.
pub const DEFAULT_ALPHA_PIECES: usize = 10;

/// Which triangles the alpha method outputs (docs/conventions.md §6 "Alpha shapes").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum AlphaRule {
    /// The alpha complex (CGAL's Alpha_shape_3, GENERAL mode): the faces of exactly one kept
    /// tetrahedron plus the singular triangles, whose own smallest circumsphere is empty and
    /// of radius <= alpha; without --alpha, the smallest alpha (1.5 to 12 mean spacings, 4
    /// steps per doubling) whose mesh has at most --alpha-pieces pieces, per frame. One piece
    /// or few, but not manifold (folds: its area exceeds the surface's).
    Complex,
    /// The boundary of the solid the alpha complex encloses (docs/conventions.md §6 "Alpha
    /// complex"): the complex's triangles between a tetrahedron reachable from outside and one
    /// that is not, oriented outward; folds, interior sheets and fins are dropped. Without
    /// --alpha, searched as `complex`. The default: one piece, about the surface's area.
    #[default]
    Solid,
    /// Open3D's regularised alpha shape (faces of exactly one tetrahedron of circumradius <=
    /// alpha); without --alpha, 6 mean spacings. Hundreds of pieces on surface samples.
    Open3d,
}
impl AlphaRule {
    /// The alpha complex's output for the complex rules, `None` for Open3D's shape.
    #[must_use]
    pub fn surface(self) -> Option<Surface> {
        match self {
            Self::Complex => Some(Surface::General),
            Self::Solid => Some(Surface::Solid),
            Self::Open3d => None,
        }
    }
}

/// Default [`VisibilityRule::min_contribution`]: one step of an 8-bit image.
pub const DEFAULT_MIN_CONTRIBUTION: f32 = 1.0 / 255.0;
/// Default [`VisibilityRule::floater_neighbors`] (Open3D's tutorial value).
pub const DEFAULT_FLOATER_NEIGHBORS: usize = 20;

/// The rule deciding which Gaussians the point methods use (module `visibility` applies it;
/// docs/conventions.md §6).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct VisibilityRule {
    /// Delaunay and alpha: leave out the Gaussians whose largest blending weight (alpha x
    /// transmittance) at any pixel of the tsdf rig's views of the rest pose and of 4 frames
    /// spread over the whole track is below W: they change no pixel by that much, such as those
    /// inside the closed mouth (the default is one 8-bit step; 0 keeps them all; tsdf renders
    /// every Gaussian in each frame anyway; docs/conventions.md §6).
    #[cfg_attr(feature = "cli", arg(long, value_name = "W",
        default_value_t = DEFAULT_MIN_CONTRIBUTION))]
    pub min_contribution: f32,
    /// Delaunay and alpha: leave out floating Gaussians, Open3D's statistical outliers among the
    /// rest-pose means of the others: mean distance to the K nearest (K = --floater-neighbors)
    /// above the mean of those distances plus R standard deviations. Off unless given: on a
    /// bound avatar it also takes the sparse parts of the surface (docs/conventions.md §6).
    #[cfg_attr(feature = "cli", arg(long, value_name = "R"))]
    pub floater_std_ratio: Option<f64>,
    /// Neighbours K of the floater rule.
    #[cfg_attr(feature = "cli", arg(long, value_name = "K",
        default_value_t = DEFAULT_FLOATER_NEIGHBORS,
        value_parser = super::arg::parse_positive, requires = "floater_std_ratio"))]
    pub floater_neighbors: usize,
}

impl Default for VisibilityRule {
    fn default() -> Self {
        Self {
            min_contribution: DEFAULT_MIN_CONTRIBUTION,
            floater_std_ratio: None,
            floater_neighbors: DEFAULT_FLOATER_NEIGHBORS,
        }
    }
}

impl VisibilityRule {
    /// Whether the rule leaves every Gaussian in (no threshold, no floater rule).
    #[must_use]
    pub fn keeps_all(&self) -> bool {
        self.min_contribution <= 0.0 && self.floater_std_ratio.is_none()
    }
}

/// The delaunay method's incremental updates.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct DelaunayOptions {
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
}

impl Default for DelaunayOptions {
    fn default() -> Self {
        Self {
            rebuild_every: 0,
            no_auto_rebuild: false,
            hop_threshold: DEFAULT_HOP_THRESHOLD,
        }
    }
}

/// The alpha method's rule, radius and the pieces it keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct AlphaOptions {
    /// Alpha radius in scene units, the same on every frame [default: per frame, the smallest
    /// alpha from 1.5 to 12 mean nearest-neighbour spacings of the rest-pose Gaussian means
    /// whose mesh has at most --alpha-pieces pieces (--alpha-rule open3d: 6 spacings)].
    #[cfg_attr(feature = "cli", arg(long, value_name = "A"))]
    pub alpha: Option<f64>,
    /// Alpha: which triangles form the mesh.
    #[cfg_attr(feature = "cli", arg(long = "alpha-rule", value_name = "RULE",
        value_enum, default_value_t = AlphaRule::Solid))]
    pub rule: AlphaRule,
    /// Alpha, without --alpha: the piece count the alpha search stops at (if no alpha up to
    /// 12 spacings reaches it, the one with the fewest pieces is used).
    #[cfg_attr(feature = "cli", arg(long = "alpha-pieces", value_name = "N",
        default_value_t = DEFAULT_ALPHA_PIECES, value_parser = super::arg::parse_positive))]
    pub pieces: usize,
    /// Alpha: keep the edge-connected pieces at least as large (in triangles) as the K-th
    /// largest, as tsdf keeps its largest (0: keep every piece; the report counts them).
    #[cfg_attr(
        feature = "cli",
        arg(
            id = "alpha_keep_clusters",
            long = "alpha-keep-clusters",
            value_name = "K",
            default_value_t = 0
        )
    )]
    pub keep_clusters: usize,
}

impl Default for AlphaOptions {
    fn default() -> Self {
        Self {
            alpha: None,
            rule: AlphaRule::Solid,
            pieces: DEFAULT_ALPHA_PIECES,
            keep_clusters: 0,
        }
    }
}
