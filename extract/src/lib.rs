//! Mesh extraction for trisplat (docs/conventions.md §6): TSDF fusion of depth maps with marching
//! cubes ([`tsdf`], [`marching_cubes()`]), incremental Delaunay meshing of triangle-bound
//! Gaussians that only re-triangulates what moved ([`incremental_delaunay`]), alpha shapes over
//! our own exact 3D Delaunay tetrahedralisation ([`delaunay3d`], [`alpha_shape`], and the
//! alpha complex with singular faces, [`alpha_complex`]), and visual
//! hulls carved from silhouettes ([`carve`]), and the Gaussians' opacity field meshed by
//! marching tetrahedra ([`opacity`], Gaussian Opacity Fields).
//!
//! This crate takes depth images, cameras and point sets, never renderer types.
//!
//! # Public paths
//! Each meshing method is a namespace of its own, addressed as such (`tsdf::fuse`,
//! `alpha_shape::alpha_shape`, …): [`tsdf`], [`incremental_delaunay`], [`delaunay3d`],
//! [`alpha_shape`], [`alpha_complex`], [`carve`] and [`opacity`] each bring their options, their error type (two of them are
//! called `DelaunayError`) and their entry points. The building blocks shared by several
//! methods live in private modules and are re-exported here, at the root: the sparse voxel
//! [`BlockGrid`] and [`marching_cubes()`] over it. Everything else (the case table of marching
//! cubes, the pieces of each method) is private.

pub mod alpha_complex;
pub mod alpha_shape;
mod block_grid;
pub mod carve;
pub mod delaunay3d;
mod image_file;
pub mod incremental_delaunay;
mod marching_cubes;
mod mc_tables;
pub mod opacity;
pub mod tsdf;

pub use crate::block_grid::BlockGrid;
pub use crate::marching_cubes::{VERTEX_EDGE_MARGIN, marching_cubes, marching_cubes_dense};
