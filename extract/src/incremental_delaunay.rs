//! Incremental Delaunay meshing of triangle-bound Gaussians (SPEC §6).
