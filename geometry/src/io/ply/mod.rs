//! Stanford PLY: a general reader and writer (ascii, binary little- and big-endian) and the
//! mapping between PLY elements and [`TriMesh`](crate::TriMesh) /
//! [`PointCloud`](crate::PointCloud).
//!
//! The reader is hand-written rather than built on `ply-rs-bw` so that every failure names the
//! element and row at fault and so that no allocation is ever sized from a header count alone:
//! before an element is read, its count is checked against the bytes left in the file (each row
//! needs at least its fixed-size part in binary, at least two bytes per property in ascii).
//!
//! What becomes mesh data:
//! - `vertex`: `x y z` (any numeric type; NaN or infinite is an error naming the vertex),
//!   normals `nx ny nz`, colours `red green blue [alpha]` (integers are divided by the type's
//!   maximum, so `uchar` 255 is 1.0; floats are taken as they are), texture coordinates as
//!   `texture_u texture_v`, `u v`, `s t` or `texture_s texture_t` (the names trimesh tries).
//! - `face`: a list property `vertex_indices` or `vertex_index` of any integer types; polygons
//!   are fan-triangulated (`0 1 2`, `0 2 3`, ...), faces with fewer than three corners are
//!   skipped. An index out of range is an error naming the face.
//! - `tristrips`: a list `vertex_indices` where `-1` restarts the strip; triangle `k` of a strip
//!   is `(s[k], s[k+1], s[k+2])` for even `k` and `(s[k+1], s[k], s[k+2])` for odd `k`, and
//!   triangles with a repeated index (strip-joining degenerates) are dropped.
//!
//! Everything else is kept in [`PlyExtras`] and written back by [`write_ply_mesh`]: extra vertex
//! properties (one value per vertex), extra face properties when every face was a triangle
//! (so faces map one to one; after fan triangulation they are dropped), and whole other
//! elements verbatim. Comments and `obj_info` lines are kept too.
//!
//! One job a file: `model` holds the document types (typed columns, elements, extras),
//! `header` parses the header and its limits, `read` decodes the body, `plain` decodes plain
//! float point clouds straight into vectors (no document), `write` encodes
//! documents and borrowed columns, and `convert` maps documents to and from meshes and points.

mod convert;
mod header;
mod model;
mod plain;
mod read;
mod write;

pub use convert::{
    mesh_to_ply, ply_to_mesh, ply_to_points, ply_to_points_local, points_to_ply, points_to_ply_at,
    read_ply_mesh, write_ply_mesh, write_ply_points, write_ply_points_at,
};
pub use model::{
    PlyDocument, PlyElement, PlyEncoding, PlyExtras, PlyProperty, PropertyData, ScalarColumn,
    ScalarType,
};
pub use plain::read_plain_points;
pub use read::{parse_ply, read_ply_document};
pub use write::{ColumnView, write_ply_columns, write_ply_document};
