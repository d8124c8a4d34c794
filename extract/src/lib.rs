//! Mesh extraction for trisplat (docs/conventions.md §6): TSDF fusion of depth maps with marching cubes
//! ([`tsdf`], [`marching_cubes`]), incremental Delaunay meshing of triangle-bound Gaussians that
//! only re-triangulates what moved ([`incremental_delaunay`]), and alpha shapes over our own
//! exact 3D Delaunay tetrahedralisation ([`delaunay3d`], [`alpha_shape`]).
//!
//! This crate takes depth images, cameras and point sets, never renderer types.

pub mod alpha_shape;
pub mod carve;
pub mod delaunay3d;
pub mod incremental_delaunay;
pub mod marching_cubes;
pub mod mc_tables;
pub mod tsdf;
