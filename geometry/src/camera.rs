//! Pinhole cameras with OpenCV axes (x right, y down, z forward), the 3DGS `cameras.json` and
//! NeRF `transforms.json` formats, and camera rigs around an object.

use std::path::Path;

use glam::{DMat3, DVec2, DVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::io::atomic::write_atomically;
use crate::io::error::IoError;

/// Largest deviation from orthonormality accepted in a camera rotation read from a file
/// (max |RᵀR − I| entry). Real files store rotations as decimal text with ~1e-7 rounding.
pub const ROTATION_TOLERANCE: f64 = 1e-4;

/// A pinhole camera, with OpenCV axes (x right, y down, z forward).
///
/// Pixel (row i, column j) is sampled at (j + 0.5, i + 0.5); a camera-space point (x, y, z)
/// projects to u = fx x / z + cx, v = fy y / z + cy (gsplat's convention, docs/conventions.md §2).
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Numeric id (3DGS `id`).
    pub id: i64,
    /// Image name (3DGS `img_name`); outputs are named after it.
    pub name: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length in pixels along x.
    pub fx: f64,
    /// Focal length in pixels along y.
    pub fy: f64,
    /// Principal point x in pixels.
    pub cx: f64,
    /// Principal point y in pixels.
    pub cy: f64,
    /// Camera-to-world rotation: its columns are the camera's x, y, z axes in world space.
    rotation: DMat3,
    /// Camera centre in world space.
    position: DVec3,
}

/// Why a camera is invalid.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum CameraError {
    /// Width or height is zero.
    #[error("image size {width}x{height} is empty")]
    EmptyImage {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// A focal length or principal point is not finite, or a focal length is not positive.
    #[error(
        "intrinsics fx={fx} fy={fy} cx={cx} cy={cy} are invalid (focal lengths must be finite and > 0)"
    )]
    BadIntrinsics {
        /// fx.
        fx: f64,
        /// fy.
        fy: f64,
        /// cx.
        cx: f64,
        /// cy.
        cy: f64,
    },
    /// The position is not finite.
    #[error("camera position is not finite")]
    BadPosition,
    /// The rotation is not a proper rotation (orthonormal with determinant +1).
    #[error("rotation is not orthonormal with determinant +1 (error {error:.2e})")]
    BadRotation {
        /// max |RᵀR − I| entry, or |det − 1|.
        error: f64,
    },
}

impl Camera {
    /// Builds a camera, checking every field. The rotation is re-orthonormalised (it passed
    /// [`ROTATION_TOLERANCE`]) so later maths can rely on it being exact to f64 precision.
    ///
    /// # Errors
    /// [`CameraError`] naming the first invalid field.
    #[expect(
        clippy::too_many_arguments,
        reason = "mirrors the file fields one to one"
    )]
    pub fn try_new(
        id: i64,
        name: impl Into<String>,
        width: u32,
        height: u32,
        (fx, fy): (f64, f64),
        (cx, cy): (f64, f64),
        rotation: DMat3,
        position: DVec3,
    ) -> Result<Self, CameraError> {
        if width == 0 || height == 0 {
            return Err(CameraError::EmptyImage { width, height });
        }
        let finite = [fx, fy, cx, cy].iter().all(|v| v.is_finite());
        if !finite || fx <= 0.0 || fy <= 0.0 {
            return Err(CameraError::BadIntrinsics { fx, fy, cx, cy });
        }
        if !position.is_finite() {
            return Err(CameraError::BadPosition);
        }
        let rotation = checked_rotation(rotation)?;
        Ok(Self {
            id,
            name: name.into(),
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            rotation,
            position,
        })
    }

    /// A camera at `eye` looking at `target`, with the image's "up" (−y) as close to `up` as
    /// possible, a vertical field of view `fov_y_deg` and square pixels, principal point at the
    /// image centre.
    ///
    /// # Errors
    /// [`CameraError`] when `eye == target`, the field of view is not in (0°, 180°) or the size
    /// is empty.
    pub fn look_at(
        name: impl Into<String>,
        eye: DVec3,
        target: DVec3,
        up: DVec3,
        (width, height): (u32, u32),
        fov_y_deg: f64,
    ) -> Result<Self, CameraError> {
        let forward = (target - eye).normalize_or_zero();
        if forward == DVec3::ZERO || !valid_fov(fov_y_deg) {
            return Err(CameraError::BadPosition);
        }
        // Image x (right) = forward × up; when up is parallel to forward pick any other axis.
        let mut right = forward.cross(up).normalize_or_zero();
        if right.length_squared() < 0.5 {
            right = forward.any_orthonormal_vector();
        }
        let down = forward.cross(right);
        let focal = 0.5 * f64::from(height) / (0.5 * fov_y_deg.to_radians()).tan();
        Self::try_new(
            0,
            name,
            width,
            height,
            (focal, focal),
            (0.5 * f64::from(width), 0.5 * f64::from(height)),
            DMat3::from_cols(right, down, forward),
            eye,
        )
    }

    /// Camera-to-world rotation (columns: camera x, y, z axes in world space).
    #[must_use]
    pub fn rotation(&self) -> DMat3 {
        self.rotation
    }

    /// Camera centre in world space.
    #[must_use]
    pub fn position(&self) -> DVec3 {
        self.position
    }

    /// The same camera moved by `offset` (in world space, f64): the view of a scene moved by
    /// the same offset, e.g. to a local origin ([`crate::Aabb::local_origin`]).
    #[must_use]
    pub fn translated(&self, offset: DVec3) -> Self {
        Self {
            position: self.position + offset,
            ..self.clone()
        }
    }

    /// World-to-camera rotation (the transpose of [`Camera::rotation`]).
    #[must_use]
    pub fn world_to_camera_rotation(&self) -> DMat3 {
        self.rotation.transpose()
    }

    /// A world point in camera coordinates.
    #[inline]
    #[must_use]
    pub fn world_to_camera(&self, p: DVec3) -> DVec3 {
        self.rotation.transpose() * (p - self.position)
    }

    /// A camera-space point in world coordinates.
    #[inline]
    #[must_use]
    pub fn camera_to_world(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.position
    }

    /// Pixel coordinates (u, v) of a camera-space point with z > 0.
    #[inline]
    #[must_use]
    pub fn project(&self, p: DVec3) -> DVec2 {
        DVec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }

    /// Camera-space direction (z = 1, not normalised) through pixel coordinates (u, v).
    #[inline]
    #[must_use]
    pub fn unproject(&self, u: f64, v: f64) -> DVec3 {
        DVec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// World-space ray through the centre of pixel (row, col): origin at the camera centre
    /// and a unit direction. Multiply a z-depth by [`Camera::ray_length_factor`] to get the
    /// distance along this ray.
    #[must_use]
    pub fn pixel_ray(&self, row: u32, col: u32) -> (DVec3, DVec3) {
        let d = self.unproject(f64::from(col) + 0.5, f64::from(row) + 0.5);
        (self.position, (self.rotation * d).normalize())
    }

    /// Ratio of the distance along the ray through pixel (row, col) to the z-depth.
    #[must_use]
    pub fn ray_length_factor(&self, row: u32, col: u32) -> f64 {
        self.unproject(f64::from(col) + 0.5, f64::from(row) + 0.5)
            .length()
    }

    /// Horizontal field of view in radians.
    #[must_use]
    pub fn fov_x(&self) -> f64 {
        2.0 * (0.5 * f64::from(self.width) / self.fx).atan()
    }

    /// Vertical field of view in radians.
    #[must_use]
    pub fn fov_y(&self) -> f64 {
        2.0 * (0.5 * f64::from(self.height) / self.fy).atan()
    }
}

/// A field of view strictly between 0° and 180°.
fn valid_fov(fov_deg: f64) -> bool {
    fov_deg > 0.0 && fov_deg < 180.0
}

/// Orthonormalises `r` after checking it is within [`ROTATION_TOLERANCE`] of a rotation.
fn checked_rotation(r: DMat3) -> Result<DMat3, CameraError> {
    if !r.is_finite() {
        return Err(CameraError::BadRotation {
            error: f64::INFINITY,
        });
    }
    let gram = r.transpose() * r;
    let ortho_error = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| (gram.col(j)[i] - f64::from(u8::from(i == j))).abs())
        .fold(0.0, f64::max);
    let det_error = (r.determinant() - 1.0).abs();
    let error = ortho_error.max(det_error);
    if error > ROTATION_TOLERANCE {
        return Err(CameraError::BadRotation { error });
    }
    // Gram-Schmidt keeps the first axis and the handedness.
    let x = r.x_axis.normalize();
    let y = (r.y_axis - x * x.dot(r.y_axis)).normalize();
    Ok(DMat3::from_cols(x, y, x.cross(y)))
}

/// One camera of a 3DGS `cameras.json` (field names as the 3DGS code writes them).
#[derive(Debug, Serialize, Deserialize)]
struct CameraJson {
    id: i64,
    img_name: String,
    width: u32,
    height: u32,
    position: [f64; 3],
    rotation: [[f64; 3]; 3],
    fx: f64,
    fy: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cx: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cy: Option<f64>,
}

/// Reads a 3DGS `cameras.json`: a list of cameras with camera-to-world `rotation` (row-major
/// nested lists), `position`, `fx`, `fy`, optional `cx`, `cy` (default: image centre).
///
/// # Errors
/// [`IoError`] naming the file and the camera index at fault.
pub fn read_cameras_json(path: &Path) -> Result<Vec<Camera>, IoError> {
    let text = std::fs::read_to_string(path).map_err(|e| IoError::os(path, e))?;
    parse_cameras_json(path, &text)
}

/// Parses the text of a 3DGS `cameras.json` held in memory; `path` only names it in errors.
///
/// # Errors
/// As [`read_cameras_json`], but for an unreadable file.
pub fn parse_cameras_json(path: &Path, text: &str) -> Result<Vec<Camera>, IoError> {
    let raw: Vec<CameraJson> = serde_json::from_str(text)
        .map_err(|e| IoError::malformed(path, "cameras", e.to_string()))?;
    raw.into_iter()
        .enumerate()
        .map(|(i, c)| {
            let rotation = DMat3::from_cols_array_2d(&c.rotation).transpose();
            Camera::try_new(
                c.id,
                c.img_name,
                c.width,
                c.height,
                (c.fx, c.fy),
                (
                    c.cx.unwrap_or(0.5 * f64::from(c.width)),
                    c.cy.unwrap_or(0.5 * f64::from(c.height)),
                ),
                rotation,
                DVec3::from_array(c.position),
            )
            .map_err(|e| IoError::malformed(path, format!("camera {i}"), e.to_string()))
        })
        .collect()
}

/// Writes cameras as a 3DGS `cameras.json` (with `cx`, `cy`), atomically.
///
/// # Errors
/// [`IoError::Os`] when the file cannot be written.
pub fn write_cameras_json(path: &Path, cameras: &[Camera]) -> Result<(), IoError> {
    let raw: Vec<CameraJson> = cameras
        .iter()
        .map(|c| CameraJson {
            id: c.id,
            img_name: c.name.clone(),
            width: c.width,
            height: c.height,
            position: c.position.to_array(),
            rotation: c.rotation.transpose().to_cols_array_2d(),
            fx: c.fx,
            fy: c.fy,
            cx: Some(c.cx),
            cy: Some(c.cy),
        })
        .collect();
    write_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, &raw).map_err(|e| IoError::os(path, e.into()))?;
        w.write_all(b"\n").map_err(|e| IoError::os(path, e))
    })
}

/// A NeRF `transforms.json` (Blender/instant-ngp layout).
#[derive(Debug, Deserialize)]
struct TransformsJson {
    camera_angle_x: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    frames: Vec<TransformsFrame>,
}

#[derive(Debug, Deserialize)]
struct TransformsFrame {
    file_path: Option<String>,
    transform_matrix: [[f64; 4]; 4],
    w: Option<f64>,
    h: Option<f64>,
}

/// Reads a NeRF `transforms.json`: `camera_angle_x` (or `fl_x`/`fl_y`), optional `cx`, `cy`,
/// and `frames[].transform_matrix` (camera-to-world, OpenGL axes; the y and z columns are
/// flipped to OpenCV). The image size comes from `w`/`h` (top level or per frame), else from
/// `default_size` (NeRF files often leave it to the images).
///
/// # Errors
/// [`IoError`] naming the file and the frame at fault, also when no image size is known.
pub fn read_transforms_json(
    path: &Path,
    default_size: Option<(u32, u32)>,
) -> Result<Vec<Camera>, IoError> {
    let text = std::fs::read_to_string(path).map_err(|e| IoError::os(path, e))?;
    parse_transforms_json(path, &text, default_size)
}

/// Parses the text of a NeRF `transforms.json` held in memory; `path` only names it in errors.
///
/// # Errors
/// As [`read_transforms_json`], but for an unreadable file.
pub fn parse_transforms_json(
    path: &Path,
    text: &str,
    default_size: Option<(u32, u32)>,
) -> Result<Vec<Camera>, IoError> {
    let raw: TransformsJson = serde_json::from_str(text)
        .map_err(|e| IoError::malformed(path, "transforms", e.to_string()))?;
    raw.frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let element = format!("frame {i}");
            let size = match (f.w.or(raw.w), f.h.or(raw.h)) {
                (Some(w), Some(h)) if w >= 1.0 && h >= 1.0 && w.is_finite() && h.is_finite() => {
                    (w.round() as u32, h.round() as u32)
                }
                _ => default_size.ok_or_else(|| {
                    IoError::malformed(path, &element, "no image size (w, h) in the file")
                })?,
            };
            let (width, height) = (f64::from(size.0), f64::from(size.1));
            let fx = match (raw.fl_x, raw.camera_angle_x) {
                (Some(fl), _) => fl,
                (None, Some(angle)) => 0.5 * width / (0.5 * angle).tan(),
                (None, None) => {
                    return Err(IoError::malformed(
                        path,
                        &element,
                        "neither fl_x nor camera_angle_x is given",
                    ));
                }
            };
            let fy = raw.fl_y.unwrap_or(fx);
            let m = DMat3::from_cols_array_2d(&[
                [
                    f.transform_matrix[0][0],
                    f.transform_matrix[1][0],
                    f.transform_matrix[2][0],
                ],
                [
                    f.transform_matrix[0][1],
                    f.transform_matrix[1][1],
                    f.transform_matrix[2][1],
                ],
                [
                    f.transform_matrix[0][2],
                    f.transform_matrix[1][2],
                    f.transform_matrix[2][2],
                ],
            ]);
            let rotation = DMat3::from_cols(m.x_axis, -m.y_axis, -m.z_axis);
            let position = DVec3::new(
                f.transform_matrix[0][3],
                f.transform_matrix[1][3],
                f.transform_matrix[2][3],
            );
            let name = f.file_path.as_deref().map_or_else(
                || format!("frame_{i:06}"),
                |p| {
                    Path::new(p)
                        .file_stem()
                        .map_or_else(|| format!("frame_{i:06}"), |s| s.to_string_lossy().into())
                },
            );
            Camera::try_new(
                i as i64,
                name,
                size.0,
                size.1,
                (fx, fy),
                (
                    raw.cx.unwrap_or(0.5 * width),
                    raw.cy.unwrap_or(0.5 * height),
                ),
                rotation,
                position,
            )
            .map_err(|e| IoError::malformed(path, &element, e.to_string()))
        })
        .collect()
}

/// Smallest bounding radius [`bounding_sphere`] gives, relative to the coordinates' magnitude
/// (a single point still gets a rig).
const MIN_RADIUS_REL: f64 = f32::EPSILON as f64;

/// Centre and radius of the bounding sphere (about the box centre) of mesh `vertices` and
/// `points` together (either may be empty): the ball a [`sphere_rig`] or [`orbit_rig`] frames.
/// `None` when there is no point or a coordinate is infinite; the radius is at least
/// `f32::EPSILON` times the centre's distance from the origin (at least 1), so a single point
/// still gets a rig.
#[must_use]
pub fn bounding_sphere(vertices: &[DVec3], points: &[Vec3]) -> Option<(DVec3, f64)> {
    let all = || {
        vertices
            .iter()
            .copied()
            .chain(points.iter().map(|p| p.as_dvec3()))
    };
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for p in all() {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let center = (lo + hi) * 0.5;
    let radius = all().map(|p| (p - center).length()).fold(0.0, f64::max);
    let floor = MIN_RADIUS_REL * center.length().max(1.0);
    Some((center, radius.max(floor)))
}

/// Cameras spread evenly over a sphere around `center` (a Fibonacci lattice), all looking at
/// `center`, far enough that a ball of `radius` fits in the vertical field of view with a 10%
/// margin. World up is +y. Names are `view_000`, `view_001`, ...
///
/// # Errors
/// [`CameraError`] when `radius` is not positive and finite, `count` is 0, or the size or field
/// of view is invalid.
pub fn sphere_rig(
    center: DVec3,
    radius: f64,
    count: usize,
    size: (u32, u32),
    fov_y_deg: f64,
) -> Result<Vec<Camera>, CameraError> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    rig(center, radius, count, size, fov_y_deg, |i| {
        let y = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
        let r = (1.0 - y * y).max(0.0).sqrt();
        let phi = golden * i as f64;
        DVec3::new(r * phi.cos(), y, r * phi.sin())
    })
}

/// Cameras on a horizontal circle (world up +y) around `center` at elevation `elevation_deg`,
/// looking at `center`, framing a ball of `radius` as [`sphere_rig`] does.
///
/// # Errors
/// As [`sphere_rig`], and when the elevation is not finite.
pub fn orbit_rig(
    center: DVec3,
    radius: f64,
    count: usize,
    elevation_deg: f64,
    size: (u32, u32),
    fov_y_deg: f64,
) -> Result<Vec<Camera>, CameraError> {
    if !elevation_deg.is_finite() {
        return Err(CameraError::BadPosition);
    }
    let (se, ce) = elevation_deg.to_radians().sin_cos();
    rig(center, radius, count, size, fov_y_deg, |i| {
        let phi = std::f64::consts::TAU * i as f64 / count as f64;
        DVec3::new(ce * phi.cos(), se, ce * phi.sin())
    })
}

/// `count` cameras at `center + direction(i) · distance` looking at `center`, where the distance
/// frames a ball of `radius` in the vertical field of view with a 10% margin.
fn rig(
    center: DVec3,
    radius: f64,
    count: usize,
    size: (u32, u32),
    fov_y_deg: f64,
    direction: impl Fn(usize) -> DVec3,
) -> Result<Vec<Camera>, CameraError> {
    if !(radius.is_finite() && radius > 0.0) || count == 0 || !center.is_finite() {
        return Err(CameraError::BadPosition);
    }
    if !valid_fov(fov_y_deg) {
        return Err(CameraError::BadPosition);
    }
    let distance = 1.1 * radius / (0.5 * fov_y_deg.to_radians()).sin();
    (0..count)
        .map(|i| {
            let mut cam = Camera::look_at(
                format!("view_{i:03}"),
                center + direction(i) * distance,
                center,
                DVec3::Y,
                size,
                fov_y_deg,
            )?;
            cam.id = i as i64;
            Ok(cam)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounding_sphere_of_a_box() {
        let pts = [Vec3::new(-1.0, 0.0, 0.0), Vec3::new(1.0, 2.0, 0.0)];
        let (c, r) = bounding_sphere(&[], &pts).expect("finite");
        assert_eq!(c, DVec3::new(0.0, 1.0, 0.0));
        assert!((r - 2f64.sqrt()).abs() < 1e-12);
        assert!(bounding_sphere(&[], &[]).is_none());
        // One point: a tiny positive radius.
        let (_, r) = bounding_sphere(&[DVec3::ONE], &[]).expect("finite");
        assert!(r > 0.0);
        // Vertices and points together; a non-finite coordinate gives none.
        let (c, r) = bounding_sphere(&[DVec3::new(0.0, 0.0, 4.0)], &pts).expect("finite");
        assert_eq!(c, DVec3::new(0.0, 1.0, 2.0));
        assert_eq!(r, (1.0f64 + 1.0 + 4.0).sqrt());
        assert!(bounding_sphere(&[DVec3::new(f64::INFINITY, 0.0, 0.0)], &pts).is_none());
    }

    fn cam() -> Camera {
        Camera::look_at(
            "c",
            DVec3::new(0.0, 0.0, -2.0),
            DVec3::ZERO,
            DVec3::Y,
            (64, 48),
            60.0,
        )
        .unwrap()
    }

    #[test]
    fn look_at_axes_are_opencv() {
        let c = cam();
        // Looking along +z from z = -2 with +y up: image right is -x? forward × up = z × y = -x.
        let r = c.rotation();
        assert!((r.z_axis - DVec3::Z).length() < 1e-12);
        assert!(
            (r.y_axis - DVec3::NEG_Y).length() < 1e-12,
            "image down is world -y"
        );
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        // The target projects to the principal point.
        let uv = c.project(c.world_to_camera(DVec3::ZERO));
        assert!((uv - DVec2::new(32.0, 24.0)).length() < 1e-12);
        // A point above the target appears above the centre (smaller v).
        assert!(c.project(c.world_to_camera(DVec3::Y * 0.1)).y < 24.0);
        assert!((c.fov_y().to_degrees() - 60.0).abs() < 1e-9);
    }

    #[test]
    fn pixel_ray_hits_projected_pixel() {
        let c = cam();
        let (o, d) = c.pixel_ray(10, 20);
        let p = o + d * 3.0;
        let uv = c.project(c.world_to_camera(p));
        assert!((uv - DVec2::new(20.5, 10.5)).length() < 1e-9);
        let z = c.world_to_camera(p).z;
        assert!((3.0 / z - c.ray_length_factor(10, 20)).abs() < 1e-12);
    }

    #[test]
    fn cameras_json_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cameras.json");
        let rig = sphere_rig(DVec3::new(0.1, 0.2, 0.3), 0.5, 7, (32, 24), 40.0).unwrap();
        write_cameras_json(&path, &rig).unwrap();
        let back = read_cameras_json(&path).unwrap();
        assert_eq!(back.len(), 7);
        for (a, b) in rig.iter().zip(&back) {
            assert_eq!(a.name, b.name);
            assert!(
                (a.rotation() - b.rotation())
                    .abs()
                    .to_cols_array()
                    .iter()
                    .all(|v| *v < 1e-12)
            );
            assert!((a.position() - b.position()).length() < 1e-12);
            // Every camera sees the centre at its principal point.
            let uv = b.project(b.world_to_camera(DVec3::new(0.1, 0.2, 0.3)));
            assert!((uv - DVec2::new(16.0, 12.0)).length() < 1e-9);
        }
    }

    #[test]
    fn bad_cameras_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cameras.json");
        std::fs::write(
            &path,
            r#"[{"id":0,"img_name":"a","width":4,"height":4,"position":[0,0,0],
                "rotation":[[1,0,0],[0,1,0],[0,0,1]],"fx":2,"fy":2},
               {"id":1,"img_name":"b","width":4,"height":4,"position":[0,0,0],
                "rotation":[[2,0,0],[0,1,0],[0,0,1]],"fx":2,"fy":2}]"#,
        )
        .unwrap();
        let err = read_cameras_json(&path).unwrap_err().to_string();
        assert!(
            err.contains("camera 1") && err.contains("rotation"),
            "{err}"
        );
        assert!(matches!(
            Camera::try_new(
                0,
                "x",
                0,
                4,
                (1.0, 1.0),
                (0.0, 0.0),
                DMat3::IDENTITY,
                DVec3::ZERO
            ),
            Err(CameraError::EmptyImage { .. })
        ));
        assert!(matches!(
            Camera::try_new(
                0,
                "x",
                4,
                4,
                (f64::NAN, 1.0),
                (0.0, 0.0),
                DMat3::IDENTITY,
                DVec3::ZERO
            ),
            Err(CameraError::BadIntrinsics { .. })
        ));
    }

    #[test]
    fn transforms_json_flips_opengl_axes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("transforms.json");
        // Identity camera-to-world in OpenGL looks down -z with +y up.
        std::fs::write(
            &path,
            r#"{"camera_angle_x": 1.0, "w": 40, "h": 30,
                "frames": [{"file_path": "./train/r_0.png",
                "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,5],[0,0,0,1]]}]}"#,
        )
        .unwrap();
        let cams = read_transforms_json(&path, None).unwrap();
        assert_eq!(cams[0].name, "r_0");
        let c = &cams[0];
        assert!((c.rotation().z_axis - DVec3::NEG_Z).length() < 1e-12);
        assert!((c.position() - DVec3::new(0.0, 0.0, 5.0)).length() < 1e-12);
        // The origin is in front of the camera.
        assert!(c.world_to_camera(DVec3::ZERO).z > 0.0);
        assert!((c.fov_x() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn orbit_rig_looks_at_center() {
        let rig = orbit_rig(DVec3::ZERO, 1.0, 12, 20.0, (16, 16), 50.0).unwrap();
        for c in &rig {
            let p = c.world_to_camera(DVec3::ZERO);
            assert!(p.x.abs() < 1e-9 && p.y.abs() < 1e-9 && p.z > 0.0);
        }
        // Looking straight down (elevation 90°) still gives a valid camera.
        assert!(orbit_rig(DVec3::ZERO, 1.0, 2, 90.0, (8, 8), 50.0).is_ok());
    }
}
