//! Colour textures: an RGBA image in `f32` and its filtered lookup with glTF's sampler rules
//! (docs/conventions.md §5 "Fitting", "Textured targets").
//!
//! - Texels are stored as the file holds them: 8-bit values `/ 255` (16-bit `/ 65535`), so an
//!   sRGB-encoded base-colour image stays sRGB-encoded; nothing is linearised on read.
//! - Texture coordinates follow glTF 2.0 (§3.7.2.1 "Images"): `(0, 0)` is the top-left corner of
//!   the image's first pixel, `u` goes right and `v` goes **down** (no flip); texel `(i, j)`
//!   (column `i`, row `j`) has its centre at `((i + ½) / width, (j + ½) / height)`.
//! - [`Filter::Linear`] is bilinear between the four texels around the point, in the stored
//!   (encoded) values, as an image resize does; [`Filter::Nearest`] takes the texel the point
//!   is in. There are no mipmaps: minification filters with the magnification rule.
//! - Wrap modes (`wrapS` for `u`, `wrapT` for `v`) apply to texel indices, as OpenGL's: repeat
//!   (`i mod width`), clamp to edge, mirrored repeat (period `2 × width`, texel `-1` is texel
//!   `0`).

use glam::Vec2;

/// How texel indices outside the image wrap (glTF `sampler.wrapS` / `wrapT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Wrap {
    /// `REPEAT` (10497), glTF's default: the image tiles the plane.
    #[default]
    Repeat,
    /// `CLAMP_TO_EDGE` (33071): the edge texels extend outwards.
    ClampToEdge,
    /// `MIRRORED_REPEAT` (33648): the image tiles the plane, every other copy mirrored.
    MirroredRepeat,
}

impl Wrap {
    /// The texel index in `0..size` that index `i` wraps to (`size > 0`).
    #[must_use]
    pub fn index(self, i: i64, size: u32) -> u32 {
        let n = i64::from(size.max(1));
        let k = match self {
            Self::Repeat => i.rem_euclid(n),
            Self::ClampToEdge => i.clamp(0, n - 1),
            Self::MirroredRepeat => {
                let k = i.rem_euclid(2 * n);
                if k < n { k } else { 2 * n - 1 - k }
            }
        };
        // In 0..n by construction.
        u32::try_from(k).unwrap_or(0)
    }
}

/// How a lookup between texel centres is filtered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Filter {
    /// Bilinear between the four nearest texels (glTF `LINEAR`, the default here).
    #[default]
    Linear,
    /// The texel the point falls in (glTF `NEAREST`).
    Nearest,
}

/// A texture's sampler: wrap per axis and the filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Sampler {
    /// Wrap along `u` (columns).
    pub wrap_u: Wrap,
    /// Wrap along `v` (rows).
    pub wrap_v: Wrap,
    /// The filter (magnification and minification alike: no mipmaps).
    pub filter: Filter,
}

/// Errors building a [`Texture`] from raw texels.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[non_exhaustive]
pub enum TextureError {
    /// Width or height is zero, or `width × height` is not the number of texels given.
    #[error("{width}x{height} texture with {texels} texels")]
    Size {
        /// Width in texels.
        width: u32,
        /// Height in texels.
        height: u32,
        /// Texels given.
        texels: usize,
    },
    /// A texel value is NaN or infinite.
    #[error("texel {index} is not finite")]
    NonFinite {
        /// Row-major texel index.
        index: usize,
    },
}

/// An RGBA image, row-major from the top row, each channel an `f32` (normally in `0..=1`).
#[derive(Clone, PartialEq)]
pub struct Texture {
    width: u32,
    height: u32,
    texels: Vec<[f32; 4]>,
}

impl std::fmt::Debug for Texture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Not the texels: a texture holds millions.
        write!(f, "Texture({}x{})", self.width, self.height)
    }
}

impl Texture {
    /// A texture of `width × height` texels, row-major from the top row.
    ///
    /// # Errors
    /// [`TextureError`] for an empty image, a texel count that is not `width × height`, or a
    /// non-finite value.
    pub fn new(width: u32, height: u32, texels: Vec<[f32; 4]>) -> Result<Self, TextureError> {
        let expected = u64::from(width) * u64::from(height);
        if width == 0 || height == 0 || expected != texels.len() as u64 {
            return Err(TextureError::Size {
                width,
                height,
                texels: texels.len(),
            });
        }
        if let Some(index) = texels.iter().position(|t| !t.iter().all(|c| c.is_finite())) {
            return Err(TextureError::NonFinite { index });
        }
        Ok(Self {
            width,
            height,
            texels,
        })
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

    /// Texel at column `i`, row `j` (`i < width`, `j < height`).
    ///
    /// # Panics
    /// When the texel is outside the image.
    #[must_use]
    pub fn texel(&self, i: u32, j: u32) -> [f32; 4] {
        assert!(
            i < self.width && j < self.height,
            "texel ({i}, {j}) outside the image"
        );
        self.texels[j as usize * self.width as usize + i as usize]
    }

    /// The texels, row-major from the top row.
    #[must_use]
    pub fn texels(&self) -> &[[f32; 4]] {
        &self.texels
    }

    /// The filtered value at texture coordinates `uv` (module docs). A non-finite `uv` gives
    /// texel `(0, 0)` wrapped, never a panic.
    #[must_use]
    pub fn sample(&self, uv: Vec2, sampler: Sampler) -> [f32; 4] {
        let (w, h) = (self.width, self.height);
        // In f64: u × width must keep its fraction for |u| far above 1.
        let x = f64::from(uv.x) * f64::from(w);
        let y = f64::from(uv.y) * f64::from(h);
        let (x, y) = (finite_or_zero(x), finite_or_zero(y));
        let at =
            |i: i64, j: i64| self.texel(sampler.wrap_u.index(i, w), sampler.wrap_v.index(j, h));
        match sampler.filter {
            Filter::Nearest => at(floor_index(x), floor_index(y)),
            Filter::Linear => {
                let (x, y) = (x - 0.5, y - 0.5);
                let (i, j) = (floor_index(x), floor_index(y));
                #[expect(clippy::cast_possible_truncation, reason = "a fraction in 0..1")]
                let (fx, fy) = ((x - x.floor()) as f32, (y - y.floor()) as f32);
                let (a, b) = (at(i, j), at(i + 1, j));
                let (c, d) = (at(i, j + 1), at(i + 1, j + 1));
                std::array::from_fn(|k| {
                    let top = a[k] + (b[k] - a[k]) * fx;
                    let bottom = c[k] + (d[k] - c[k]) * fx;
                    top + (bottom - top) * fy
                })
            }
        }
    }
}

/// Texel coordinates are clamped to `±2⁵²` (where `f64` has no fraction left), so that
/// `floor + 1` cannot overflow.
const MAX_TEXEL_COORDINATE: f64 = 4_503_599_627_370_496.0;

fn finite_or_zero(x: f64) -> f64 {
    if x.is_finite() {
        x.clamp(-MAX_TEXEL_COORDINATE, MAX_TEXEL_COORDINATE)
    } else {
        0.0
    }
}

/// `floor(x)` as an index (`|x| ≤ 2⁵²`: exact).
#[expect(clippy::cast_possible_truncation, reason = "|x| <= 2^52")]
fn floor_index(x: f64) -> i64 {
    x.floor() as i64
}

/// The sRGB transfer function's inverse (IEC 61966-2-1): an encoded value in `0..=1` to linear.
#[must_use]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB transfer function (IEC 61966-2-1): a linear value in `0..=1` to its encoding.
#[must_use]
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 4 × 2 texture whose red channel is the column and green channel the row, blue 0.5.
    fn ramp() -> Texture {
        let texels = (0..2)
            .flat_map(|j| (0..4).map(move |i| [i as f32, j as f32, 0.5, 1.0]))
            .collect();
        Texture::new(4, 2, texels).unwrap()
    }

    fn wrap_all(wrap: Wrap) -> Sampler {
        Sampler {
            wrap_u: wrap,
            wrap_v: wrap,
            filter: Filter::Linear,
        }
    }

    #[test]
    fn wrap_indices() {
        let repeat: Vec<u32> = (-5..9).map(|i| Wrap::Repeat.index(i, 4)).collect();
        assert_eq!(repeat, [3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0]);
        let clamp: Vec<u32> = (-2..6).map(|i| Wrap::ClampToEdge.index(i, 4)).collect();
        assert_eq!(clamp, [0, 0, 0, 1, 2, 3, 3, 3]);
        // Period 8: 0 1 2 3 3 2 1 0, and -1 mirrors to 0.
        let mirror: Vec<u32> = (-4..12).map(|i| Wrap::MirroredRepeat.index(i, 4)).collect();
        assert_eq!(mirror, [3, 2, 1, 0, 0, 1, 2, 3, 3, 2, 1, 0, 0, 1, 2, 3]);
    }

    #[test]
    fn texel_centres_give_texels_exactly() {
        let t = ramp();
        for j in 0..2 {
            for i in 0..4 {
                let uv = Vec2::new((i as f32 + 0.5) / 4.0, (j as f32 + 0.5) / 2.0);
                assert_eq!(
                    t.sample(uv, Sampler::default()),
                    t.texel(i, j),
                    "({i}, {j})"
                );
            }
        }
    }

    #[test]
    fn bilinear_between_centres() {
        let t = ramp();
        // A quarter of the way from texel (1, 0) to texel (2, 1), measured from the texel
        // centres: x = 1.25 + 0.5 texels, y = 0.25 + 0.5 texels.
        let uv = Vec2::new(1.75 / 4.0, 0.75 / 2.0);
        let c = t.sample(uv, Sampler::default());
        assert!((c[0] - 1.25).abs() < 1e-6, "{c:?}");
        assert!((c[1] - 0.25).abs() < 1e-6, "{c:?}");
        assert!((c[2] - 0.5).abs() < 1e-6);
        // v goes down the image: v = 1 - ½ texel is the bottom row.
        let bottom = t.sample(Vec2::new(0.125, 0.75), Sampler::default());
        assert_eq!(bottom[1], 1.0);
    }

    #[test]
    fn edges_follow_the_wrap_mode() {
        let t = ramp();
        // u = 0 lies halfway between texel 3 (wrapped -1) and texel 0.
        let v = 0.25; // row 0's centre
        let at = |u: f32, s: Sampler| t.sample(Vec2::new(u, v), s)[0];
        assert!((at(0.0, wrap_all(Wrap::Repeat)) - 1.5).abs() < 1e-6);
        assert!((at(0.0, wrap_all(Wrap::ClampToEdge)) - 0.0).abs() < 1e-6);
        assert!((at(0.0, wrap_all(Wrap::MirroredRepeat)) - 0.0).abs() < 1e-6);
        // u = 1: between texel 3 and texel 4 (0 repeated, 3 clamped, 3 mirrored).
        assert!((at(1.0, wrap_all(Wrap::Repeat)) - 1.5).abs() < 1e-6);
        assert!((at(1.0, wrap_all(Wrap::ClampToEdge)) - 3.0).abs() < 1e-6);
        assert!((at(1.0, wrap_all(Wrap::MirroredRepeat)) - 3.0).abs() < 1e-6);
        // Whole periods: repeat is periodic with period 1, mirrored with period 2.
        for u in [0.1f32, 0.3, 0.62, 0.9] {
            let r = wrap_all(Wrap::Repeat);
            assert!((at(u + 3.0, r) - at(u, r)).abs() < 1e-5);
            assert!((at(u - 2.0, r) - at(u, r)).abs() < 1e-5);
            let m = wrap_all(Wrap::MirroredRepeat);
            assert!((at(u + 2.0, m) - at(u, m)).abs() < 1e-5);
            assert!((at(-u, m) - at(u, m)).abs() < 1e-5, "mirror about 0 at {u}");
            let c = wrap_all(Wrap::ClampToEdge);
            assert_eq!(at(u + 5.0, c), 3.0);
            assert_eq!(at(-u - 5.0, c), 0.0);
        }
        // Per axis: v clamps while u repeats.
        let s = Sampler {
            wrap_u: Wrap::Repeat,
            wrap_v: Wrap::ClampToEdge,
            filter: Filter::Linear,
        };
        assert_eq!(t.sample(Vec2::new(0.125, 7.9), s)[1], 1.0);
        assert_eq!(t.sample(Vec2::new(0.125, -7.9), s)[1], 0.0);
    }

    #[test]
    fn nearest_takes_the_texel_the_point_is_in() {
        let t = ramp();
        let s = Sampler {
            filter: Filter::Nearest,
            ..Sampler::default()
        };
        assert_eq!(t.sample(Vec2::new(0.49, 0.51), s), t.texel(1, 1));
        assert_eq!(t.sample(Vec2::new(0.5, 0.49), s), t.texel(2, 0));
        assert_eq!(t.sample(Vec2::new(-0.01, 0.0), s), t.texel(3, 0));
    }

    #[test]
    fn bad_input_is_refused_or_harmless() {
        assert!(Texture::new(0, 1, vec![]).is_err());
        assert!(Texture::new(2, 2, vec![[0.0; 4]; 3]).is_err());
        assert_eq!(
            Texture::new(1, 1, vec![[f32::NAN, 0.0, 0.0, 1.0]]),
            Err(TextureError::NonFinite { index: 0 })
        );
        let t = ramp();
        for uv in [
            Vec2::new(f32::NAN, 0.5),
            Vec2::new(f32::INFINITY, f32::NEG_INFINITY),
            Vec2::new(1e30, -1e30),
        ] {
            let c = t.sample(uv, Sampler::default());
            assert!(c.iter().all(|x| x.is_finite()), "{uv:?}: {c:?}");
        }
    }

    #[test]
    fn srgb_round_trip() {
        for i in 0..=255 {
            let c = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-6, "{c}");
        }
        assert!((srgb_to_linear(0.5) - 0.214_041_14).abs() < 1e-6);
    }
}
