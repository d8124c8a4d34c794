//! Output images of a render ([`RenderImages`]) and writing them as `.npy` (float32) and PNG
//! pictures (docs/conventions.md §2, §10).
//!
//! Files, for an image stem `NAME` in folder `DIR`: `NAME_rgb.npy` `[H, W, 3]`, `NAME_alpha.npy`
//! `[H, W]`, `NAME_depth.npy` `[H, W]` (expected z-depth), `NAME_median_depth.npy` `[H, W]`,
//! `NAME_normal.npy` `[H, W, 3]`, each with a PNG beside it: rgb clamped to 0..1 and quantised to
//! 8 bits; alpha as 8-bit grey; depths through the turbo colour map over the image's own range of
//! valid depths (nearest = red end, farthest = blue end, no surface = black); normals normalised
//! and mapped `(n + 1) / 2` (no surface = black).

use std::path::{Path, PathBuf};

use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use trisplat_geometry::io::{IoError, write_atomically, write_npy};

use super::options::Outputs;

/// The rendered images, row-major (row 0 at the top), `None` where not requested.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderImages {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `[H, W, 3]` colour.
    pub rgb: Option<Vec<f32>>,
    /// `[H, W]` accumulated opacity.
    pub alpha: Option<Vec<f32>>,
    /// `[H, W]` expected z-depth (0 where alpha is 0).
    pub depth: Option<Vec<f32>>,
    /// `[H, W]` median z-depth (0 where there is none).
    pub median_depth: Option<Vec<f32>>,
    /// `[H, W]` front z-depth: that of the splat at which the accumulated alpha first reaches
    /// the front alpha asked of [`super::render_front`] (0 where it never does); not written
    /// to files.
    pub front_depth: Option<Vec<f32>>,
    /// `[H, W, 3]` composited normals.
    pub normal: Option<Vec<f32>>,
}

impl RenderImages {
    /// Blank images (transmittance 1, nothing composited) for the requested outputs; `rgb` is
    /// zero, not yet the background.
    #[must_use]
    pub fn new(width: u32, height: u32, outputs: Outputs) -> Self {
        let n = width as usize * height as usize;
        let make = |on: bool, c: usize| on.then(|| vec![0.0f32; n * c]);
        Self {
            width,
            height,
            rgb: make(outputs.rgb, 3),
            alpha: make(outputs.alpha, 1),
            depth: make(outputs.depth, 1),
            median_depth: make(outputs.median_depth, 1),
            front_depth: None,
            normal: make(outputs.normal, 3),
        }
    }

    /// Images of a render that hit nothing: background colour, zero elsewhere.
    #[must_use]
    pub fn empty(width: u32, height: u32, outputs: Outputs, background: [f32; 3]) -> Self {
        let mut images = Self::new(width, height, outputs);
        if let Some(rgb) = images.rgb.as_mut() {
            for px in rgb.chunks_exact_mut(3) {
                px.copy_from_slice(&background);
            }
        }
        images
    }

    /// Whether every value of every image is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        [
            &self.rgb,
            &self.alpha,
            &self.depth,
            &self.median_depth,
            &self.front_depth,
            &self.normal,
        ]
        .into_iter()
        .flatten()
        .all(|v| v.iter().all(|x| x.is_finite()))
    }

    /// Writes every present image as `.npy` and PNG into `dir` (see the module documentation),
    /// named after `stem` (path separators in it become `_`). Returns the files written.
    ///
    /// # Errors
    /// [`IoError`] naming the file that could not be written.
    pub fn write(&self, dir: &Path, stem: &str) -> Result<Vec<PathBuf>, IoError> {
        let stem = file_stem(stem);
        let (w, h) = (self.width as usize, self.height as usize);
        let mut written = Vec::new();
        let mut out = |suffix: &str, shape: &[usize], data: &[f32], png: Vec<u8>, colour: bool| {
            let npy = dir.join(format!("{stem}_{suffix}.npy"));
            write_npy(&npy, shape, data)?;
            written.push(npy);
            let png_path = dir.join(format!("{stem}_{suffix}.png"));
            write_png(&png_path, self.width, self.height, &png, colour)?;
            written.push(png_path);
            Ok::<(), IoError>(())
        };
        if let Some(rgb) = &self.rgb {
            out(
                "rgb",
                &[h, w, 3],
                rgb,
                rgb.iter().map(|&v| to_u8(v)).collect(),
                true,
            )?;
        }
        if let Some(alpha) = &self.alpha {
            out(
                "alpha",
                &[h, w],
                alpha,
                alpha.iter().map(|&v| to_u8(v)).collect(),
                false,
            )?;
        }
        if let Some(depth) = &self.depth {
            out("depth", &[h, w], depth, depth_picture(depth), true)?;
        }
        if let Some(depth) = &self.median_depth {
            out("median_depth", &[h, w], depth, depth_picture(depth), true)?;
        }
        if let Some(normal) = &self.normal {
            out("normal", &[h, w, 3], normal, normal_picture(normal), true)?;
        }
        Ok(written)
    }
}

/// The names [`RenderImages::write`] gives the images of `stem`: `<stem>_<kind>.npy` and
/// `.png` for kind rgb, alpha, depth, median_depth and normal.
pub const IMAGE_KINDS: [&str; 5] = ["rgb", "alpha", "depth", "median_depth", "normal"];

/// The file stem [`RenderImages::write`] uses for a camera name: path separators become `_`.
#[must_use]
pub fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| if matches!(c, '/' | '\\') { '_' } else { c })
        .collect()
}

/// Every file [`RenderImages::write`] may write for `stem` in `dir` (all kinds, both formats).
#[must_use]
pub fn image_files(dir: &Path, stem: &str) -> Vec<PathBuf> {
    let stem = file_stem(stem);
    IMAGE_KINDS
        .iter()
        .flat_map(|kind| ["npy", "png"].map(|ext| dir.join(format!("{stem}_{kind}.{ext}"))))
        .collect()
}

/// `v` in 0..1 to 0..255 (clamped, rounded; NaN gives 0).
fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    data: &[u8],
    colour: bool,
) -> Result<(), IoError> {
    let ty = if colour {
        image::ExtendedColorType::Rgb8
    } else {
        image::ExtendedColorType::L8
    };
    write_atomically(path, |w| {
        PngEncoder::new(w)
            .write_image(data, width, height, ty)
            .map_err(|e| IoError::os(path, std::io::Error::other(e.to_string())))
    })
}

/// Depths (> 0 valid, else no surface) through the turbo colour map over their own range.
#[must_use]
pub fn depth_picture(depth: &[f32]) -> Vec<u8> {
    let valid = depth.iter().copied().filter(|d| *d > 0.0 && d.is_finite());
    let (lo, hi) = valid.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), d| {
        (lo.min(d), hi.max(d))
    });
    let span = if hi > lo { hi - lo } else { 1.0 };
    depth
        .iter()
        .flat_map(|&d| {
            if d > 0.0 && d.is_finite() {
                turbo(1.0 - (d - lo) / span)
            } else {
                [0; 3]
            }
        })
        .collect()
}

/// Normals mapped `(n / |n| + 1) / 2`; zero normals (no surface) are black.
#[must_use]
pub fn normal_picture(normal: &[f32]) -> Vec<u8> {
    normal
        .chunks_exact(3)
        .flat_map(|n| {
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if len > 0.0 && len.is_finite() {
                [0, 1, 2].map(|c| to_u8(0.5 * (n[c] / len + 1.0)))
            } else {
                [0; 3]
            }
        })
        .collect()
}

/// The turbo colour map (Mikhailov 2019), polynomial approximation, `t` in 0..1.
#[must_use]
pub fn turbo(t: f32) -> [u8; 3] {
    let t = f64::from(t.clamp(0.0, 1.0));
    let poly = |c: [f64; 6]| c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))));
    let r = poly([
        0.135_721_38,
        4.615_392_6,
        -42.660_322_6,
        132.131_082_34,
        -152.942_393_96,
        59.286_379_77,
    ]);
    let g = poly([
        0.091_402_61,
        2.194_188_39,
        4.842_966_58,
        -14.185_033_33,
        4.277_298_55,
        2.829_566_04,
    ]);
    let b = poly([
        0.106_673_3,
        12.641_946_08,
        -60.582_048_36,
        110.362_767_71,
        -89.903_109_13,
        27.348_249_81,
    ]);
    [r, g, b].map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pictures_and_files() {
        assert!(turbo(0.1)[2] > turbo(0.1)[0]);
        assert!(turbo(1.0)[0] > turbo(1.0)[2]);
        let pic = depth_picture(&[0.0, 1.0, 2.0, f32::NAN]);
        assert_eq!(&pic[..3], &[0, 0, 0]);
        assert_eq!(&pic[9..], &[0, 0, 0]);
        assert_eq!(normal_picture(&[0.0, 0.0, -2.0]), vec![128, 128, 0]);
        let dir = tempfile::tempdir().unwrap();
        let images = RenderImages::empty(3, 2, Outputs::ALL, [0.25, 0.5, 1.0]);
        let files = images.write(dir.path(), "a/b").unwrap();
        assert_eq!(files.len(), 10);
        let rgb = trisplat_geometry::io::read_npy(&dir.path().join("a_b_rgb.npy")).unwrap();
        assert_eq!(rgb.shape, vec![2, 3, 3]);
        assert_eq!(&rgb.data[..3], &[0.25, 0.5, 1.0]);
        assert!(images.is_finite());
    }
}
