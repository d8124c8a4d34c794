//! One view ([`Frame`]) and what fusion prepares from it once: the camera maths, the
//! effective depth and the culling tiles, and what the view does to a block (skip it, free
//! space, or voxel by voxel).

use glam::{DMat3, DVec3};
use trisplat_geometry::Camera;

use super::error::TsdfError;
use super::image::{ColorImage, DepthImage};
use super::params::DepthLookup;

/// Projected coordinates must lie in `[PIXEL_MARGIN, size − PIXEL_MARGIN)` (Open3D's 0.0001).
pub const PIXEL_MARGIN: f64 = 1e-4;

/// Side of the square pixel tiles whose largest depth culls blocks behind the surface.
pub(super) const TILE: usize = 16;

/// A 2 x 2 cell of pixels is interpolated only when its depths differ by at most this many
/// pixel footprints at its nearest depth (`d_min / f`; a surface seen up to about 80° from
/// head-on), or by at most the truncation; wider cells straddle a depth edge and are read at
/// the nearest pixel.
pub const MAX_CELL_SPREAD_PIXELS: f64 = 8.0;

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
pub(super) struct Prepared<'a> {
    pub(super) name: &'a str,
    pub(super) world_to_camera: DMat3,
    pub(super) center: DVec3,
    pub(super) fx: f64,
    pub(super) fy: f64,
    pub(super) cx: f64,
    pub(super) cy: f64,
    pub(super) width: usize,
    pub(super) height: usize,
    /// Per pixel `k = i · width + j` (and one more, 0, so that `k + 1` can always be read):
    /// its depth (invalid values and those beyond `depth_trunc` set to 0) and that of the
    /// pixel below it (0 in the last row), the first negated when the cell of pixel centres
    /// `(i, j)`, `(i, j + 1)`, `(i + 1, j)`, `(i + 1, j + 1)` is not interpolated (not all four
    /// valid, or their depths more than [`Prepared::max_spread`] of the nearest apart; always
    /// in the last row and column). A cell is read from two neighbouring entries.
    pub(super) cells: Vec<[f32; 2]>,
    /// [`MAX_CELL_SPREAD_PIXELS`] / min(fx, fy): a cell's largest interpolated spread per
    /// unit of its nearest depth.
    pub(super) spread_per_depth: f64,
    /// The truncation: the smallest spread a cell may always have.
    pub(super) min_spread: f64,
    /// Largest depth per TILE x TILE tile (0 = no valid pixel).
    pub(super) tile_max: Vec<f32>,
    /// Smallest valid depth per tile (`f32::INFINITY` = none).
    pub(super) tile_min: Vec<f32>,
    /// Whether every pixel of the tile is valid.
    pub(super) tile_full: Vec<bool>,
    pub(super) tiles_x: usize,
    /// Per [`WINDOW`] x [`WINDOW`] window of pixels starting at every even pixel (i, j)
    /// (row-major over `(i / 2, j / 2)`, clipped at the image's edges): the largest depth and
    /// the smallest, invalid pixels counting as 0 (so the smallest is 0 unless all are
    /// valid). Any rectangle of pixels is covered by a few windows reaching at most one
    /// pixel past it on each side when it is at least 3 pixels wide and high
    /// ([`Prepared::window_depths`]).
    pub(super) windows: Vec<[f32; 2]>,
    /// Windows per row of [`Prepared::windows`]: `⌈width / 2⌉`.
    pub(super) windows_x: usize,
    pub(super) color: Option<&'a [[f32; 3]]>,
    /// Per pixel (and one more), the depth beyond which it marks no free space: its front
    /// depth ([`DepthImage::with_front`]) when that lies before its depth, else its depth;
    /// `None` when the depth map has no front depths.
    pub(super) limits: Option<Vec<f32>>,
    /// Smallest limit of a valid pixel per tile (`f32::INFINITY` = none); empty without
    /// limits.
    pub(super) tile_limit_min: Vec<f32>,
}

impl<'a> Prepared<'a> {
    /// The tables of `frame`.
    /// `lookup` [`DepthLookup::Nearest`] marks every cell as not interpolated.
    pub(super) fn new(
        frame: &Frame<'a>,
        depth_trunc: f64,
        trunc: f64,
        lookup: DepthLookup,
    ) -> Result<Self, TsdfError> {
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
            .map(|&d| {
                if d > 0.0 && f64::from(d) <= depth_trunc {
                    d
                } else {
                    0.0
                }
            })
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
        let (windows, windows_x) = window_table(&depth, width, height);
        let spread_per_depth = MAX_CELL_SPREAD_PIXELS / cam.fx.min(cam.fy);
        let mut cells = vec![[0.0f32; 2]; width * height + 1];
        for i in 0..height {
            for j in 0..width {
                let k = i * width + j;
                let below = if i + 1 < height {
                    depth[k + width]
                } else {
                    0.0
                };
                let ok = lookup == DepthLookup::Bilinear && i + 1 < height && j + 1 < width && {
                    let c = [depth[k], depth[k + 1], below, depth[k + width + 1]];
                    let (lo, hi) = cell_range(c);
                    lo > 0.0 && f64::from(hi - lo) <= (f64::from(lo) * spread_per_depth).max(trunc)
                };
                cells[k] = [if ok { depth[k] } else { -depth[k] }, below];
            }
        }
        let limits = frame.depth.front().map(|front| {
            let mut limits: Vec<f32> = depth
                .iter()
                .zip(front)
                .map(|(&d, &f)| if f > 0.0 && f < d { f } else { d })
                .collect();
            limits.push(0.0);
            limits
        });
        let mut tile_limit_min = Vec::new();
        if let Some(limits) = &limits {
            tile_limit_min = vec![f32::INFINITY; tiles_x * tiles_y];
            for (k, &l) in limits[..width * height].iter().enumerate() {
                if l > 0.0 {
                    let t = (k / width / TILE) * tiles_x + (k % width) / TILE;
                    tile_limit_min[t] = tile_limit_min[t].min(l);
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
            cells,
            spread_per_depth,
            min_spread: trunc,
            tile_max,
            tile_min,
            tile_full,
            tiles_x,
            windows,
            windows_x,
            color: frame.color.map(ColorImage::data),
            limits,
            tile_limit_min,
        })
    }

    /// The depth seen at image point `(u, v)` (inside `[PIXEL_MARGIN, size − PIXEL_MARGIN)`,
    /// pixel centres at `j + ½`) and the index of the pixel whose centre is nearest: the
    /// bilinear interpolation of the 2 x 2 pixel centres around the point when all four are
    /// valid and their depths differ by at most [`Self::max_spread`] of the nearest, else the
    /// nearest pixel's depth (0: none). Without branches: both are computed (three loads from
    /// neighbouring entries) and one is selected, so the lanes of a row do not wait on each
    /// other's mispredictions.
    #[inline(always)]
    pub(super) fn sample(&self, u: f64, v: f64) -> (f64, usize) {
        let w = self.width;
        let last = self.cells.len() - 2;
        let nearest = ((v as usize) * w + u as usize).min(last);
        let (x, y) = ((u - 0.5).max(0.0), (v - 0.5).max(0.0));
        let (j, i) = (x as usize, y as usize);
        let c = (i * w + j).min(last);
        let (tx, ty) = (x - j as f64, y - i as f64);
        let ([a, d10], [b, d11]) = (self.cells[c], self.cells[c + 1]);
        let (d00, d01) = (f64::from(a.abs()), f64::from(b.abs()));
        let (d10, d11) = (f64::from(d10), f64::from(d11));
        let top = d00 + tx * (d01 - d00);
        let bottom = d10 + tx * (d11 - d10);
        let bilinear = top + ty * (bottom - top);
        let near = f64::from(self.cells[nearest][0].abs());
        let interpolated = a.is_sign_positive() & (u >= 0.5) & (v >= 0.5);
        (if interpolated { bilinear } else { near }, nearest)
    }

    /// The depth of the pixel whose centre is nearest image point `(u, v)` (inside
    /// `[PIXEL_MARGIN, size − PIXEL_MARGIN)`) and its index: [`Self::sample`] when no cell is
    /// interpolated ([`DepthLookup::Nearest`]), with one read.
    #[inline(always)]
    pub(super) fn sample_nearest(&self, u: f64, v: f64) -> (f64, usize) {
        let k = ((v as usize) * self.width + u as usize).min(self.cells.len() - 2);
        (f64::from(self.cells[k][0].abs()), k)
    }

    /// The depth beyond which pixel `k` marks no free space (`+∞` without front depths).
    #[inline(always)]
    pub(super) fn limit(&self, k: usize) -> f64 {
        self.limits
            .as_ref()
            .map_or(f64::INFINITY, |l| f64::from(l[k]))
    }

    /// The depth of pixel `k` (0: none).
    #[inline]
    pub(super) fn depth(&self, k: usize) -> f32 {
        self.cells[k][0].abs()
    }

    /// Whether the cell whose first pixel is `k` is interpolated.
    #[inline]
    pub(super) fn cell_ok(&self, k: usize) -> bool {
        self.cells[k][0].is_sign_positive()
    }

    /// The largest depth spread of an interpolated cell whose nearest depth is `d`.
    #[inline]
    pub(super) fn max_spread(&self, d: f64) -> f64 {
        (d * self.spread_per_depth).max(self.min_spread)
    }

    /// What this frame does to the voxels of the box `[lo, hi]` (world; the first and last
    /// voxel centres of a block): nothing when the box is behind the camera, projects outside
    /// the image, or lies more than `trunc` behind the farthest depth of the pixels it covers;
    /// tsdf = 1 for every voxel when the whole box projects inside the image onto valid
    /// pixels and lies at least `trunc` in front of the nearest of them; otherwise it must be
    /// looked at voxel by voxel, with [`RowBounds`] that settle the rows lying wholly behind
    /// or in front of the truncation band.
    pub(super) fn visit(&self, lo: DVec3, hi: DVec3, trunc: f64) -> Visit {
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
            return Visit::Voxels(RowBounds::NONE);
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
        // The pixels the voxel centres can read (the projection of the box lies in the box
        // of its projected corners; interpolation reads one pixel further).
        let col = |u: f64| (u - 0.5).clamp(0.0, w - 1.0) as usize;
        let row = |v: f64| (v - 0.5).clamp(0.0, h - 1.0) as usize;
        let (col_end, row_end) = (|u: f64| col(u + 1.0), |v: f64| row(v + 1.0));
        let (j0, j1, i0, i1) = (col(u_min), col_end(u_max), row(v_min), row_end(v_max));
        let (cols, rows) = (j1 - j0 + 1, i1 - i0 + 1);
        let range = if self.limits.is_none()
            && cols.div_ceil(WINDOW) * rows.div_ceil(WINDOW) <= WINDOW_SCAN_MAX
        {
            self.window_depths(j0, j1, i0, i1)
        } else if cols * rows <= RECT_SCAN_MAX {
            self.rect_depths(j0, j1, i0, i1)
        } else {
            self.tile_depths(j0, j1, i0, i1)
        };
        // A depth read lies between the smallest and largest of the pixels it reads.
        // sdf ≤ (d_max − z_min) · factor and factor ≥ 1: nothing passes sdf > −trunc.
        if range.max == 0.0 || z_min - f64::from(range.max) >= trunc {
            return Visit::Skip;
        }
        // sdf ≥ (d_min − z_max) · factor ≥ trunc for every voxel: tsdf = 1.
        // ... and no voxel lies beyond a pixel's free-space limit.
        if inside
            && range.all_valid
            && f64::from(range.min) - z_max >= trunc
            && f64::from(range.limit_min) >= z_max
        {
            return Visit::Free;
        }
        let (d_min, d_max) = (f64::from(range.min), f64::from(range.max));
        let margin = SHORTCUT_MARGIN * (d_max + trunc);
        let free_z = if inside && range.all_valid {
            (d_min - trunc - margin).min(f64::from(range.limit_min))
        } else {
            f64::NEG_INFINITY
        };
        Visit::Voxels(RowBounds {
            skip_z: d_max + trunc + margin,
            free_z,
        })
    }

    /// The depth range of the pixels `[j0, j1] × [i0, i1]`, read one by one.
    fn rect_depths(&self, j0: usize, j1: usize, i0: usize, i1: usize) -> DepthRange {
        let mut range = DepthRange::EMPTY;
        for i in i0..=i1 {
            for cell in &self.cells[i * self.width + j0..=i * self.width + j1] {
                let d = cell[0].abs();
                range.add(d, d > 0.0);
            }
        }
        if let Some(limits) = &self.limits {
            for i in i0..=i1 {
                for &l in &limits[i * self.width + j0..=i * self.width + j1] {
                    if l > 0.0 {
                        range.limit_min = range.limit_min.min(l);
                    }
                }
            }
        }
        range
    }

    /// A depth range containing that of the pixels `[j0, j1] × [i0, i1]` (and of at most one
    /// more column and row on each side, or of the 4 x 4 pixels from `(i0 & !1, j0 & !1)` for
    /// a smaller rectangle: [`window_starts`]), from the windows that cover them; no
    /// free-space limits (use it only without them).
    fn window_depths(&self, j0: usize, j1: usize, i0: usize, i1: usize) -> DepthRange {
        let (mut max, mut min) = (0.0f32, f32::INFINITY);
        for si in window_starts(i0, i1) {
            let row = &self.windows[(si / 2) * self.windows_x..];
            for sj in window_starts(j0, j1) {
                let [hi, lo] = row[sj / 2];
                max = max.max(hi);
                min = min.min(lo);
            }
        }
        DepthRange {
            max,
            min,
            all_valid: min > 0.0,
            limit_min: f32::INFINITY,
        }
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
                if let Some(&l) = self.tile_limit_min.get(t) {
                    range.limit_min = range.limit_min.min(l);
                }
            }
        }
        range
    }
}

/// Side of the windows of [`Prepared::windows`].
const WINDOW: usize = 4;

/// Most windows read by [`Prepared::visit`] for one block (larger rectangles use the tiles).
const WINDOW_SCAN_MAX: usize = 64;

/// The window table of [`Prepared::windows`] for a `width` x `height` depth map (0 =
/// invalid), and its row length.
fn window_table(depth: &[f32], width: usize, height: usize) -> (Vec<[f32; 2]>, usize) {
    let windows_x = width.div_ceil(2);
    let windows_y = height.div_ceil(2);
    // Rows first: each row's windows of WINDOW pixels at even columns.
    let mut rows = vec![[0.0f32, f32::INFINITY]; height * windows_x];
    for (row, out) in depth
        .chunks_exact(width)
        .zip(rows.chunks_exact_mut(windows_x))
    {
        for (x, o) in out.iter_mut().enumerate() {
            let run = &row[2 * x..(2 * x + WINDOW).min(width)];
            *o = run.iter().fold([0.0f32, f32::INFINITY], |[hi, lo], &d| {
                [hi.max(d), lo.min(d)]
            });
        }
    }
    let mut windows = vec![[0.0f32, f32::INFINITY]; windows_y * windows_x];
    for (y, out) in windows.chunks_exact_mut(windows_x).enumerate() {
        for r in 2 * y..(2 * y + WINDOW).min(height) {
            for (o, &[hi, lo]) in out
                .iter_mut()
                .zip(&rows[r * windows_x..(r + 1) * windows_x])
            {
                *o = [o[0].max(hi), o[1].min(lo)];
            }
        }
    }
    (windows, windows_x)
}

/// Even starts of [`WINDOW`]-pixel windows whose union covers `[a, b]` (`a ≤ b`) and lies in
/// `[a & !1, max(b + 1, (a & !1) + 3)]`: at most one pixel before `a`, and one past `b` unless the
/// range is narrower than a window.
fn window_starts(a: usize, b: usize) -> impl Iterator<Item = usize> {
    let last = (b.saturating_sub(WINDOW - 1) + 1) & !1;
    let mut next = Some(a & !1);
    std::iter::from_fn(move || {
        let s = next?;
        next = (s + WINDOW - 1 < b).then(|| (s + WINDOW).min(last));
        Some(s)
    })
}

/// The smallest and largest of a cell's four depths.
#[inline]
pub(super) fn cell_range(c: [f32; 4]) -> (f32, f32) {
    (
        c[0].min(c[1]).min(c[2].min(c[3])),
        c[0].max(c[1]).max(c[2].max(c[3])),
    )
}

/// Largest rectangle of pixels scanned one by one by [`Prepared::visit`] (larger ones use the
/// tiles).
const RECT_SCAN_MAX: usize = 64;

/// What a frame does to a block ([`Prepared::visit`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Visit {
    /// Nothing: no voxel is integrated.
    Skip,
    /// Every voxel is integrated with tsdf = 1 (free space in front of the surface).
    Free,
    /// Each voxel must be projected, except in the rows the bounds settle.
    Voxels(RowBounds),
}

/// Relative margin (of the depth) by which [`RowBounds`] keep clear of the truncation band's
/// edges: far above the rounding of a depth read (about 1e-16 of it), far below any distance
/// that matters, so that a row they settle is settled the same way voxel by voxel.
const SHORTCUT_MARGIN: f64 = 1e-9;

/// Camera depths that settle a whole row of a block's voxels from the depth range of the
/// pixels the block covers (every depth a voxel of the block reads lies in that range; the
/// ray-length factor is ≥ 1): a row whose nearest voxel lies at or beyond `skip_z` is behind
/// the band in every voxel (none is updated); a row whose farthest voxel lies at or before
/// `free_z` is in front of it in every voxel, inside the image on valid pixels and in front of
/// every free-space limit (tsdf = 1 in all).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct RowBounds {
    pub(super) skip_z: f64,
    pub(super) free_z: f64,
}

impl RowBounds {
    /// Bounds that settle no row.
    pub(super) const NONE: Self = Self {
        skip_z: f64::INFINITY,
        free_z: f64::NEG_INFINITY,
    };
}

/// Depths seen over some pixels: the largest (0 when none is valid), the smallest valid
/// (`+∞` when none), whether every pixel is valid, and the smallest free-space limit (`+∞`
/// when none or without limits).
#[derive(Clone, Copy, Debug)]
struct DepthRange {
    max: f32,
    min: f32,
    all_valid: bool,
    limit_min: f32,
}

impl DepthRange {
    const EMPTY: Self = Self {
        max: 0.0,
        min: f32::INFINITY,
        all_valid: true,
        limit_min: f32::INFINITY,
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

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use trisplat_geometry::sphere_rig;

    use super::*;

    /// The last pixel the windows of [`window_starts`]`(a, b)` may reach.
    fn window_end(a: usize, b: usize) -> usize {
        (b + 1).max((a & !1) + WINDOW - 1)
    }

    #[test]
    fn window_starts_cover_the_range_and_reach_at_most_a_pixel_past_it() {
        for a in 0..24 {
            for b in a..40 {
                let starts: Vec<usize> = window_starts(a, b).collect();
                assert_eq!(starts[0], a & !1, "[{a}, {b}]");
                for pair in starts.windows(2) {
                    assert!(
                        pair[0] < pair[1] && pair[1] <= pair[0] + WINDOW,
                        "{starts:?}"
                    );
                }
                let last = *starts.last().unwrap();
                assert!(starts.iter().all(|s| s % 2 == 0), "{starts:?}");
                assert!(
                    last + WINDOW > b && last + WINDOW - 1 <= window_end(a, b),
                    "[{a}, {b}]: {starts:?}"
                );
            }
        }
    }

    /// The window ranges contain the exact range of every rectangle (pixel by pixel, as
    /// `rect_depths`) and lie within that of the rectangle grown by a pixel on each side, on
    /// a depth map with invalid pixels (odd sizes, so windows are clipped at the edges).
    #[test]
    fn window_depths_bound_the_rectangle_within_a_pixel() {
        let cam = sphere_rig(DVec3::ZERO, 1.0, 1, (37, 29), 50.0).unwrap()[0].clone();
        let mut state = 7u64;
        let data: Vec<f32> = (0..37 * 29)
            .map(|_| {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1);
                let r = (state >> 40) as f32 / (1u64 << 24) as f32;
                if r < 0.03 { 0.0 } else { 1.0 + r }
            })
            .collect();
        let depth = DepthImage::try_new(37, 29, data).unwrap();
        let frame = Frame {
            camera: &cam,
            depth: &depth,
            color: None,
        };
        let f = Prepared::new(&frame, f64::INFINITY, 0.1, DepthLookup::Bilinear).unwrap();
        let (mut tight_max, mut all_valid_seen) = (0, 0);
        for (j0, i0) in [(0, 0), (1, 3), (5, 2), (6, 7), (20, 11), (30, 20)] {
            for j1 in j0..(j0 + 14).min(37) {
                for i1 in i0..(i0 + 9).min(29) {
                    let exact = f.rect_depths(j0, j1, i0, i1);
                    let grown = f.rect_depths(
                        j0 & !1,
                        window_end(j0, j1).min(36),
                        i0 & !1,
                        window_end(i0, i1).min(28),
                    );
                    let w = f.window_depths(j0, j1, i0, i1);
                    assert!(w.max >= exact.max, "{j0}..={j1} x {i0}..={i1}");
                    assert!(w.max <= grown.max, "{j0}..={j1} x {i0}..={i1}");
                    tight_max += usize::from(w.max == exact.max);
                    assert!(!w.all_valid || exact.all_valid);
                    assert!(!grown.all_valid || w.all_valid);
                    if w.all_valid {
                        all_valid_seen += 1;
                        assert!(w.min <= exact.min && w.min >= grown.min);
                    }
                }
            }
        }
        assert!(
            tight_max > 0 && all_valid_seen > 0,
            "{tight_max} {all_valid_seen}"
        );
    }
}
