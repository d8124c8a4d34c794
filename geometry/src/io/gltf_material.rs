//! glTF 2.0 base colour of the static mesh: per triangle its material's
//! `pbrMetallicRoughness.baseColorFactor` and `baseColorTexture`, the corners' `TEXCOORD_0` and
//! `COLOR_0` (see [`crate::base_color`] for how they combine).
//!
//! Triangles are those of [`super::gltf::read_gltf`] (and of the animated template,
//! `animation::gltf`) in the same order, so the result attaches to a template read from the
//! same file ([`crate::TriMesh::with_base_color`]). Read here:
//! - images from a buffer view, a base64 `data:` URI or a file URI relative to the glTF file
//!   (`%XX` escapes decoded); PNG (8 or 16 bits, grey, grey-alpha, rgb, rgba) and JPEG, chosen
//!   by `mimeType`, else by the image's first bytes; at most [`MAX_TEXTURE_PIXELS`] pixels;
//! - the sampler's `wrapS` / `wrapT` and `magFilter` (`NEAREST` → nearest, otherwise
//!   bilinear; `minFilter` is ignored: no mipmaps);
//! - only images of materials some triangle uses are decoded, each once.
//!
//! Refused (clear errors naming the file and the material, image or primitive): a base-colour
//! texture on `TEXCOORD_n` with `n ≠ 0`, `KHR_texture_transform` on it, a textured primitive
//! without a `TEXCOORD_0` of one entry per vertex, a missing or undecodable image, another
//! image format.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::Path;
use std::sync::Arc;

use base64::Engine as _;

use super::error::IoError;
use super::gltf::gather;
use super::gltf_data::{GltfData, percent_decode};
use crate::base_color::{BaseColor, Material, MaterialTexture};
use crate::texture::{Filter, Sampler, Texture, Wrap};

/// Largest base-colour image read, in pixels (8192²: 1 GiB as `f32` RGBA), checked from the
/// image's header before its pixels are decoded.
pub const MAX_TEXTURE_PIXELS: u64 = 8192 * 8192;

/// Reads the base colour of the static mesh of a glTF or GLB file (module docs): one entry per
/// triangle of [`super::gltf::read_gltf`] on the same file. A file without materials gives
/// glTF's default material (white) everywhere; [`BaseColor::has_texture`] says whether any
/// triangle is textured.
///
/// # Errors
/// [`IoError::Os`] / [`IoError::MissingReference`] for a file or an image file that cannot be
/// read, [`IoError::Unsupported`] for another `TEXCOORD` set, a texture transform or image
/// format, [`IoError::Malformed`] naming the material, image or primitive at fault.
pub fn read_gltf_base_color(path: &Path) -> Result<BaseColor, IoError> {
    let data = GltfData::open(path)?;
    let gathered = gather(&data, true)?;
    let parts = gathered.surface.unwrap_or_default();
    let doc = &data.document;
    let default_material = doc.materials().len();
    let mut used = vec![false; default_material + 1];
    for m in &parts.material {
        used[m.unwrap_or(default_material)] = true;
    }
    let mut decoded: HashMap<usize, Arc<Texture>> = HashMap::new();
    let mut materials = Vec::with_capacity(default_material + 1);
    for material in doc.materials() {
        let index = material.index().unwrap_or(default_material);
        let pbr = material.pbr_metallic_roughness();
        let factor = pbr.base_color_factor();
        if let Some(i) = factor.iter().position(|c| !c.is_finite()) {
            return Err(IoError::malformed(
                path,
                format!("material {index}"),
                format!("baseColorFactor component {i} is not finite"),
            ));
        }
        let texture = match pbr.base_color_texture() {
            Some(info) if used[index] => {
                check_texture_info(path, &data.json, index, info.tex_coord())?;
                let texture = info.texture();
                let image = texture.source();
                let image_index = image.index();
                let decoded_image = match decoded.get(&image_index) {
                    Some(t) => t.clone(),
                    None => {
                        let t = Arc::new(decode_image(&data, &image)?);
                        decoded.insert(image_index, t.clone());
                        t
                    }
                };
                Some(MaterialTexture {
                    texture: decoded_image,
                    sampler: sampler_of(&texture.sampler()),
                })
            }
            _ => None,
        };
        materials.push(Material { factor, texture });
    }
    materials.push(Material::default());
    for (element, material, why) in &parts.without_uvs {
        let m = material.unwrap_or(default_material);
        if materials[m].texture.is_some() {
            return Err(IoError::malformed(
                path,
                element.as_str(),
                format!("material {m} has a base colour texture, but {why}"),
            ));
        }
    }
    let triangle_material = parts
        .material
        .iter()
        .map(|m| u32::try_from(m.unwrap_or(default_material)).unwrap_or(u32::MAX))
        .collect();
    let colors = parts.any_colors.then_some(parts.corner_colors);
    BaseColor::new(parts.corner_uvs, colors, triangle_material, materials)
        .map_err(|e| IoError::malformed(path, "base colour", e.to_string()))
}

/// Refuses what the texture lookup does not do: another uv set, a texture transform.
fn check_texture_info(
    path: &Path,
    json: &serde_json::Value,
    material: usize,
    tex_coord: u32,
) -> Result<(), IoError> {
    if tex_coord != 0 {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: format!(
                "material {material}: baseColorTexture uses TEXCOORD_{tex_coord} (only \
                 TEXCOORD_0 is read)"
            ),
        });
    }
    let transform = json
        .pointer(&format!(
            "/materials/{material}/pbrMetallicRoughness/baseColorTexture/extensions/KHR_texture_transform"
        ))
        .is_some();
    if transform {
        return Err(IoError::Unsupported {
            path: path.to_path_buf(),
            what: format!("material {material}: KHR_texture_transform on baseColorTexture"),
        });
    }
    Ok(())
}

fn wrap_of(mode: gltf::texture::WrappingMode) -> Wrap {
    use gltf::texture::WrappingMode as W;
    match mode {
        W::Repeat => Wrap::Repeat,
        W::ClampToEdge => Wrap::ClampToEdge,
        W::MirroredRepeat => Wrap::MirroredRepeat,
    }
}

fn sampler_of(s: &gltf::texture::Sampler<'_>) -> Sampler {
    Sampler {
        wrap_u: wrap_of(s.wrap_s()),
        wrap_v: wrap_of(s.wrap_t()),
        filter: match s.mag_filter() {
            Some(gltf::texture::MagFilter::Nearest) => Filter::Nearest,
            _ => Filter::Linear,
        },
    }
}

/// The encoded bytes of `image` and its declared MIME type.
fn image_bytes<'a>(
    data: &'a GltfData,
    image: &gltf::Image<'a>,
) -> Result<(std::borrow::Cow<'a, [u8]>, Option<&'a str>), IoError> {
    let path = data.path();
    let element = format!("image {}", image.index());
    match image.source() {
        gltf::image::Source::View { view, mime_type } => {
            let bytes = data
                .buffer_view_bytes(&view)
                .map_err(|m| IoError::malformed(path, &element, m))?;
            Ok((bytes.into(), Some(mime_type)))
        }
        gltf::image::Source::Uri { uri, mime_type } if uri.starts_with("data:") => {
            let (head, payload) = uri.split_once(";base64,").ok_or_else(|| {
                IoError::malformed(
                    path,
                    &element,
                    "data URI is not base64 (only base64 data URIs are supported)",
                )
            })?;
            let bytes = base64::engine::general_purpose::STANDARD
                .decode(payload)
                .map_err(|e| IoError::malformed(path, &element, format!("bad base64: {e}")))?;
            let declared = mime_type.or_else(|| head.strip_prefix("data:"));
            Ok((bytes.into(), declared))
        }
        gltf::image::Source::Uri { uri, mime_type } => {
            let base = path.parent().unwrap_or_else(|| Path::new("."));
            let resolved = base.join(percent_decode(uri));
            let bytes = std::fs::read(&resolved).map_err(|error| IoError::MissingReference {
                path: path.to_path_buf(),
                reference: resolved.clone(),
                error,
            })?;
            Ok((bytes.into(), mime_type))
        }
    }
}

/// Decodes `image` (PNG or JPEG) to texels as stored (module docs of [`crate::texture`]).
fn decode_image(data: &GltfData, image: &gltf::Image<'_>) -> Result<Texture, IoError> {
    use image::ImageFormat as F;
    let path = data.path();
    let element = format!("image {}", image.index());
    let (bytes, mime) = image_bytes(data, image)?;
    let unsupported = |what: String| IoError::Unsupported {
        path: path.to_path_buf(),
        what: format!("{element}: {what} (PNG and JPEG images are read)"),
    };
    let format = match mime {
        Some("image/png") => F::Png,
        Some("image/jpeg") => F::Jpeg,
        Some(other) => return Err(unsupported(format!("MIME type {other}"))),
        None => match image::guess_format(&bytes) {
            Ok(f @ (F::Png | F::Jpeg)) => f,
            Ok(f) => return Err(unsupported(format!("{f:?} image"))),
            Err(_) => return Err(unsupported("an image of unknown format".into())),
        },
    };
    let name = if format == F::Png { "PNG" } else { "JPEG" };
    let cannot = |e: image::ImageError| {
        IoError::malformed(path, &element, format!("cannot decode {name}: {e}"))
    };
    let (w, h) = image::ImageReader::with_format(Cursor::new(&bytes[..]), format)
        .into_dimensions()
        .map_err(cannot)?;
    if u64::from(w) * u64::from(h) > MAX_TEXTURE_PIXELS {
        return Err(unsupported(format!(
            "a {w}x{h} image, over the limit of {MAX_TEXTURE_PIXELS} pixels"
        )));
    }
    let mut reader = image::ImageReader::with_format(Cursor::new(&bytes[..]), format);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    // 16-bit RGBA and the decoder's own buffers.
    limits.max_alloc = Some(MAX_TEXTURE_PIXELS * 8 * 2);
    reader.limits(limits);
    let decoded = reader.decode().map_err(cannot)?;
    let rgba = decoded.to_rgba32f();
    let texels = rgba
        .as_raw()
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    Texture::new(w, h, texels).map_err(|e| IoError::malformed(path, &element, e.to_string()))
}
