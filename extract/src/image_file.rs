//! Reading per-camera image files, shared by the TSDF's depth and colour images and the
//! carving masks: PNG detection and decoding, the shape of a one-channel `.npy` plane, and one
//! file per camera read in parallel.

use std::path::Path;

use rayon::prelude::*;
use trisplat_geometry::Camera;

/// Whether `path` names a PNG file (by its extension, in any case).
pub(crate) fn is_png(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
}

/// Opens and decodes the image at `path`, its format guessed from the content; the error is
/// the image crate's message.
pub(crate) fn decode_image(path: &Path) -> Result<image::DynamicImage, String> {
    image::ImageReader::open(path)
        .map_err(|e| e.to_string())?
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .decode()
        .map_err(|e| e.to_string())
}

/// Whether an `.npy` shape is one plane of `height` rows and `width` columns: `[H, W]` or
/// `[H, W, 1]`.
pub(crate) fn is_plane(shape: &[usize], width: usize, height: usize) -> bool {
    match shape {
        [rows, cols] | [rows, cols, 1] => (*rows, *cols) == (height, width),
        _ => false,
    }
}

/// `read(camera)` for every camera, in parallel; the error reported is the first camera's (in
/// order) that fails.
pub(crate) fn per_camera<T, E, F>(cameras: &[Camera], read: F) -> Result<Vec<T>, E>
where
    T: Send,
    E: Send,
    F: Fn(&Camera) -> Result<T, E> + Sync + Send,
{
    let results: Vec<Result<T, E>> = cameras.par_iter().map(read).collect();
    results.into_iter().collect()
}
