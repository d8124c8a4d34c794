//! Pictures of one frame's meshes for report.html, and per-vertex error colours
//! (`extract --error-colors`).
//!
//! A thumbnail is one mesh seen by one camera, ray cast through a BVH of its triangles
//! ([`TriangleBvh::cast_ray`], 2x2 rays per pixel averaged): a point that is hit takes the
//! viridis colour of its distance to the ground truth's surface (exact: the metrics' `GtSamples::distance`)
//! from 0 up to `scale` (farther points take the top colour), or light grey without a ground
//! truth, shaded by the angle between its triangle's normal and the ray (a light at the
//! camera), so that the shape reads as well as the error. The background is white.
//!
//! Every picture of a frame uses the same camera ([`frame_camera`]): it looks at the points it
//! is given (the ground truth's vertices, else the meshes') from the front, 30° to the model's
//! left and 12° above, in the template's axes (`extract --view-axes`; glTF's by default: +Y up,
//! the model facing +Z), and is fitted to them with a margin, 360 pixels high and as wide as
//! their outline needs (144 to 576 pixels).
//!
//! Error colours on meshes: each vertex's distance to the ground truth through the same colour
//! map and scale ([`error_colors`]).

use glam::{DMat3, DVec3};
use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use plotters::style::colors::colormaps::{ColorMap, ViridisRGB};
use rayon::prelude::*;
use trisplat_geometry::io::{IoError, write_atomically};
use trisplat_geometry::spatial::{SpatialError, TriangleBvh};
use trisplat_geometry::{Camera, Rgba, TriMesh};
use trisplat_splat::Axes;

/// Height of a thumbnail in pixels.
pub const THUMBNAIL_HEIGHT: u32 = 360;
/// The camera's direction from the model, degrees about the model's up axis from its front
/// (towards its left: +X in glTF's axes).
pub const AZIMUTH_DEG: f64 = 30.0;
/// The camera's height above the model's centre, degrees.
pub const ELEVATION_DEG: f64 = 12.0;
/// Rays per pixel along each axis (averaged: smooth edges).
const SUPERSAMPLE: u32 = 2;
/// Colour of a mesh without a ground truth to measure against.
const GREY: [f64; 3] = [0.82, 0.82, 0.82];

/// The viridis colour of `t` (clamped to 0..=1; NaN gives the top colour): dark purple at 0,
/// through blue and green, yellow at 1.
#[must_use]
pub fn viridis(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
    let c = ViridisRGB.get_color(t);
    [c.0, c.1, c.2]
}

/// Per-vertex colours of `distances` through [`viridis`] from 0 to `scale` (opaque).
#[must_use]
pub fn error_colors(distances: &[f64], scale: f64) -> Vec<Rgba> {
    distances
        .iter()
        .map(|&d| {
            let [r, g, b] = viridis(d / scale);
            [
                f32::from(r) / 255.0,
                f32::from(g) / 255.0,
                f32::from(b) / 255.0,
                1.0,
            ]
        })
        .collect()
}

/// The camera of one frame's thumbnails (see the module docs), fitted to `points` given in
/// `axes`, in coordinates relative to the centre of their bounding box (returned beside it);
/// `None` for no points or points that all coincide.
#[must_use]
pub fn frame_camera(points: &[DVec3], axes: Axes) -> Option<(Camera, DVec3)> {
    let bounds = trisplat_geometry::Aabb::from_dpoints(points)?;
    let centre = bounds.center();
    let radius = 0.5 * bounds.diagonal();
    if !(radius > 0.0 && radius.is_finite()) {
        return None;
    }
    let (az, el) = (AZIMUTH_DEG.to_radians(), ELEVATION_DEG.to_radians());
    // In glTF's axes (luf), then in the points' own.
    let to_points = Axes::Luf.to(axes);
    let towards_eye = to_points * DVec3::new(az.sin() * el.cos(), el.sin(), az.cos() * el.cos());
    let eye = towards_eye * (4.0 * radius);
    let up = to_points * DVec3::Y;
    let aim = Camera::look_at("thumbnail", eye, DVec3::ZERO, up, (64, 64), 30.0).ok()?;
    // The outline of the points in normalised image coordinates (at most ~20,000 of them).
    let step = (points.len() / 20_000).max(1);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points.iter().step_by(step).filter(|p| p.is_finite()) {
        let c = aim.world_to_camera(*p - centre);
        if c.z <= 0.0 {
            continue;
        }
        let (u, v) = (c.x / c.z, c.y / c.z);
        lo = [lo[0].min(u), lo[1].min(v)];
        hi = [hi[0].max(u), hi[1].max(v)];
    }
    let span = [hi[0] - lo[0], hi[1] - lo[1]];
    if !(span[0] > 0.0 && span[1] > 0.0) {
        return None;
    }
    let h = f64::from(THUMBNAIL_HEIGHT);
    let w = (h * span[0] / span[1]).clamp(0.4 * h, 1.6 * h).round();
    let focal = (0.92 * w / span[0]).min(0.92 * h / span[1]);
    let cx = 0.5 * w - focal * 0.5 * (lo[0] + hi[0]);
    let cy = 0.5 * h - focal * 0.5 * (lo[1] + hi[1]);
    let camera = Camera::try_new(
        0,
        "thumbnail",
        w as u32,
        THUMBNAIL_HEIGHT,
        (focal, focal),
        (cx, cy),
        aim.rotation(),
        eye,
    )
    .ok()?;
    Some((camera, centre))
}

/// The distance of a world-space point to the ground truth's surface (`None` when it cannot
/// be measured): the metrics' `GtSamples::distance`, as the caller supplies it.
pub type DistanceTo<'a> = &'a (dyn Fn(DVec3) -> Option<f64> + Sync);

/// How a thumbnail colours the surface.
#[derive(Clone, Copy)]
pub enum Colouring<'a> {
    /// Light grey (no ground truth, or the ground truth itself).
    Grey,
    /// By the distance to the ground truth through [`viridis`] from 0 to `scale`.
    Distance {
        /// The distance of a point to the ground truth.
        distance: DistanceTo<'a>,
        /// The distance at the top of the colour map.
        scale: f64,
    },
}

impl std::fmt::Debug for Colouring<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Grey => f.write_str("Grey"),
            Self::Distance { scale, .. } => {
                f.debug_struct("Distance").field("scale", scale).finish()
            }
        }
    }
}

/// An 8-bit RGB picture, row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Picture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height` RGB triples.
    pub rgb: Vec<u8>,
}

impl Picture {
    /// The colour of pixel (`col`, `row`).
    #[must_use]
    pub fn pixel(&self, col: u32, row: u32) -> Option<[u8; 3]> {
        (col < self.width && row < self.height).then(|| {
            let i = 3 * (row as usize * self.width as usize + col as usize);
            [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
        })
    }

    /// Writes the picture as a PNG (atomically).
    ///
    /// # Errors
    /// [`IoError`] when the file cannot be written.
    pub fn write_png(&self, path: &std::path::Path) -> Result<(), IoError> {
        write_atomically(path, |w| {
            PngEncoder::new(w)
                .write_image(
                    &self.rgb,
                    self.width,
                    self.height,
                    image::ExtendedColorType::Rgb8,
                )
                .map_err(|e| IoError::os(path, std::io::Error::other(e.to_string())))
        })
    }
}

/// `mesh` (world space) seen by `camera`, whose coordinates are relative to `origin` (as
/// [`frame_camera`] gives them), coloured as `colouring` says (see the module docs).
///
/// # Errors
/// [`SpatialError`] when the mesh cannot be indexed.
pub fn render(
    mesh: &TriMesh,
    camera: &Camera,
    origin: DVec3,
    colouring: Colouring<'_>,
) -> Result<Picture, SpatialError> {
    let mut local = mesh.clone();
    local.translate(-origin);
    let bvh = TriangleBvh::new(&local)?;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let rotation: DMat3 = camera.rotation();
    let eye = camera.position();
    let mut rgb = vec![255u8; w * h * 3];
    rgb.par_chunks_mut(3 * w.max(1))
        .enumerate()
        .for_each(|(row, line)| {
            for col in 0..w {
                let mut sum = [0.0f64; 3];
                for k in 0..SUPERSAMPLE * SUPERSAMPLE {
                    let (su, sv) = (k % SUPERSAMPLE, k / SUPERSAMPLE);
                    let u = col as f64 + (f64::from(su) + 0.5) / f64::from(SUPERSAMPLE);
                    let v = row as f64 + (f64::from(sv) + 0.5) / f64::from(SUPERSAMPLE);
                    let dir = (rotation * camera.unproject(u, v)).normalize();
                    let c = shade(&bvh, eye, dir, origin, colouring);
                    for (s, x) in sum.iter_mut().zip(c) {
                        *s += x;
                    }
                }
                let n = f64::from(SUPERSAMPLE * SUPERSAMPLE);
                for (k, s) in sum.iter().enumerate() {
                    line[3 * col + k] = (255.0 * s / n).round().clamp(0.0, 255.0) as u8;
                }
            }
        });
    Ok(Picture {
        width: camera.width,
        height: camera.height,
        rgb,
    })
}

/// The colour (0..1) seen along the ray from `eye` in unit direction `dir`: white for a miss.
fn shade(
    bvh: &TriangleBvh,
    eye: DVec3,
    dir: DVec3,
    origin: DVec3,
    colouring: Colouring<'_>,
) -> [f64; 3] {
    let Some(hit) = bvh.cast_ray(eye.as_vec3(), dir.as_vec3(), f64::INFINITY) else {
        return [1.0; 3];
    };
    let Some([a, b, c]) = bvh.corners(hit.triangle as usize) else {
        return [1.0; 3];
    };
    let normal = (b - a).cross(c - a).normalize_or_zero();
    let light = 0.3 + 0.7 * normal.dot(dir).abs();
    let base = match colouring {
        Colouring::Grey => GREY,
        Colouring::Distance { distance, scale } => {
            let point = a * hit.barycentric[0] + b * hit.barycentric[1] + c * hit.barycentric[2];
            let d = distance(point + origin).unwrap_or(f64::NAN);
            viridis(d / scale).map(|x| f64::from(x) / 255.0)
        }
    };
    base.map(|x| x * light)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::GtSamples;

    fn tetra(scale: f64, shift: DVec3) -> TriMesh {
        let p: Vec<DVec3> = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z]
            .iter()
            .map(|v| *v * scale + shift)
            .collect();
        TriMesh::new(p, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    }

    #[test]
    fn viridis_runs_from_purple_to_yellow() {
        assert_eq!(viridis(0.0), [68, 1, 84]);
        assert_eq!(viridis(1.0), [254, 232, 37]);
        assert_eq!(viridis(-3.0), viridis(0.0));
        assert_eq!(viridis(7.0), viridis(1.0));
        assert_eq!(viridis(f64::NAN), viridis(1.0));
        // Brighter as it goes (viridis is perceptually ordered).
        let lum =
            |c: [u8; 3]| 0.3 * f64::from(c[0]) + 0.59 * f64::from(c[1]) + 0.11 * f64::from(c[2]);
        let l: Vec<f64> = (0..=10)
            .map(|k| lum(viridis(f64::from(k) / 10.0)))
            .collect();
        assert!(l.windows(2).all(|w| w[1] > w[0]), "{l:?}");
        let c = error_colors(&[0.0, 0.5, 2.0], 1.0);
        assert_eq!(c[0], [68.0 / 255.0, 1.0 / 255.0, 84.0 / 255.0, 1.0]);
        let unit = |t: f64| {
            let [r, g, b] = viridis(t).map(|x| f32::from(x) / 255.0);
            [r, g, b, 1.0]
        };
        assert_eq!(c[1], unit(0.5));
        assert_eq!(c[2], unit(1.0), "beyond the scale: the top colour");
    }

    #[test]
    fn the_camera_follows_the_template_axes() {
        // A lopsided shape in glTF's axes, and the same shape stored Z-up facing -Y (lbu):
        // told the axes, the camera sees both alike (every vertex at the same pixel).
        let luf: Vec<DVec3> = tetra(1.0, DVec3::ZERO)
            .positions()
            .iter()
            .map(|p| *p * DVec3::new(1.0, 2.0, 0.5))
            .collect();
        let m = Axes::Luf.to(Axes::Lbu);
        let lbu: Vec<DVec3> = luf.iter().map(|p| m * *p).collect();
        let (a, oa) = frame_camera(&luf, Axes::Luf).expect("camera");
        let (b, ob) = frame_camera(&lbu, Axes::Lbu).expect("camera");
        assert_eq!((a.width, a.height), (b.width, b.height));
        for (p, q) in luf.iter().zip(&lbu) {
            let pa = a.project(a.world_to_camera(*p - oa));
            let pb = b.project(b.world_to_camera(*q - ob));
            assert!((pa - pb).length() < 1e-9, "{pa} {pb}");
        }
        // Told the wrong axes, it does not.
        let (c, oc) = frame_camera(&lbu, Axes::Luf).expect("camera");
        let moved = luf.iter().zip(&lbu).any(|(p, q)| {
            let pa = a.project(a.world_to_camera(*p - oa));
            (pa - c.project(c.world_to_camera(*q - oc))).length() > 1.0
        });
        assert!(moved);
    }

    #[test]
    fn the_camera_frames_the_points_and_the_picture_shows_the_error() {
        // A unit tetrahedron far from the origin; the ground truth is the same shape.
        let shift = DVec3::new(1.0e4, -2.0e4, 5.0e3);
        let gt_mesh = tetra(1.0, shift);
        let (camera, origin) = frame_camera(gt_mesh.positions(), Axes::Luf).expect("camera");
        assert_eq!(camera.height, THUMBNAIL_HEIGHT);
        assert!((144..=576).contains(&camera.width), "{}", camera.width);
        // Every vertex projects inside the picture.
        for p in gt_mesh.positions() {
            let q = camera.project(camera.world_to_camera(*p - origin));
            assert!(q.x > 0.0 && q.x < f64::from(camera.width), "{q}");
            assert!(q.y > 0.0 && q.y < f64::from(camera.height), "{q}");
        }
        let gt = GtSamples::new(gt_mesh.clone(), 200).expect("area");
        let grey = render(&gt_mesh, &camera, origin, Colouring::Grey).expect("render");
        let same = render(
            &gt_mesh,
            &camera,
            origin,
            Colouring::Distance {
                distance: &|p| gt.distance(p),
                scale: 0.1,
            },
        )
        .expect("render");
        // A bigger tetrahedron about the same corner: its far faces are off the ground truth.
        let far = render(
            &tetra(1.5, shift),
            &camera,
            origin,
            Colouring::Distance {
                distance: &|p| gt.distance(p),
                scale: 0.1,
            },
        )
        .expect("render");
        let count = |p: &Picture, f: &dyn Fn([u8; 3]) -> bool| {
            (0..p.height)
                .flat_map(|r| (0..p.width).map(move |c| (c, r)))
                .filter(|&(c, r)| p.pixel(c, r).is_some_and(f))
                .count()
        };
        let white = |c: [u8; 3]| c == [255; 3];
        let total = (camera.width * camera.height) as usize;
        let covered = total - count(&grey, &white);
        assert!(
            covered > total / 20,
            "the mesh fills the picture: {covered} of {total}"
        );
        assert_eq!(count(&grey, &white), count(&same, &white), "same outline");
        // Grey pixels have equal channels; on the ground truth itself, the colours are the
        // bottom of the map (blue above red and green); far off it, yellow (red and green
        // above blue).
        let is_grey = |c: [u8; 3]| c != [255; 3] && c[0] == c[1] && c[1] == c[2];
        assert_eq!(count(&grey, &is_grey), covered);
        let purple = |c: [u8; 3]| c != [255; 3] && c[2] > c[0] && c[2] > c[1];
        assert!(count(&same, &purple) > covered * 9 / 10);
        let yellow = |c: [u8; 3]| c != [255; 3] && c[0] > c[2] && c[1] > c[2];
        assert!(
            count(&far, &yellow) > covered / 10,
            "far faces in the top colour"
        );
        // No points, or one point: no camera.
        assert!(frame_camera(&[], Axes::Luf).is_none());
        assert!(frame_camera(&[DVec3::ONE; 3], Axes::Luf).is_none());
    }
}
