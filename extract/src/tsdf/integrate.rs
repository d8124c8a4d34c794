//! Integrating prepared frames, in order, into one block: the per-voxel running average of
//! the truncated signed distance (and colour), row by row.

use glam::{DVec3, IVec3};

use super::frame::{PIXEL_MARGIN, Prepared, RowBounds, Visit};
use super::params::{DepthLookup, TsdfParams};
use crate::block_grid::{BLOCK, BLOCK_VOXELS, local_coords};

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

/// Mutable storage of one block.
pub(super) struct BlockData<'a> {
    pub(super) value: &'a mut [f32],
    pub(super) weight: &'a mut [f32],
    pub(super) color: Option<&'a mut [[f32; 3]]>,
}

/// Integrates every frame, in order, into one block.
pub(super) fn integrate_block(
    mut block: BlockData<'_>,
    key: IVec3,
    voxel: f64,
    origin: DVec3,
    frames: &[Prepared<'_>],
    params: TsdfParams,
    lookup: DepthLookup,
) {
    let trunc = params.trunc;
    let inv_trunc = 1.0 / trunc;
    let base = key * BLOCK;
    let lo = origin + base.as_dvec3() * voxel;
    let hi = lo + DVec3::splat(f64::from(BLOCK - 1) * voxel);
    for f in frames {
        let bounds = match f.visit(lo, hi, trunc) {
            Visit::Skip => continue,
            Visit::Free if block.color.is_none() => {
                integrate_free(block.value, block.weight);
                continue;
            }
            Visit::Free => RowBounds::NONE,
            Visit::Voxels(bounds) => bounds,
        };
        let step = f.world_to_camera * DVec3::new(voxel, 0.0, 0.0);
        if block.color.is_none() {
            let row = match (lookup, f.limits.is_some()) {
                (DepthLookup::Nearest, false) => integrate_row::<true, false>,
                (DepthLookup::Nearest, true) => integrate_row::<true, true>,
                (DepthLookup::Bilinear, false) => integrate_row::<false, false>,
                (DepthLookup::Bilinear, true) => integrate_row::<false, true>,
            };
            for start in (0..BLOCK_VOXELS).step_by(ROW) {
                let l = local_coords(start);
                let p = origin + (base + l).as_dvec3() * voxel;
                let q = f.world_to_camera * (p - f.center);
                let voxels = start..start + ROW;
                // The lanes' depths are `q.z + k · step.z` (as in the row), monotone in k.
                let z_last = q.z + (ROW - 1) as f64 * step.z;
                if q.z.min(z_last) >= bounds.skip_z {
                    continue;
                }
                if q.z.max(z_last) <= bounds.free_z {
                    integrate_free(&mut block.value[voxels.clone()], &mut block.weight[voxels]);
                    continue;
                }
                row(
                    f,
                    q,
                    step,
                    trunc,
                    (&mut block.value[voxels.clone()])
                        .try_into()
                        .expect("a block row"),
                    (&mut block.weight[voxels]).try_into().expect("a block row"),
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
                let (d, pixel) = match lookup {
                    DepthLookup::Nearest => f.sample_nearest(u, v),
                    DepthLookup::Bilinear => f.sample(u, v),
                };
                if d <= 0.0 {
                    continue;
                }
                // The ray-length factor is ≥ 1: sdf ≥ trunc when dz ≥ trunc (tsdf = 1) and
                // sdf ≤ −trunc when dz ≤ −trunc, so the square root is only needed between.
                let dz = d - q.z;
                if dz <= -trunc {
                    continue;
                }
                let sdf = dz * ray_factor(q);
                if sdf <= -trunc || (sdf >= trunc && q.z > f.limit(pixel)) {
                    continue;
                }
                let tsdf = (sdf * inv_trunc).min(1.0);
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

/// `‖q‖ / q.z`: the length along the voxel's own ray per unit of z-depth (≥ 1).
#[inline]
fn ray_factor(q: DVec3) -> f64 {
    let inv_z = 1.0 / q.z;
    (1.0 + (q.x * q.x + q.y * q.y) * (inv_z * inv_z)).sqrt()
}

/// Integrates one frame into one row of [`ROW`] voxels whose first voxel is at camera-space `q`
/// and whose next ones follow by `step`, in four passes over the lanes, none with a branch:
/// project them; find the 2 x 2 cell of pixel centres around each projection (and, when
/// `NEAREST`, only the pixel whose centre is nearest); read the cells and select the bilinear
/// or the nearest depth ([`Prepared::sample`]'s rule); update the lanes that pass (with
/// `LIMIT`, free space only in front of each pixel's [`Prepared::limit`]). All in f64, as
/// the plain rule.
#[inline]
fn integrate_row<const NEAREST: bool, const LIMIT: bool>(
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
    let mut u = [0.0f64; ROW];
    let mut v = [0.0f64; ROW];
    let mut inside = [false; ROW];
    let mut z = [0.0f64; ROW];
    let mut ray = [0.0f64; ROW];
    for k in 0..ROW {
        let kf = k as f64;
        let (qx, qy, qz) = (q.x + kf * step.x, q.y + kf * step.y, q.z + kf * step.z);
        let inv_z = 1.0 / qz;
        let (x, y) = (qx * inv_z, qy * inv_z);
        u[k] = f.fx * x + f.cx;
        v[k] = f.fy * y + f.cy;
        z[k] = qz;
        ray[k] = (1.0 + x * x + y * y).sqrt();
    }
    for k in 0..ROW {
        inside[k] = (z[k] > 0.0)
            & (u[k] >= PIXEL_MARGIN)
            & (u[k] < u_end)
            & (v[k] >= PIXEL_MARGIN)
            & (v[k] < v_end);
    }
    if !inside.iter().any(|&b| b) {
        return;
    }
    let w = f.width;
    let last = f.cells.len() - 2;
    let mut depth = [0.0f64; ROW];
    let mut pixel = [0usize; ROW];
    if NEAREST {
        for k in 0..ROW {
            let (d, p) = f.sample_nearest(u[k], v[k]);
            depth[k] = d;
            pixel[k] = p;
        }
    } else {
        // The cell's first pixel centre (i, j) and the point's offsets from it. Lanes
        // outside the image read clamped indices and are dropped below; inside, x and y lie
        // in [0, size) and the casts are floors (u − 0.5 is exact there).
        let mut cell = [0usize; ROW];
        let mut t = [[0.0f64; 2]; ROW];
        for k in 0..ROW {
            let (x, y) = ((u[k] - 0.5).max(0.0), (v[k] - 0.5).max(0.0));
            let (j, i) = (x as i32, y as i32);
            t[k] = [x - f64::from(j), y - f64::from(i)];
            cell[k] = (i as u32 as usize * w + j as u32 as usize).min(last);
        }
        for k in 0..ROW {
            let c = cell[k];
            let [tx, ty] = t[k];
            let ([a, d10], [b, d11]) = (f.cells[c], f.cells[c + 1]);
            let (d00, d01) = (f64::from(a.abs()), f64::from(b.abs()));
            let (d10, d11) = (f64::from(d10), f64::from(d11));
            let top = d00 + tx * (d01 - d00);
            let bottom = d10 + tx * (d11 - d10);
            let bilinear = top + ty * (bottom - top);
            // The nearest pixel centre is the cell's corner nearest the point (the last row
            // and column have ty, tx < ½).
            let (right, down) = (tx >= 0.5, ty >= 0.5);
            let nearest_top = if right { d01 } else { d00 };
            let nearest_bottom = if right { d11 } else { d10 };
            let nearest = if down { nearest_bottom } else { nearest_top };
            let interpolated = a.is_sign_positive() & (u[k] >= 0.5) & (v[k] >= 0.5);
            depth[k] = if interpolated { bilinear } else { nearest };
            if LIMIT {
                pixel[k] = (c + usize::from(right) + w * usize::from(down)).min(last);
            }
        }
    }
    let mut limit = [f64::INFINITY; ROW];
    if LIMIT {
        for k in 0..ROW {
            limit[k] = f.limit(pixel[k]);
        }
    }
    let inv_trunc = 1.0 / trunc;
    for k in 0..ROW {
        let d = depth[k];
        let sdf = (d - z[k]) * ray[k];
        let mut ok = inside[k] & (d > 0.0) & (sdf > -trunc);
        if LIMIT {
            ok &= (sdf < trunc) | (z[k] <= limit[k]);
        }
        let tsdf = (sdf * inv_trunc).min(1.0);
        let w0 = f64::from(weight[k]);
        let averaged = ((f64::from(value[k]) * w0 + tsdf) / (w0 + 1.0)) as f32;
        value[k] = if ok { averaged } else { value[k] };
        weight[k] = if ok { weight[k] + 1.0 } else { weight[k] };
    }
}
