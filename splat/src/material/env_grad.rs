//! The gradient of a loss with respect to the environment map (issue 33 item 4, "and the
//! environment map"): [`EnvGrad`] gathers `∂L/∂` of everything the shading reads from an
//! [`Environment`] — the nine irradiance coefficients and every texel of every prefiltered
//! level — and [`EnvGrad::to_texels`] pushes it back through the preparation, which is linear in
//! the map's texels, to the texels of the map given to [`Environment::new`].
//!
//! Per shaded point, with `g_c = ∂L/∂c_c` (docs/conventions.md §5 "Relighting"):
//!
//! - `E_c/π = max(Σ_k K_kc y_k(M n), 0)`, so `∂L/∂K_kc += g_c (1 − k_s) albedo_c y_k(M n)` where
//!   the clamp is not active;
//! - `L_spec,c = (1 − f) B_k0(M R) + f B_k0+1(M R)` (`B_k` bilinear in level `k`), so each of the
//!   four taps `(t, w)` of each level gets `g_c k_s (1 − f) w`, resp. `g_c k_s f w`.
//!
//! Back to the map (its texels `T`, intensity `s`):
//!
//! - `K_kc = (Â_l/π) Σ_t s D_I(T)_tc y_k(d_t) ΔΩ_t`, `D_I` the downsampling to
//!   [`IRRADIANCE_WIDTH`]: `∂L/∂D_I(T)_tc = s (Â_l/π) Σ_k ∂L/∂K_kc y_k(d_t) ΔΩ_t`;
//! - level 0 `= D_0(s T)`; level `k ≥ 1` `= P_k D_k(s T)`, `P_k` the GGX prefilter, whose output
//!   texel `o` is `Σ_j w_oj S_j / Σ_j w_oj` with weights that do not depend on the texels:
//!   `∂L/∂S_j = Σ_o ∂L/∂L_o w_oj / Σ_j' w_oj'`;
//! - `D` (each new texel the solid-angle weighted mean of the texels whose centres it holds):
//!   `∂L/∂T_t = ∂L/∂D_k(t) ΔΩ_t / Σ_{t' ∈ k(t)} ΔΩ_t'`, the identity when the map is no wider.
//!
//! The transposed prefilter costs `2 × texels out × texels in` per level, so this is meant for
//! the small maps an environment is fitted at (`fit --env-fit-width`, at most 128 wide).

use glam::DVec3;
use trisplat_geometry::envmap::EnvMap;

use super::irradiance::band_factor;
use super::lookup_grad::bilinear_taps;
use super::prefilter::{LEVEL_WIDTHS, LEVELS, SOURCE_WIDTHS, ggx_weight};
use super::shade::{EnvOptions, Environment, IRRADIANCE_WIDTH};
use crate::sh::sh_basis;

/// `∂L/∂` of what the shading reads from an [`Environment`], summed over shaded points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EnvGrad {
    /// Per basis function and channel: `∂L/∂K_kc` of the irradiance coefficients.
    pub irradiance: [[f64; 3]; 9],
    /// Per level of the prefiltered chain, per texel: `∂L/∂L_level`.
    pub levels: Vec<Vec<[f64; 3]>>,
}

impl EnvGrad {
    /// Zeros shaped like `env`'s chain.
    #[must_use]
    pub fn zeros(env: &Environment) -> Self {
        Self {
            irradiance: [[0.0; 3]; 9],
            levels: env
                .specular
                .levels()
                .iter()
                .map(|l| vec![[0.0; 3]; l.texels().len()])
                .collect(),
        }
    }

    /// Adds `other` (same shape) into `self`.
    ///
    /// # Panics
    /// If the shapes differ.
    pub fn add(&mut self, other: &Self) {
        for (a, b) in self.irradiance.iter_mut().zip(&other.irradiance) {
            for c in 0..3 {
                a[c] += b[c];
            }
        }
        assert_eq!(self.levels.len(), other.levels.len(), "same chain");
        for (a, b) in self.levels.iter_mut().zip(&other.levels) {
            assert_eq!(a.len(), b.len(), "same level sizes");
            for (x, y) in a.iter_mut().zip(b) {
                for c in 0..3 {
                    x[c] += y[c];
                }
            }
        }
    }

    /// `∂L/∂T` of the texels of `map`, the map `env` was prepared from with `options` (its
    /// rotation changes nothing here: the gradients are gathered in the map's frame). See the
    /// module documentation.
    ///
    /// # Panics
    /// If `self` is not shaped like the chain of `map`.
    #[must_use]
    pub fn to_texels(&self, map: &EnvMap, options: EnvOptions) -> Vec<[f64; 3]> {
        let (w, h) = (map.width(), map.height());
        let mut out = vec![[0.0f64; 3]; map.texels().len()];
        // Irradiance.
        let small = map.downsampled(IRRADIANCE_WIDTH);
        let mut g = vec![[0.0f64; 3]; small.texels().len()];
        for j in 0..small.height() {
            let omega = small.row_solid_angle(j);
            for i in 0..small.width() {
                let y = sh_basis(2, small.texel_direction(i, j));
                let t = &mut g[(j * small.width() + i) as usize];
                for (k, gk) in self.irradiance.iter().enumerate() {
                    let f = band_factor(k) * y[k] * omega;
                    for c in 0..3 {
                        t[c] += gk[c] * f;
                    }
                }
            }
        }
        add_downsample_transpose(map, small.width(), &g, &mut out);
        assert_eq!(self.levels.len(), LEVELS, "one gradient per level");
        add_downsample_transpose(map, LEVEL_WIDTHS[0], &self.levels[0], &mut out);
        for k in 1..LEVELS {
            let r = k as f64 / (LEVELS - 1) as f64;
            let source = map.downsampled(SOURCE_WIDTHS[k]);
            let width = LEVEL_WIDTHS[k].min(source.width());
            let g = prefilter_transpose(&source, width, r, &self.levels[k]);
            add_downsample_transpose(map, source.width(), &g, &mut out);
        }
        let s = f64::from(options.intensity);
        debug_assert_eq!(out.len(), (w * h) as usize);
        for t in &mut out {
            *t = t.map(|v| v * s);
        }
        out
    }
}

/// Adds to `out` (`map`'s texels) the transpose of [`EnvMap::downsampled`]`(new_width)` applied
/// to `g` (the downsampled map's gradient).
fn add_downsample_transpose(map: &EnvMap, new_width: u32, g: &[[f64; 3]], out: &mut [[f64; 3]]) {
    let (w, h) = (u64::from(map.width()), u64::from(map.height()));
    let nw = new_width.clamp(2, map.width()) & !1;
    if u64::from(nw) == w {
        for (o, g) in out.iter_mut().zip(g) {
            for c in 0..3 {
                o[c] += g[c];
            }
        }
        return;
    }
    let nh = nw / 2;
    let index = |i: u64, j: u64| {
        let tj = ((2 * j + 1) * u64::from(nh) / (2 * h)) as usize;
        let ti = ((2 * i + 1) * u64::from(nw) / (2 * w)) as usize;
        tj * nw as usize + ti
    };
    let mut weight = vec![0.0f64; (nw * nh) as usize];
    for j in 0..h {
        let omega = map.row_solid_angle(j as u32);
        for i in 0..w {
            weight[index(i, j)] += omega;
        }
    }
    for j in 0..h {
        let omega = map.row_solid_angle(j as u32);
        for i in 0..w {
            let k = index(i, j);
            if weight[k] > 0.0 {
                let f = omega / weight[k];
                let o = &mut out[(j * w + i) as usize];
                for c in 0..3 {
                    o[c] += g[k][c] * f;
                }
            }
        }
    }
}

/// The transpose of [`super::prefilter`]`(source, width, r)` applied to `g` (the prefiltered
/// map's gradient): the gradient with respect to `source`'s texels.
fn prefilter_transpose(source: &EnvMap, width: u32, r: f64, g: &[[f64; 3]]) -> Vec<[f64; 3]> {
    use rayon::prelude::*;
    let a2 = (r * r) * (r * r);
    let (w, h) = (width as usize, (width / 2) as usize);
    let sources: Vec<(DVec3, f64)> = (0..source.height())
        .flat_map(|j| (0..source.width()).map(move |i| (i, j)))
        .map(|(i, j)| (source.texel_direction(i, j), source.row_solid_angle(j)))
        .collect();
    let outputs: Vec<DVec3> = (0..w * h)
        .map(|k| {
            EnvMap::direction(
                ((k % w) as f64 + 0.5) / w as f64,
                ((k / w) as f64 + 0.5) / h as f64,
            )
        })
        .collect();
    // Each output's gradient divided by its total weight.
    let scaled: Vec<[f64; 3]> = outputs
        .par_iter()
        .zip(g)
        .map(|(rdir, g)| {
            let total: f64 = sources
                .iter()
                .map(|&(l, omega)| ggx_weight(a2, rdir.dot(l), omega))
                .sum();
            if total > 0.0 {
                g.map(|v| v / total)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    sources
        .par_iter()
        .map(|&(l, omega)| {
            let mut acc = [0.0f64; 3];
            for (rdir, s) in outputs.iter().zip(&scaled) {
                let wt = ggx_weight(a2, rdir.dot(l), omega);
                for c in 0..3 {
                    acc[c] += s[c] * wt;
                }
            }
            acc
        })
        .collect()
}

impl Environment {
    /// Adds to `out` the gradient, with respect to this environment's irradiance coefficients
    /// and prefiltered texels, of a loss whose gradient with respect to the colour
    /// [`Environment::shade`]`(n, v, albedo, roughness, f0)` is `d_color` (module
    /// documentation). `out` must be shaped by [`EnvGrad::zeros`] of this environment.
    #[expect(
        clippy::too_many_arguments,
        reason = "the arguments of `shade` and its output gradient"
    )]
    pub fn shade_env_grad(
        &self,
        n: DVec3,
        v: DVec3,
        albedo: [f32; 3],
        roughness: f32,
        f0: f32,
        d_color: [f32; 3],
        out: &mut EnvGrad,
    ) {
        let n_dot_v = n.dot(v).clamp(0.0, 1.0);
        let r = 2.0 * n_dot_v * n - v;
        let [a, b] = self.brdf.lookup(n_dot_v as f32, roughness);
        let ks = f64::from(f0 * a + b);
        let y = sh_basis(2, self.to_map * n);
        let coeffs = self.irradiance.coeffs();
        for c in 0..3 {
            let e: f64 = coeffs.iter().zip(&y).map(|(k, y)| k[c] * y).sum();
            if e > 0.0 {
                let f = f64::from(d_color[c]) * (1.0 - ks) * f64::from(albedo[c]);
                for (k, g) in out.irradiance.iter_mut().enumerate() {
                    g[c] += f * y[k];
                }
            }
        }
        // The chain's level pair and weight, as `SpecularChain::lookup_with_dr`.
        let t = roughness.clamp(0.0, 1.0) * (LEVELS - 1) as f32;
        let k0 = (t as usize).min(LEVELS - 2);
        let f = f64::from(t - k0 as f32);
        let dir = self.to_map * r;
        let levels = self.specular.levels();
        for (k, wk) in [(k0, 1.0 - f), (k0 + 1, f)] {
            if wk == 0.0 {
                continue;
            }
            for (texel, w) in bilinear_taps(&levels[k], dir) {
                let g = &mut out.levels[k][texel];
                for c in 0..3 {
                    g[c] += f64::from(d_color[c]) * ks * wk * w;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::rng::Rng;

    /// `Σ g · shade` over a few points is linear in the texels: its gradient against central
    /// differences per texel (exact up to rounding), for a map small enough that every level
    /// is its own width (identity downsampling) and one wider (every transpose used).
    #[test]
    fn texel_gradient_matches_finite_differences() {
        for (w, probes) in [(16u32, 24usize), (160, 4)] {
            let h = w / 2;
            let mut rng = Rng::new(9);
            let texels: Vec<[f32; 3]> = (0..w * h)
                .map(|_| {
                    [
                        0.2 + rng.uniform_f32(),
                        0.2 + rng.uniform_f32(),
                        0.2 + rng.uniform_f32(),
                    ]
                })
                .collect();
            let map = EnvMap::try_new(w, h, texels).unwrap();
            let options = EnvOptions {
                rotation_deg: 30.0,
                intensity: 0.7,
            };
            let env = Environment::new(&map, options).unwrap();
            let mut u = move || f64::from(rng.uniform_f32());
            let points: Vec<_> = (0..12)
                .map(|i| {
                    let n = DVec3::new(u() - 0.5, u() - 0.5, u() - 0.5).normalize();
                    let v = (n + n.any_orthonormal_vector() * u()).normalize();
                    let albedo = [u() as f32, u() as f32, u() as f32];
                    let rough = (0.05 + 0.08 * i as f64) as f32;
                    let g = [u() as f32 - 0.4, u() as f32 - 0.4, u() as f32 - 0.4];
                    (n, v, albedo, rough, u() as f32, g)
                })
                .collect();
            let loss = |env: &Environment| -> f64 {
                points
                    .iter()
                    .map(|&(n, v, a, r, f0, g)| {
                        let c = env.shade(n, v, a, r, f0).color;
                        (0..3)
                            .map(|k| f64::from(g[k]) * f64::from(c[k]))
                            .sum::<f64>()
                    })
                    .sum()
            };
            let mut acc = EnvGrad::zeros(&env);
            for &(n, v, a, r, f0, g) in &points {
                env.shade_env_grad(n, v, a, r, f0, g, &mut acc);
            }
            let grad = acc.to_texels(&map, options);
            let scale = grad
                .iter()
                .flat_map(|g| g.iter())
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(scale > 1e-3, "{w}: a degenerate case");
            let step = 0.05f32;
            for p in 0..probes {
                // Probe the texels with the largest gradients and some others.
                let t = (p * 7919 + 13) % grad.len();
                let c = p % 3;
                let bump = |d: f32| {
                    let mut texels = map.texels().to_vec();
                    texels[t][c] += d;
                    let mut e = env.clone();
                    e.set_map(&EnvMap::try_new(w, h, texels).unwrap(), options.intensity)
                        .unwrap();
                    loss(&e)
                };
                let fd = (bump(step) - bump(-step)) / f64::from(2.0 * step);
                assert!(
                    (fd - grad[t][c]).abs() < 2e-4 * scale + 1e-3 * fd.abs(),
                    "{w}: texel {t} channel {c}: {} vs {fd}",
                    grad[t][c]
                );
            }
        }
    }
}
