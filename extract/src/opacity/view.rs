//! One camera's view of the Gaussians: which Gaussians can touch the ray through each 2x2
//! pixel tile, in order of their nearest depth, and each Gaussian's whitened camera centre.
//! The buffers are reused from view to view, so a run holds one view at a time.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use trisplat_geometry::Camera;

use super::gaussians::Prepared;

/// Side of a binning tile, pixels.
pub(crate) const TILE: u32 = 2;
/// Camera z below which a Gaussian's centre is culled and a point is not seen (the renderer's
/// near plane, docs/conventions.md §5).
pub(crate) const NEAR: f64 = 0.01;

/// What the walk along a ray reads of one Gaussian, packed in one cache-line-sized record.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Packed {
    /// Whitened camera centre `M (origin - mean)`.
    pub centre: [f64; 3],
    /// Whitening rows `R_k / s_k`.
    pub whiten: [[f32; 3]; 3],
    /// Smallest camera z of the reach box, rounded down to f32 (-inf when it reaches the near
    /// plane).
    pub zmin: f32,
    /// Squared whitened reach (see [`Prepared::q_max`]).
    pub q_max: f32,
    /// Opacity.
    pub opacity: f32,
    /// Index among the kept Gaussians.
    pub index: u32,
}

/// One view's bins (reused across views).
#[derive(Debug, Default)]
pub(crate) struct ViewBins {
    /// Camera centre, world.
    pub origin: DVec3,
    /// World-to-camera rotation.
    rot: DMat3,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    width: u32,
    height: u32,
    tiles_x: u32,
    /// The binned Gaussians by (zmin, index).
    pub packed: Vec<Packed>,
    /// Tile `t`'s Gaussians are `packed[entries[offsets[t]..offsets[t + 1]]]`.
    offsets: Vec<u32>,
    entries: Vec<u32>,
    order: Vec<u32>,
    /// Per Gaussian: smallest box depth and tile rectangle.
    foot: Vec<(f64, [u32; 4])>,
}

/// Where a point falls in a view.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Hit {
    /// The point's camera z.
    pub z: f64,
    /// Its tile.
    pub tile: usize,
}

impl ViewBins {
    /// Bins the Gaussians of `p` for `camera`. A Gaussian reaches the alpha cut only on rays
    /// through its ellipsoid of squared whitened radius `q_max`, whose projection lies inside
    /// that of its bounding box: the box's projected corners bound the tiles it is listed in.
    pub fn prepare(&mut self, p: &Prepared, camera: &Camera) {
        self.origin = camera.position();
        self.rot = camera.world_to_camera_rotation();
        (self.fx, self.fy, self.cx, self.cy) = (camera.fx, camera.fy, camera.cx, camera.cy);
        (self.width, self.height) = (camera.width, camera.height);
        self.tiles_x = self.width.div_ceil(TILE);
        let tiles_y = self.height.div_ceil(TILE);
        let n = p.len();
        let mut foot = std::mem::take(&mut self.foot);
        foot.clear();
        foot.par_extend(
            (0..n)
                .into_par_iter()
                .with_min_len(1024)
                .map(|g| self.footprint(p, g, tiles_y)),
        );
        self.foot = foot;
        self.order.clear();
        self.order.extend((0..n as u32).filter(|&g| {
            let r = self.foot[g as usize].1;
            r[0] < r[1] && r[2] < r[3]
        }));
        let foot = &self.foot;
        self.order.par_sort_unstable_by(|&a, &b| {
            foot[a as usize]
                .0
                .total_cmp(&foot[b as usize].0)
                .then(a.cmp(&b))
        });
        let origin = self.origin;
        self.packed.clear();
        self.packed
            .par_extend(self.order.par_iter().with_min_len(1024).map(|&g| {
                let g = g as usize;
                let zmin = foot[g].0;
                let mut z32 = zmin as f32;
                if f64::from(z32) > zmin {
                    z32 = z32.next_down();
                }
                Packed {
                    centre: p.whitened(g, origin - p.means[g]).to_array(),
                    whiten: p.whiten[g],
                    zmin: z32,
                    // Rounded up: the alpha test decides at the cut itself.
                    q_max: (p.q_max[g] as f32).next_up(),
                    opacity: p.opacity[g],
                    index: g as u32,
                }
            }));
        let tiles = (self.tiles_x * tiles_y) as usize;
        self.offsets.clear();
        self.offsets.resize(tiles + 1, 0);
        for &g in &self.order {
            let [x0, x1, y0, y1] = self.foot[g as usize].1;
            for ty in y0..y1 {
                for tx in x0..x1 {
                    self.offsets[(ty * self.tiles_x + tx) as usize + 1] += 1;
                }
            }
        }
        for t in 0..tiles {
            self.offsets[t + 1] += self.offsets[t];
        }
        self.entries.clear();
        self.entries.resize(self.offsets[tiles] as usize, 0);
        let mut fill: Vec<u32> = self.offsets[..tiles].to_vec();
        for (k, &g) in self.order.iter().enumerate() {
            let [x0, x1, y0, y1] = self.foot[g as usize].1;
            for ty in y0..y1 {
                for tx in x0..x1 {
                    let t = (ty * self.tiles_x + tx) as usize;
                    self.entries[fill[t] as usize] = k as u32;
                    fill[t] += 1;
                }
            }
        }
    }

    /// The smallest camera z of Gaussian `g`'s reach box and the tiles `[x0, x1) x [y0, y1)`
    /// its projection touches (empty when culled).
    fn footprint(&self, p: &Prepared, g: usize, tiles_y: u32) -> (f64, [u32; 4]) {
        const EMPTY: [u32; 4] = [0, 0, 0, 0];
        let c = self.rot * (p.means[g] - self.origin);
        if c.z <= NEAR || p.q_max[g] <= 0.0 {
            return (f64::INFINITY, EMPTY);
        }
        let r = p.q_max[g].sqrt();
        let a = p.axes[g].map(|axis| self.rot * axis * r);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut zmin = f64::INFINITY;
        for corner in 0..8u32 {
            let sign = |bit: u32| if corner >> bit & 1 == 0 { -1.0 } else { 1.0 };
            let q = c + a[0] * sign(0) + a[1] * sign(1) + a[2] * sign(2);
            zmin = zmin.min(q.z);
            if q.z <= NEAR {
                continue;
            }
            let uv = [self.fx * q.x / q.z + self.cx, self.fy * q.y / q.z + self.cy];
            for k in 0..2 {
                lo[k] = lo[k].min(uv[k]);
                hi[k] = hi[k].max(uv[k]);
            }
        }
        let tiles_x = self.tiles_x;
        if zmin <= NEAR {
            // The box reaches the camera: any ray may cross it.
            return (f64::NEG_INFINITY, [0, tiles_x, 0, tiles_y]);
        }
        let t = f64::from(TILE);
        let range = |lo: f64, hi: f64, size: u32, tiles: u32| {
            if hi < 0.0 || lo >= f64::from(size) {
                return (0, 0);
            }
            let a = (lo.max(0.0) / t).floor() as u32;
            let b = ((hi.min(f64::from(size) - 1e-9) / t).floor() as u32 + 1).min(tiles);
            (a, b)
        };
        let (x0, x1) = range(lo[0], hi[0], self.width, tiles_x);
        let (y0, y1) = range(lo[1], hi[1], self.height, tiles_y);
        (zmin, [x0, x1, y0, y1])
    }

    /// Where world point `x` falls: `None` behind the near plane or outside the image.
    #[inline]
    pub fn locate(&self, x: DVec3) -> Option<Hit> {
        let c = self.rot * (x - self.origin);
        if c.z.is_nan() || c.z <= NEAR {
            return None;
        }
        let u = self.fx * c.x / c.z + self.cx;
        let v = self.fy * c.y / c.z + self.cy;
        if !(u >= 0.0 && v >= 0.0 && u < f64::from(self.width) && v < f64::from(self.height)) {
            return None;
        }
        let (tx, ty) = ((u as u32) / TILE, (v as u32) / TILE);
        Some(Hit {
            z: c.z,
            tile: (ty * self.tiles_x + tx) as usize,
        })
    }

    /// The Gaussians of `tile` (indices into [`Self::packed`]), nearest first.
    #[inline]
    pub fn tile(&self, tile: usize) -> &[u32] {
        &self.entries[self.offsets[tile] as usize..self.offsets[tile + 1] as usize]
    }
}
