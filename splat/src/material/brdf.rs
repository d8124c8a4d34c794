//! [`BrdfTable`]: the split sum's BRDF integration table (Karis 2013, "Real Shading in Unreal
//! Engine 4"), computed once by importance sampling, not from an analytic fit.
//!
//! For `n·v` and roughness `r` (`α = r²`), with `N` Hammersley points `(k / N, radical
//! inverse₂(k))` turned into GGX half vectors (`φ = 2π ξ₁`, `cos θ = √((1 − ξ₂) / (1 + (α² − 1)
//! ξ₂))`), `v = (√(1 − (n·v)²), 0, n·v)`, `l = 2 (v·h) h − v`, and over the samples with
//! `n·l > 0`:
//!
//! `A = (1/N) Σ (1 − F_c) G_vis`, `B = (1/N) Σ F_c G_vis`, `F_c = (1 − v·h)⁵`,
//! `G_vis = G (v·h) / ((n·h)(n·v))`, `G = G₁(n·v) G₁(n·l)`, `G₁(x) = x / (x (1 − k) + k)`,
//! `k = α / 2` (Schlick-Smith for image lighting).
//!
//! The specular reflectance of the lobe is then `F0 A + B`. The table holds `A, B` at the
//! centres of a [`BRDF_TABLE_SIZE`]² grid (`n·v = (i + ½) / S`, `r = (j + ½) / S`), summed in
//! `f64` over [`BRDF_TABLE_SAMPLES`] points, and [`BrdfTable::lookup`] is bilinear between
//! centres, clamped at the edges.

use std::f64::consts::PI;

use rayon::prelude::*;

/// Grid points per axis of the table.
pub const BRDF_TABLE_SIZE: usize = 32;

/// Hammersley samples per table entry.
pub const BRDF_TABLE_SAMPLES: u32 = 1024;

/// The split sum's `A, B` over `n·v` and roughness (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct BrdfTable {
    size: usize,
    /// `[A, B]`, row-major: row `j` (roughness), column `i` (`n·v`).
    ab: Vec<[f32; 2]>,
}

impl Default for BrdfTable {
    fn default() -> Self {
        Self::new(BRDF_TABLE_SIZE, BRDF_TABLE_SAMPLES)
    }
}

impl BrdfTable {
    /// The table on a `size × size` grid (at least 2) with `samples` points per entry.
    #[must_use]
    pub fn new(size: usize, samples: u32) -> Self {
        let size = size.max(2);
        let hammersley: Vec<(f64, f64, f64)> = (0..samples)
            .map(|s| {
                let phi = 2.0 * PI * f64::from(s) / f64::from(samples);
                (phi.cos(), phi.sin(), radical_inverse(s))
            })
            .collect();
        let ab = (0..size)
            .into_par_iter()
            .flat_map_iter(|j| {
                let r = (j as f64 + 0.5) / size as f64;
                let row = integrate_row(size, r, &hammersley);
                row.into_iter()
            })
            .collect();
        Self { size, ab }
    }

    /// Grid points per axis.
    #[must_use]
    pub fn size(&self) -> usize {
        self.size
    }

    /// `[A, B]` at grid point `(i, j)` (`n·v` index, roughness index).
    ///
    /// # Panics
    /// If an index is `>= size`.
    #[must_use]
    pub fn at(&self, i: usize, j: usize) -> [f32; 2] {
        self.ab[j * self.size + i]
    }

    /// `[A, B]` at `n·v` and roughness `r` (each clamped to 0..=1), bilinear between grid
    /// centres.
    #[must_use]
    pub fn lookup(&self, n_dot_v: f32, r: f32) -> [f32; 2] {
        self.lookup_with_dr(n_dot_v, r).0
    }

    /// [`BrdfTable::lookup`] and its derivative in `r` (0 where `r` or its grid coordinate is
    /// clamped; one-sided at grid centres, where the bilinear lookup has a kink).
    #[must_use]
    pub fn lookup_with_dr(&self, n_dot_v: f32, r: f32) -> ([f32; 2], [f32; 2]) {
        let (value, dr, _) = self.lookup_with_grads(n_dot_v, r);
        (value, dr)
    }

    /// [`BrdfTable::lookup`] and its derivatives in `r` and in `n·v` (each 0 where that
    /// argument or its grid coordinate is clamped; one-sided at grid centres, where the
    /// bilinear lookup has a kink).
    #[must_use]
    pub fn lookup_with_grads(&self, n_dot_v: f32, r: f32) -> ([f32; 2], [f32; 2], [f32; 2]) {
        let s = self.size;
        let coord = |x: f32| {
            let t = (x.clamp(0.0, 1.0) * s as f32 - 0.5).clamp(0.0, (s - 1) as f32);
            let i0 = (t as usize).min(s - 2);
            (i0, t - i0 as f32)
        };
        let inside = |x: f32| {
            let t = x * s as f32 - 0.5;
            (0.0..=1.0).contains(&x) && t > 0.0 && t < (s - 1) as f32
        };
        let (i0, fx) = coord(n_dot_v);
        let (j0, fy) = coord(r);
        let a = self.at(i0, j0);
        let b = self.at(i0 + 1, j0);
        let c = self.at(i0, j0 + 1);
        let d = self.at(i0 + 1, j0 + 1);
        let (in_r, in_nv) = (inside(r), inside(n_dot_v));
        let mut value = [0.0; 2];
        let mut dr = [0.0; 2];
        let mut dnv = [0.0; 2];
        for k in 0..2 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bottom = c[k] + (d[k] - c[k]) * fx;
            value[k] = top + (bottom - top) * fy;
            if in_r {
                dr[k] = (bottom - top) * s as f32;
            }
            if in_nv {
                dnv[k] = ((b[k] - a[k]) * (1.0 - fy) + (d[k] - c[k]) * fy) * s as f32;
            }
        }
        (value, dr, dnv)
    }
}

/// Van der Corput's radical inverse in base 2.
fn radical_inverse(k: u32) -> f64 {
    f64::from(k.reverse_bits()) / 4_294_967_296.0
}

/// One row of the table (roughness `r`, every `n·v` of the grid) by the sums of the module
/// documentation; `hammersley` holds `(cos φ, sin φ, ξ₂)` of each sample.
fn integrate_row(size: usize, r: f64, hammersley: &[(f64, f64, f64)]) -> Vec<[f32; 2]> {
    let alpha = r * r;
    let a2 = alpha * alpha;
    let k = alpha / 2.0;
    let g1 = |x: f64| x / (x * (1.0 - k) + k);
    // Half vectors of this roughness, once for the row.
    let halves: Vec<[f64; 3]> = hammersley
        .iter()
        .map(|&(cp, sp, xi2)| {
            let cos_t = ((1.0 - xi2) / (1.0 + (a2 - 1.0) * xi2)).sqrt();
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            [sin_t * cp, sin_t * sp, cos_t]
        })
        .collect();
    let n = hammersley.len().max(1) as f64;
    (0..size)
        .map(|i| {
            let n_dot_v = (i as f64 + 0.5) / size as f64;
            let v = [(1.0 - n_dot_v * n_dot_v).max(0.0).sqrt(), 0.0, n_dot_v];
            let g1v = g1(n_dot_v);
            let (mut sum_a, mut sum_b) = (0.0, 0.0);
            for h in &halves {
                let v_dot_h = v[0] * h[0] + v[2] * h[2];
                let n_dot_l = 2.0 * v_dot_h * h[2] - v[2];
                if n_dot_l > 0.0 {
                    let v_dot_h = v_dot_h.max(0.0);
                    let g_vis = g1v * g1(n_dot_l) * v_dot_h / (h[2] * n_dot_v);
                    let fc = (1.0 - v_dot_h).powi(5);
                    sum_a += (1.0 - fc) * g_vis;
                    sum_b += fc * g_vis;
                }
            }
            [(sum_a / n) as f32, (sum_b / n) as f32]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_matches_known_values_and_lookup_hits_centres() {
        let t = BrdfTable::new(8, 512);
        // A smooth lobe seen head-on reflects everything: A + B ≈ 1, B small.
        let [a, b] = t.lookup(1.0, 0.0);
        assert!((a + b - 1.0).abs() < 0.02, "A {a} B {b}");
        assert!(b < 0.05);
        // Every entry: 0 ≤ A, B and A + B ≤ 1 (single scattering loses energy, never gains).
        for j in 0..8 {
            for i in 0..8 {
                let [a, b] = t.at(i, j);
                assert!(
                    a >= 0.0 && b >= 0.0 && a + b <= 1.0 + 1e-3,
                    "{i},{j}: {a} {b}"
                );
            }
        }
        assert_eq!(t.lookup(2.5 / 8.0, 5.5 / 8.0), t.at(2, 5));
    }
}
