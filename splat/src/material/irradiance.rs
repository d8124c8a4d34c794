//! [`Irradiance`]: the diffuse half of the split sum, from a 9-coefficient spherical-harmonics
//! projection of the environment (Ramamoorthi and Hanrahan 2001, "An Efficient Representation
//! for Irradiance Environment Maps").
//!
//! `L_lm = Σ_texels L(d) Y_lm(d) ΔΩ` over the map (each texel at its centre's direction with its
//! exact solid angle, `f64`), for bands `l ≤ 2`; the irradiance is `E(n) = Σ Â_l L_lm Y_lm(n)`
//! with `Â₀ = π`, `Â₁ = 2π/3`, `Â₂ = π/4`, and [`Irradiance::eval`] gives `max(E(n), 0) / π`:
//! the radiance a white Lambertian surface sends back (1 under a uniform radiance of 1).

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::envmap::EnvMap;

use crate::render::sh_basis_grad;
use crate::sh::sh_basis;

/// `Â_l / π` of basis function `k` (band `l` = 0, 1, 1, 1, 2, ...).
pub(super) fn band_factor(k: usize) -> f64 {
    match k {
        0 => 1.0,
        1..=3 => 2.0 / 3.0,
        _ => 0.25,
    }
}

/// `E(n) / π` of an environment, as 9 SH coefficients per channel (see the module
/// documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Irradiance {
    /// `Â_l L_lm / π` per basis function (3DGS's real SH basis, [`sh_basis`]) and channel.
    coeffs: [[f64; 3]; 9],
}

impl Irradiance {
    /// Projects `map` onto the first three SH bands.
    #[must_use]
    pub fn project(map: &EnvMap) -> Self {
        let w = map.width();
        let rows: Vec<[[f64; 3]; 9]> = (0..map.height())
            .into_par_iter()
            .map(|j| {
                let omega = map.row_solid_angle(j);
                let mut acc = [[0.0f64; 3]; 9];
                for i in 0..w {
                    let y = sh_basis(2, map.texel_direction(i, j));
                    let t = map.texels()[(j * w + i) as usize];
                    for (k, a) in acc.iter_mut().enumerate() {
                        for c in 0..3 {
                            a[c] += f64::from(t[c]) * y[k] * omega;
                        }
                    }
                }
                acc
            })
            .collect();
        let mut coeffs = [[0.0f64; 3]; 9];
        for row in rows {
            for (c, r) in coeffs.iter_mut().zip(row) {
                for k in 0..3 {
                    c[k] += r[k];
                }
            }
        }
        for (k, c) in coeffs.iter_mut().enumerate() {
            for v in c.iter_mut() {
                *v *= band_factor(k);
            }
        }
        Self { coeffs }
    }

    /// The coefficients `Â_l L_lm / π`, per basis function and channel.
    #[must_use]
    pub(super) fn coeffs(&self) -> &[[f64; 3]; 9] {
        &self.coeffs
    }

    /// `max(E(n), 0) / π` towards unit normal `n`.
    #[must_use]
    pub fn eval(&self, n: DVec3) -> [f32; 3] {
        let y = sh_basis(2, n);
        std::array::from_fn(|c| {
            let e: f64 = self.coeffs.iter().zip(&y).map(|(k, y)| k[c] * y).sum();
            e.max(0.0) as f32
        })
    }

    /// [`Irradiance::eval`] and, per channel, its gradient with respect to `n` (tangent to the
    /// sphere: the basis is evaluated at `n / |n|`; zero where `E` is clamped at 0).
    #[must_use]
    pub fn eval_with_grad(&self, n: DVec3) -> ([f32; 3], [DVec3; 3]) {
        let y = sh_basis(2, n);
        let len = n.length();
        let unit = if len > 0.0 { n / len } else { DVec3::Z };
        let dy = sh_basis_grad(2, unit);
        let mut value = [0.0f32; 3];
        let mut grad = [DVec3::ZERO; 3];
        for c in 0..3 {
            let e: f64 = self.coeffs.iter().zip(&y).map(|(k, y)| k[c] * y).sum();
            value[c] = e.max(0.0) as f32;
            if e > 0.0 && len > 0.0 {
                let g: DVec3 = self
                    .coeffs
                    .iter()
                    .zip(&dy)
                    .map(|(k, d)| DVec3::from_array(*d) * k[c])
                    .sum();
                grad[c] = (g - unit * unit.dot(g)) / len;
            }
        }
        (value, grad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_light_gives_one_and_a_sky_gives_the_cosine_lobe() {
        let irr = Irradiance::project(&EnvMap::uniform(32, [1.0, 2.0, 0.5]).unwrap());
        for n in [DVec3::X, DVec3::NEG_Y, DVec3::new(0.6, 0.0, 0.8)] {
            let e = irr.eval(n);
            assert!(
                (e[0] - 1.0).abs() < 1e-3 && (e[1] - 2.0).abs() < 2e-3,
                "{e:?}"
            );
        }
        // Radiance 1 from the upper hemisphere only: E(+Y) = π exactly, E(-Y) = 0; the
        // three-band fit of Ramamoorthi and Hanrahan gives 1.0 and 0.0 to within its known
        // error (below 10% near the horizon, less at the poles).
        let (w, h) = (64u32, 32u32);
        let texels = (0..w * h)
            .map(|k| if k / w < h / 2 { [1.0; 3] } else { [0.0; 3] })
            .collect();
        let irr = Irradiance::project(&EnvMap::try_new(w, h, texels).unwrap());
        assert!((irr.eval(DVec3::Y)[0] - 1.0).abs() < 0.05);
        assert!(irr.eval(DVec3::NEG_Y)[0] < 0.05);
        assert!((irr.eval(DVec3::X)[0] - 0.5).abs() < 0.01);
    }
}
