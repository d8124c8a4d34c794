//! The error of the spatial indexes.

/// Why a spatial index could not be built or queried.
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum SpatialError {
    /// A point index needs at least one point.
    #[error("no points to index")]
    Empty,
    /// A coordinate is NaN or infinite.
    #[error("point {index} has a non-finite coordinate")]
    NonFinite {
        /// Index of the point (or query, or vertex).
        index: usize,
    },
    /// A coordinate exceeds [`MAX_COORDINATE`](super::MAX_COORDINATE) in magnitude.
    #[error("point {index} has a coordinate beyond 1e18 in magnitude")]
    TooLarge {
        /// Index of the point (or query, or vertex).
        index: usize,
    },
    /// A triangle names a vertex past the end of the positions.
    #[error("triangle {triangle} names a vertex past the {vertex_count} vertices")]
    BadIndex {
        /// Index of the triangle.
        triangle: usize,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// More points than `u32` indices can address.
    #[error("{count} points do not fit in u32 indices")]
    TooMany {
        /// Number of points.
        count: usize,
    },
    /// The k-d tree library refused the input.
    #[error("cannot build the k-d tree: {message}")]
    Build {
        /// The library's message.
        message: String,
    },
}
