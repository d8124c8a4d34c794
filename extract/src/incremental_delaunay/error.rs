//! Why incremental Delaunay meshing fails: [`DelaunayError`].

use trisplat_geometry::spatial::SpatialError;

/// Errors of incremental Delaunay meshing.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DelaunayError {
    /// The template has no triangles.
    #[error("the template has no triangles")]
    NoTriangles,
    /// A template triangle names a vertex the template does not have.
    #[error("template triangle {triangle} names vertex {vertex}, but there are {vertex_count}")]
    BadTriangle {
        /// Triangle index.
        triangle: usize,
        /// The vertex it names.
        vertex: u32,
        /// Template vertices.
        vertex_count: usize,
    },
    /// An option is out of range.
    #[error("option {name} is out of range")]
    InvalidOption {
        /// Which option.
        name: &'static str,
    },
    /// A position array has the wrong length.
    #[error("{what} has {got} entries, expected {expected}")]
    Count {
        /// Which array.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// A coordinate is NaN, infinite or larger than `MAX_COORDINATE` in magnitude.
    #[error("{what} {index} is not finite or too large")]
    BadCoordinate {
        /// Which array (template vertex, canonical mean, deformed vertex, deformed mean).
        what: &'static str,
        /// Index in it.
        index: usize,
    },
    /// Template vertices plus Gaussians exceed `u32` vertex ids.
    #[error("{count} output vertices do not fit u32 ids")]
    TooMany {
        /// Vertices needed.
        count: usize,
    },
    /// The triangle BVH refused the deformed template (not expected after the checks above).
    #[error("deformed template: {0}")]
    Bvh(#[from] SpatialError),
}
