//! x

pub mod delaunay3d;
