//! x

pub mod delaunay3d;
pub mod incremental_delaunay;
