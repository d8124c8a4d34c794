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
    /// Largest camera z of the reach box, rounded up to f32.
    pub zmax: f32,
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
    /// Per Gaussian: its footprint.
    foot: Vec<Footprint>,
    /// (tile, rank in `packed`) pairs, sorted.
    pairs: Vec<u64>,
    /// Per tile, a depth beyond which every point of the tile is known to be at or above the
    /// level (see [`Self::certify`]); empty when not computed.
    certain: Vec<f32>,
}

/// Where one Gaussian's reach ellipsoid can meet the view's rays.
#[derive(Clone, Copy, Debug)]
struct Footprint {
    /// Smallest camera z of the reach box.
    zmin: f64,
    /// Largest camera z of the reach box.
    zmax: f64,
    /// Tiles `[x0, x1) x [y0, y1)` the projected box touches (empty when culled).
    rect: [u32; 4],
    /// The reach ellipsoid's silhouette on the image plane `z = 1`, `(x, y, 1) K (x, y, 1)ᵀ >= 0`,
    /// as `[k00, k01, k11, k02, k12, k22]`; `None` when every tile of the box is kept.
    conic: Option<[f64; 6]>,
}

const CULLED: Footprint = Footprint {
    zmin: f64::INFINITY,
    zmax: f64::INFINITY,
    rect: [0, 0, 0, 0],
    conic: None,
};

/// Pixels by which a tile is widened before its test against a silhouette, so that rounding
/// never drops a Gaussian the exact test along a ray would keep.
const TILE_MARGIN: f64 = 0.01;

/// Whether a silhouette conic can be trusted: bounded, and its peak value at the centre far
/// above the rounding of its entries, which is relative to `magnitude`, the size of the terms
/// `b bᵀ` and `κ A` that cancel in them (a thin Gaussian cancels them to almost nothing).
/// Untrusted conics keep every tile of the box; so does a Gaussian under ~0.4 px across at
/// 256², whose box is a tile or two anyway.
fn well_conditioned(k: &[f64; 6], magnitude: f64) -> bool {
    let [k00, k01, k11, k02, k12, k22] = *k;
    let det = k00 * k11 - k01 * k01;
    if !(k00 < 0.0 && k11 < 0.0 && det > 0.0 && det.is_finite()) {
        return false;
    }
    let xc = (k01 * k12 - k11 * k02) / det;
    let yc = (k01 * k02 - k00 * k12) / det;
    let peak =
        k00 * xc * xc + 2.0 * k01 * xc * yc + k11 * yc * yc + 2.0 * k02 * xc + 2.0 * k12 * yc + k22;
    peak.is_finite() && peak > 1e-6 * magnitude * (1.0 + xc * xc + yc * yc)
}

/// Whether the conic region `Q(x, y) >= 0` (bounded: negative definite quadratic part) meets
/// the rectangle `[x0, x1] x [y0, y1]`. Conservative: `true` when the region is not bounded.
fn conic_meets(k: &[f64; 6], x0: f64, x1: f64, y0: f64, y1: f64) -> bool {
    let [k00, k01, k11, k02, k12, k22] = *k;
    let q = |x: f64, y: f64| {
        k00 * x * x + 2.0 * k01 * x * y + k11 * y * y + 2.0 * k02 * x + 2.0 * k12 * y + k22
    };
    let det = k00 * k11 - k01 * k01;
    if !(k00 < 0.0 && k11 < 0.0 && det > 0.0) {
        return true;
    }
    // The maximum of the concave Q over the rectangle: its centre if inside, else on an edge.
    let xc = (k01 * k12 - k11 * k02) / det;
    let yc = (k01 * k02 - k00 * k12) / det;
    if (x0..=x1).contains(&xc) && (y0..=y1).contains(&yc) {
        return q(xc, yc) >= 0.0;
    }
    [y0, y1]
        .iter()
        .any(|&y| q((-(k01 * y + k02) / k00).clamp(x0, x1), y) >= 0.0)
        || [x0, x1]
            .iter()
            .any(|&x| q(x, (-(k01 * x + k12) / k11).clamp(y0, y1)) >= 0.0)
}

/// The level a view's tiles certify points at or above, and the alpha rules it is reached by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CertifyAt {
    /// The level.
    pub level: f64,
    /// Alphas are clamped to at most this.
    pub max_alpha: f32,
    /// Alphas below this add nothing.
    pub min_alpha: f32,
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
            let r = self.foot[g as usize].rect;
            r[0] < r[1] && r[2] < r[3]
        }));
        let foot = &self.foot;
        self.order.par_sort_unstable_by(|&a, &b| {
            foot[a as usize]
                .zmin
                .total_cmp(&foot[b as usize].zmin)
                .then(a.cmp(&b))
        });
        let origin = self.origin;
        self.packed.clear();
        self.packed
            .par_extend(self.order.par_iter().with_min_len(1024).map(|&g| {
                let g = g as usize;
                let zmin = foot[g].zmin;
                let mut z32 = zmin as f32;
                if f64::from(z32) > zmin {
                    z32 = z32.next_down();
                }
                let zmax = foot[g].zmax;
                let mut zmax32 = zmax as f32;
                if f64::from(zmax32) < zmax {
                    zmax32 = zmax32.next_up();
                }
                Packed {
                    centre: p.whitened(g, origin - p.means[g]).to_array(),
                    whiten: p.whiten[g],
                    zmin: z32,
                    zmax: zmax32,
                    // Rounded up: the alpha test decides at the cut itself.
                    q_max: (p.q_max[g] as f32).next_up(),
                    opacity: p.opacity[g],
                    index: g as u32,
                }
            }));
        // (tile, rank) for every tile the Gaussian's silhouette meets, sorted: each tile's
        // Gaussians by rank, that is by (zmin, index).
        let (tiles_x, t) = (self.tiles_x, f64::from(TILE));
        let (fx, fy, cx, cy) = (self.fx, self.fy, self.cx, self.cy);
        let mut pairs = std::mem::take(&mut self.pairs);
        pairs.clear();
        pairs.par_extend(
            self.order
                .par_iter()
                .enumerate()
                .with_min_len(256)
                .flat_map_iter(|(rank, &g)| {
                    let f = foot[g as usize];
                    let [x0, x1, y0, y1] = f.rect;
                    (y0..y1).flat_map(move |ty| {
                        (x0..x1).filter_map(move |tx| {
                            let keep = f.conic.as_ref().is_none_or(|k| {
                                let u0 = f64::from(tx) * t - TILE_MARGIN;
                                let v0 = f64::from(ty) * t - TILE_MARGIN;
                                let (u1, v1) =
                                    (u0 + t + 2.0 * TILE_MARGIN, v0 + t + 2.0 * TILE_MARGIN);
                                conic_meets(
                                    k,
                                    (u0 - cx) / fx,
                                    (u1 - cx) / fx,
                                    (v0 - cy) / fy,
                                    (v1 - cy) / fy,
                                )
                            });
                            keep.then(|| u64::from(ty * tiles_x + tx) << 32 | rank as u64)
                        })
                    })
                }),
        );
        pairs.par_sort_unstable();
        let tiles = (self.tiles_x * tiles_y) as usize;
        self.offsets.clear();
        self.offsets.resize(tiles + 1, 0);
        for &pair in &pairs {
            self.offsets[(pair >> 32) as usize + 1] += 1;
        }
        for t in 0..tiles {
            self.offsets[t + 1] += self.offsets[t];
        }
        self.entries.clear();
        self.entries.extend(pairs.iter().map(|&pair| pair as u32));
        self.pairs = pairs;
        self.certain.clear();
    }

    /// Computes, per tile, a depth beyond which the opacity accumulated up to any point of the
    /// tile is at least `level`: walking the tile's Gaussians in order, each contributes at
    /// least its alpha at the worst of the tile's four corner rays' peaks (the rays' smallest
    /// whitened distance is quasi-convex over the image plane: its sublevel sets are the
    /// silhouette ellipses of the Gaussian's level ellipsoids, so its largest over the tile
    /// is at a corner) once the point lies beyond its reach box (the peak then lies before the
    /// point, where every ray model takes it). The depth is the farthest reach box of the
    /// Gaussians needed to bring that lower bound to `level` (+1e-6 for rounding); infinite
    /// when they do not. Gaussians whose whitened camera distance exceeds 1e4 (rounding of
    /// their distances above 1e-8) count for nothing.
    pub fn certify(&mut self, at: CertifyAt) {
        /// Most Gaussians of a tile looked at.
        const LOOK: usize = 256;
        let tiles = self.offsets.len().saturating_sub(1);
        let rot_t = self.rot.transpose();
        let (fx, fy, cx, cy) = (self.fx, self.fy, self.cx, self.cy);
        let t = f64::from(TILE);
        let (level, max_alpha, min_alpha) =
            (at.level, f64::from(at.max_alpha), f64::from(at.min_alpha));
        let this = &*self;
        let certain: Vec<f32> = (0..tiles)
            .into_par_iter()
            .with_min_len(256)
            .map(|tile| {
                let (tx, ty) = (tile as u32 % this.tiles_x, tile as u32 / this.tiles_x);
                let corners: [DVec3; 4] = std::array::from_fn(|k| {
                    let u = (f64::from(tx) + (k & 1) as f64) * t;
                    let v = (f64::from(ty) + (k >> 1) as f64) * t;
                    rot_t * DVec3::new((u - cx) / fx, (v - cy) / fy, 1.0)
                });
                let mut transmittance = 1.0f64;
                let mut depth = f64::NEG_INFINITY;
                for &k in this.tile(tile).iter().take(LOOK) {
                    let g = &this.packed[k as usize];
                    let u = DVec3::from_array(g.centre);
                    let uu = u.length_squared();
                    if g.zmin.is_nan() || g.zmin <= NEAR as f32 || uu.is_nan() || uu > 1e8 {
                        continue;
                    }
                    let m = &g.whiten;
                    let mut q_worst = 0.0f64;
                    for d in &corners {
                        let row = |r: usize| {
                            f64::from(m[r][0]) * d.x
                                + f64::from(m[r][1]) * d.y
                                + f64::from(m[r][2]) * d.z
                        };
                        let v = DVec3::new(row(0), row(1), row(2));
                        let vv = v.length_squared();
                        let q = if vv > 0.0 {
                            (u + v * (-u.dot(v) / vv)).length_squared()
                        } else {
                            f64::INFINITY
                        };
                        q_worst = q_worst.max(q);
                    }
                    let q_worst = q_worst + 1e-6;
                    if q_worst.is_nan() || q_worst > f64::from(g.q_max) {
                        continue;
                    }
                    let alpha = (f64::from(g.opacity) * (-0.5 * q_worst).exp()).min(max_alpha);
                    if alpha < min_alpha {
                        continue;
                    }
                    transmittance *= 1.0 - alpha;
                    depth = depth.max(f64::from(g.zmax));
                    if 1.0 - transmittance >= level + 1e-6 {
                        let mut z = depth as f32;
                        if f64::from(z) < depth {
                            z = z.next_up();
                        }
                        return z;
                    }
                }
                f32::INFINITY
            })
            .collect();
        self.certain = certain;
    }

    /// Whether the point `hit` locates is known to be at or above the level of
    /// [`Self::certify`] (never when that was not called).
    #[inline]
    pub fn is_certain(&self, hit: Hit) -> bool {
        self.certain
            .get(hit.tile)
            .is_some_and(|&z| hit.z > f64::from(z))
    }

    /// Gaussian `g`'s reach box's smallest camera z, the tiles its projection touches, and the
    /// silhouette of its reach ellipsoid.
    fn footprint(&self, p: &Prepared, g: usize, tiles_y: u32) -> Footprint {
        let c = self.rot * (p.means[g] - self.origin);
        if c.z <= NEAR || p.q_max[g] <= 0.0 {
            return CULLED;
        }
        let r = p.q_max[g].sqrt();
        let a = p.axes[g].map(|axis| self.rot * axis * r);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let (mut zmin, mut zmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for corner in 0..8u32 {
            let sign = |bit: u32| if corner >> bit & 1 == 0 { -1.0 } else { 1.0 };
            let q = c + a[0] * sign(0) + a[1] * sign(1) + a[2] * sign(2);
            zmin = zmin.min(q.z);
            zmax = zmax.max(q.z);
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
            return Footprint {
                zmin: f64::NEG_INFINITY,
                zmax,
                rect: [0, tiles_x, 0, tiles_y],
                conic: None,
            };
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
        // A ray `s d` (camera space) meets the ellipsoid `|N (X - c)|² <= q_max` (N = M Wᵀ)
        // iff `(dᵀ A c)² >= (cᵀ A c - q_max) dᵀ A d`, A = NᵀN: the cone `dᵀ (b bᵀ - κ A) d >= 0`
        // with `b = A c`, `κ = cᵀ A c - q_max` (> 0: the camera lies outside the box).
        let m = DMat3::from_cols_array_2d(&p.whiten[g].map(|row| row.map(f64::from))).transpose();
        let n = m * self.rot.transpose();
        let am = n.transpose() * n;
        let b = am * c;
        let kappa = c.dot(b) - p.q_max[g];
        // The terms cancel: rounding is relative to the largest before cancelling.
        let magnitude = b.length_squared()
            + kappa.abs()
                * am.to_cols_array()
                    .iter()
                    .fold(0.0f64, |m, v| m.max(v.abs()))
                * 3.0;
        let conic = (kappa > 0.0)
            .then(|| {
                let k = |i: usize, j: usize| b[i] * b[j] - kappa * am.col(j)[i];
                [k(0, 0), k(0, 1), k(1, 1), k(0, 2), k(1, 2), k(2, 2)]
            })
            .filter(|k| well_conditioned(k, magnitude));
        Footprint {
            zmin,
            zmax,
            rect: [x0, x1, y0, y1],
            conic,
        }
    }

    /// Bytes of what the walks read ([`Self::compact`]'s size).
    pub fn held_bytes(&self) -> usize {
        self.packed.len() * std::mem::size_of::<Packed>()
            + (self.entries.len() + self.offsets.len()) * std::mem::size_of::<u32>()
            + self.certain.len() * std::mem::size_of::<f32>()
    }

    /// A copy of what the walks read, without the scratch buffers of [`Self::prepare`].
    pub fn compact(&self) -> Self {
        Self {
            origin: self.origin,
            rot: self.rot,
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            width: self.width,
            height: self.height,
            tiles_x: self.tiles_x,
            packed: self.packed.clone(),
            offsets: self.offsets.clone(),
            entries: self.entries.clone(),
            certain: self.certain.clone(),
            ..Self::default()
        }
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
