//! Integrating prepared frames, in order, into one block: the per-voxel running average of
//! the truncated signed distance (and colour), row by row.

use glam::{DVec3, IVec3};

use super::frame::{PIXEL_MARGIN, Prepared, Visit};
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
/// and whose next ones follow by `step`: project the lanes without branches, read the depth
/// of the lanes inside the image ([`Prepared::sample`], or [`Prepared::sample_nearest`] when
/// `NEAREST`), then update the lanes that pass without branches (with `LIMIT`, free space
/// only in front of each pixel's [`Prepared::limit`]). All in f64, as the plain rule.
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
    let mut uv = [[0.0f64; 2]; ROW];
    let mut inside = [false; ROW];
    let mut z = [0.0f64; ROW];
    let mut ray = [0.0f64; ROW];
    for k in 0..ROW {
        let kf = k as f64;
        let (qx, qy, qz) = (q.x + kf * step.x, q.y + kf * step.y, q.z + kf * step.z);
        let inv_z = 1.0 / qz;
        let (x, y) = (qx * inv_z, qy * inv_z);
        let u = f.fx * x + f.cx;
        let v = f.fy * y + f.cy;
        let ok = (qz > 0.0) & (u >= PIXEL_MARGIN) & (u < u_end) & (v >= PIXEL_MARGIN) & (v < v_end);
        uv[k] = [u, v];
        inside[k] = ok;
        z[k] = qz;
        ray[k] = (1.0 + x * x + y * y).sqrt();
    }
    if !inside.iter().any(|&b| b) {
        return;
    }
    // Every lane reads (at indices clamped into the image, without branches); lanes outside
    // the image then select 0.
    let mut depth = [0.0f64; ROW];
    let mut limit = [f64::INFINITY; ROW];
    for k in 0..ROW {
        let (d, pixel) = if NEAREST {
            f.sample_nearest(uv[k][0], uv[k][1])
        } else {
            f.sample(uv[k][0], uv[k][1])
        };
        depth[k] = if inside[k] { d } else { 0.0 };
        if LIMIT {
            limit[k] = f.limit(pixel);
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
