//! Front-to-back alpha compositing of tile-sorted splats, generic over the mode's
//! [`SplatKernel`] (docs/conventions.md §5).
//!
//! Each 16×16 tile is composited on its own, splat by splat in depth order, over the pixels of
//! the splat's box (or of the whole tile); every pixel sees its splats in the same order as in
//! gsplat's per-pixel loop, so the result is the same, and it does not depend on the thread
//! count. Tile rows run in parallel. Per-pixel sums are `f32`, like gsplat's kernel.

use std::sync::atomic::{AtomicU32, Ordering};

use glam::Vec4;
use rayon::prelude::*;

use super::image::RenderImages;
use super::options::Outputs;
use super::screen::{ScreenSplats, SplatKernel};
use super::tiles::{TILE_SIZE, TileBins, TileRect, box_pixels, depth_order, hi, lo};

/// Pixels per tile.
const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;

/// gsplat's and 3DGS's skip threshold: contributions with alpha below it are ignored.
pub const ALPHA_THRESHOLD: f32 = 1.0 / 255.0;
/// gsplat's alpha clamp.
pub const GSPLAT_MAX_ALPHA: f32 = 0.999;
/// The original 3DGS (and 2DGS) alpha clamp.
pub const ORIGINAL_MAX_ALPHA: f32 = 0.99;
/// Transmittance at which a pixel stops accepting splats.
pub const STOP_TRANSMITTANCE: f32 = 1e-4;
/// Transmittance threshold of the median depth.
pub const MEDIAN_TRANSMITTANCE: f32 = 0.5;

/// Which splat gives a pixel its median depth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MedianRule {
    /// docs/conventions.md §5 (3DGS): the splat at which the transmittance first drops below 0.5; 0 where it
    /// never does.
    #[default]
    FirstBelowHalf,
    /// 2DGS (hbb1): the last splat met while the transmittance before it is above 0.5 (so the
    /// deepest splat of a pixel that never gets below 0.5).
    LastWhileAboveHalf,
}

/// The per-pixel rules of front-to-back compositing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeRules {
    /// `alpha = min(max_alpha, sample.alpha)`.
    pub max_alpha: f32,
    /// Samples with `alpha < min_alpha` are skipped.
    pub min_alpha: f32,
    /// A pixel stops before a splat that would bring its transmittance to this value or below
    /// (`stop_inclusive`) or strictly below it.
    pub stop_transmittance: f32,
    /// `<=` (gsplat) or `<` (3DGS, 2DGS) in the stop test.
    pub stop_inclusive: bool,
    /// Pixel (row i, column j) is sampled at `(j + offset, i + offset)`: 0.5 in gsplat, 0 in the
    /// original 3DGS code (whose means are shifted by −0.5 to match).
    pub pixel_offset: f32,
    /// Evaluate a splat only at pixels within one pixel of its screen box (exact when the box
    /// bounds the `alpha ≥ min_alpha` region, as gsplat's boxes do); otherwise at every pixel of
    /// every tile it touches (the original 3DGS behaviour, whose 3σ radius is not a bound).
    pub clip_to_box: bool,
    /// How screen boxes become tile rectangles.
    pub tile_rect: TileRect,
    /// The median-depth rule.
    pub median: MedianRule,
}

impl CompositeRules {
    /// gsplat 1.5.3's rules.
    pub const GSPLAT: Self = Self {
        max_alpha: GSPLAT_MAX_ALPHA,
        min_alpha: ALPHA_THRESHOLD,
        stop_transmittance: STOP_TRANSMITTANCE,
        stop_inclusive: true,
        pixel_offset: 0.5,
        clip_to_box: true,
        tile_rect: TileRect::Gsplat,
        median: MedianRule::FirstBelowHalf,
    };
    /// The original 3DGS rasterizer's rules.
    pub const ORIGINAL_3DGS: Self = Self {
        max_alpha: ORIGINAL_MAX_ALPHA,
        min_alpha: ALPHA_THRESHOLD,
        stop_transmittance: STOP_TRANSMITTANCE,
        stop_inclusive: false,
        pixel_offset: 0.0,
        clip_to_box: false,
        tile_rect: TileRect::Original3dgs,
        median: MedianRule::FirstBelowHalf,
    };
}

/// Wall-clock seconds per stage and counts, for benchmarks and `--verbose` reports.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Projection (culling, covariance, SH colour).
    pub project_s: f64,
    /// Tile binning and per-tile depth sort.
    pub sort_s: f64,
    /// Front-to-back compositing.
    pub composite_s: f64,
    /// Splats that survived culling.
    pub visible: usize,
    /// (tile, splat) pairs.
    pub intersections: usize,
}

/// One tile row's slices of the output images.
struct Band<'a> {
    rgb: Option<&'a mut [f32]>,
    alpha: Option<&'a mut [f32]>,
    depth: Option<&'a mut [f32]>,
    median: Option<&'a mut [f32]>,
    front: Option<&'a mut [f32]>,
    normal: Option<&'a mut [f32]>,
}

/// `buf` cut into `n` chunks of `chunk` values (the last may be shorter), or `n` `None`s.
fn split_bands(buf: &mut Option<Vec<f32>>, chunk: usize, n: usize) -> Vec<Option<&mut [f32]>> {
    match buf.as_mut() {
        Some(buf) => buf.chunks_mut(chunk.max(1)).map(Some).collect(),
        None => (0..n).map(|_| None).collect(),
    }
}

/// Bins, sorts and composites `screen` (evaluated by `kernel`) into a `width × height` image.
/// Fills `stats.sort_s`, `stats.composite_s`, `stats.visible` and `stats.intersections`.
#[must_use]
pub fn rasterize<K: SplatKernel>(
    screen: &ScreenSplats,
    kernel: &K,
    size: (u32, u32),
    rules: &CompositeRules,
    outputs: Outputs,
    background: [f32; 3],
    stats: &mut RenderStats,
) -> RenderImages {
    rasterize_with_contribution(
        screen, kernel, size, rules, outputs, background, false, stats,
    )
    .0
}

/// [`rasterize`], and with `contribution` each screen splat's largest blending weight
/// `w = α·T` at any pixel of the image (indexed like `screen`; 0 where it was skipped or
/// hidden everywhere).
#[must_use]
#[allow(clippy::too_many_arguments)]
pub fn rasterize_with_contribution<K: SplatKernel>(
    screen: &ScreenSplats,
    kernel: &K,
    size: (u32, u32),
    rules: &CompositeRules,
    outputs: Outputs,
    background: [f32; 3],
    contribution: bool,
    stats: &mut RenderStats,
) -> (RenderImages, Option<Vec<f32>>) {
    let extra = Extra {
        contribution,
        front_alpha: None,
    };
    rasterize_extra(
        screen, kernel, size, rules, outputs, background, extra, stats,
    )
}

/// What [`rasterize_extra`] computes besides the images of `outputs`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Extra {
    /// Each screen splat's largest blending weight (as [`rasterize_with_contribution`]).
    pub(super) contribution: bool,
    /// [`RenderImages::front_depth`] at this accumulated alpha (in (0, 1)).
    pub(super) front_alpha: Option<f32>,
}

/// [`rasterize_with_contribution`], and with `extra.front_alpha` the front depth.
#[allow(clippy::too_many_arguments)]
pub(super) fn rasterize_extra<K: SplatKernel>(
    screen: &ScreenSplats,
    kernel: &K,
    (width, height): (u32, u32),
    rules: &CompositeRules,
    outputs: Outputs,
    background: [f32; 3],
    extra: Extra,
    stats: &mut RenderStats,
) -> (RenderImages, Option<Vec<f32>>) {
    let Extra {
        contribution,
        front_alpha,
    } = extra;
    let start = std::time::Instant::now();
    // One global depth sort; the per-splat data the tile loop reads is gathered into that
    // order so each tile walks memory forwards.
    let order = depth_order(&screen.depths);
    let centers: Vec<[f32; 2]> = order.iter().map(|&i| screen.centers[i as usize]).collect();
    let radii: Vec<[f32; 2]> = order.iter().map(|&i| screen.radii[i as usize]).collect();
    let gather3 = |v: &[[f32; 3]], on: bool| -> Vec<[f32; 3]> {
        if on {
            order.iter().map(|&i| v[i as usize]).collect()
        } else {
            Vec::new()
        }
    };
    let colors = gather3(&screen.colors, outputs.rgb);
    let packed = centers
        .iter()
        .zip(&radii)
        .enumerate()
        .map(|(k, (&center, &radius))| PackedSplat {
            center,
            radius,
            color: colors.get(k).copied().unwrap_or([0.0; 3]),
            _pad: 0.0,
        })
        .collect();
    let sorted = SortedSplats {
        packed,
        normals: gather3(&screen.normals, outputs.normal),
        centers,
        radii,
    };
    let reordered = kernel.reordered(&order);
    let (kernel, kernel_index) = match &reordered {
        Some(k) => (k, None),
        None => (kernel, Some(order.as_slice())),
    };
    let bins = TileBins::bin(
        &sorted.centers,
        &sorted.radii,
        width,
        height,
        rules.tile_rect,
    );
    stats.sort_s = start.elapsed().as_secs_f64();
    stats.visible = screen.len();
    stats.intersections = bins.intersections();

    let start = std::time::Instant::now();
    let mut images = RenderImages::new(width, height, outputs);
    if front_alpha.is_some() {
        images.front_depth = Some(vec![0.0; width as usize * height as usize]);
    }
    let w = width as usize;
    let band_px = TILE_SIZE as usize * w;
    let n = bins.tiles_y as usize;
    let rgb = split_bands(&mut images.rgb, 3 * band_px, n);
    let alpha = split_bands(&mut images.alpha, band_px, n);
    let depth = split_bands(&mut images.depth, band_px, n);
    let median = split_bands(&mut images.median_depth, band_px, n);
    let front = split_bands(&mut images.front_depth, band_px, n);
    let normal = split_bands(&mut images.normal, 3 * band_px, n);
    let bands: Vec<Band<'_>> = rgb
        .into_iter()
        .zip(alpha)
        .zip(depth)
        .zip(median)
        .zip(front)
        .zip(normal)
        .map(|(((((rgb, alpha), depth), median), front), normal)| Band {
            rgb,
            alpha,
            depth,
            median,
            front,
            normal,
        })
        .collect();
    // Largest weight per depth-order position, as the bits of a non-negative f32 (which order
    // like the floats), raised by every tile the splat touches.
    let largest: Vec<AtomicU32> = if contribution {
        (0..screen.len()).map(|_| AtomicU32::new(0)).collect()
    } else {
        Vec::new()
    };
    let ctx = TileContext {
        splats: &sorted,
        largest: contribution.then_some(largest.as_slice()),
        kernel,
        kernel_index,
        rules,
        outputs,
        front_alpha,
        background,
        width,
        height,
    };
    bands
        .into_par_iter()
        .enumerate()
        .for_each(|(ty, mut band)| {
            let mut state = TileState::default();
            for tx in 0..bins.tiles_x {
                let (entries, ty) = (bins.tile(tx, ty as u32), ty as u32);
                if contribution {
                    ctx.composite_tile::<true>(entries, tx, ty, &mut band, &mut state);
                } else {
                    ctx.composite_tile::<false>(entries, tx, ty, &mut band, &mut state);
                }
            }
        });
    stats.composite_s = start.elapsed().as_secs_f64();
    let contribution = contribution.then(|| {
        let mut by_screen = vec![0.0f32; screen.len()];
        for (&i, w) in order.iter().zip(&largest) {
            by_screen[i as usize] = f32::from_bits(w.load(Ordering::Relaxed));
        }
        by_screen
    });
    (images, contribution)
}

/// What the tile loop reads of one splat besides the kernel's data, in one 32-byte record (one
/// cache line: a tile's splats lie far apart in the depth order).
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct PackedSplat {
    center: [f32; 2],
    radius: [f32; 2],
    /// Zero unless rgb is rendered.
    color: [f32; 3],
    _pad: f32,
}

/// The screen data the tile loop reads, in depth order.
struct SortedSplats {
    /// Centre, radius and colour per splat.
    packed: Vec<PackedSplat>,
    /// Box centres, for binning.
    centers: Vec<[f32; 2]>,
    /// Box half sizes, for binning.
    radii: Vec<[f32; 2]>,
    normals: Vec<[f32; 3]>,
}

struct TileContext<'a, K> {
    splats: &'a SortedSplats,
    /// Each depth-order position's largest weight so far (f32 bits), when asked for.
    largest: Option<&'a [AtomicU32]>,
    kernel: &'a K,
    /// Kernel index of each depth-order position, unless the kernel was reordered.
    kernel_index: Option<&'a [u32]>,
    rules: &'a CompositeRules,
    outputs: Outputs,
    /// The alpha of the front depth, when it is asked for.
    front_alpha: Option<f32>,
    background: [f32; 3],
    width: u32,
    height: u32,
}

/// Per-pixel accumulators of one tile, one array per quantity so the row loop vectorises
/// (reused across the tiles of a band: no allocation).
struct TileState {
    transmittance: [f32; TILE_PIXELS],
    /// 1 while the pixel accepts splats, 0 once it stopped.
    alive: [f32; TILE_PIXELS],
    rgb: [[f32; TILE_PIXELS]; 3],
    depth: [f32; TILE_PIXELS],
    median: [f32; TILE_PIXELS],
    /// Depth where the accumulated alpha first reaches the front alpha (0: not yet).
    front: [f32; TILE_PIXELS],
    normal: [[f32; TILE_PIXELS]; 3],
}

impl Default for TileState {
    fn default() -> Self {
        Self {
            transmittance: [1.0; TILE_PIXELS],
            alive: [1.0; TILE_PIXELS],
            rgb: [[0.0; TILE_PIXELS]; 3],
            depth: [0.0; TILE_PIXELS],
            median: [0.0; TILE_PIXELS],
            front: [0.0; TILE_PIXELS],
            normal: [[0.0; TILE_PIXELS]; 3],
        }
    }
}

/// Per-splat constants of the row loop.
#[derive(Clone, Copy)]
struct RowSplat {
    color: [f32; 3],
    normal: [f32; 3],
}

/// The rules as the row loop uses them.
#[derive(Clone, Copy)]
struct RowRules {
    max_alpha: f32,
    min_alpha: f32,
    /// A pixel stops when `next_T < stop_below` (the `<=` rule uses the next float up).
    stop_below: f32,
    median: MedianRule,
    /// The front depth is taken where the transmittance first drops to this or below (−1:
    /// never, when it is not asked for).
    front_t: f32,
}

/// Pixels evaluated together: rows are processed in groups of this many pixels (the width of
/// an SSE vector), so the loops compile to fixed-width vector code. Pixels of a group
/// outside a splat's box are evaluated too — exactly what gsplat does for every pixel of a
/// tile — and contribute nothing (their alpha is below the skip threshold).
const CHUNK: usize = 4;

/// Splats whose data the tile loop loads ahead in one batch.
const LOOKAHEAD: usize = 16;

/// Composites one splat over the `CHUNK` pixels of a row starting at tile index `p0`, given the
/// kernel's `alpha` (0 where it does not contribute) and `depth` per pixel. Branch-free so it
/// vectorises. Returns which pixels stopped (bit `k` for pixel `p0 + k`) and the splat's
/// blending weight `α·T` at each pixel (0 where it was not accepted).
#[inline(always)]
fn composite_chunk<const EXTRA: bool>(
    s: &mut TileState,
    p0: usize,
    alpha: Vec4,
    depth: Vec4,
    g: RowSplat,
    r: RowRules,
) -> (u32, Vec4) {
    let range = p0..p0 + CHUNK;
    if range.end > TILE_PIXELS {
        return (0, Vec4::ZERO);
    }
    let t = Vec4::from_slice(&s.transmittance[range.clone()]);
    let alive = Vec4::from_slice(&s.alive[range.clone()]);
    let a = alpha.min(Vec4::splat(r.max_alpha));
    let valid = alive.cmpgt(Vec4::ZERO) & a.cmpge(Vec4::splat(r.min_alpha));
    let next_t = t * (Vec4::ONE - a);
    let stop = valid & next_t.cmplt(Vec4::splat(r.stop_below));
    let accept = valid & !stop;
    let w = Vec4::select(accept, a * t, Vec4::ZERO);
    for c in 0..3 {
        let acc = &mut s.rgb[c][range.clone()];
        (Vec4::from_slice(acc) + w * g.color[c]).write_to_slice(acc);
    }
    let acc = &mut s.depth[range.clone()];
    (Vec4::from_slice(acc) + w * depth).write_to_slice(acc);
    Vec4::select(accept, next_t, t).write_to_slice(&mut s.transmittance[range.clone()]);
    Vec4::select(stop, Vec4::ZERO, alive).write_to_slice(&mut s.alive[range.clone()]);
    if EXTRA {
        let half = Vec4::splat(MEDIAN_TRANSMITTANCE);
        let take = match r.median {
            MedianRule::FirstBelowHalf => accept & t.cmpge(half) & next_t.cmplt(half),
            MedianRule::LastWhileAboveHalf => accept & t.cmpgt(half),
        };
        let med = &mut s.median[range.clone()];
        Vec4::select(take, depth, Vec4::from_slice(med)).write_to_slice(med);
        let front_t = Vec4::splat(r.front_t);
        let take = accept & t.cmpgt(front_t) & next_t.cmple(front_t);
        let front = &mut s.front[range.clone()];
        Vec4::select(take, depth, Vec4::from_slice(front)).write_to_slice(front);
        for c in 0..3 {
            let acc = &mut s.normal[c][range.clone()];
            (Vec4::from_slice(acc) + w * g.normal[c]).write_to_slice(acc);
        }
    }
    (stop.bitmask(), w)
}

impl<K: SplatKernel> TileContext<'_, K> {
    /// Composites one tile; with `TRACK`, raises each splat's largest weight in
    /// `self.largest` (a separate instance, so the plain render does no tracking at all).
    fn composite_tile<const TRACK: bool>(
        &self,
        entries: &[u32],
        tx: u32,
        ty: u32,
        band: &mut Band<'_>,
        s: &mut TileState,
    ) {
        let ts = TILE_SIZE as usize;
        let x_start = tx * TILE_SIZE;
        let y_start = ty * TILE_SIZE;
        let tw = (self.width - x_start).min(TILE_SIZE) as usize;
        let th = (self.height - y_start).min(TILE_SIZE) as usize;
        s.transmittance.fill(1.0);
        // Pixels of a partial tile outside the image never accept splats.
        for (p, alive) in s.alive.iter_mut().enumerate() {
            *alive = if p % ts < tw && p / ts < th { 1.0 } else { 0.0 };
        }
        for c in &mut s.rgb {
            c.fill(0.0);
        }
        s.depth.fill(0.0);
        let o = self.outputs;
        let extra = o.median_depth || o.normal || self.front_alpha.is_some();
        if extra {
            s.median.fill(0.0);
            s.front.fill(0.0);
            for c in &mut s.normal {
                c.fill(0.0);
            }
        }
        let r = self.rules;
        let row_rules = RowRules {
            max_alpha: r.max_alpha,
            min_alpha: r.min_alpha,
            stop_below: if r.stop_inclusive {
                r.stop_transmittance.next_up()
            } else {
                r.stop_transmittance
            },
            median: r.median,
            front_t: self.front_alpha.map_or(-1.0, |a| 1.0 - a),
        };
        let mut remaining = tw * th;
        let off = r.pixel_offset;
        for (k, &entry) in entries.iter().enumerate() {
            if remaining == 0 {
                break;
            }
            // Tile lists jump through memory: every `LOOKAHEAD` splats, load the next
            // `LOOKAHEAD` splats' data at once, so their cache misses overlap each other
            // (one wait per batch rather than one per splat).
            if k % LOOKAHEAD == 0 {
                let ahead = entries.get(k + 1..(k + 1 + LOOKAHEAD).min(entries.len()));
                for &next in ahead.unwrap_or(&[]) {
                    let next = next as usize;
                    let kn = self.kernel_index.map_or(next, |m| m[next] as usize);
                    std::hint::black_box(self.kernel.touch(kn));
                    std::hint::black_box(self.splats.packed.get(next).map(|p| p.center[0]));
                }
            }
            let g = entry as usize;
            let kg = self.kernel_index.map_or(g, |m| m[g] as usize);
            let Some(&packed) = self.splats.packed.get(g) else {
                continue;
            };
            // Local pixel range of this splat in the tile: pixel centres j + off within
            // [c - r, c + r] (rounded outwards), or the whole tile.
            let (lx0, lx1, ly0, ly1) = box_pixels(
                r.clip_to_box,
                packed.center,
                packed.radius,
                off,
                (x_start, y_start),
                (tw, th),
            );
            let mut largest = Vec4::ZERO;
            let splat = RowSplat {
                color: packed.color,
                normal: if o.normal {
                    self.splats.normals[g]
                } else {
                    [0.0; 3]
                },
            };
            for ly in ly0..ly1 {
                let py = (y_start as usize + ly) as f32 + off;
                let (sx0, sx1) = match self.kernel.row_span(kg, py) {
                    Some((a, b)) => (
                        lo(a - off, x_start, tw).max(lx0),
                        hi(b - off, x_start, tw).min(lx1),
                    ),
                    None => (lx0, lx1),
                };
                if sx0 >= sx1 {
                    continue;
                }
                let row = ly * ts;
                // Stopped pixels of this row, one bit per pixel (counted once per row: the
                // baseline x86-64 target has no popcount instruction).
                let mut stopped = 0u32;
                // The fewest groups covering the span, shifted left where they would leave
                // the tile row (each lane is still evaluated at its own pixel).
                let groups = (sx1 - sx0).div_ceil(CHUNK);
                let gx0 = sx0.min(ts.saturating_sub(groups * CHUNK));
                for j in 0..groups {
                    let lx = gx0 + j * CHUNK;
                    let px0 = (x_start as usize + lx) as f32 + off;
                    let (alpha, depth) = self.kernel.sample4(kg, py, px0);
                    let (mask, w) = if extra {
                        composite_chunk::<true>(s, row + lx, alpha, depth, splat, row_rules)
                    } else {
                        composite_chunk::<false>(s, row + lx, alpha, depth, splat, row_rules)
                    };
                    stopped |= mask << lx;
                    if TRACK {
                        largest = largest.max(w);
                    }
                }
                remaining = remaining.saturating_sub(stopped.count_ones() as usize);
            }
            if TRACK && let Some(slots) = self.largest {
                let w = largest.max_element();
                if w > 0.0 {
                    slots[g].fetch_max(w.to_bits(), Ordering::Relaxed);
                }
            }
        }
        // Write the tile into the band.
        let w = self.width as usize;
        for ly in 0..th {
            for lx in 0..tw {
                let p = ly * ts + lx;
                let q = ly * w + x_start as usize + lx;
                let t = s.transmittance[p];
                let acc = 1.0 - t;
                if let Some(rgb) = band.rgb.as_deref_mut() {
                    for c in 0..3 {
                        rgb[3 * q + c] = s.rgb[c][p] + t * self.background[c];
                    }
                }
                if let Some(alpha) = band.alpha.as_deref_mut() {
                    alpha[q] = acc;
                }
                if let Some(depth) = band.depth.as_deref_mut() {
                    // gsplat: depth / max(alpha, 1e-10); 0 where nothing was composited.
                    depth[q] = if acc > 0.0 {
                        s.depth[p] / acc.max(1e-10)
                    } else {
                        0.0
                    };
                }
                if let Some(median) = band.median.as_deref_mut() {
                    median[q] = s.median[p];
                }
                if let Some(front) = band.front.as_deref_mut() {
                    front[q] = s.front[p];
                }
                if let Some(normal) = band.normal.as_deref_mut() {
                    for c in 0..3 {
                        normal[3 * q + c] = s.normal[c][p];
                    }
                }
            }
        }
    }
}
