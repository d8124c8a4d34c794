//! [`Environment`]: an environment map made ready for split-sum shading (irradiance, the
//! prefiltered chain, the BRDF table) and [`Environment::shade`], one surface point's colour.
//!
//! With unit normal `n` facing the viewer, unit view vector `v` (surface to camera), `n·v`
//! clamped to 0..=1, reflection `R = 2 (n·v) n − v`, and the environment turned by
//! [`EnvOptions::rotation_deg`] about +Y (a lookup direction `d` reads the map at `R_y(−θ) d`):
//!
//! - `k_s = F0 A + B` with `[A, B]` = [`BrdfTable::lookup`]`(n·v, roughness)`;
//! - specular `s = k_s L_spec(R, roughness)` ([`SpecularChain::lookup`]);
//! - diffuse `d = (1 − k_s) albedo E(n) / π` ([`Irradiance::eval`], projected from the map
//!   downsampled to [`IRRADIANCE_WIDTH`]): the light the specular lobe
//!   reflects is not also scattered diffusely;
//! - colour `c = d + s`.
//!
//! Under a uniform radiance of 1, `E / π = L_spec = 1`, so `c = (1 − k_s) albedo + k_s`: 1 for a
//! white albedo whatever `F0` and roughness (the white furnace), and `F0 A + B` for a black one.

use glam::{DMat3, DVec3};
use trisplat_geometry::envmap::EnvMap;

use super::brdf::BrdfTable;
use super::irradiance::Irradiance;
use super::prefilter::SpecularChain;

/// Width of the map the irradiance is projected from (the map downsampled to it at most):
/// three SH bands vary far more slowly than its texels.
pub const IRRADIANCE_WIDTH: u32 = 128;

/// How the environment is placed and scaled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvOptions {
    /// Turn of the environment about world +Y, in degrees, right-handed (90 moves what was
    /// towards +X to −Z: counter-clockwise seen from above).
    pub rotation_deg: f64,
    /// Factor on every radiance of the map.
    pub intensity: f32,
}

impl Default for EnvOptions {
    fn default() -> Self {
        Self {
            rotation_deg: 0.0,
            intensity: 1.0,
        }
    }
}

/// One shaded surface point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Shading {
    /// Outgoing radiance, diffuse plus specular.
    pub color: [f32; 3],
    /// Its specular part `k_s L_spec`.
    pub specular: [f32; 3],
}

/// Gradients of a loss through [`Environment::shade`] with respect to the material, the normal
/// and the view vector, for a given gradient of the colour.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShadingGrad {
    /// `∂L/∂albedo = ∂L/∂c ⊙ (1 − k_s) E/π`.
    pub albedo: [f32; 3],
    /// `∂L/∂r = Σ_c ∂L/∂c_c (k_s'(r) (L_spec − albedo E/π)_c + k_s ∂L_spec,c/∂r)`.
    pub roughness: f32,
    /// `∂L/∂F0 = Σ_c ∂L/∂c_c A (L_spec − albedo E/π)_c`.
    pub f0: f32,
    /// `∂L/∂n` (world): through `E(n)`, `n·v` (the BRDF table) and `R = 2 (n·v) n − v`.
    pub normal: DVec3,
    /// `∂L/∂v` (world): through `n·v` and `R`.
    pub view: DVec3,
}

/// An environment map ready for split-sum shading.
#[derive(Clone, Debug)]
pub struct Environment {
    pub(super) irradiance: Irradiance,
    pub(super) specular: SpecularChain,
    pub(super) brdf: BrdfTable,
    /// World direction to map direction (`R_y(−θ)`).
    pub(super) to_map: DMat3,
}

impl Environment {
    /// Prepares `map` (scaled by `options.intensity`, turned by `options.rotation_deg`).
    ///
    /// # Errors
    /// [`trisplat_geometry::envmap::EnvMapError`] when the intensity makes a radiance negative or
    /// not finite.
    pub fn new(
        map: &EnvMap,
        options: EnvOptions,
    ) -> Result<Self, trisplat_geometry::envmap::EnvMapError> {
        let scaled;
        let map = if options.intensity == 1.0 {
            map
        } else {
            scaled = map.scaled(options.intensity)?;
            &scaled
        };
        Ok(Self {
            irradiance: Irradiance::project(&map.downsampled(IRRADIANCE_WIDTH)),
            specular: SpecularChain::new(map),
            brdf: BrdfTable::default(),
            to_map: DMat3::from_rotation_y(-options.rotation_deg.to_radians()),
        })
    }

    /// Prepares `map` again in place of the current one (scaled by `intensity`; the rotation
    /// and the BRDF table kept): an environment being fitted, rebuilt from its texels each step.
    ///
    /// # Errors
    /// As [`Environment::new`].
    pub fn set_map(
        &mut self,
        map: &EnvMap,
        intensity: f32,
    ) -> Result<(), trisplat_geometry::envmap::EnvMapError> {
        let scaled;
        let map = if intensity == 1.0 {
            map
        } else {
            scaled = map.scaled(intensity)?;
            &scaled
        };
        self.irradiance = Irradiance::project(&map.downsampled(IRRADIANCE_WIDTH));
        self.specular = SpecularChain::new(map);
        Ok(())
    }

    /// The BRDF integration table.
    #[must_use]
    pub fn brdf(&self) -> &BrdfTable {
        &self.brdf
    }

    /// The prefiltered chain.
    #[must_use]
    pub fn specular_chain(&self) -> &SpecularChain {
        &self.specular
    }

    /// The colour of a point with unit normal `n` (facing `v`) seen along unit `v` (point to
    /// camera), see the module documentation.
    #[must_use]
    pub fn shade(&self, n: DVec3, v: DVec3, albedo: [f32; 3], roughness: f32, f0: f32) -> Shading {
        let n_dot_v = n.dot(v).clamp(0.0, 1.0);
        let r = 2.0 * n_dot_v * n - v;
        let [a, b] = self.brdf.lookup(n_dot_v as f32, roughness);
        let ks = f0 * a + b;
        let irradiance = self.irradiance.eval(self.to_map * n);
        let radiance = self.specular.lookup(self.to_map * r, roughness);
        let specular = radiance.map(|l| ks * l);
        let color = std::array::from_fn(|c| (1.0 - ks) * albedo[c] * irradiance[c] + specular[c]);
        Shading { color, specular }
    }
}

impl Environment {
    /// The gradient of a loss through [`Environment::shade`] given `d_color = ∂L/∂c`
    /// (see [`ShadingGrad`]). The lookups are piecewise linear in roughness, `n·v` and the map's
    /// texel coordinates, so those derivatives are one-sided at the grids' nodes; where `n·v` is
    /// clamped (0 or 1) nothing passes through it.
    ///
    /// With `g_c = ∂L/∂c_c`, `M` the world-to-map rotation:
    /// `∂L/∂(n·v) = Σ g_c (L_spec − albedo E/π)_c ∂k_s/∂(n·v)`,
    /// `∂L/∂R = Σ g_c k_s Mᵀ ∇L_spec,c`, `∂L/∂n|_E = Σ g_c (1 − k_s) albedo_c Mᵀ ∇(E_c/π)`, then
    /// `∂L/∂n = ∂L/∂n|_E + ∂L/∂(n·v) v + 2 (n·v) ∂L/∂R + 2 (∂L/∂R · n) v` and
    /// `∂L/∂v = ∂L/∂(n·v) n + 2 (∂L/∂R · n) n − ∂L/∂R`.
    #[must_use]
    pub fn shade_grad(
        &self,
        n: DVec3,
        v: DVec3,
        albedo: [f32; 3],
        roughness: f32,
        f0: f32,
        d_color: [f32; 3],
    ) -> ShadingGrad {
        let raw = n.dot(v);
        let n_dot_v = raw.clamp(0.0, 1.0);
        let nv_free = raw > 0.0 && raw < 1.0;
        let r = 2.0 * n_dot_v * n - v;
        let ([a, b], [da, db], [da_nv, db_nv]) =
            self.brdf.lookup_with_grads(n_dot_v as f32, roughness);
        let ks = f0 * a + b;
        let dks = f0 * da + db;
        let dks_nv = f64::from(f0 * da_nv + db_nv);
        let (irradiance, g_irr) = self.irradiance.eval_with_grad(self.to_map * n);
        let (radiance, d_radiance, g_rad) =
            self.specular.lookup_with_grads(self.to_map * r, roughness);
        let mut grad = ShadingGrad::default();
        let (mut g_nv, mut g_n_map, mut g_r_map) = (0.0f64, DVec3::ZERO, DVec3::ZERO);
        for c in 0..3 {
            let g = d_color[c];
            let diffuse = albedo[c] * irradiance[c];
            grad.albedo[c] = g * (1.0 - ks) * irradiance[c];
            grad.f0 += g * a * (radiance[c] - diffuse);
            grad.roughness += g * (dks * (radiance[c] - diffuse) + ks * d_radiance[c]);
            let g = f64::from(g);
            g_nv += g * f64::from(radiance[c] - diffuse) * dks_nv;
            g_n_map += g_irr[c] * (g * f64::from((1.0 - ks) * albedo[c]));
            g_r_map += g_rad[c] * (g * f64::from(ks));
        }
        let to_world = self.to_map.transpose();
        let g_r = to_world * g_r_map;
        let mut g_n = to_world * g_n_map + 2.0 * n_dot_v * g_r;
        let mut g_v = -g_r;
        if nv_free {
            let g_nv = g_nv + 2.0 * g_r.dot(n);
            g_n += g_nv * v;
            g_v += g_nv * n;
        }
        grad.normal = g_n;
        grad.view = g_v;
        grad
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The material gradient against central differences in f64 of the f32 shading, away from
    /// the roughness grid's kinks.
    #[test]
    fn material_gradient_matches_finite_differences() {
        let (w, h) = (64u32, 32u32);
        let texels = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                [
                    1.0 + (i as f32 * 0.3).sin(),
                    0.5 + 0.4 * (j as f32 * 0.5).cos(),
                    (0.05 * (i + j) as f32).fract() * 3.0,
                ]
            })
            .collect();
        let env = Environment::new(
            &EnvMap::try_new(w, h, texels).unwrap(),
            EnvOptions::default(),
        )
        .unwrap();
        let mut rng = trisplat_geometry::rng::Rng::new(3);
        let mut u = move || f64::from(rng.uniform_f32());
        for case in 0..40 {
            let n = DVec3::new(u() - 0.5, u() - 0.5, u() - 0.5).normalize();
            let t = n.any_orthonormal_vector();
            let v = (n + t * (1.5 * u())).normalize();
            let albedo = [u() as f32, u() as f32, u() as f32];
            // Roughness between grid kinks: table centres (j + ½)/32, chain levels k/4.
            let r = ((case % 29) as f32 + 0.25) / 29.0 * 0.98 + 0.01;
            let r = if ((r * 32.0 - 0.5).fract() - 0.5).abs() > 0.45 {
                r + 0.007
            } else {
                r
            };
            let f0 = u() as f32;
            let g = [u() as f32 - 0.5, u() as f32 - 0.5, u() as f32 - 0.5];
            let loss = |albedo: [f32; 3], r: f32, f0: f32| -> f64 {
                let c = env.shade(n, v, albedo, r, f0).color;
                (0..3).map(|k| f64::from(g[k]) * f64::from(c[k])).sum()
            };
            let grad = env.shade_grad(n, v, albedo, r, f0, g);
            let step = 1e-3f32;
            let fd_f0 = (loss(albedo, r, f0 + step) - loss(albedo, r, f0 - step)) / (2e-3);
            let fd_r = (loss(albedo, r + step, f0) - loss(albedo, r - step, f0)) / (2e-3);
            let mut a1 = albedo;
            a1[1] += step;
            let mut a0 = albedo;
            a0[1] -= step;
            let fd_a = (loss(a1, r, f0) - loss(a0, r, f0)) / (2e-3);
            let tol = |x: f64| 2e-3 * x.abs().max(0.1);
            assert!(
                (f64::from(grad.f0) - fd_f0).abs() < tol(fd_f0),
                "{case}: F0 {} vs {fd_f0}",
                grad.f0
            );
            assert!(
                (f64::from(grad.albedo[1]) - fd_a).abs() < tol(fd_a),
                "{case}: albedo"
            );
            assert!(
                (f64::from(grad.roughness) - fd_r).abs() < 2e-2 * fd_r.abs().max(0.1),
                "{case}: roughness {} vs {fd_r} (r {r})",
                grad.roughness
            );
        }
    }

    #[test]
    fn rotation_turns_the_environment_about_up() {
        // Bright towards +X only (a column band of the map around u = 0.75).
        let (w, h) = (64u32, 32u32);
        let texels = (0..w * h)
            .map(|k| {
                if (k % w).abs_diff(48) <= 2 {
                    [5.0; 3]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let map = EnvMap::try_new(w, h, texels).unwrap();
        let env = Environment::new(&map, EnvOptions::default()).unwrap();
        let at = |env: &Environment, n: DVec3| env.shade(n, n, [0.0; 3], 0.0, 1.0).color[0];
        assert!(at(&env, DVec3::X) > 1.0 && at(&env, DVec3::Z) < 1e-3);
        // Turned 90° about +Y, the band that was at +X is now at -Z.
        let turned = Environment::new(
            &map,
            EnvOptions {
                rotation_deg: 90.0,
                intensity: 2.0,
            },
        )
        .unwrap();
        let before = at(&env, DVec3::X);
        let after = at(&turned, DVec3::NEG_Z);
        assert!(
            (after - 2.0 * before).abs() < 1e-3 * before,
            "{before} {after}"
        );
    }
}
