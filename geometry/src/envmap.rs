//! [`EnvMap`]: an equirectangular (latitude-longitude) environment map of linear RGB radiance
//! (docs/conventions.md §5 "Relighting").
//!
//! - The map is 2:1 (`width = 2 height`), row 0 at the top. World **+Y is up**.
//! - Texel `(i, j)` (column `i`, row `j`) has its centre at `u = (i + ½) / W`, `v = (j + ½) / H`;
//!   `(u, v)` is the direction `d = (sin θ sin φ, cos θ, −sin θ cos φ)` with polar angle
//!   `θ = π v` from +Y and longitude `φ = 2π (u − ½)`: the image centre looks along −Z, `u`
//!   grows towards +X (`φ = atan2(d.x, −d.z)`).
//! - A texel covers the solid angle `(2π / W) (cos θ₀ − cos θ₁)` between its row's edges
//!   (the rows sum to exactly 4π).
//! - [`EnvMap::bilinear`] interpolates between texel centres, wrapping in `u` and clamping in
//!   `v`; [`EnvMap::downsampled`] averages, weighted by solid angle, the texels whose centres fall
//!   in each new texel.

use std::f64::consts::PI;
use std::path::Path;

use glam::DVec3;

use crate::io::IoError;
use crate::io::hdr::read_hdr;

/// Why radiance values do not make an environment map.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EnvMapError {
    /// Not 2:1 (or empty).
    #[error("an equirectangular map must be 2:1 (width = 2 height); got {width}x{height}")]
    NotTwoToOne {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// The texel count is not `width × height`.
    #[error("{len} texels for a {width}x{height} map")]
    Length {
        /// Texels given.
        len: usize,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// A radiance value that is NaN, infinite or negative.
    #[error("texel {index} (row {row}, column {column}): radiance {value} is not finite and >= 0")]
    BadRadiance {
        /// Texel index (row-major).
        index: usize,
        /// Its row.
        row: u32,
        /// Its column.
        column: u32,
        /// The value.
        value: f32,
    },
}

/// An equirectangular map of linear RGB radiance (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    width: u32,
    height: u32,
    texels: Vec<[f32; 3]>,
}

impl EnvMap {
    /// A map from row-major texels, checked: 2:1, one texel per pixel, every value finite and
    /// non-negative.
    ///
    /// # Errors
    /// The first problem, naming the texel.
    pub fn try_new(width: u32, height: u32, texels: Vec<[f32; 3]>) -> Result<Self, EnvMapError> {
        if height == 0 || u64::from(width) != 2 * u64::from(height) {
            return Err(EnvMapError::NotTwoToOne { width, height });
        }
        if texels.len() as u64 != u64::from(width) * u64::from(height) {
            return Err(EnvMapError::Length {
                len: texels.len(),
                width,
                height,
            });
        }
        let bad = texels.iter().enumerate().find_map(|(index, t)| {
            t.iter()
                .find(|v| !(v.is_finite() && **v >= 0.0))
                .map(|&value| (index, value))
        });
        if let Some((index, value)) = bad {
            return Err(EnvMapError::BadRadiance {
                index,
                row: (index / width as usize) as u32,
                column: (index % width as usize) as u32,
                value,
            });
        }
        Ok(Self {
            width,
            height,
            texels,
        })
    }

    /// A `2h × h` map of one radiance everywhere.
    ///
    /// # Errors
    /// [`EnvMapError::BadRadiance`] for a negative or non-finite value, or `h = 0`.
    pub fn uniform(height: u32, rgb: [f32; 3]) -> Result<Self, EnvMapError> {
        let n = 2 * height as usize * height as usize;
        Self::try_new(2 * height, height, vec![rgb; n])
    }

    /// Reads a Radiance `.hdr` file as a map (see [`crate::io::hdr`]).
    ///
    /// # Errors
    /// [`IoError`] naming the file: unreadable or malformed, not 2:1, a radiance that is not
    /// finite and non-negative.
    pub fn read(path: &Path) -> Result<Self, IoError> {
        let image = read_hdr(path)?;
        Self::try_new(image.width, image.height, image.rgb).map_err(|e| match e {
            EnvMapError::NotTwoToOne { .. } => IoError::Unsupported {
                path: path.into(),
                what: e.to_string(),
            },
            _ => IoError::malformed(path, "pixel data", e.to_string()),
        })
    }

    /// Writes the map as a Radiance `.hdr` file ([`crate::io::hdr::write_hdr`], atomic).
    ///
    /// # Errors
    /// [`IoError`] naming the file when the write fails.
    pub fn write(&self, path: &Path) -> Result<(), IoError> {
        crate::io::hdr::write_hdr(path, self.width, self.height, &self.texels)
    }

    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Row-major texels.
    #[must_use]
    pub fn texels(&self) -> &[[f32; 3]] {
        &self.texels
    }

    /// The map with every radiance multiplied by `k`.
    ///
    /// # Errors
    /// [`EnvMapError::BadRadiance`] when `k` is negative or not finite or a product overflows.
    pub fn scaled(&self, k: f32) -> Result<Self, EnvMapError> {
        let texels = self.texels.iter().map(|t| t.map(|v| v * k)).collect();
        Self::try_new(self.width, self.height, texels)
    }

    /// The unit direction of map coordinates `(u, v)`.
    #[must_use]
    pub fn direction(u: f64, v: f64) -> DVec3 {
        let (theta, phi) = (PI * v, 2.0 * PI * (u - 0.5));
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        DVec3::new(st * sp, ct, -st * cp)
    }

    /// The map coordinates `(u, v)` of direction `d` (any length > 0), `u` in `[0, 1)`.
    #[must_use]
    pub fn uv(d: DVec3) -> (f64, f64) {
        let len = d.length();
        let y = if len > 0.0 {
            (d.y / len).clamp(-1.0, 1.0)
        } else {
            1.0
        };
        let u = (d.x.atan2(-d.z) / (2.0 * PI) + 0.5).rem_euclid(1.0);
        (u, y.acos() / PI)
    }

    /// The direction of texel `(i, j)`'s centre.
    #[must_use]
    pub fn texel_direction(&self, i: u32, j: u32) -> DVec3 {
        Self::direction(
            (f64::from(i) + 0.5) / f64::from(self.width),
            (f64::from(j) + 0.5) / f64::from(self.height),
        )
    }

    /// The solid angle of one texel of row `j`.
    #[must_use]
    pub fn row_solid_angle(&self, j: u32) -> f64 {
        let h = f64::from(self.height);
        let (t0, t1) = (PI * f64::from(j) / h, PI * f64::from(j + 1) / h);
        2.0 * PI / f64::from(self.width) * (t0.cos() - t1.cos())
    }

    /// The radiance towards `d`, bilinear between texel centres (wrapping in `u`, clamped in
    /// `v`).
    #[must_use]
    pub fn bilinear(&self, d: DVec3) -> [f32; 3] {
        let (u, v) = Self::uv(d);
        let (w, h) = (self.width as usize, self.height as usize);
        let x = u * w as f64 - 0.5;
        let y = (v * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let i0 = (x0 as i64).rem_euclid(w as i64) as usize;
        let i1 = (i0 + 1) % w;
        let j0 = y0 as usize;
        let j1 = (j0 + 1).min(h - 1);
        let t = |i: usize, j: usize| self.texels[j * w + i];
        let (a, b, c, e) = (t(i0, j0), t(i1, j0), t(i0, j1), t(i1, j1));
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bottom = c[k] + (e[k] - c[k]) * fx;
            top + (bottom - top) * fy
        })
    }

    /// The map at `new_width × new_width / 2` (at most the current size): each new texel is
    /// the solid-angle weighted mean of the texels whose centres it contains.
    #[must_use]
    pub fn downsampled(&self, new_width: u32) -> Self {
        let nw = new_width.clamp(2, self.width) & !1;
        let nh = nw / 2;
        if nw == self.width {
            return self.clone();
        }
        let (w, h) = (self.width as u64, self.height as u64);
        let mut sum = vec![[0.0f64; 3]; nw as usize * nh as usize];
        let mut weight = vec![0.0f64; sum.len()];
        for j in 0..h {
            let tj = ((2 * j + 1) * u64::from(nh) / (2 * h)) as usize;
            let omega = self.row_solid_angle(j as u32);
            for i in 0..w {
                let ti = ((2 * i + 1) * u64::from(nw) / (2 * w)) as usize;
                let k = tj * nw as usize + ti;
                let t = self.texels[(j * w + i) as usize];
                for c in 0..3 {
                    sum[k][c] += f64::from(t[c]) * omega;
                }
                weight[k] += omega;
            }
        }
        let texels = sum
            .iter()
            .zip(&weight)
            .map(|(s, &wt)| s.map(|v| if wt > 0.0 { (v / wt) as f32 } else { 0.0 }))
            .collect();
        Self {
            width: nw,
            height: nh,
            texels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_and_coordinates_round_trip() {
        for &(u, v) in &[(0.5, 0.5), (0.1, 0.3), (0.9, 0.8), (0.25, 0.5)] {
            let (u2, v2) = EnvMap::uv(EnvMap::direction(u, v));
            assert!((u - u2).abs() < 1e-12 && (v - v2).abs() < 1e-12);
        }
        assert!((EnvMap::direction(0.5, 0.5) - DVec3::NEG_Z).length() < 1e-12);
        assert!((EnvMap::direction(0.75, 0.5) - DVec3::X).length() < 1e-12);
        assert!((EnvMap::direction(0.3, 0.0) - DVec3::Y).length() < 1e-12);
        let map = EnvMap::uniform(8, [1.0; 3]).unwrap();
        let total: f64 = (0..8).map(|j| 16.0 * map.row_solid_angle(j)).sum();
        assert!((total - 4.0 * PI).abs() < 1e-12);
    }

    #[test]
    fn bilinear_and_downsampling_keep_a_constant_and_the_mean() {
        let map = EnvMap::uniform(8, [2.0, 1.0, 0.5]).unwrap();
        assert_eq!(map.bilinear(DVec3::new(0.3, -0.9, 0.1)), [2.0, 1.0, 0.5]);
        let texels: Vec<[f32; 3]> = (0..32).map(|k| [k as f32; 3]).collect();
        let map = EnvMap::try_new(8, 4, texels).unwrap();
        // The centre of texel (2, 1) gives its value exactly.
        assert_eq!(map.bilinear(map.texel_direction(2, 1)), [10.0; 3]);
        let small = map.downsampled(4);
        assert_eq!((small.width(), small.height()), (4, 2));
        // Top-left new texel: rows 0-1, columns 0-1, weighted by each row's solid angle.
        let (a, b) = (map.row_solid_angle(0), map.row_solid_angle(1));
        let want = (a * (0.0 + 1.0) + b * (8.0 + 9.0)) / (2.0 * (a + b));
        assert!((f64::from(small.texels()[0][0]) - want).abs() < 1e-5);
    }

    #[test]
    fn bad_maps_are_refused() {
        assert!(matches!(
            EnvMap::try_new(6, 2, vec![[0.0; 3]; 12]),
            Err(EnvMapError::NotTwoToOne { .. })
        ));
        let mut t = vec![[0.0; 3]; 8];
        t[5][1] = -1.0;
        assert!(matches!(
            EnvMap::try_new(4, 2, t.clone()),
            Err(EnvMapError::BadRadiance {
                index: 5,
                row: 1,
                column: 1,
                ..
            })
        ));
        t[5][1] = f32::NAN;
        assert!(EnvMap::try_new(4, 2, t).is_err());
        assert!(
            EnvMap::uniform(4, [1.0; 3])
                .unwrap()
                .scaled(f32::NAN)
                .is_err()
        );
    }
}
