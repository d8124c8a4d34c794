//! [`SpecularChain`]: the environment prefiltered with the GGX lobe for a few roughnesses, the
//! radiance half of the split sum (Karis 2013), interpolated linearly in roughness.
//!
//! Level 0 (roughness 0, a mirror) is the map itself, at most [`MIRROR_WIDTH`] wide. Level `k`
//! of [`LEVELS`] (roughness `k / (LEVELS − 1)`, `α = r²`) is a map [`LEVEL_WIDTHS`]`[k]` wide
//! whose texel towards `R` is, with `n = v = R` (the split sum's assumption) and the
//! environment downsampled to [`SOURCE_WIDTHS`]`[k]` ([`EnvMap::downsampled`]):
//!
//! `L_k(R) = Σ_j L_j D(R·h_j) max(R·l_j, 0) ΔΩ_j / Σ_j D(R·h_j) max(R·l_j, 0) ΔΩ_j`,
//! `h_j = normalize(R + l_j)`, `D(x) = α² / (π ((α² − 1) x² + 1)²)`,
//!
//! a sum over every source texel `j` (direction `l_j`, solid angle `ΔΩ_j`) in `f64`: the
//! weighting Karis's importance-sampled prefilter converges to (its pdf `D (n·h) / (4 v·h)` is
//! `D / 4` when `n = v`), without its sampling noise. [`SpecularChain::lookup`] is bilinear
//! within the two levels around the roughness and linear between them. Widths are capped at the
//! map's own.

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::envmap::EnvMap;

use super::lookup_grad::bilinear_with_grad;

/// Number of prefiltered levels, roughness `k / (LEVELS − 1)`.
pub const LEVELS: usize = 5;

/// Width of the mirror level (the map, downsampled to this at most).
pub const MIRROR_WIDTH: u32 = 512;

/// Width of each level's map (level 0: [`MIRROR_WIDTH`]).
pub const LEVEL_WIDTHS: [u32; LEVELS] = [MIRROR_WIDTH, 64, 32, 32, 32];

/// Width of the downsampled environment each level sums over (level 0: not prefiltered).
pub const SOURCE_WIDTHS: [u32; LEVELS] = [MIRROR_WIDTH, 128, 64, 32, 32];

/// The GGX-prefiltered levels of an environment map.
#[derive(Clone, Debug, PartialEq)]
pub struct SpecularChain {
    levels: Vec<EnvMap>,
}

impl SpecularChain {
    /// Prefilters `map` (module documentation).
    #[must_use]
    pub fn new(map: &EnvMap) -> Self {
        let mut levels = Vec::with_capacity(LEVELS);
        levels.push(map.downsampled(LEVEL_WIDTHS[0]));
        for k in 1..LEVELS {
            let r = k as f64 / (LEVELS - 1) as f64;
            let source = map.downsampled(SOURCE_WIDTHS[k]);
            levels.push(prefilter(&source, LEVEL_WIDTHS[k].min(source.width()), r));
        }
        Self { levels }
    }

    /// The levels, roughness `k / (LEVELS − 1)` for level `k`.
    #[must_use]
    pub fn levels(&self) -> &[EnvMap] {
        &self.levels
    }

    /// Prefiltered radiance towards `r` (unit) for `roughness` (clamped to 0..=1).
    #[must_use]
    pub fn lookup(&self, r: DVec3, roughness: f32) -> [f32; 3] {
        self.lookup_with_dr(r, roughness).0
    }

    /// [`SpecularChain::lookup`] and its derivative in `roughness` (0 outside 0..1; one-sided at
    /// the levels' roughnesses, where the linear interpolation has a kink).
    #[must_use]
    pub fn lookup_with_dr(&self, r: DVec3, roughness: f32) -> ([f32; 3], [f32; 3]) {
        let t = roughness.clamp(0.0, 1.0) * (LEVELS - 1) as f32;
        let k0 = (t as usize).min(LEVELS - 2);
        let f = t - k0 as f32;
        let a = self.levels[k0].bilinear(r);
        let b = self.levels[k0 + 1].bilinear(r);
        let inside = roughness > 0.0 && roughness < 1.0;
        let scale = (LEVELS - 1) as f32;
        (
            std::array::from_fn(|c| a[c] + (b[c] - a[c]) * f),
            std::array::from_fn(|c| if inside { (b[c] - a[c]) * scale } else { 0.0 }),
        )
    }
}

impl SpecularChain {
    /// [`SpecularChain::lookup_with_dr`] and, per channel, the gradient with respect to the
    /// direction `r` (bilinear within each level, [`bilinear_with_grad`]; linear between levels).
    #[must_use]
    pub fn lookup_with_grads(&self, r: DVec3, roughness: f32) -> ([f32; 3], [f32; 3], [DVec3; 3]) {
        let t = roughness.clamp(0.0, 1.0) * (LEVELS - 1) as f32;
        let k0 = (t as usize).min(LEVELS - 2);
        let f = t - k0 as f32;
        let (a, ga) = bilinear_with_grad(&self.levels[k0], r);
        let (b, gb) = bilinear_with_grad(&self.levels[k0 + 1], r);
        let inside = roughness > 0.0 && roughness < 1.0;
        let scale = (LEVELS - 1) as f32;
        let fw = f64::from(f);
        (
            std::array::from_fn(|c| a[c] + (b[c] - a[c]) * f),
            std::array::from_fn(|c| if inside { (b[c] - a[c]) * scale } else { 0.0 }),
            std::array::from_fn(|c| ga[c] * (1.0 - fw) + gb[c] * fw),
        )
    }
}

/// The weight `D(R·h) max(R·l, 0) ΔΩ` of a source texel (module documentation), `a2 = α²`.
pub(super) fn ggx_weight(a2: f64, r_dot_l: f64, omega: f64) -> f64 {
    if r_dot_l <= 0.0 {
        return 0.0;
    }
    // h = normalize(R + l): R·h = √((1 + R·l) / 2).
    let x2 = 0.5 * (1.0 + r_dot_l);
    let denom = (a2 - 1.0) * x2 + 1.0;
    a2 / (std::f64::consts::PI * denom * denom) * r_dot_l * omega
}

/// `source` prefiltered for roughness `r` on a `width`-wide map (module documentation).
///
/// When the source width is a multiple of `width` the weight of a source texel depends only on
/// the two rows and the column offset, so each pair of rows evaluates it once per offset and
/// the sum over columns is a circular convolution; otherwise every pair of texels is summed.
/// Both give the sum of the module documentation (up to the order of additions).
#[must_use]
pub fn prefilter(source: &EnvMap, width: u32, r: f64) -> EnvMap {
    let height = width / 2;
    let a2 = (r * r) * (r * r);
    let (sw, sh) = (source.width() as usize, source.height() as usize);
    let weight = move |r_dot_l: f64, omega: f64| ggx_weight(a2, r_dot_l, omega);
    let texels: Vec<[f64; 3]> = source.texels().iter().map(|t| t.map(f64::from)).collect();
    let (w, h) = (width as usize, height as usize);
    let out: Vec<[f32; 3]> = if sw % w == 0 {
        let m = sw / w;
        (0..h)
            .into_par_iter()
            .flat_map_iter(|jo| {
                let (so, co) = (std::f64::consts::PI * (jo as f64 + 0.5) / h as f64).sin_cos();
                let mut sum = vec![[0.0f64; 3]; w];
                let mut total = 0.0f64;
                let mut kernel = vec![0.0f64; sw];
                for js in 0..sh {
                    let (ss, cs) = (std::f64::consts::PI * (js as f64 + 0.5) / sh as f64).sin_cos();
                    let omega = source.row_solid_angle(js as u32);
                    for (d, k) in kernel.iter_mut().enumerate() {
                        let dphi = 2.0 * std::f64::consts::PI * (d as f64 + 0.5 * (m as f64 - 1.0))
                            / sw as f64;
                        *k = weight(so * ss * dphi.cos() + co * cs, omega);
                    }
                    total += kernel.iter().sum::<f64>();
                    let row = &texels[js * sw..(js + 1) * sw];
                    for (i, acc) in sum.iter_mut().enumerate() {
                        let base = m * i;
                        // d = (base - p) mod sw, split where it wraps.
                        for (p, t) in row.iter().enumerate() {
                            let d = if p <= base { base - p } else { base + sw - p };
                            let k = kernel[d];
                            acc[0] += k * t[0];
                            acc[1] += k * t[1];
                            acc[2] += k * t[2];
                        }
                    }
                }
                sum.into_iter().map(move |s| {
                    if total > 0.0 {
                        s.map(|v| (v / total) as f32)
                    } else {
                        [0.0; 3]
                    }
                })
            })
            .collect()
    } else {
        let sources: Vec<(DVec3, f64)> = (0..sh)
            .flat_map(|j| (0..sw).map(move |i| (i, j)))
            .map(|(i, j)| {
                (
                    source.texel_direction(i as u32, j as u32),
                    source.row_solid_angle(j as u32),
                )
            })
            .collect();
        (0..w * h)
            .into_par_iter()
            .map(|k| {
                let rdir = EnvMap::direction(
                    ((k % w) as f64 + 0.5) / w as f64,
                    ((k / w) as f64 + 0.5) / h as f64,
                );
                let (mut sum, mut total) = ([0.0f64; 3], 0.0f64);
                for (&(l, omega), t) in sources.iter().zip(&texels) {
                    let wt = weight(rdir.dot(l), omega);
                    for c in 0..3 {
                        sum[c] += t[c] * wt;
                    }
                    total += wt;
                }
                if total > 0.0 {
                    sum.map(|v| (v / total) as f32)
                } else {
                    [0.0; 3]
                }
            })
            .collect()
    };
    EnvMap::try_new(width, height, out).unwrap_or_else(|_| source.clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_uniform_map_stays_uniform_and_rough_levels_blur() {
        let chain = SpecularChain::new(&EnvMap::uniform(32, [1.0; 3]).unwrap());
        for r in [0.0, 0.1, 0.37, 0.8, 1.0] {
            let v = chain.lookup(DVec3::new(0.2, 0.5, -0.7).normalize(), r);
            assert!(v.iter().all(|x| (x - 1.0).abs() < 1e-6), "{r}: {v:?}");
        }
        // A bright cap around +Y: the rough levels spread it, keeping the mean.
        let (w, h) = (64u32, 32u32);
        let texels = (0..w * h)
            .map(|k| if k / w < 3 { [10.0; 3] } else { [0.0; 3] })
            .collect();
        let chain = SpecularChain::new(&EnvMap::try_new(w, h, texels).unwrap());
        let side = DVec3::new(1.0, 0.2, 0.0).normalize();
        let sharp = chain.lookup(side, 0.0)[0];
        let rough = chain.lookup(side, 1.0)[0];
        assert!(sharp < 1e-6 && rough > 0.05, "{sharp} {rough}");
        // The convolution (64 over 64) and the direct sum (48 over 64) agree where they meet:
        // texel centres of the 48-wide map are not those of the 64-wide one, so compare each
        // against a brute-force sum at its own centres.
        let source = EnvMap::try_new(
            w,
            h,
            (0..w * h)
                .map(|k| [((k * 7919) % 101) as f32 / 10.0; 3])
                .collect(),
        )
        .unwrap();
        for width in [32u32, 48, 64] {
            let fast = prefilter(&source, width, 0.6);
            for (k, t) in fast.texels().iter().enumerate().step_by(37) {
                let k = k as u32;
                let rdir = fast.texel_direction(k % width, k / width);
                let (mut s, mut tot) = (0.0f64, 0.0f64);
                let a2 = 0.6f64.powi(4);
                for j in 0..h {
                    for i in 0..w {
                        let c = rdir.dot(source.texel_direction(i, j));
                        if c <= 0.0 {
                            continue;
                        }
                        let den = (a2 - 1.0) * 0.5 * (1.0 + c) + 1.0;
                        let wt =
                            a2 / (std::f64::consts::PI * den * den) * c * source.row_solid_angle(j);
                        s += f64::from(source.texels()[(j * w + i) as usize][0]) * wt;
                        tot += wt;
                    }
                }
                assert!((f64::from(t[0]) - s / tot).abs() < 1e-5, "{width} {k}");
            }
        }
        let up = chain.lookup(DVec3::Y, 1.0)[0];
        assert!(up < chain.lookup(DVec3::Y, 0.0)[0] && up > rough);
    }
}
