//! The options of incremental Delaunay meshing: [`DelaunayOptions`], [`Lift`] and their defaults.

/// Default hop threshold (relative to the mean template edge length): 0, every change of
/// nearest triangle is a hop, and the result equals a from-scratch triangulation of the frame.
pub const DEFAULT_HOP_THRESHOLD: f64 = 0.0;

/// Default shrink of canonical barycentric weights toward the centroid (`b' = (1 - 3m) b + m`):
/// a point on an edge ends up `m` (relative) inside, far above the rounding of the 2D
/// coordinates (~1e-16) and far below anything visible.
pub const DEFAULT_INTERIOR_MARGIN: f64 = 1e-3;

/// A candidate triangle is dismissed by a lower bound only when the bound exceeds the needed
/// distance by this fraction of the template's bounding-box diagonal, far above the f64
/// rounding of the distances (so the answer is the same as the exact search's).
pub const FILTER_MARGIN_REL: f64 = 1e-9;

/// Default degeneracy tolerance of rest triangles: degenerate when twice the area is at most
/// this times the longest edge squared (height below 1e-9 of the longest edge).
pub const DEFAULT_DEGENERATE_TOL: f64 = 1e-9;

/// Where Gaussian vertices are placed each frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Lift {
    /// At the Gaussian's deformed mean.
    #[default]
    Means,
    /// Moved with the chart triangle: canonical plane barycentric weights on the deformed
    /// triangle plus the canonical plane offset along its unit normal.
    Surface,
}

/// Options of [`IncrementalDelaunay`](super::IncrementalDelaunay).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DelaunayOptions {
    /// Hop hysteresis `τ`, relative to the mean template edge length: a Gaussian leaves its
    /// chart only when another triangle is nearer by more than `τ` times that length
    /// ([`DEFAULT_HOP_THRESHOLD`]). Finite and `≥ 0`.
    pub hop_threshold: f64,
    /// Rebuild from scratch every this many updates (0: never).
    pub rebuild_every: usize,
    /// Rebuild from scratch instead of updating while updates cost more than rebuilds (see
    /// [`AutoRebuild`](super::AutoRebuild)); `false` keeps updating whatever the motion.
    pub auto_rebuild: bool,
    /// Placement of Gaussian vertices.
    pub lift: Lift,
    /// Shrink of canonical weights toward the centroid ([`DEFAULT_INTERIOR_MARGIN`]), in
    /// `(0, 1/3)`.
    pub interior_margin: f64,
    /// Degeneracy tolerance of rest triangles ([`DEFAULT_DEGENERATE_TOL`]), finite and `≥ 0`.
    pub degenerate_tol: f64,
}

impl Default for DelaunayOptions {
    fn default() -> Self {
        Self {
            hop_threshold: DEFAULT_HOP_THRESHOLD,
            rebuild_every: 0,
            auto_rebuild: true,
            lift: Lift::Means,
            interior_margin: DEFAULT_INTERIOR_MARGIN,
            degenerate_tol: DEFAULT_DEGENERATE_TOL,
        }
    }
}
