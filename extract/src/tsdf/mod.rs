//! TSDF fusion of depth maps into a sparse voxel-block grid (docs/conventions.md §6).
//!
//! Per-voxel rules are Open3D's legacy integrator
//! (`UniformTSDFVolume::IntegrateWithDepthToCameraDistanceMultiplier`), in trisplat's pixel
//! convention (pixel (i, j) centred at (j + ½, i + ½), docs/conventions.md §2):
//! - voxel `g` is centred at `(g + ½) · voxel` (world);
//! - its camera-space point `q` (skipped when `q.z ≤ 0`) projects to `(u, v) = (fx q.x / q.z +
//!   cx, fy q.y / q.z + cy)`; voxels with `u` or `v` outside `[1e-4, size − 1e-4)` are skipped
//!   ([`PIXEL_MARGIN`]); the pixel is the one whose centre is nearest, `(⌊v⌋, ⌊u⌋)` — Open3D's
//!   `(int)(u + 0.5)` with its pixel centres at integers;
//! - pixels with no depth (0, invalid, or beyond `depth_trunc`) are skipped;
//! - `sdf = (d − q.z) · ‖((j + ½ − cx)/fx, (i + ½ − cy)/fy, 1)‖` (the z difference times the
//!   ray-length factor of the pixel);
//! - only when `sdf > −trunc`: `tsdf = min(1, sdf / trunc)` and the running average with unit
//!   weights `value ← (value · w + tsdf) / (w + 1)`, `w ← w + 1` (colour likewise).
//!
//! Open3D's dense volume integrates every voxel of a box; here blocks of 8³ voxels are created
//! only near observed depth: for each valid pixel, every block within `trunc + √3 voxel +
//! (d + trunc) · ½ √(1/fx² + 1/fy²)` of its back-projected point (see [`TsdfVolume::allocate`]).
//! That radius covers every voxel with |sdf| < trunc for that pixel and every corner of a cell
//! that has such a voxel, so the extracted surface is the one the dense volume would give.
//! Values are stored in f32, computed in f64. Blocks are integrated in parallel, each looping
//! over the frames in order, so the result does not depend on the thread count.
//!
//! Per block and frame, the depth range of the pixels the block projects onto (read pixel by
//! pixel when the block covers at most `frame::RECT_SCAN_MAX` of them, else from 16-pixel tiles)
//! decides the work: nothing when the block is behind the camera, outside the image or
//! `trunc` behind every depth; tsdf = 1 for all its voxels without projecting them when it
//! projects inside the image onto valid pixels only and lies `trunc` in front of all of them
//! (free space); otherwise each row of 8 voxels is projected lane by lane without branches.
//! The outcome is the plain per-voxel rule's, which a test checks voxel by voxel on a dense
//! box at coarse and fine voxels.

mod allocate;
mod error;
mod frame;
mod fuse;
mod image;
mod integrate;
mod params;
mod volume;

pub use self::error::TsdfError;
pub use self::frame::{Frame, PIXEL_MARGIN};
pub use self::fuse::{
    DEFAULT_KEEP_CLUSTERS, DEFAULT_TRUNC_VOXELS, DEFAULT_VOXELS_PER_DEPTH_TRUNC, Fused,
    TsdfOptions, fuse, fuse_streamed, post_process, scene_radius,
};
pub use self::image::{
    ColorImage, DEFAULT_DEPTH_SCALE, DepthImage, find_image, read_color, read_color_dir,
    read_depth, read_depth_dir,
};
pub use self::params::TsdfParams;
pub use self::volume::{DEFAULT_MAX_BLOCKS, STREAM_BUDGET_BYTES, TsdfVolume};
