//! The gradient of an equirectangular map's bilinear lookup ([`EnvMap::bilinear`]) with respect
//! to the lookup direction, for the backward pass through the normal.
//!
//! `u = atan2(d_x, −d_z) / 2π + ½`, `v = acos(d_y / |d|) / π`, pixel coordinates
//! `x = u W − ½` (wrapping) and `y = v H − ½` (clamped to the rows' centres), then bilinear
//! weights `fx`, `fy`. With `ρ² = d_x² + d_z²`:
//! `∇u = (−d_z, 0, d_x) / (2π ρ²)`, `∇v = −(e_y − ŷ d̂) / (π ρ̂ |d|)` (`d̂ = d / |d|`,
//! `ρ̂ = √(1 − ŷ²)`), and `∇value = (∂value/∂fx) W ∇u + (∂value/∂fy) H ∇v`, the second term 0
//! where `y` is clamped (the top and bottom half rows). At the poles (`ρ̂` below 1e-9) `u` is
//! undefined and the gradient is taken as 0. The bilinear weights are piecewise linear, so the
//! gradient jumps across texel centres (one-sided there).

use std::f64::consts::PI;

use glam::DVec3;
use trisplat_geometry::envmap::EnvMap;

/// [`EnvMap::bilinear`] of `map` towards `d` (any length > 0) and, per channel, its gradient with
/// respect to `d` (module documentation).
#[must_use]
pub fn bilinear_with_grad(map: &EnvMap, d: DVec3) -> ([f32; 3], [DVec3; 3]) {
    let (u, v) = EnvMap::uv(d);
    let (w, h) = (map.width() as usize, map.height() as usize);
    let x = u * w as f64 - 0.5;
    let y_raw = v * h as f64 - 0.5;
    let y = y_raw.clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let i0 = (x0 as i64).rem_euclid(w as i64) as usize;
    let i1 = (i0 + 1) % w;
    let j0 = y0 as usize;
    let j1 = (j0 + 1).min(h - 1);
    let texels = map.texels();
    let t = |i: usize, j: usize| texels[j * w + i];
    let (a, b, c, e) = (t(i0, j0), t(i1, j0), t(i0, j1), t(i1, j1));
    let value = std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bottom = c[k] + (e[k] - c[k]) * fx;
        top + (bottom - top) * fy
    });
    let len = d.length();
    let rho2 = d.x * d.x + d.z * d.z;
    let mut grad = [DVec3::ZERO; 3];
    if !len.is_finite() || len <= 0.0 || rho2 <= (1e-9 * len) * (1e-9 * len) {
        return (value, grad);
    }
    let unit = d / len;
    let rho_hat = (1.0 - unit.y * unit.y)
        .max(0.0)
        .sqrt()
        .max(rho2.sqrt() / len);
    let grad_u = DVec3::new(-d.z, 0.0, d.x) / (2.0 * PI * rho2);
    let y_inside = y_raw > 0.0 && y_raw < (h - 1) as f64;
    let grad_v = if y_inside {
        -(DVec3::Y - unit * unit.y) / (PI * rho_hat * len)
    } else {
        DVec3::ZERO
    };
    let (fx, fy) = (f64::from(fx), f64::from(fy));
    for k in 0..3 {
        let (a, b, c, e) = (
            f64::from(a[k]),
            f64::from(b[k]),
            f64::from(c[k]),
            f64::from(e[k]),
        );
        let d_fx = (b - a) * (1.0 - fy) + (e - c) * fy;
        let top = a + (b - a) * fx;
        let bottom = c + (e - c) * fx;
        let d_fy = bottom - top;
        grad[k] = grad_u * (d_fx * w as f64) + grad_v * (d_fy * h as f64);
    }
    (value, grad)
}

/// The four texels [`EnvMap::bilinear`] of `map` blends towards `d` and their weights (texel
/// index `j W + i`, weight; the same floors and `f32` fractions as the lookup): the lookup's
/// derivative with respect to the map's texels.
#[must_use]
pub fn bilinear_taps(map: &EnvMap, d: DVec3) -> [(usize, f64); 4] {
    let (u, v) = EnvMap::uv(d);
    let (w, h) = (map.width() as usize, map.height() as usize);
    let x = u * w as f64 - 0.5;
    let y = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (f64::from((x - x0) as f32), f64::from((y - y0) as f32));
    let i0 = (x0 as i64).rem_euclid(w as i64) as usize;
    let i1 = (i0 + 1) % w;
    let j0 = y0 as usize;
    let j1 = (j0 + 1).min(h - 1);
    [
        (j0 * w + i0, (1.0 - fx) * (1.0 - fy)),
        (j0 * w + i1, fx * (1.0 - fy)),
        (j1 * w + i0, (1.0 - fx) * fy),
        (j1 * w + i1, fx * fy),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Equal to [`EnvMap::bilinear`]; the gradient against central differences away from
    /// texel centres.
    #[test]
    fn value_matches_and_gradient_matches_differences() {
        let (w, h) = (16u32, 8u32);
        let texels = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                [
                    (i as f32 * 0.7).sin() + 1.5,
                    (j as f32 * 0.9).cos() + 1.2,
                    ((i * 3 + j * 5) % 7) as f32,
                ]
            })
            .collect();
        let map = EnvMap::try_new(w, h, texels).unwrap();
        let mut rng = trisplat_geometry::rng::Rng::new(11);
        let mut checked = 0;
        for _ in 0..200 {
            let d = DVec3::new(
                f64::from(rng.uniform_f32()) - 0.5,
                f64::from(rng.uniform_f32()) - 0.5,
                f64::from(rng.uniform_f32()) - 0.5,
            ) * 1.7;
            let (value, grad) = bilinear_with_grad(&map, d);
            assert_eq!(value, map.bilinear(d));
            // Skip directions within a step of a texel centre line (the kinks).
            let (u, v) = EnvMap::uv(d);
            let near = |x: f64| (x - x.round()).abs() < 0.02;
            if near(u * f64::from(w) - 0.5) || near(v * f64::from(h) - 0.5) {
                continue;
            }
            let step = 1e-4;
            for axis in 0..3 {
                let mut e = DVec3::ZERO;
                e[axis] = step;
                let (p, m) = (map.bilinear(d + e), map.bilinear(d - e));
                for k in 0..3 {
                    let fd = (f64::from(p[k]) - f64::from(m[k])) / (2.0 * step);
                    assert!(
                        (fd - grad[k][axis]).abs() < 2e-2 * fd.abs().max(1.0),
                        "{d:?} axis {axis} channel {k}: {fd} vs {}",
                        grad[k][axis]
                    );
                }
            }
            checked += 1;
        }
        assert!(checked > 100);
    }
}
