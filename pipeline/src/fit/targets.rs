//! Target views for [`super::fit`]: mesh renders of the posed template ([`mesh_targets`]) and
//! user images ([`read_image_targets`]).
//!
//! A mesh target's rgb at a hit (docs/conventions.md §5 "Fitting") is, per [`TargetColor`]:
//! the template's base colour ([`trisplat_geometry::base_color`]: material factor × base-colour
//! texture × `COLOR_0`, in the texture's own encoding, sRGB for glTF; uv interpolated from the
//! hit triangle's corners), its vertex colours interpolated, or the world normal as colour
//! `(n + 1) / 2`; the barycentric weights are those of the hit point projected onto the hit
//! triangle.

use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;
use trisplat_extract::tsdf::{find_image, read_depth};
use trisplat_geometry::Rgba;
use trisplat_geometry::base_color::BaseColor;
use trisplat_geometry::mesh_render::{MeshRenderOptions, MeshRenderer, NormalFrame, NormalSource};
use trisplat_geometry::{Camera, TriMesh};

use super::inputs::{FitError, Target};

/// How a mesh target is coloured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum TargetColor {
    /// `texture` when the template carries a base colour with a texture
    /// ([`TriMesh::base_color`]), else its vertex colours (interpolated at the hit), else
    /// `normal`.
    #[default]
    Auto,
    /// The interpolated world-space normal as colour `(n + 1) / 2` (view-independent, so
    /// Gaussians with SH degree 0 can match it).
    Normal,
    /// The template's base colour (material factor × base-colour texture × `COLOR_0`, module
    /// docs); an error when it has no base-colour texture.
    Texture,
}

/// Where a mesh target's rgb comes from.
#[derive(Clone, Copy)]
enum Rgb<'a> {
    BaseColor(&'a BaseColor),
    Vertex(&'a [Rgba]),
    Normal,
}

fn rgb_source(template: &TriMesh, color: TargetColor) -> Result<Rgb<'_>, FitError> {
    let textured = template
        .base_color()
        .filter(|b| b.has_texture())
        .map(|b| Rgb::BaseColor(b));
    Ok(match color {
        TargetColor::Normal => Rgb::Normal,
        TargetColor::Auto => textured
            .or_else(|| template.colors().map(Rgb::Vertex))
            .unwrap_or(Rgb::Normal),
        TargetColor::Texture => textured.ok_or_else(|| {
            FitError::Target(
                "texture colour asked for, but the template has no base-colour texture (a \
                 glTF material's baseColorTexture, read with its base colour)"
                    .into(),
            )
        })?,
    })
}

/// Target views of `template` with its vertices at `positions`, ray cast from each camera
/// (docs/conventions.md §2 "Mesh ray casting"): rgb (module docs; `background` where nothing is
/// hit), alpha (the hit mask), z-depth and camera-frame normals.
///
/// # Errors
/// [`FitError::Target`] when the posed mesh cannot be indexed, or `color` is
/// [`TargetColor::Texture`] and the template has no base-colour texture.
pub fn mesh_targets(
    template: &TriMesh,
    positions: &[DVec3],
    cameras: &[Camera],
    color: TargetColor,
    background: [f32; 3],
) -> Result<Vec<Target>, FitError> {
    let source = rgb_source(template, color)?;
    let mut posed = template.clone();
    posed
        .set_positions(positions.to_vec())
        .map_err(|e| FitError::Target(format!("the posed template: {e}")))?;
    let renderer = MeshRenderer::new(
        &posed,
        MeshRenderOptions {
            normals: NormalSource::Interpolated,
            frame: NormalFrame::World,
        },
    )
    .map_err(|e| FitError::Target(format!("the posed template: {e}")))?;
    let tris = posed.triangles();
    Ok(cameras
        .par_iter()
        .map(|camera| {
            let maps = renderer.render(camera);
            let px = maps.depth.len();
            let r = camera.rotation();
            let rt = r.transpose();
            let mut rgb = vec![0.0f32; 3 * px];
            let mut normal = vec![0.0f32; 3 * px];
            for p in 0..px {
                let hit = maps.mask[p] > 0.0;
                let n = DVec3::from_array(maps.normal[p].map(f64::from));
                let c: [f32; 3] = if !hit {
                    background
                } else if let Rgb::Normal = source {
                    (n * 0.5 + 0.5).as_vec3().to_array()
                } else {
                    let (i, j) = (p / camera.width as usize, p % camera.width as usize);
                    let ray = DVec3::new(
                        (j as f64 + 0.5 - camera.cx) / camera.fx,
                        (i as f64 + 0.5 - camera.cy) / camera.fy,
                        1.0,
                    );
                    let x = camera.position() + r * ray * f64::from(maps.depth[p]);
                    let tri = maps.triangle[p] as usize;
                    let t = tris[tri];
                    let w = barycentric(x, t.map(|v| positions[v as usize]));
                    match source {
                        Rgb::BaseColor(b) => b.rgb_at(tri, w),
                        Rgb::Vertex(colors) => {
                            let mut c = [0.0f32; 3];
                            for (k, &v) in t.iter().enumerate() {
                                for ch in 0..3 {
                                    c[ch] += w[k] as f32 * colors[v as usize][ch];
                                }
                            }
                            c
                        }
                        Rgb::Normal => unreachable!("handled above"),
                    }
                };
                rgb[3 * p..3 * p + 3].copy_from_slice(&c);
                if hit {
                    normal[3 * p..3 * p + 3].copy_from_slice(&(rt * n).as_vec3().to_array());
                }
            }
            Target {
                camera: camera.clone(),
                rgb,
                alpha: Some(maps.mask.clone()),
                depth: Some(maps.depth.clone()),
                normal: Some(normal),
            }
        })
        .collect())
}

/// Barycentric weights of `x` (projected onto the triangle's plane), clamped to the triangle.
fn barycentric(x: DVec3, v: [DVec3; 3]) -> [f64; 3] {
    let (e0, e1, d) = (v[1] - v[0], v[2] - v[0], x - v[0]);
    let (a, b, c) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (p, q) = (d.dot(e0), d.dot(e1));
    let det = a * c - b * b;
    if det.abs() <= f64::MIN_POSITIVE {
        return [1.0, 0.0, 0.0];
    }
    let u = ((c * p - b * q) / det).clamp(0.0, 1.0);
    let w = ((a * q - b * p) / det).clamp(0.0, 1.0 - u);
    [1.0 - u - w, u, w]
}

/// Target views from user images: per camera `DIR/<img_name>.png` (8-bit or 16-bit, grey,
/// rgb or rgba; an alpha channel becomes the mask) and, when present, `DIR/<img_name>_mask.png`
/// (grey, > 0.5 is inside), and `DIR/<img_name>_depth.npy` or `_depth.png` (z-depth as
/// `trisplat tsdf` reads it: float `.npy`, or 16-bit `.png` divided by `depth_scale`; 0, NaN
/// and negative values mean no depth) for RGB-D captures. Images must have the camera's size.
///
/// # Errors
/// [`FitError::Target`] naming the file: missing, unreadable, or of another size.
pub fn read_image_targets(
    dir: &Path,
    cameras: &[Camera],
    depth_scale: f64,
) -> Result<Vec<Target>, FitError> {
    cameras
        .iter()
        .map(|camera| {
            let stem = camera.name.replace(['/', '\\'], "_");
            let path = dir.join(format!("{stem}.png"));
            let img = image::open(&path).map_err(|e| {
                FitError::Target(format!(
                    "{}: cannot read the image of camera '{}': {e}",
                    path.display(),
                    camera.name
                ))
            })?;
            let (w, h) = (img.width(), img.height());
            if (w, h) != (camera.width, camera.height) {
                return Err(FitError::Target(format!(
                    "{}: the image is {w}x{h}, camera '{}' is {}x{}",
                    path.display(),
                    camera.name,
                    camera.width,
                    camera.height
                )));
            }
            let has_alpha = img.color().has_alpha();
            let rgba = img.to_rgba32f();
            let rgb: Vec<f32> = rgba
                .pixels()
                .flat_map(|p| [p.0[0], p.0[1], p.0[2]])
                .collect();
            let mut alpha = has_alpha.then(|| rgba.pixels().map(|p| p.0[3]).collect::<Vec<_>>());
            let mask_path = dir.join(format!("{stem}_mask.png"));
            if mask_path.exists() {
                let m = image::open(&mask_path).map_err(|e| {
                    FitError::Target(format!(
                        "{}: cannot read the mask: {e}",
                        mask_path.display()
                    ))
                })?;
                if (m.width(), m.height()) != (w, h) {
                    return Err(FitError::Target(format!(
                        "{}: the mask is {}x{}, the image {w}x{h}",
                        mask_path.display(),
                        m.width(),
                        m.height()
                    )));
                }
                let grey = m.to_luma32f();
                alpha = Some(
                    grey.pixels()
                        .map(|p| if p.0[0] > 0.5 { 1.0 } else { 0.0 })
                        .collect(),
                );
            }
            let depth = match find_image(dir, camera, "depth") {
                Ok(path) => Some(
                    read_depth(&path, camera, depth_scale)
                        .map_err(|e| {
                            FitError::Target(format!("the depth of camera '{}': {e}", camera.name))
                        })?
                        .data()
                        .to_vec(),
                ),
                Err(_) => None,
            };
            Ok(Target {
                camera: camera.clone(),
                rgb,
                alpha,
                depth,
                normal: None,
            })
        })
        .collect()
}
