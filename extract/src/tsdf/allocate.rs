//! Which blocks the observed depth needs: the keys of every block within reach of a valid
//! pixel's back-projected point (see the [`crate::tsdf`] module docs), sorted and unique.

use std::sync::atomic::{AtomicBool, Ordering};

use glam::{DVec3, IVec3};
use rayon::prelude::*;

use super::error::TsdfError;
use super::frame::{Prepared, TILE, cell_range};
use super::params::TsdfParams;
use crate::block_grid::{BLOCK, KeyMap};

/// Voxel indices are kept within ±2³⁰ so that block keys and neighbours never overflow `i32`.
const MAX_VOXEL_INDEX: f64 = (1u64 << 30) as f64;

/// Calls `visit(lo, hi)` with the inclusive range of block keys that may hold a voxel with
/// |sdf| < trunc read from pixel `(i, j)` of row `i` of frame `f`, skipping repeats of the
/// previous pixel's range. A voxel reads the pixel's depth `d` when it projects into the
/// pixel's square `[j, j + 1] × [i, i + 1]`, or the cell interpolated from it and its right and
/// lower neighbours when it projects into `[j + ½, j + 3⁄2] × [i + ½, i + 3⁄2]` (depths
/// between the cell's smallest and largest, `lo` and `hi`); with |sdf| < trunc its z lies in
/// `(lo − trunc, hi + trunc)`. The range covers the frustum piece over the union of both
/// squares between those depths, widened by a voxel diagonal for the corners of the cells
/// around such voxels.
fn row_ranges(
    f: &Prepared<'_>,
    i: usize,
    params: TsdfParams,
    origin: DVec3,
    limit: usize,
    mut visit: impl FnMut(IVec3, IVec3),
) -> Result<(), TsdfError> {
    let margin = 3f64.sqrt() * params.voxel;
    let inv_voxel = 1.0 / params.voxel;
    let mut last: Option<(IVec3, IVec3)> = None;
    for j in 0..f.width {
        let k = i * f.width + j;
        let d = f.depth(k);
        if d <= 0.0 {
            continue;
        }
        let (lo, hi, reach) = if f.cell_ok(k) {
            let ([d00, d10], [d01, d11]) = (f.cells[k], f.cells[k + 1]);
            let (lo, hi) = cell_range([d00, d01.abs(), d10, d11]);
            (lo, hi, 1.5)
        } else {
            (d, d, 1.0)
        };
        let (b_min, b_max) = frustum_box(
            f,
            [j as f64, j as f64 + reach],
            [i as f64, i as f64 + reach],
            [f64::from(lo) - params.trunc, f64::from(hi) + params.trunc],
        );
        let lo = (b_min - margin - origin) * inv_voxel;
        let hi = (b_max + margin - origin) * inv_voxel;
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

/// The world box of the points that project into image rectangle `us × vs` (pixel units)
/// at camera depths `zs`: that of its eight corners (each coordinate is bilinear in the
/// normalised image coordinate and the depth, so its extremes are at corners).
fn frustum_box(f: &Prepared<'_>, us: [f64; 2], vs: [f64; 2], zs: [f64; 2]) -> (DVec3, DVec3) {
    let camera_to_world = f.world_to_camera.transpose();
    let xs = us.map(|u| (u - f.cx) / f.fx);
    let ys = vs.map(|v| (v - f.cy) / f.fy);
    let mut b_min = DVec3::INFINITY;
    let mut b_max = DVec3::NEG_INFINITY;
    for z in zs {
        for x in xs {
            for y in ys {
                let p = camera_to_world * DVec3::new(x * z, y * z, z) + f.center;
                b_min = b_min.min(p);
                b_max = b_max.max(p);
            }
        }
    }
    (b_min, b_max)
}

/// Component-wise floor of values within ±2³⁰ (checked by the caller), without the libm call
/// that `f64::floor` becomes on targets without SSE4.1.
#[inline]
pub(super) fn floor(v: DVec3) -> DVec3 {
    let t = v.as_i64vec3().as_dvec3();
    DVec3::select(t.cmpgt(v), t - 1.0, t)
}

/// The box of block keys that contains the range of every valid pixel of `f`, from its tiles:
/// each tile's pixels and the cells they start read within the tile's rectangle widened by
/// half a pixel right and down, at depths within its smallest and largest depth widened by
/// the largest spread of a cell there ([`Prepared::max_spread`] at the largest depth) and the
/// truncation (see [`row_ranges`]).
fn tile_bounds(
    f: &Prepared<'_>,
    params: TsdfParams,
    origin: DVec3,
) -> Result<Option<(IVec3, IVec3)>, TsdfError> {
    let margin = 3f64.sqrt() * params.voxel;
    let inv_voxel = 1.0 / params.voxel;
    let mut out: Option<(IVec3, IVec3)> = None;
    for (t, (&d_min, &d_max)) in f.tile_min.iter().zip(&f.tile_max).enumerate() {
        if d_max <= 0.0 {
            continue;
        }
        let (ty, tx) = (t / f.tiles_x, t % f.tiles_x);
        let (i0, j0) = (ty * TILE, tx * TILE);
        let (i1, j1) = ((i0 + TILE).min(f.height), (j0 + TILE).min(f.width));
        let (d_min, d_max) = (f64::from(d_min), f64::from(d_max));
        let reach = f.max_spread(d_max) + params.trunc;
        let (b_min, b_max) = frustum_box(
            f,
            [j0 as f64, j1 as f64 + 0.5],
            [i0 as f64, i1 as f64 + 0.5],
            [d_min - reach, d_max + reach],
        );
        let lo = (b_min - margin - origin) * inv_voxel;
        let hi = (b_max + margin - origin) * inv_voxel;
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
pub(super) fn frame_blocks(
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
