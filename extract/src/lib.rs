//! x

pub mod alpha_shape;
pub mod delaunay3d;
pub mod incremental_delaunay;
pub mod marching_cubes;
pub mod mc_tables;
pub mod tsdf;
