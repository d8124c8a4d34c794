//! Writing the material maps of a relit render beside the renderer's images, under the same
//! contract (docs/conventions.md §10): `NAME_albedo.npy` `[H, W, 3]`, `NAME_roughness.npy`
//! `[H, W]`, `NAME_specular.npy` `[H, W, 3]` in float32, each with a PNG picture (values clamped
//! to 0..1 and quantised to 8 bits; roughness as grey).

use std::path::{Path, PathBuf};

use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use trisplat_geometry::io::{IoError, write_atomically, write_npy};

use super::relight::RelitRender;
use crate::render::file_stem;

/// The kinds of material map, as they appear in file names (`<stem>_<kind>.npy` / `.png`).
pub const MATERIAL_KINDS: [&str; 3] = ["albedo", "roughness", "specular"];

/// Every file [`write_material_maps`] may write for `stem` in `dir`.
#[must_use]
pub fn material_image_files(dir: &Path, stem: &str) -> Vec<PathBuf> {
    let stem = file_stem(stem);
    MATERIAL_KINDS
        .iter()
        .flat_map(|kind| ["npy", "png"].map(|ext| dir.join(format!("{stem}_{kind}.{ext}"))))
        .collect()
}

/// Writes the material maps present in `relit` into `dir`, named after `stem`; returns the
/// files written (each atomically).
///
/// # Errors
/// [`IoError`] naming the file that could not be written.
pub fn write_material_maps(
    relit: &RelitRender,
    dir: &Path,
    stem: &str,
) -> Result<Vec<PathBuf>, IoError> {
    let stem = file_stem(stem);
    let images = &relit.output.images;
    let (w, h) = (images.width, images.height);
    let mut written = Vec::new();
    let maps = [
        ("albedo", relit.albedo.as_deref(), 3usize),
        ("roughness", relit.roughness.as_deref(), 1),
        ("specular", relit.specular.as_deref(), 3),
    ];
    for (kind, data, channels) in maps {
        let Some(data) = data else { continue };
        let npy = dir.join(format!("{stem}_{kind}.npy"));
        let shape: Vec<usize> = if channels == 3 {
            vec![h as usize, w as usize, 3]
        } else {
            vec![h as usize, w as usize]
        };
        write_npy(&npy, &shape, data)?;
        written.push(npy);
        let png = dir.join(format!("{stem}_{kind}.png"));
        let bytes: Vec<u8> = data
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let ty = if channels == 3 {
            image::ExtendedColorType::Rgb8
        } else {
            image::ExtendedColorType::L8
        };
        write_atomically(&png, |out| {
            PngEncoder::new(out)
                .write_image(&bytes, w, h, ty)
                .map_err(|e| IoError::os(&png, std::io::Error::other(e.to_string())))
        })?;
        written.push(png);
    }
    Ok(written)
}
