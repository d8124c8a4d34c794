//! Front-to-back alpha compositing of tile-sorted splats, generic over the mode's
//! [`SplatKernel`] (SPEC §5).
//!
//! Each 16×16 tile is composited on its own, splat by splat in depth order, over the pixels of
//! the splat's box (or of the whole tile); every pixel sees its splats in the same order as in
//! gsplat's per-pixel loop, so the result is the same, and it does not depend on the thread
//! count. Tile rows run in parallel. Per-pixel sums are `f32`, like gsplat's kernel.

use rayon::prelude::*;

use super::image::RenderImages;
use super::options::Outputs;
use super::screen::{ScreenSplats, SplatKernel};
use super::tiles::{TILE_SIZE, TileBins, TileRect};

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
    /// SPEC §5 (3DGS): the splat at which the transmittance first drops below 0.5; 0 where it
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
    (width, height): (u32, u32),
    rules: &CompositeRules,
    outputs: Outputs,
    background: [f32; 3],
    stats: &mut RenderStats,
) -> RenderImages {
    let start = std::time::Instant::now();
    let mut bins = TileBins::bin(screen, width, height, rules.tile_rect);
    bins.sort();
    stats.sort_s = start.elapsed().as_secs_f64();
    stats.visible = screen.len();
    stats.intersections = bins.intersections();

    let start = std::time::Instant::now();
    let mut images = RenderImages::new(width, height, outputs);
    let w = width as usize;
    let band_px = TILE_SIZE as usize * w;
    let n = bins.tiles_y as usize;
    let rgb = split_bands(&mut images.rgb, 3 * band_px, n);
    let alpha = split_bands(&mut images.alpha, band_px, n);
    let depth = split_bands(&mut images.depth, band_px, n);
    let median = split_bands(&mut images.median_depth, band_px, n);
    let normal = split_bands(&mut images.normal, 3 * band_px, n);
    let bands: Vec<Band<'_>> = rgb
        .into_iter()
        .zip(alpha)
        .zip(depth)
        .zip(median)
        .zip(normal)
        .map(|((((rgb, alpha), depth), median), normal)| Band {
            rgb,
            alpha,
            depth,
            median,
            normal,
        })
        .collect();
    let ctx = TileContext {
        screen,
        kernel,
        rules,
        outputs,
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
                ctx.composite_tile(
                    bins.tile(tx, ty as u32),
                    tx,
                    ty as u32,
                    &mut band,
                    &mut state,
                );
            }
        });
    stats.composite_s = start.elapsed().as_secs_f64();
    images
}

struct TileContext<'a, K> {
    screen: &'a ScreenSplats,
    kernel: &'a K,
    rules: &'a CompositeRules,
    outputs: Outputs,
    background: [f32; 3],
    width: u32,
    height: u32,
}

/// Per-pixel accumulators of one tile (reused across the tiles of a band: no allocation).
struct TileState {
    transmittance: [f32; TILE_PIXELS],
    done: [bool; TILE_PIXELS],
    rgb: [[f32; 3]; TILE_PIXELS],
    depth: [f32; TILE_PIXELS],
    median: [f32; TILE_PIXELS],
    normal: [[f32; 3]; TILE_PIXELS],
}

impl Default for TileState {
    fn default() -> Self {
        Self {
            transmittance: [1.0; TILE_PIXELS],
            done: [false; TILE_PIXELS],
            rgb: [[0.0; 3]; TILE_PIXELS],
            depth: [0.0; TILE_PIXELS],
            median: [0.0; TILE_PIXELS],
            normal: [[0.0; 3]; TILE_PIXELS],
        }
    }
}

impl<K: SplatKernel> TileContext<'_, K> {
    fn composite_tile(
        &self,
        keys: &[u64],
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
        s.done.fill(false);
        let o = self.outputs;
        if o.rgb {
            s.rgb.fill([0.0; 3]);
        }
        if o.depth {
            s.depth.fill(0.0);
        }
        if o.median_depth {
            s.median.fill(0.0);
        }
        if o.normal {
            s.normal.fill([0.0; 3]);
        }
        let r = self.rules;
        let mut remaining = tw * th;
        let off = r.pixel_offset;
        for &key in keys {
            if remaining == 0 {
                break;
            }
            let g = (key & 0xffff_ffff) as usize;
            // Local pixel range of this splat in the tile.
            let (lx0, lx1, ly0, ly1) = if r.clip_to_box {
                let c = self.screen.centers[g];
                let rad = self.screen.radii[g];
                let lo = |v: f32, start: u32, n: usize| {
                    ((v.floor() - start as f32).max(0.0) as usize).min(n)
                };
                let hi = |v: f32, start: u32, n: usize| {
                    ((v.ceil() - start as f32 + 1.0).max(0.0) as usize).min(n)
                };
                (
                    lo(c[0] - rad[0] - 1.0, x_start, tw),
                    hi(c[0] + rad[0] + 1.0, x_start, tw),
                    lo(c[1] - rad[1] - 1.0, y_start, th),
                    hi(c[1] + rad[1] + 1.0, y_start, th),
                )
            } else {
                (0, tw, 0, th)
            };
            let color = if o.rgb {
                self.screen.colors[g]
            } else {
                [0.0; 3]
            };
            let normal = if o.normal {
                self.screen.normals[g]
            } else {
                [0.0; 3]
            };
            for ly in ly0..ly1 {
                let py = (y_start as usize + ly) as f32 + off;
                for lx in lx0..lx1 {
                    let p = ly * ts + lx;
                    if s.done[p] {
                        continue;
                    }
                    let px = (x_start as usize + lx) as f32 + off;
                    let Some(sample) = self.kernel.sample(g, px, py) else {
                        continue;
                    };
                    let alpha = sample.alpha.min(r.max_alpha);
                    if alpha < r.min_alpha {
                        continue;
                    }
                    let t = s.transmittance[p];
                    let next_t = t * (1.0 - alpha);
                    let stop = if r.stop_inclusive {
                        next_t <= r.stop_transmittance
                    } else {
                        next_t < r.stop_transmittance
                    };
                    if stop {
                        s.done[p] = true;
                        remaining -= 1;
                        continue;
                    }
                    let w = alpha * t;
                    if o.rgb {
                        let acc = &mut s.rgb[p];
                        acc[0] += w * color[0];
                        acc[1] += w * color[1];
                        acc[2] += w * color[2];
                    }
                    if o.depth {
                        s.depth[p] += w * sample.depth;
                    }
                    if o.median_depth {
                        match r.median {
                            MedianRule::FirstBelowHalf => {
                                if t >= MEDIAN_TRANSMITTANCE && next_t < MEDIAN_TRANSMITTANCE {
                                    s.median[p] = sample.depth;
                                }
                            }
                            MedianRule::LastWhileAboveHalf => {
                                if t > MEDIAN_TRANSMITTANCE {
                                    s.median[p] = sample.depth;
                                }
                            }
                        }
                    }
                    if o.normal {
                        let acc = &mut s.normal[p];
                        acc[0] += w * normal[0];
                        acc[1] += w * normal[1];
                        acc[2] += w * normal[2];
                    }
                    s.transmittance[p] = next_t;
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
                        rgb[3 * q + c] = s.rgb[p][c] + t * self.background[c];
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
                if let Some(normal) = band.normal.as_deref_mut() {
                    normal[3 * q..3 * q + 3].copy_from_slice(&s.normal[p]);
                }
            }
        }
    }
}
