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
        let t = roughness.clamp(0.0, 1.0) * (LEVELS - 1) as f32;
        let k0 = (t as usize).min(LEVELS - 2);
        let f = t - k0 as f32;
        let a = self.levels[k0].bilinear(r);
        if f == 0.0 {
            return a;
        }
        let b = self.levels[k0 + 1].bilinear(r);
        std::array::from_fn(|c| a[c] + (b[c] - a[c]) * f)
    }
}

/// `source` prefiltered for roughness `r` on a `width`-wide map (module documentation).
#[must_use]
pub fn prefilter(source: &EnvMap, width: u32, r: f64) -> EnvMap {
    let height = width / 2;
    let a2 = (r * r) * (r * r);
    // Source texels: direction and solid angle, once.
    let (sw, sh) = (source.width(), source.height());
    let dirs: Vec<(DVec3, f64, [f64; 3])> = (0..sh)
        .flat_map(|j| {
            let omega = source.row_solid_angle(j);
            (0..sw).map(move |i| (j, i, omega))
        })
        .map(|(j, i, omega)| {
            let t = source.texels()[(j * sw + i) as usize];
            (source.texel_direction(i, j), omega, t.map(f64::from))
        })
        .collect();
    let texels: Vec<[f32; 3]> = (0..width * height)
        .into_par_iter()
        .map(|k| {
            let rdir = EnvMap::direction(
                (f64::from(k % width) + 0.5) / f64::from(width),
                (f64::from(k / width) + 0.5) / f64::from(height),
            );
            let (mut sum, mut weight) = ([0.0f64; 3], 0.0f64);
            for &(l, omega, t) in &dirs {
                let r_dot_l = rdir.dot(l);
                if r_dot_l <= 0.0 {
                    continue;
                }
                // h = normalize(R + l): R·h = √((1 + R·l) / 2).
                let x2 = 0.5 * (1.0 + r_dot_l);
                let denom = (a2 - 1.0) * x2 + 1.0;
                let w = a2 / (std::f64::consts::PI * denom * denom) * r_dot_l * omega;
                for c in 0..3 {
                    sum[c] += t[c] * w;
                }
                weight += w;
            }
            if weight > 0.0 {
                sum.map(|v| (v / weight) as f32)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    EnvMap::try_new(width, height, texels).unwrap_or_else(|_| source.clone())
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
        let up = chain.lookup(DVec3::Y, 1.0)[0];
        assert!(up < chain.lookup(DVec3::Y, 0.0)[0] && up > rough);
    }
}
