//! The sparse TSDF volume: its blocks, allocation near the observed depth of frames,
//! integration (all at once or streamed in batches), and marching cubes of the result (the
//! rules are in the [`crate::tsdf`] module docs).

use glam::{DVec3, IVec3};
use rayon::prelude::*;
use trisplat_geometry::{Camera, TriMesh};

use super::allocate::frame_blocks;
use super::error::TsdfError;
use super::frame::{Frame, Prepared};
use super::image::{ColorImage, DepthImage};
use super::integrate::{BlockData, integrate_block};
use super::params::{DepthLookup, TsdfParams};
use crate::block_grid::{BLOCK_VOXELS, BlockGrid};
use crate::marching_cubes::marching_cubes;

/// Default cap on the number of 8³ blocks (about 4 KiB each without colour, 10 KiB with):
/// 2²⁰ blocks are 4 GiB. A voxel too small for the scene is refused instead of exhausting
/// memory.
pub const DEFAULT_MAX_BLOCKS: usize = 1 << 20;

/// Largest box of block keys marked in a dense array during allocation (16 Mi cells, 16 MiB);
/// larger boxes use a hash set.
const DENSE_MARK_CELLS: u64 = 1 << 24;

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
/// images, their depth-pair, window and tile tables: about 15 bytes per pixel, 27 with colour): 60
/// views of 512² make one batch, read once for both passes.
pub const STREAM_BUDGET_BYTES: usize = 256 << 20;

/// Views per batch of [`TsdfVolume::integrate_streamed`]: as many of the largest camera's
/// size as fit in [`STREAM_BUDGET_BYTES`], at least one.
fn views_per_batch(cameras: &[Camera], with_color: bool) -> usize {
    let per_pixel = if with_color { 27 } else { 15 };
    let largest = cameras
        .iter()
        .map(|c| c.width as usize * c.height as usize)
        .max()
        .unwrap_or(1)
        .max(1);
    (STREAM_BUDGET_BYTES / (largest * per_pixel)).max(1)
}

/// A sparse TSDF volume (see the module docs).
#[derive(Clone, Debug)]
pub struct TsdfVolume {
    grid: BlockGrid,
    params: TsdfParams,
    max_blocks: usize,
    lookup: DepthLookup,
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
            lookup: DepthLookup::default(),
        })
    }

    /// Sets the cap on the number of blocks (default [`DEFAULT_MAX_BLOCKS`]).
    #[must_use]
    pub fn with_max_blocks(mut self, max_blocks: usize) -> Self {
        self.max_blocks = max_blocks;
        self
    }

    /// Sets how voxels read the depth (default [`DepthLookup::Bilinear`]; set it before
    /// allocating: with [`DepthLookup::Nearest`] fewer blocks are needed).
    #[must_use]
    pub fn with_depth_lookup(mut self, lookup: DepthLookup) -> Self {
        self.lookup = lookup;
        self
    }

    /// How voxels read the depth.
    #[must_use]
    pub fn depth_lookup(&self) -> DepthLookup {
        self.lookup
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
        let (params, lookup) = (self.params, self.lookup);
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
                    integrate_block(block, key, voxel, origin, prepared, params, lookup);
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
                    integrate_block(block, key, voxel, origin, prepared, params, lookup);
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
    /// see [`super::post_process`].
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
                Prepared::new(f, self.params.depth_trunc, self.params.trunc, self.lookup)
            })
            .collect();
        prepared.into_iter().collect()
    }
}

#[cfg(test)]
mod tests;
