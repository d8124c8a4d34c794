//! Depth and colour images for fusion, and reading them from a folder (docs/conventions.md §2).
//!
//! A depth map is z-depth (distance along the camera's +z axis) in the scene's unit, 0 where
//! nothing was seen. Values that are NaN, infinite or negative are treated as 0 (invalid), as
//! Open3D does for `d <= 0`; [`DepthImage::invalid_count`] says how many there were.
//!
//! Files: `<img_name>_depth.npy` (float32 or float64, shape `[H, W]` or `[H, W, 1]`) or
//! `<img_name>_depth.png` (16-bit greyscale, divided by `depth_scale`, 1000 for millimetres as
//! Open3D and TUM do). Colours: `<img_name>_rgb.npy` (`[H, W, 3]` floats in 0..1) or
//! `<img_name>_rgb.png` (8-bit RGB or RGBA, scaled to 0..1).

use std::path::{Path, PathBuf};

use trisplat_geometry::Camera;
use trisplat_geometry::io::read_npy;

use super::error::TsdfError;
use crate::image_file::{decode_image, is_plane, is_png, per_camera};

/// Default divisor of 16-bit PNG depth values: millimetres to metres (Open3D, TUM).
pub const DEFAULT_DEPTH_SCALE: f64 = 1000.0;

/// A depth map: `width * height` z-depths in row-major order, 0 = no surface.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    width: u32,
    height: u32,
    data: Vec<f32>,
    invalid: usize,
    front: Option<Vec<f32>>,
}

impl DepthImage {
    /// A depth map from row-major values. NaN, infinite and negative values become 0 (no
    /// surface) and are counted in [`DepthImage::invalid_count`].
    ///
    /// # Errors
    /// [`TsdfError::ImageSize`] when `data.len() != width * height`.
    pub fn try_new(width: u32, height: u32, mut data: Vec<f32>) -> Result<Self, TsdfError> {
        if data.len() as u64 != u64::from(width) * u64::from(height) {
            return Err(TsdfError::ImageSize {
                what: "depth map".into(),
                expected: (width, height),
                found: format!("{} values", data.len()),
            });
        }
        // Branch-free, so the loop vectorises: a depth map is read for every view.
        let mut invalid = 0;
        for d in &mut data {
            let bad = !(d.is_finite() && *d >= 0.0);
            invalid += usize::from(bad);
            *d = if bad { 0.0 } else { *d };
        }
        Ok(Self {
            width,
            height,
            data,
            invalid,
            front: None,
        })
    }

    /// This depth map with a front depth per pixel (row-major, same size): where the view
    /// saw the first appreciable opacity along the pixel's ray, at or before the depth (for
    /// rendered Gaussians, where the accumulated alpha first reaches a small value). Fusion
    /// then marks free space only in front of it: a voxel between the front depth and the
    /// surface is not updated by this view (docs/conventions.md §6). 0, NaN, negative or
    /// infinite values mean none (the depth itself is the front).
    ///
    /// # Errors
    /// [`TsdfError::ImageSize`] when `front.len() != width * height`.
    pub fn with_front(mut self, mut front: Vec<f32>) -> Result<Self, TsdfError> {
        if front.len() != self.data.len() {
            return Err(TsdfError::ImageSize {
                what: "front depth map".into(),
                expected: (self.width, self.height),
                found: format!("{} values", front.len()),
            });
        }
        for f in &mut front {
            *f = if f.is_finite() && *f > 0.0 { *f } else { 0.0 };
        }
        self.front = Some(front);
        Ok(self)
    }

    /// The front depths of [`DepthImage::with_front`], if any (0 = none).
    #[must_use]
    pub fn front(&self) -> Option<&[f32]> {
        self.front.as_deref()
    }

    /// Width in pixels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Row-major depths (0 = no surface).
    #[must_use]
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// How many input values were NaN, infinite or negative (now 0).
    #[must_use]
    pub fn invalid_count(&self) -> usize {
        self.invalid
    }
}

/// An RGB image with channels in 0..1, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct ColorImage {
    width: u32,
    height: u32,
    data: Vec<[f32; 3]>,
}

impl ColorImage {
    /// A colour image from row-major RGB values (non-finite channels become 0).
    ///
    /// # Errors
    /// [`TsdfError::ImageSize`] when `data.len() != width * height`.
    pub fn try_new(width: u32, height: u32, mut data: Vec<[f32; 3]>) -> Result<Self, TsdfError> {
        if data.len() as u64 != u64::from(width) * u64::from(height) {
            return Err(TsdfError::ImageSize {
                what: "colour image".into(),
                expected: (width, height),
                found: format!("{} pixels", data.len()),
            });
        }
        for c in data.iter_mut().flatten() {
            if !c.is_finite() {
                *c = 0.0;
            }
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Width in pixels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Row-major RGB values.
    #[must_use]
    pub fn data(&self) -> &[[f32; 3]] {
        &self.data
    }
}

/// The first existing file among `<dir>/<img_name>_<suffix>.npy` and `.png`.
///
/// # Errors
/// [`TsdfError::MissingImage`] naming the `.npy` path when neither exists.
pub fn find_image(dir: &Path, camera: &Camera, suffix: &str) -> Result<PathBuf, TsdfError> {
    let stem = format!("{}_{suffix}", camera.name);
    let npy = dir.join(format!("{stem}.npy"));
    if npy.is_file() {
        return Ok(npy);
    }
    let png = dir.join(format!("{stem}.png"));
    if png.is_file() {
        return Ok(png);
    }
    Err(TsdfError::MissingImage {
        path: npy,
        camera: camera.name.clone(),
    })
}

fn image_error(path: &Path, message: impl Into<String>) -> TsdfError {
    TsdfError::ImageFile {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn size_error(path: &Path, camera: &Camera, found: String) -> TsdfError {
    TsdfError::ImageSize {
        what: format!("{} (camera {})", path.display(), camera.name),
        expected: (camera.width, camera.height),
        found,
    }
}

/// Reads a depth map for `camera` from `.npy` (any float shape `[H, W]` or `[H, W, 1]`) or a
/// 16-bit greyscale `.png` (values divided by `depth_scale`).
///
/// # Errors
/// [`TsdfError::Io`] / [`TsdfError::ImageFile`] for unreadable files,
/// [`TsdfError::ImageSize`] naming the file when its size is not the camera's,
/// [`TsdfError::Parameter`] for a non-positive `depth_scale`.
pub fn read_depth(path: &Path, camera: &Camera, depth_scale: f64) -> Result<DepthImage, TsdfError> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    if is_png(path) {
        if !(depth_scale.is_finite() && depth_scale > 0.0) {
            return Err(TsdfError::Parameter {
                name: "depth_scale",
                value: depth_scale,
            });
        }
        let img = decode_image(path).map_err(|message| image_error(path, message))?;
        let image::DynamicImage::ImageLuma16(img) = img else {
            return Err(image_error(
                path,
                format!(
                    "depth PNGs must be 16-bit greyscale (millimetres), not {:?}",
                    img.color()
                ),
            ));
        };
        if (img.width() as usize, img.height() as usize) != (w, h) {
            return Err(size_error(
                path,
                camera,
                format!("{}x{}", img.width(), img.height()),
            ));
        }
        let data = img
            .into_raw()
            .into_iter()
            .map(|v| (f64::from(v) / depth_scale) as f32)
            .collect();
        return DepthImage::try_new(camera.width, camera.height, data);
    }
    let array = read_npy(path)?;
    if !is_plane(&array.shape, w, h) {
        return Err(size_error(
            path,
            camera,
            format!("shape {:?} (expected [{h}, {w}])", array.shape),
        ));
    }
    DepthImage::try_new(camera.width, camera.height, array.data)
}

/// Reads a colour image for `camera` from `.npy` (`[H, W, 3]` or `[H, W, 4]` floats in 0..1;
/// alpha is ignored) or an 8/16-bit `.png`.
///
/// # Errors
/// As [`read_depth`].
pub fn read_color(path: &Path, camera: &Camera) -> Result<ColorImage, TsdfError> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    if is_png(path) {
        let img = decode_image(path).map_err(|message| image_error(path, message))?;
        if (img.width() as usize, img.height() as usize) != (w, h) {
            return Err(size_error(
                path,
                camera,
                format!("{}x{}", img.width(), img.height()),
            ));
        }
        let rgb = img.into_rgb32f();
        let data = rgb
            .into_raw()
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        return ColorImage::try_new(camera.width, camera.height, data);
    }
    let array = read_npy(path)?;
    let channels = match array.shape.as_slice() {
        [rows, cols, c @ (3 | 4)] if (*rows, *cols) == (h, w) => *c,
        _ => {
            return Err(size_error(
                path,
                camera,
                format!("shape {:?} (expected [{h}, {w}, 3])", array.shape),
            ));
        }
    };
    let data = array
        .data
        .chunks_exact(channels)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    ColorImage::try_new(camera.width, camera.height, data)
}

/// Reads `<dir>/<img_name>_depth.npy` (or `.png`) for every camera, in parallel. The error
/// reported is the one of the first camera (in order) that fails.
///
/// # Errors
/// As [`find_image`] and [`read_depth`].
pub fn read_depth_dir(
    dir: &Path,
    cameras: &[Camera],
    depth_scale: f64,
) -> Result<Vec<DepthImage>, TsdfError> {
    per_camera(cameras, |c| {
        read_depth(&find_image(dir, c, "depth")?, c, depth_scale)
    })
}

/// Reads `<dir>/<img_name>_rgb.npy` (or `.png`) for every camera, in parallel.
///
/// # Errors
/// As [`find_image`] and [`read_color`].
pub fn read_color_dir(dir: &Path, cameras: &[Camera]) -> Result<Vec<ColorImage>, TsdfError> {
    per_camera(cameras, |c| read_color(&find_image(dir, c, "rgb")?, c))
}
