//! The sparse TSDF volume: block allocation near the observed depth, integration of frames,
//! and marching cubes of the result (the rules are in the [`crate::tsdf`] module docs).

use std::sync::atomic::{AtomicBool, Ordering};

use glam::{DMat3, DVec3, IVec3};
use rayon::prelude::*;
use trisplat_geometry::{Camera, TriMesh};

use super::error::TsdfError;
use super::image::{ColorImage, DepthImage};
use super::params::TsdfParams;
use crate::block_grid::{BLOCK, BLOCK_VOXELS, BlockGrid, KeyMap, local_coords};
use crate::marching_cubes::marching_cubes;

/// Projected coordinates must lie in `[PIXEL_MARGIN, size − PIXEL_MARGIN)` (Open3D's 0.0001).
pub const PIXEL_MARGIN: f64 = 1e-4;

/// Default cap on the number of 8³ blocks (about 4 KiB each without colour, 10 KiB with):
/// 2²⁰ blocks are 4 GiB. A voxel too small for the scene is refused instead of exhausting
/// memory.
pub const DEFAULT_MAX_BLOCKS: usize = 1 << 20;

/// Voxel indices are kept within ±2³⁰ so that block keys and neighbours never overflow `i32`.
const MAX_VOXEL_INDEX: f64 = (1u64 << 30) as f64;

/// Largest box of block keys marked in a dense array during allocation (16 Mi cells, 16 MiB);
/// larger boxes use a hash set.
const DENSE_MARK_CELLS: u64 = 1 << 24;

/// `RECIPROCALS[w] = 1 / (w + 1)`: the running average multiplies instead of dividing for
/// the first 256 observations of a voxel.
const RECIPROCALS: [f64; 256] = {
    let mut out = [0.0; 256];
    let mut w = 0;
    while w < 256 {
        out[w] = 1.0 / (w as f64 + 1.0);
        w += 1;
    }
    out
};

/// The frames of `cameras` with their loaded `images` (same order).
fn frames_of<'a>(
    cameras: &'a [Camera],
    images: &'a [(DepthImage, Option<ColorImage>)],
) -> Vec<Frame<'a>> {
    cameras
        .iter()
        .zip(images)
        .map(|(camera, (depth, color))| Frame {
            camera,
            depth,
            color: color.as_ref(),
        })
        .collect()
}

/// Memory for the per-view tables of one batch of [`TsdfVolume::integrate_streamed`] (the
/// images, their depth and tile tables: about 9 bytes per pixel, 21 with colour): 60 views of
/// 512² make one batch, read once for both passes.
pub const STREAM_BUDGET_BYTES: usize = 256 << 20;

/// Views per batch of [`TsdfVolume::integrate_streamed`]: as many of the largest camera's
/// size as fit in [`STREAM_BUDGET_BYTES`], at least one.
fn views_per_batch(cameras: &[Camera], with_color: bool) -> usize {
    let per_pixel = if with_color { 21 } else { 9 };
    let largest = cameras
        .iter()
        .map(|c| c.width as usize * c.height as usize)
        .max()
        .unwrap_or(1)
        .max(1);
    (STREAM_BUDGET_BYTES / (largest * per_pixel)).max(1)
}

/// Side of the square pixel tiles whose largest depth culls blocks behind the surface.
const TILE: usize = 16;

/// One view: a camera, its depth map and optionally its colours (same size as the camera).
#[derive(Clone, Copy, Debug)]
pub struct Frame<'a> {
    /// The camera.
    pub camera: &'a Camera,
    /// Its depth map.
    pub depth: &'a DepthImage,
    /// Its colour image, for coloured volumes.
    pub color: Option<&'a ColorImage>,
}

/// Per-frame data prepared once: camera maths, effective depth, culling tiles.
struct Prepared<'a> {
    name: &'a str,
    world_to_camera: DMat3,
    center: DVec3,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    width: usize,
    height: usize,
    /// Depth with invalid values and those beyond `depth_trunc` set to 0.
    depth: Vec<f32>,
    /// ((j + ½ − cx)/fx)² per column and ((i + ½ − cy)/fy)² per row: a pixel's ray-length
    /// factor is `sqrt(1 + col_sq[j] + row_sq[i])`.
    col_sq: Vec<f64>,
    row_sq: Vec<f64>,
    /// Largest depth per TILE x TILE tile (0 = no valid pixel).
    tile_max: Vec<f32>,
    /// Smallest valid depth per tile (`f32::INFINITY` = none).
    tile_min: Vec<f32>,
    /// Whether every pixel of the tile is valid.
    tile_full: Vec<bool>,
    tiles_x: usize,
    color: Option<&'a [[f32; 3]]>,
}

impl<'a> Prepared<'a> {
    /// The tables of `frame`.
    fn new(frame: &Frame<'a>, depth_trunc: f64) -> Result<Self, TsdfError> {
        let cam = frame.camera;
        let (width, height) = (cam.width as usize, cam.height as usize);
        if (frame.depth.width(), frame.depth.height()) != (cam.width, cam.height) {
            return Err(TsdfError::ImageSize {
                what: format!("depth map of camera {}", cam.name),
                expected: (cam.width, cam.height),
                found: format!("{}x{}", frame.depth.width(), frame.depth.height()),
            });
        }
        if let Some(c) = frame.color
            && (c.width(), c.height()) != (cam.width, cam.height)
        {
            return Err(TsdfError::ImageSize {
                what: format!("colour image of camera {}", cam.name),
                expected: (cam.width, cam.height),
                found: format!("{}x{}", c.width(), c.height()),
            });
        }
        let depth: Vec<f32> = frame
            .depth
            .data()
            .iter()
            .map(|&d| if f64::from(d) <= depth_trunc { d } else { 0.0 })
            .collect();
        let col_sq: Vec<f64> = (0..width)
            .map(|j| ((j as f64 + 0.5 - cam.cx) / cam.fx).powi(2))
            .collect();
        let row_sq: Vec<f64> = (0..height)
            .map(|i| ((i as f64 + 0.5 - cam.cy) / cam.fy).powi(2))
            .collect();
        let tiles_x = width.div_ceil(TILE);
        let tiles_y = height.div_ceil(TILE);
        let mut tile_max = vec![0.0f32; tiles_x * tiles_y];
        let mut tile_min = vec![f32::INFINITY; tiles_x * tiles_y];
        let mut tile_full = vec![true; tiles_x * tiles_y];
        for (i, row) in depth.chunks_exact(width).enumerate() {
            for (j, &d) in row.iter().enumerate() {
                let t = (i / TILE) * tiles_x + j / TILE;
                tile_max[t] = tile_max[t].max(d);
                if d > 0.0 {
                    tile_min[t] = tile_min[t].min(d);
                } else {
                    tile_full[t] = false;
                }
            }
        }
        Ok(Self {
            name: &cam.name,
            world_to_camera: cam.world_to_camera_rotation(),
            center: cam.position(),
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            width,
            height,
            depth,
            col_sq,
            row_sq,
            tile_max,
            tile_min,
            tile_full,
            tiles_x,
            color: frame.color.map(ColorImage::data),
        })
    }

    /// What this frame does to the voxels of the box `[lo, hi]` (world; the first and last
    /// voxel centres of a block): nothing when the box is behind the camera, projects outside
    /// the image, or lies more than `trunc` behind the farthest depth of the pixels it covers;
    /// tsdf = 1 for every voxel when the whole box projects inside the image onto valid
    /// pixels and lies at least `trunc` in front of the nearest of them; otherwise it must be
    /// looked at voxel by voxel.
    fn visit(&self, lo: DVec3, hi: DVec3, trunc: f64) -> Visit {
        let mut z_min = f64::INFINITY;
        let mut z_max = f64::NEG_INFINITY;
        let (mut u_min, mut u_max) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut v_min, mut v_max) = (f64::INFINITY, f64::NEG_INFINITY);
        for c in 0..8 {
            let p = DVec3::new(
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            );
            let q = self.world_to_camera * (p - self.center);
            z_min = z_min.min(q.z);
            z_max = z_max.max(q.z);
            if q.z > 0.0 {
                let (u, v) = (self.fx * q.x / q.z + self.cx, self.fy * q.y / q.z + self.cy);
                u_min = u_min.min(u);
                u_max = u_max.max(u);
                v_min = v_min.min(v);
                v_max = v_max.max(v);
            }
        }
        if z_max <= 0.0 {
            return Visit::Skip;
        }
        if z_min <= 0.0 {
            // Straddles the camera plane: the projection is unbounded.
            return Visit::Voxels;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        if u_max < PIXEL_MARGIN
            || v_max < PIXEL_MARGIN
            || u_min >= w - PIXEL_MARGIN
            || v_min >= h - PIXEL_MARGIN
        {
            return Visit::Skip;
        }
        let inside = u_min >= PIXEL_MARGIN
            && v_min >= PIXEL_MARGIN
            && u_max < w - PIXEL_MARGIN
            && v_max < h - PIXEL_MARGIN;
        // The pixels the voxel centres can land on (the projection of the box lies in the
        // box of its projected corners).
        let col = |u: f64| u.clamp(0.0, w - 1.0) as usize;
        let row = |v: f64| v.clamp(0.0, h - 1.0) as usize;
        let (j0, j1, i0, i1) = (col(u_min), col(u_max), row(v_min), row(v_max));
        let range = if (j1 - j0 + 1) * (i1 - i0 + 1) <= RECT_SCAN_MAX {
            self.rect_depths(j0, j1, i0, i1)
        } else {
            self.tile_depths(j0, j1, i0, i1)
        };
        // sdf ≤ (d_max − z_min) · factor and factor ≥ 1: nothing passes sdf > −trunc.
        if range.max == 0.0 || z_min - f64::from(range.max) >= trunc {
            return Visit::Skip;
        }
        // sdf ≥ (d_min − z_max) · factor ≥ trunc for every voxel: tsdf = 1.
        if inside && range.all_valid && f64::from(range.min) - z_max >= trunc {
            return Visit::Free;
        }
        Visit::Voxels
    }

    /// The depth range of the pixels `[j0, j1] × [i0, i1]`, read one by one.
    fn rect_depths(&self, j0: usize, j1: usize, i0: usize, i1: usize) -> DepthRange {
        let mut range = DepthRange::EMPTY;
        for i in i0..=i1 {
            for &d in &self.depth[i * self.width + j0..=i * self.width + j1] {
                range.add(d, d > 0.0);
            }
        }
        range
    }

    /// A depth range containing that of the pixels `[j0, j1] × [i0, i1]`, from the tiles
    /// that cover them.
    fn tile_depths(&self, j0: usize, j1: usize, i0: usize, i1: usize) -> DepthRange {
        let mut range = DepthRange::EMPTY;
        for ty in i0 / TILE..=i1 / TILE {
            for tx in j0 / TILE..=j1 / TILE {
                let t = ty * self.tiles_x + tx;
                range.max = range.max.max(self.tile_max[t]);
                range.min = range.min.min(self.tile_min[t]);
                range.all_valid &= self.tile_full[t];
            }
        }
        range
    }
}

/// Largest rectangle of pixels scanned one by one by [`Prepared::visit`] (larger ones use the
/// tiles).
const RECT_SCAN_MAX: usize = 64;

/// What a frame does to a block ([`Prepared::visit`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Visit {
    /// Nothing: no voxel is integrated.
    Skip,
    /// Every voxel is integrated with tsdf = 1 (free space in front of the surface).
    Free,
    /// Each voxel must be projected.
    Voxels,
}

/// Depths seen over some pixels: the largest (0 when none is valid), the smallest valid
/// (`+∞` when none), and whether every pixel is valid.
#[derive(Clone, Copy, Debug)]
struct DepthRange {
    max: f32,
    min: f32,
    all_valid: bool,
}

impl DepthRange {
    const EMPTY: Self = Self {
        max: 0.0,
        min: f32::INFINITY,
        all_valid: true,
    };

    /// Adds a depth, valid or not (an invalid depth is 0 and only clears `all_valid`).
    #[inline]
    fn add(&mut self, d: f32, valid: bool) {
        self.max = self.max.max(d);
        if valid {
            self.min = self.min.min(d);
        } else {
            self.all_valid = false;
        }
    }
}

/// A sparse TSDF volume (see the module docs).
#[derive(Clone, Debug)]
pub struct TsdfVolume {
    grid: BlockGrid,
    params: TsdfParams,
    max_blocks: usize,
}

impl TsdfVolume {
    /// An empty volume; `with_color` keeps a colour per voxel (frames must then carry colour
    /// images).
    ///
    /// # Errors
    /// [`TsdfError::Parameter`] for invalid parameters.
    pub fn new(params: TsdfParams, with_color: bool) -> Result<Self, TsdfError> {
        params.validate()?;
        Ok(Self {
            grid: BlockGrid::new(params.voxel, DVec3::splat(0.5 * params.voxel), with_color),
            params,
            max_blocks: DEFAULT_MAX_BLOCKS,
        })
    }

    /// Sets the cap on the number of blocks (default [`DEFAULT_MAX_BLOCKS`]).
    #[must_use]
    pub fn with_max_blocks(mut self, max_blocks: usize) -> Self {
        self.max_blocks = max_blocks;
        self
    }

    /// The parameters.
    #[must_use]
    pub fn params(&self) -> TsdfParams {
        self.params
    }

    /// The voxel blocks (values, weights, colours).
    #[must_use]
    pub fn grid(&self) -> &BlockGrid {
        &self.grid
    }

    /// Creates the blocks near the observed depth of `frames` (see the module docs), without
    /// integrating. New blocks are added in sorted key order, so the block order depends only
    /// on the frames.
    ///
    /// # Errors
    /// [`TsdfError::ImageSize`] for a depth map of the wrong size,
    /// [`TsdfError::OutOfRange`] for points too far from the origin,
    /// [`TsdfError::TooManyBlocks`] past the block cap.
    pub fn allocate(&mut self, frames: &[Frame<'_>]) -> Result<(), TsdfError> {
        let prepared = self.prepare(frames)?;
        self.allocate_prepared(&prepared)
    }

    /// [`TsdfVolume::allocate`] on frames prepared by [`TsdfVolume::prepare`].
    fn allocate_prepared(&mut self, prepared: &[Prepared<'_>]) -> Result<(), TsdfError> {
        let keys = self.blocks_near(prepared)?;
        self.add_blocks(keys)
    }

    /// Keys of the blocks near the observed depth of `prepared`, sorted and unique (existing
    /// blocks included).
    fn blocks_near(&self, prepared: &[Prepared<'_>]) -> Result<Vec<IVec3>, TsdfError> {
        frame_blocks(
            prepared,
            self.params,
            self.grid.origin,
            self.max_blocks,
            DENSE_MARK_CELLS,
        )
    }

    /// Adds the blocks of `all` (sorted and unique) that do not exist yet, in that order.
    fn add_blocks(&mut self, mut all: Vec<IVec3>) -> Result<(), TsdfError> {
        let (limit, params) = (self.max_blocks, self.params);
        all.retain(|k| !self.grid.lookup.contains_key(k));
        if self.grid.block_count() + all.len() > limit {
            return Err(TsdfError::TooManyBlocks {
                limit,
                voxel: params.voxel,
            });
        }
        self.grid.push_blocks(&all);
        Ok(())
    }

    /// Integrates `frames` in order into the existing blocks (see the module docs). Blocks
    /// are not created: call [`TsdfVolume::allocate`] first with every frame to get the
    /// result of a dense volume, or use [`TsdfVolume::integrate`].
    ///
    /// # Errors
    /// [`TsdfError::ImageSize`] for an image of the wrong size, [`TsdfError::NoColor`] when
    /// the volume has colour and a frame has none.
    pub fn integrate_allocated(&mut self, frames: &[Frame<'_>]) -> Result<(), TsdfError> {
        let prepared = self.prepare(frames)?;
        self.integrate_prepared(&prepared);
        Ok(())
    }

    /// [`TsdfVolume::integrate_allocated`] on frames prepared by [`TsdfVolume::prepare`].
    fn integrate_prepared(&mut self, prepared: &[Prepared<'_>]) {
        let params = self.params;
        let grid = &mut self.grid;
        let (voxel, origin) = (grid.voxel, grid.origin);
        let keys = &grid.keys;
        match &mut grid.color {
            Some(color) => grid
                .value
                .par_chunks_mut(BLOCK_VOXELS)
                .zip(grid.weight.par_chunks_mut(BLOCK_VOXELS))
                .zip(color.par_chunks_mut(BLOCK_VOXELS))
                .zip(keys.par_iter())
                .for_each(|(((value, weight), color), &key)| {
                    let block = BlockData {
                        value,
                        weight,
                        color: Some(color),
                    };
                    integrate_block(block, key, voxel, origin, prepared, params);
                }),
            None => grid
                .value
                .par_chunks_mut(BLOCK_VOXELS)
                .zip(grid.weight.par_chunks_mut(BLOCK_VOXELS))
                .zip(keys.par_iter())
                .for_each(|((value, weight), &key)| {
                    let block = BlockData {
                        value,
                        weight,
                        color: None,
                    };
                    integrate_block(block, key, voxel, origin, prepared, params);
                }),
        }
    }

    /// Allocates the blocks `frames` need, then integrates them: the result equals Open3D's
    /// dense legacy volume on the same frames (up to f32 rounding). Calling it once per frame
    /// instead gives Open3D `VoxelBlockGrid` behaviour, where blocks created by a later frame
    /// lack the earlier frames' free-space observations.
    ///
    /// # Errors
    /// As [`TsdfVolume::allocate`] and [`TsdfVolume::integrate_allocated`].
    pub fn integrate(&mut self, frames: &[Frame<'_>]) -> Result<(), TsdfError> {
        self.integrate_timed(frames).map(|_| ())
    }

    /// [`TsdfVolume::integrate`] with views produced on demand, a batch at a time, so that
    /// memory does not grow with the number of views: `load(i)` gives view `i`'s depth image
    /// (and colour image for a coloured volume), read or made when needed, twice per view
    /// (allocation, then integration) unless all views fit in one batch (then once), views of
    /// a batch in parallel. Batches hold as many
    /// views as fit in [`STREAM_BUDGET_BYTES`] of per-view tables (at least one). The result
    /// is [`TsdfVolume::integrate`]'s on all the views at once. Returns (seconds reading and
    /// allocating, seconds reading and integrating).
    ///
    /// # Errors
    /// `load`'s errors, and those of [`TsdfVolume::integrate`].
    pub fn integrate_streamed<L>(
        &mut self,
        cameras: &[Camera],
        load: L,
    ) -> Result<(f64, f64), TsdfError>
    where
        L: Fn(usize) -> Result<(DepthImage, Option<ColorImage>), TsdfError> + Sync,
    {
        let batch = views_per_batch(cameras, self.grid.has_color());
        self.integrate_in_batches(cameras, load, batch)
    }

    /// [`TsdfVolume::integrate_streamed`] with `batch` views per batch.
    fn integrate_in_batches<L>(
        &mut self,
        cameras: &[Camera],
        load: L,
        batch: usize,
    ) -> Result<(f64, f64), TsdfError>
    where
        L: Fn(usize) -> Result<(DepthImage, Option<ColorImage>), TsdfError> + Sync,
    {
        let batch = batch.max(1);
        let load_batch = |views: std::ops::Range<usize>| -> Result<Vec<_>, TsdfError> {
            views.into_par_iter().map(&load).collect()
        };
        let batches: Vec<std::ops::Range<usize>> = (0..cameras.len())
            .step_by(batch)
            .map(|start| start..(start + batch).min(cameras.len()))
            .collect();
        let start = std::time::Instant::now();
        if let [all] = batches.as_slice() {
            // Every view fits at once: read each one once for both passes.
            let images = load_batch(all.clone())?;
            let prepared = self.prepare(&frames_of(&cameras[all.clone()], &images))?;
            self.allocate_prepared(&prepared)?;
            let allocate = start.elapsed().as_secs_f64();
            let start = std::time::Instant::now();
            self.integrate_prepared(&prepared);
            return Ok((allocate, start.elapsed().as_secs_f64()));
        }
        let mut keys = Vec::new();
        for range in &batches {
            let images = load_batch(range.clone())?;
            let prepared = self.prepare(&frames_of(&cameras[range.clone()], &images))?;
            keys.extend(self.blocks_near(&prepared)?);
            keys.par_sort_unstable_by_key(|k| (k.z, k.y, k.x));
            keys.dedup();
        }
        self.add_blocks(keys)?;
        let allocate = start.elapsed().as_secs_f64();
        let start = std::time::Instant::now();
        for range in &batches {
            let images = load_batch(range.clone())?;
            let prepared = self.prepare(&frames_of(&cameras[range.clone()], &images))?;
            self.integrate_prepared(&prepared);
        }
        Ok((allocate, start.elapsed().as_secs_f64()))
    }

    /// [`TsdfVolume::integrate`], timed: (seconds preparing the frames and allocating,
    /// seconds integrating).
    pub(crate) fn integrate_timed(
        &mut self,
        frames: &[Frame<'_>],
    ) -> Result<(f64, f64), TsdfError> {
        let start = std::time::Instant::now();
        let prepared = self.prepare(frames)?;
        self.allocate_prepared(&prepared)?;
        let allocate = start.elapsed().as_secs_f64();
        let start = std::time::Instant::now();
        self.integrate_prepared(&prepared);
        Ok((allocate, start.elapsed().as_secs_f64()))
    }

    /// The zero level set by marching cubes (welded, faces toward free space, cells with an
    /// unobserved corner skipped), with vertex colours when the volume has them. Not cleaned:
    /// see [`post_process`].
    #[must_use]
    pub fn extract_mesh(&self) -> TriMesh {
        marching_cubes(&self.grid)
    }

    /// The per-frame data of `frames` (checked sizes, camera maths, depth and tile tables).
    fn prepare<'a>(&self, frames: &[Frame<'a>]) -> Result<Vec<Prepared<'a>>, TsdfError> {
        let with_color = self.grid.has_color();
        let prepared: Vec<Result<Prepared<'a>, TsdfError>> = frames
            .par_iter()
            .map(|f| {
                if with_color && f.color.is_none() {
                    return Err(TsdfError::NoColor {
                        camera: f.camera.name.clone(),
                    });
                }
                Prepared::new(f, self.params.depth_trunc)
            })
            .collect();
        prepared.into_iter().collect()
    }
}

/// Calls `visit(lo, hi)` with the inclusive range of block keys near each valid pixel of row
/// `i` of frame `f` (see the module docs), skipping repeats of the previous pixel's range.
fn row_ranges(
    f: &Prepared<'_>,
    i: usize,
    params: TsdfParams,
    origin: DVec3,
    limit: usize,
    mut visit: impl FnMut(IVec3, IVec3),
) -> Result<(), TsdfError> {
    let camera_to_world = f.world_to_camera.transpose();
    let lateral = 0.5 * (1.0 / (f.fx * f.fx) + 1.0 / (f.fy * f.fy)).sqrt();
    let fixed = params.trunc + 3f64.sqrt() * params.voxel;
    let inv_voxel = 1.0 / params.voxel;
    let yn = (i as f64 + 0.5 - f.cy) / f.fy;
    let mut last: Option<(IVec3, IVec3)> = None;
    for j in 0..f.width {
        let d = f64::from(f.depth[i * f.width + j]);
        if d <= 0.0 {
            continue;
        }
        let xn = (j as f64 + 0.5 - f.cx) / f.fx;
        let p = camera_to_world * DVec3::new(xn * d, yn * d, d) + f.center;
        let r = fixed + (d + params.trunc) * lateral;
        let lo = (p - r - origin) * inv_voxel;
        let hi = (p + r - origin) * inv_voxel;
        if lo.abs().max_element() > MAX_VOXEL_INDEX || hi.abs().max_element() > MAX_VOXEL_INDEX {
            return Err(TsdfError::OutOfRange {
                camera: f.name.to_owned(),
            });
        }
        // Voxel range ceil(lo)..=floor(hi), then the blocks holding its ends.
        let lo = (-floor(-lo)).as_ivec3().div_euclid(IVec3::splat(BLOCK));
        let hi = floor(hi).as_ivec3().div_euclid(IVec3::splat(BLOCK));
        if last == Some((lo, hi)) {
            continue;
        }
        last = Some((lo, hi));
        let span = (hi - lo + 1).max(IVec3::ZERO).as_u64vec3();
        if span.x * span.y * span.z > limit as u64 {
            return Err(TsdfError::TooManyBlocks {
                limit,
                voxel: params.voxel,
            });
        }
        visit(lo, hi);
    }
    Ok(())
}

/// Component-wise floor of values within ±2³⁰ (checked by the caller), without the libm call
/// that `f64::floor` becomes on targets without SSE4.1.
#[inline]
fn floor(v: DVec3) -> DVec3 {
    let t = v.as_i64vec3().as_dvec3();
    DVec3::select(t.cmpgt(v), t - 1.0, t)
}

/// The box of block keys that contains the range of every valid pixel of `f`, from its tiles:
/// each tile's pixels lie in the frustum piece between its smallest and largest depth, whose
/// box is that of its eight corners; the radius is the largest the tile's depths give.
fn tile_bounds(
    f: &Prepared<'_>,
    params: TsdfParams,
    origin: DVec3,
) -> Result<Option<(IVec3, IVec3)>, TsdfError> {
    let camera_to_world = f.world_to_camera.transpose();
    let lateral = 0.5 * (1.0 / (f.fx * f.fx) + 1.0 / (f.fy * f.fy)).sqrt();
    let fixed = params.trunc + 3f64.sqrt() * params.voxel;
    let inv_voxel = 1.0 / params.voxel;
    let mut out: Option<(IVec3, IVec3)> = None;
    for (t, (&d_min, &d_max)) in f.tile_min.iter().zip(&f.tile_max).enumerate() {
        if d_max <= 0.0 {
            continue;
        }
        let (ty, tx) = (t / f.tiles_x, t % f.tiles_x);
        let (i0, j0) = (ty * TILE, tx * TILE);
        let (i1, j1) = ((i0 + TILE).min(f.height) - 1, (j0 + TILE).min(f.width) - 1);
        let xs = [j0, j1].map(|j| (j as f64 + 0.5 - f.cx) / f.fx);
        let ys = [i0, i1].map(|i| (i as f64 + 0.5 - f.cy) / f.fy);
        let mut b_min = DVec3::INFINITY;
        let mut b_max = DVec3::NEG_INFINITY;
        for d in [f64::from(d_min), f64::from(d_max)] {
            for x in xs {
                for y in ys {
                    let p = camera_to_world * DVec3::new(x * d, y * d, d) + f.center;
                    b_min = b_min.min(p);
                    b_max = b_max.max(p);
                }
            }
        }
        let r = fixed + (f64::from(d_max) + params.trunc) * lateral;
        let lo = (b_min - r - origin) * inv_voxel;
        let hi = (b_max + r - origin) * inv_voxel;
        if lo.abs().max_element() > MAX_VOXEL_INDEX || hi.abs().max_element() > MAX_VOXEL_INDEX {
            return Err(TsdfError::OutOfRange {
                camera: f.name.to_owned(),
            });
        }
        let lo = floor(lo).as_ivec3().div_euclid(IVec3::splat(BLOCK));
        let hi = (-floor(-hi)).as_ivec3().div_euclid(IVec3::splat(BLOCK));
        out = Some(out.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
    }
    Ok(out)
}

/// Every row of a frame, as (frame, row index) pairs.
fn rows<'f, 'a>(
    f: &'f Prepared<'a>,
) -> impl ParallelIterator<Item = (&'f Prepared<'a>, usize)> + use<'f, 'a> {
    (0..f.height).into_par_iter().map(move |i| (f, i))
}

/// Keys of the blocks near the valid depth of `frames`, sorted by (z, y, x) and unique.
///
/// A first pass finds the box of block keys the ranges cover; when it has at most
/// `dense_cells` cells ([`DENSE_MARK_CELLS`] in [`TsdfVolume::allocate`]), ranges are marked in a dense array (cheap stores), else they go
/// through a hash set per row.
fn frame_blocks(
    frames: &[Prepared<'_>],
    params: TsdfParams,
    origin: DVec3,
    limit: usize,
    dense_cells: u64,
) -> Result<Vec<IVec3>, TsdfError> {
    let bounds = frames
        .par_iter()
        .map(|f| tile_bounds(f, params, origin))
        .try_reduce(
            || None,
            |a, b| {
                Ok(match (a, b) {
                    (Some((a0, a1)), Some((b0, b1))) => Some((a0.min(b0), a1.max(b1))),
                    (x, None) | (None, x) => x,
                })
            },
        )?;
    let Some((lo, hi)) = bounds else {
        return Ok(Vec::new());
    };
    let dims = (hi - lo + 1).as_u64vec3();
    let cells = dims.x * dims.y * dims.z;
    if cells <= dense_cells {
        let (nx, ny) = (dims.x as usize, dims.y as usize);
        let marks: Vec<AtomicBool> = (0..cells).map(|_| AtomicBool::new(false)).collect();
        let outside = AtomicBool::new(false);
        frames.par_iter().flat_map(rows).try_for_each(|(f, i)| {
            row_ranges(f, i, params, origin, limit, |a, b| {
                // The tile boxes contain every pixel's range; never trust that blindly.
                if a.cmplt(lo).any() || b.cmpgt(hi).any() {
                    outside.store(true, Ordering::Relaxed);
                    return;
                }
                let (a, b) = ((a - lo).as_uvec3(), (b - lo).as_uvec3());
                for z in a.z..=b.z {
                    for y in a.y..=b.y {
                        let row = (z as usize * ny + y as usize) * nx;
                        for x in a.x..=b.x {
                            marks[row + x as usize].store(true, Ordering::Relaxed);
                        }
                    }
                }
            })
        })?;
        let keys: Vec<IVec3> = marks
            .iter()
            .enumerate()
            .filter(|(_, m)| m.load(Ordering::Relaxed))
            .map(|(k, _)| {
                let (x, rest) = (k % nx, k / nx);
                lo + IVec3::new(x as i32, (rest % ny) as i32, (rest / ny) as i32)
            })
            .collect();
        if keys.len() > limit {
            return Err(TsdfError::TooManyBlocks {
                limit,
                voxel: params.voxel,
            });
        }
        if !outside.load(Ordering::Relaxed) {
            return Ok(keys);
        }
        debug_assert!(false, "a pixel's block range left its tile's box");
    }
    let per_row: Vec<Vec<IVec3>> = frames
        .par_iter()
        .flat_map(rows)
        .map(|(f, i)| {
            let mut keys: KeyMap<()> = KeyMap::default();
            let mut too_many = false;
            row_ranges(f, i, params, origin, limit, |a, b| {
                for z in a.z..=b.z {
                    for y in a.y..=b.y {
                        for x in a.x..=b.x {
                            keys.insert(IVec3::new(x, y, z), ());
                        }
                    }
                }
                too_many |= keys.len() > limit;
            })?;
            if too_many {
                return Err(TsdfError::TooManyBlocks {
                    limit,
                    voxel: params.voxel,
                });
            }
            Ok(keys.into_keys().collect())
        })
        .collect::<Result<_, TsdfError>>()?;
    let mut all: Vec<IVec3> = per_row.into_iter().flatten().collect();
    all.par_sort_unstable_by_key(|k| (k.z, k.y, k.x));
    all.dedup();
    if all.len() > limit {
        return Err(TsdfError::TooManyBlocks {
            limit,
            voxel: params.voxel,
        });
    }
    Ok(all)
}

/// Mutable storage of one block.
struct BlockData<'a> {
    value: &'a mut [f32],
    weight: &'a mut [f32],
    color: Option<&'a mut [[f32; 3]]>,
}

/// Integrates every frame, in order, into one block.
fn integrate_block(
    mut block: BlockData<'_>,
    key: IVec3,
    voxel: f64,
    origin: DVec3,
    frames: &[Prepared<'_>],
    params: TsdfParams,
) {
    let trunc = params.trunc;
    let inv_trunc = 1.0 / trunc;
    let base = key * BLOCK;
    let lo = origin + base.as_dvec3() * voxel;
    let hi = lo + DVec3::splat(f64::from(BLOCK - 1) * voxel);
    for f in frames {
        match f.visit(lo, hi, trunc) {
            Visit::Skip => continue,
            Visit::Free if block.color.is_none() => {
                integrate_free(block.value, block.weight);
                continue;
            }
            Visit::Free | Visit::Voxels => {}
        }
        let step = f.world_to_camera * DVec3::new(voxel, 0.0, 0.0);
        if block.color.is_none() {
            for start in (0..BLOCK_VOXELS).step_by(ROW) {
                let l = local_coords(start);
                let p = origin + (base + l).as_dvec3() * voxel;
                let q = f.world_to_camera * (p - f.center);
                let row = start..start + ROW;
                integrate_row(
                    f,
                    q,
                    step,
                    trunc,
                    (&mut block.value[row.clone()])
                        .try_into()
                        .expect("a block row"),
                    (&mut block.weight[row]).try_into().expect("a block row"),
                );
            }
            continue;
        }
        let (w, h) = (f.width as f64, f.height as f64);
        for start in (0..BLOCK_VOXELS).step_by(ROW) {
            let l = local_coords(start);
            let p = origin + (base + l).as_dvec3() * voxel;
            let mut q = f.world_to_camera * (p - f.center);
            for s in start..start + ROW {
                if s > start {
                    q += step;
                }
                if q.z <= 0.0 {
                    continue;
                }
                let inv_z = 1.0 / q.z;
                let u = f.fx * q.x * inv_z + f.cx;
                let v = f.fy * q.y * inv_z + f.cy;
                if !(u >= PIXEL_MARGIN
                    && u < w - PIXEL_MARGIN
                    && v >= PIXEL_MARGIN
                    && v < h - PIXEL_MARGIN)
                {
                    continue;
                }
                let (j, i) = (u as usize, v as usize);
                let pixel = i * f.width + j;
                let d = f.depth[pixel];
                if d <= 0.0 {
                    continue;
                }
                // The ray-length factor is ≥ 1: sdf ≥ trunc when dz ≥ trunc (tsdf = 1) and
                // sdf ≤ −trunc when dz ≤ −trunc, so the square root is only needed between.
                let dz = f64::from(d) - q.z;
                if dz <= -trunc {
                    continue;
                }
                let tsdf = if dz >= trunc {
                    1.0
                } else {
                    let sdf = dz * (1.0 + f.col_sq[j] + f.row_sq[i]).sqrt();
                    if sdf <= -trunc {
                        continue;
                    }
                    (sdf * inv_trunc).min(1.0)
                };
                let w0 = f64::from(block.weight[s]);
                let w1 = w0 + 1.0;
                let inv_w1 = RECIPROCALS.get(w0 as usize).copied().unwrap_or(1.0 / w1);
                block.value[s] = ((f64::from(block.value[s]) * w0 + tsdf) * inv_w1) as f32;
                block.weight[s] = w1 as f32;
                if let (Some(color), Some(image)) = (block.color.as_deref_mut(), f.color) {
                    let c = image[pixel];
                    let old = color[s];
                    color[s] =
                        [0, 1, 2].map(|k| ((f64::from(old[k]) * w0 + f64::from(c[k])) / w1) as f32);
                }
            }
        }
    }
}

/// Integrates tsdf = 1 into every voxel of a block (in f64, as [`integrate_row`]).
fn integrate_free(value: &mut [f32], weight: &mut [f32]) {
    for (v, w) in value.iter_mut().zip(weight.iter_mut()) {
        let w0 = f64::from(*w);
        *v = ((f64::from(*v) * w0 + 1.0) / (w0 + 1.0)) as f32;
        *w += 1.0;
    }
}

/// Voxels in a row of a block (along x).
const ROW: usize = BLOCK as usize;

/// Integrates one frame into one row of [`ROW`] voxels whose first voxel is at camera-space `q`
/// and whose next ones follow by `step`, without branches per voxel so that the compiler can
/// run the lanes side by side: project, look up the pixel (one load of its depth and ray
/// factor), then update the lanes that pass. All in f64, as the plain rule.
#[inline]
fn integrate_row(
    f: &Prepared<'_>,
    q: DVec3,
    step: DVec3,
    trunc: f64,
    value: &mut [f32; ROW],
    weight: &mut [f32; ROW],
) {
    let (u_end, v_end) = (
        f.width as f64 - PIXEL_MARGIN,
        f.height as f64 - PIXEL_MARGIN,
    );
    let mut col = [0u32; ROW];
    let mut row = [0u32; ROW];
    let mut inside = [false; ROW];
    let mut z = [0.0f64; ROW];
    for k in 0..ROW {
        let kf = k as f64;
        let (qx, qy, qz) = (q.x + kf * step.x, q.y + kf * step.y, q.z + kf * step.z);
        let inv_z = 1.0 / qz;
        let u = f.fx * qx * inv_z + f.cx;
        let v = f.fy * qy * inv_z + f.cy;
        let ok = (qz > 0.0) & (u >= PIXEL_MARGIN) & (u < u_end) & (v >= PIXEL_MARGIN) & (v < v_end);
        let (j, i) = if ok { (u as u32, v as u32) } else { (0, 0) };
        col[k] = j;
        row[k] = i;
        inside[k] = ok;
        z[k] = qz;
    }
    if !inside.iter().any(|&b| b) {
        return;
    }
    // The pixel's depth and its ray-length factor, from the per-column and per-row tables
    // (small enough to stay in cache) rather than a per-pixel table.
    let mut sample = [[0.0f64; 2]; ROW];
    for k in 0..ROW {
        let (j, i) = (col[k] as usize, row[k] as usize);
        sample[k] = [
            f64::from(f.depth[i * f.width + j]),
            (1.0 + f.col_sq[j] + f.row_sq[i]).sqrt(),
        ];
    }
    let inv_trunc = 1.0 / trunc;
    for k in 0..ROW {
        let [d, ray] = sample[k];
        let sdf = (d - z[k]) * ray;
        let ok = inside[k] & (d > 0.0) & (sdf > -trunc);
        let tsdf = (sdf * inv_trunc).min(1.0);
        let w0 = f64::from(weight[k]);
        let averaged = ((f64::from(value[k]) * w0 + tsdf) / (w0 + 1.0)) as f32;
        value[k] = if ok { averaged } else { value[k] };
        weight[k] = if ok { weight[k] + 1.0 } else { weight[k] };
    }
}

#[cfg(test)]
mod tests;
