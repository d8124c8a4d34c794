//! Tile binning and per-tile depth sorting (gsplat's `isect_tiles` + `isect_offset_encode`, on
//! the CPU): every visible splat is listed in each 16×16 tile its screen box touches, and each
//! tile's list is sorted by camera z.

use rayon::prelude::*;

use super::screen::ScreenSplats;

/// Tile edge in pixels (gsplat's and 3DGS's `tile_size`).
pub const TILE_SIZE: u32 = 16;

/// Which rule turns a screen box into a tile rectangle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TileRect {
    /// gsplat: `[floor((c − r)/16), ceil((c + r)/16))` per axis, clamped to the grid.
    #[default]
    Gsplat,
    /// The original 3DGS `getRect`: `[trunc((c − r)/16), trunc((c + r + 15)/16))`, clamped.
    Original3dgs,
}

/// Splats per tile, sorted front to back: tile `t` lists `keys[offsets[t]..offsets[t + 1]]`.
/// A key is `(depth bits << 32) | splat index`, so sorting keys sorts by depth (positive floats
/// order like their bits) and then by index (ties keep the source order, as gsplat's stable
/// radix sort does).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TileBins {
    /// Tiles per image row.
    pub tiles_x: u32,
    /// Tile rows.
    pub tiles_y: u32,
    /// `tiles_x × tiles_y + 1` offsets into `keys`.
    pub offsets: Vec<usize>,
    /// Sort keys, grouped by tile.
    pub keys: Vec<u64>,
}

/// The tile rectangle `[x0, x1) × [y0, y1)` of a box, clamped to the grid.
#[inline]
#[must_use]
pub fn tile_range(
    rect: TileRect,
    center: [f32; 2],
    radius: [f32; 2],
    tiles_x: u32,
    tiles_y: u32,
) -> (u32, u32, u32, u32) {
    let ts = TILE_SIZE as f32;
    // `as` casts saturate (NaN gives 0), so huge or odd values cannot wrap.
    let clamp = |v: f32, hi: u32| (v.max(0.0) as u32).min(hi);
    match rect {
        TileRect::Gsplat => {
            let (cx, cy) = (center[0] / ts, center[1] / ts);
            let (rx, ry) = (radius[0] / ts, radius[1] / ts);
            (
                clamp((cx - rx).floor(), tiles_x),
                clamp((cx + rx).ceil(), tiles_x),
                clamp((cy - ry).floor(), tiles_y),
                clamp((cy + ry).ceil(), tiles_y),
            )
        }
        TileRect::Original3dgs => {
            let trunc = |v: f32| v.trunc();
            (
                clamp(trunc((center[0] - radius[0]) / ts), tiles_x),
                clamp(trunc((center[0] + radius[0] + ts - 1.0) / ts), tiles_x),
                clamp(trunc((center[1] - radius[1]) / ts), tiles_y),
                clamp(trunc((center[1] + radius[1] + ts - 1.0) / ts), tiles_y),
            )
        }
    }
}

/// The sort key of splat `index` at camera z `depth` (> 0).
#[inline]
#[must_use]
pub fn sort_key(depth: f32, index: usize) -> u64 {
    // Depths are > 0 (near plane > 0), so their bits order like the values.
    (u64::from(depth.max(0.0).to_bits()) << 32) | (index as u64 & 0xffff_ffff)
}

impl TileBins {
    /// Bins the splats of `screen` into the tiles of a `width × height` image (unsorted; call
    /// [`TileBins::sort`]).
    #[must_use]
    pub fn bin(screen: &ScreenSplats, width: u32, height: u32, rect: TileRect) -> Self {
        let tiles_x = width.div_ceil(TILE_SIZE);
        let tiles_y = height.div_ceil(TILE_SIZE);
        let n_tiles = tiles_x as usize * tiles_y as usize;
        let ranges: Vec<(u32, u32, u32, u32)> = screen
            .centers
            .par_iter()
            .zip(screen.radii.par_iter())
            .map(|(&c, &r)| tile_range(rect, c, r, tiles_x, tiles_y))
            .collect();
        let mut counts = vec![0usize; n_tiles + 1];
        for &(x0, x1, y0, y1) in &ranges {
            for ty in y0..y1 {
                let row = ty as usize * tiles_x as usize;
                for tx in x0..x1 {
                    counts[row + tx as usize + 1] += 1;
                }
            }
        }
        for t in 0..n_tiles {
            counts[t + 1] += counts[t];
        }
        let offsets = counts;
        let mut cursor = offsets.clone();
        let mut keys = vec![0u64; offsets[n_tiles]];
        for (i, &(x0, x1, y0, y1)) in ranges.iter().enumerate() {
            let key = sort_key(screen.depths[i], i);
            for ty in y0..y1 {
                let row = ty as usize * tiles_x as usize;
                for tx in x0..x1 {
                    let slot = &mut cursor[row + tx as usize];
                    keys[*slot] = key;
                    *slot += 1;
                }
            }
        }
        Self {
            tiles_x,
            tiles_y,
            offsets,
            keys,
        }
    }

    /// Sorts every tile's list front to back (tiles in parallel).
    pub fn sort(&mut self) {
        let mut slices = Vec::with_capacity(self.offsets.len().saturating_sub(1));
        let mut rest: &mut [u64] = &mut self.keys;
        for w in self.offsets.windows(2) {
            let (head, tail) = rest.split_at_mut(w[1] - w[0]);
            slices.push(head);
            rest = tail;
        }
        slices.into_par_iter().for_each(|s| s.sort_unstable());
    }

    /// The sorted keys of tile `(tx, ty)`.
    #[must_use]
    pub fn tile(&self, tx: u32, ty: u32) -> &[u64] {
        let t = ty as usize * self.tiles_x as usize + tx as usize;
        match (self.offsets.get(t), self.offsets.get(t + 1)) {
            (Some(&a), Some(&b)) => &self.keys[a..b],
            _ => &[],
        }
    }

    /// Total number of (tile, splat) pairs.
    #[must_use]
    pub fn intersections(&self) -> usize {
        self.keys.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gsplat_and_original_rects() {
        // Centre 20, radius 3: gsplat floor(17/16)=1 .. ceil(23/16)=2.
        assert_eq!(
            tile_range(TileRect::Gsplat, [20.0, 20.0], [3.0, 3.0], 4, 4),
            (1, 2, 1, 2)
        );
        // Original: trunc(17/16)=1 .. trunc((23+15)/16)=2.
        assert_eq!(
            tile_range(TileRect::Original3dgs, [20.0, 20.0], [3.0, 3.0], 4, 4),
            (1, 2, 1, 2)
        );
        // Off-image and non-finite boxes give empty or clamped ranges, never a wrap.
        let (x0, x1, ..) = tile_range(TileRect::Gsplat, [-1e30, 5.0], [1.0, 1.0], 4, 4);
        assert_eq!((x0, x1), (0, 0));
        let (x0, x1, ..) = tile_range(TileRect::Gsplat, [f32::NAN, 5.0], [1.0, 1.0], 4, 4);
        assert!(x0 <= x1 && x1 <= 4);
    }

    #[test]
    fn keys_sort_by_depth_then_index() {
        let mut keys = [sort_key(2.0, 0), sort_key(1.0, 5), sort_key(1.0, 3)];
        keys.sort_unstable();
        let idx: Vec<u64> = keys.iter().map(|k| k & 0xffff_ffff).collect();
        assert_eq!(idx, [3, 5, 0]);
    }
}
