//! TSDF fusion of depth maps into a sparse voxel-block grid (docs/conventions.md §6).
//!
//! Per-voxel rules are Open3D's legacy integrator
//! (`UniformTSDFVolume::IntegrateWithDepthToCameraDistanceMultiplier`), in trisplat's pixel
//! convention (pixel (i, j) centred at (j + ½, i + ½), docs/conventions.md §2), with the depth
//! read between pixel centres:
//! - voxel `g` is centred at `(g + ½) · voxel` (world);
//! - its camera-space point `q` (skipped when `q.z ≤ 0`) projects to `(u, v) = (fx q.x / q.z +
//!   cx, fy q.y / q.z + cy)`; voxels with `u` or `v` outside `[1e-4, size − 1e-4)` are skipped
//!   ([`PIXEL_MARGIN`]);
//! - pixels with no depth (0, invalid, or beyond `depth_trunc`) have none;
//! - the depth `d` is the bilinear interpolation of the four pixel centres around `(u, v)` when
//!   all four have depth and differ by at most `max(trunc, MAX_CELL_SPREAD_PIXELS · d_min /
//!   min(fx, fy))`, else that of the pixel whose centre is nearest, `(⌊v⌋, ⌊u⌋)` (Open3D's
//!   `(int)(u + 0.5)` with its pixel centres at integers), and the voxel is skipped when
//!   that has none. The nearest pixel alone turns a sloped surface into steps a pixel wide,
//!   and where the steps are deeper than the truncation the asymmetric rule below (dropped
//!   behind, clamped in front) shrinks convex shapes by part of a pixel footprint whatever the
//!   voxel (issue #34);
//! - `sdf = (d − q.z) · ‖q‖ / q.z` (the z difference along the voxel's own ray);
//! - only when `sdf > −trunc`: `tsdf = min(1, sdf / trunc)` and the running average with unit
//!   weights `value ← (value · w + tsdf) / (w + 1)`, `w ← w + 1` (colour likewise, from the
//!   nearest pixel).
//!
//! Open3D's dense volume integrates every voxel of a box; here blocks of 8³ voxels are created
//! only near observed depth: for each valid pixel, every block within a voxel diagonal of the
//! frustum piece over the pixel's square (and the interpolated cell it starts) between the
//! depths it can read ± `trunc` (see [`TsdfVolume::allocate`]). That covers every voxel with
//! |sdf| < trunc and every corner of a cell that has such a voxel, so the extracted surface is
//! the one the dense volume would give.
//! Values are stored in f32, computed in f64. Blocks are integrated in parallel, each looping
//! over the frames in order, so the result does not depend on the thread count.
//!
//! Per block and frame, the depth range of the pixels the block projects onto (from a per-view
//! table of the depth range of 4 x 4 pixel windows at every even pixel, a few windows that
//! reach at most a pixel past the block's rectangle
//! when it is 3 pixels wide or more; with front depths, pixel by pixel when the
//! block covers at most `frame::RECT_SCAN_MAX` of them; else from 16-pixel tiles)
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
pub use self::frame::{Frame, MAX_CELL_SPREAD_PIXELS, PIXEL_MARGIN};
pub use self::fuse::{
    DEFAULT_KEEP_CLUSTERS, DEFAULT_TRUNC_VOXELS, DEFAULT_VOXELS_PER_DEPTH_TRUNC, Fused,
    TsdfOptions, fuse, fuse_streamed, post_process, scene_radius,
};
pub use self::image::{
    ColorImage, DEFAULT_DEPTH_SCALE, DepthImage, find_image, read_color, read_color_dir,
    read_depth, read_depth_dir,
};
pub use self::params::{DepthLookup, TsdfParams};
pub use self::volume::{DEFAULT_MAX_BLOCKS, STREAM_BUDGET_BYTES, TsdfVolume};
