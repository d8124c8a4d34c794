//! Per-(tile, splat) gradient sums shared by every mode's backward pass: each splat owns one slot
//! of `N` `f64` values per tile of its tile rectangle, written once by the tile that owns it
//! (from any thread), then reduced per splat in tile order, so gradients do not depend on the
//! thread count.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::render::tiles::{TileBins, TileRect, tile_range};

/// Where a splat's slots start and the tile rectangle they follow.
struct SlotRect {
    offset: usize,
    x0: u32,
    y0: u32,
    width: u32,
}

/// The slots of every splat, splat-major: splat `j`'s slots are its tile rectangle's tiles in
/// row-major order (the binning's rectangles).
pub(crate) struct SlotBuffer<const N: usize> {
    rects: Vec<SlotRect>,
    slots: Vec<[AtomicU64; N]>,
}

impl<const N: usize> SlotBuffer<N> {
    /// Zeroed slots for splats with the screen boxes `(center, radius)`, in the order the tile
    /// lists index them, binned with `rect` into `bins`' grid.
    pub(crate) fn new(
        boxes: impl IndexedParallelIterator<Item = ([f32; 2], [f32; 2])>,
        rect: TileRect,
        bins: &TileBins,
    ) -> Self {
        let mut rects: Vec<SlotRect> = boxes
            .map(|(center, radius)| {
                let (x0, x1, y0, y1) = tile_range(rect, center, radius, bins.tiles_x, bins.tiles_y);
                SlotRect {
                    offset: (x1 - x0) as usize * (y1 - y0) as usize,
                    x0,
                    y0,
                    width: x1 - x0,
                }
            })
            .collect();
        let mut total = 0;
        for r in &mut rects {
            let area = r.offset;
            r.offset = total;
            total += area;
        }
        let slots = (0..total)
            .into_par_iter()
            .map(|_| std::array::from_fn(|_| AtomicU64::new(0)))
            .collect();
        Self { rects, slots }
    }

    /// Stores splat `j`'s sums of tile `(tx, ty)` (a tile of its rectangle).
    #[inline]
    pub(crate) fn store(&self, j: usize, (tx, ty): (u32, u32), sum: [f64; N]) {
        let rect = &self.rects[j];
        let at = rect.offset + ((ty - rect.y0) * rect.width + tx - rect.x0) as usize;
        for (slot, v) in self.slots[at].iter().zip(sum) {
            slot.store(v.to_bits(), Ordering::Relaxed);
        }
    }

    /// Each splat's sums over its tiles, in tile order.
    pub(crate) fn reduce(self) -> Vec<[f64; N]> {
        let total = self.slots.len();
        self.rects
            .par_iter()
            .enumerate()
            .map(|(j, r)| {
                let end = self.rects.get(j + 1).map_or(total, |n| n.offset);
                let mut sum = [0.0; N];
                for slot in &self.slots[r.offset..end] {
                    for (a, b) in sum.iter_mut().zip(slot) {
                        *a += f64::from_bits(b.load(Ordering::Relaxed));
                    }
                }
                sum
            })
            .collect()
    }
}
