//! Depth sorting and tile binning (gsplat's `isect_tiles` + sort + `isect_offset_encode`, on the
//! CPU): the visible splats are sorted once by camera z, then listed, in that order, in each
//! 16×16 tile their screen box touches, so every tile's list is front to back (the same lists
//! as gsplat's per-tile sorted keys).

use rayon::prelude::*;

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

/// First local index `>= floor(v − start)`, clamped to `0..=n` (no `floor` call: the baseline
/// x86-64 target has no rounding instruction; truncation equals floor for the values kept).
#[inline(always)]
pub(crate) fn lo(v: f32, start: u32, n: usize) -> usize {
    ((v - start as f32).max(0.0) as usize).min(n)
}

/// One past a local index `>= ceil(v − start)` (conservative by at most one), clamped to `0..=n`.
#[inline(always)]
pub(crate) fn hi(v: f32, start: u32, n: usize) -> usize {
    let x = v - start as f32 + 1.0;
    if x > 0.0 { (x as usize + 1).min(n) } else { 0 }
}

/// The local pixel rectangle `(lx0, lx1, ly0, ly1)` of a splat in the `tw × th` tile at
/// `(x0, y0)`: with `clip`, the pixel centres `j + off` within its screen box `center ± radius`
/// (rounded outwards); otherwise the whole tile.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn box_pixels(
    clip: bool,
    center: [f32; 2],
    radius: [f32; 2],
    off: f32,
    (x0, y0): (u32, u32),
    (tw, th): (usize, usize),
) -> (usize, usize, usize, usize) {
    if clip {
        let (c, r) = (center, radius);
        (
            lo(c[0] - r[0] - off, x0, tw),
            hi(c[0] + r[0] - off, x0, tw),
            lo(c[1] - r[1] - off, y0, th),
            hi(c[1] + r[1] - off, y0, th),
        )
    } else {
        (0, tw, 0, th)
    }
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

/// The front-to-back order of splats at camera z `depths`: sorted by depth, ties by index (as
/// gsplat's stable radix sort of `(tile, depth)` keys leaves them). Sorts once for the whole
/// image; binning in this order then leaves every tile's list sorted.
///
/// An LSD radix sort of the depths' bit patterns (three stable passes of 11 bits): depths are
/// clamped to `>= 0`, where the bits order like the values, and stability keeps equal depths in
/// index order, so the order is exactly that of [`sort_key`].
#[must_use]
pub fn depth_order(depths: &[f32]) -> Vec<u32> {
    const BITS: u32 = 11;
    const BUCKETS: usize = 1 << BITS;
    let n = depths.len();
    let mut keys: Vec<u32> = depths.iter().map(|d| d.max(0.0).to_bits()).collect();
    let mut order: Vec<u32> = (0..n as u32).collect();
    if n <= 1 {
        return order;
    }
    let mut keys_tmp = vec![0u32; n];
    let mut order_tmp = vec![0u32; n];
    for pass in 0..3 {
        let shift = pass * BITS;
        let mut counts = vec![0usize; BUCKETS];
        for &k in &keys {
            counts[((k >> shift) as usize) & (BUCKETS - 1)] += 1;
        }
        // A pass where every key falls in one bucket leaves the order as it is.
        if counts.contains(&n) {
            continue;
        }
        let mut sum = 0;
        for c in &mut counts {
            let here = *c;
            *c = sum;
            sum += here;
        }
        for (&k, &i) in keys.iter().zip(&order) {
            let slot = &mut counts[((k >> shift) as usize) & (BUCKETS - 1)];
            keys_tmp[*slot] = k;
            order_tmp[*slot] = i;
            *slot += 1;
        }
        std::mem::swap(&mut keys, &mut keys_tmp);
        std::mem::swap(&mut order, &mut order_tmp);
    }
    order
}

/// Splats per tile, front to back: tile `t` lists `entries[offsets[t]..offsets[t + 1]]`, each
/// entry a position in the depth order the splats were binned in.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TileBins {
    /// Tiles per image row.
    pub tiles_x: u32,
    /// Tile rows.
    pub tiles_y: u32,
    /// `tiles_x × tiles_y + 1` offsets into `entries`.
    pub offsets: Vec<usize>,
    /// Splat positions, grouped by tile, increasing within a tile.
    pub entries: Vec<u32>,
}

impl TileBins {
    /// Bins splats (screen boxes `centers` ± `radii`, already in front-to-back order) into the
    /// tiles of a `width × height` image; each tile's list comes out in that order.
    #[must_use]
    pub fn bin(
        centers: &[[f32; 2]],
        radii: &[[f32; 2]],
        width: u32,
        height: u32,
        rect: TileRect,
    ) -> Self {
        let tiles_x = width.div_ceil(TILE_SIZE);
        let tiles_y = height.div_ceil(TILE_SIZE);
        let n_tiles = tiles_x as usize * tiles_y as usize;
        let ranges: Vec<(u32, u32, u32, u32)> = centers
            .par_iter()
            .zip(radii.par_iter())
            .map(|(&c, &r)| tile_range(rect, c, r, tiles_x, tiles_y))
            .collect();
        let mut counts = vec![0usize; n_tiles + 1];
        for &(x0, x1, y0, y1) in &ranges {
            for ty in y0..y1 {
                let row = ty as usize * tiles_x as usize;
                for c in &mut counts[row + x0 as usize + 1..row + x1 as usize + 1] {
                    *c += 1;
                }
            }
        }
        for t in 0..n_tiles {
            counts[t + 1] += counts[t];
        }
        let offsets = counts;
        let mut cursor = offsets.clone();
        let mut entries = vec![0u32; offsets[n_tiles]];
        for (i, &(x0, x1, y0, y1)) in ranges.iter().enumerate() {
            for ty in y0..y1 {
                let row = ty as usize * tiles_x as usize;
                for slot in &mut cursor[row + x0 as usize..row + x1 as usize] {
                    entries[*slot] = i as u32;
                    *slot += 1;
                }
            }
        }
        Self {
            tiles_x,
            tiles_y,
            offsets,
            entries,
        }
    }

    /// The entries of tile `(tx, ty)`, front to back.
    #[must_use]
    pub fn tile(&self, tx: u32, ty: u32) -> &[u32] {
        let t = ty as usize * self.tiles_x as usize + tx as usize;
        match (self.offsets.get(t), self.offsets.get(t + 1)) {
            (Some(&a), Some(&b)) => &self.entries[a..b],
            _ => &[],
        }
    }

    /// Total number of (tile, splat) pairs.
    #[must_use]
    pub fn intersections(&self) -> usize {
        self.entries.len()
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
    fn order_is_by_depth_then_index() {
        assert_eq!(depth_order(&[2.0, 1.0, 3.0, 1.0]), [1, 3, 0, 2]);
        assert_eq!(depth_order(&[]), [0u32; 0]);
        assert_eq!(depth_order(&[5.0]), [0]);
        // Equal to sorting the (depth, index) keys, over many magnitudes and with ties.
        let mut rng = trisplat_geometry::rng::Rng::new(3);
        let depths: Vec<f32> = (0..5000)
            .map(|_| {
                let d = 10f32.powf(6.0 * rng.uniform_f32() - 2.0);
                if rng.below(4) == 0 { d.round() } else { d }
            })
            .collect();
        let mut keys: Vec<u64> = depths
            .iter()
            .enumerate()
            .map(|(i, &d)| sort_key(d, i))
            .collect();
        keys.sort_unstable();
        let expected: Vec<u32> = keys.iter().map(|k| (k & 0xffff_ffff) as u32).collect();
        assert_eq!(depth_order(&depths), expected);
        let bins = TileBins::bin(
            &[[8.0, 8.0], [20.0, 8.0], [16.0, 8.0]],
            &[[2.0, 2.0], [2.0, 2.0], [2.0, 2.0]],
            32,
            16,
            TileRect::Gsplat,
        );
        assert_eq!(bins.tile(0, 0), [0, 2]);
        assert_eq!(bins.tile(1, 0), [1, 2]);
        assert_eq!(bins.intersections(), 4);
    }
}
