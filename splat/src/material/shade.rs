//! [`Environment`]: an environment map made ready for split-sum shading (irradiance, the
//! prefiltered chain, the BRDF table) and [`Environment::shade`], one surface point's colour.
//!
//! With unit normal `n` facing the viewer, unit view vector `v` (surface to camera), `n·v`
//! clamped to 0..=1, reflection `R = 2 (n·v) n − v`, and the environment turned by
//! [`EnvOptions::rotation_deg`] about +Y (a lookup direction `d` reads the map at `R_y(−θ) d`):
//!
//! - `k_s = F0 A + B` with `[A, B]` = [`BrdfTable::lookup`]`(n·v, roughness)`;
//! - specular `s = k_s L_spec(R, roughness)` ([`SpecularChain::lookup`]);
//! - diffuse `d = (1 − k_s) albedo E(n) / π` ([`Irradiance::eval`]): the light the specular lobe
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

/// An environment map ready for split-sum shading.
#[derive(Clone, Debug)]
pub struct Environment {
    irradiance: Irradiance,
    specular: SpecularChain,
    brdf: BrdfTable,
    /// World direction to map direction (`R_y(−θ)`).
    to_map: DMat3,
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
            irradiance: Irradiance::project(map),
            specular: SpecularChain::new(map),
            brdf: BrdfTable::default(),
            to_map: DMat3::from_rotation_y(-options.rotation_deg.to_radians()),
        })
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

#[cfg(test)]
mod tests {
    use super::*;

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
