//! x

pub mod alpha_shape;
pub mod delaunay3d;
pub mod incremental_delaunay;
