//! Visual hulls carved from silhouettes (space carving), and Gaussians initialised inside
//! them: the mask-carved initialisation of static-head Gaussian avatars (issue #14, item 5).
//!
//! A voxel (its centre) is in the visual hull when it projects in front of every camera,
//! inside its image and onto a mask pixel: the largest shape whose silhouettes are inside the
//! masks (Laurentini's visual hull, sampled at the voxel centres). Every point of the object
//! whose silhouettes the masks are lies in it, so carving never removes the object's interior
//! (the tests check this on analytic silhouettes); with few views it keeps more than the
//! object (concavities and the regions no view separates).
//!
//! The carving runs twice: over the cube the cameras look at (centre and radius of
//! [`crate::tsdf::scene_radius`]) at a coarse resolution, then over the bounding box of what
//! that kept, padded by a coarse voxel, at the asked resolution; `bounds` skips the first pass.
//!
//! Masks are read per camera as `<dir>/<img_name>_mask.{npy,png}` or, as `trisplat render`
//! writes them, `<img_name>_alpha.{npy,png}`: a float `[H, W]` (or `[H, W, 1]`) array or an
//! 8/16-bit PNG (its alpha channel when it has one, else its grey level), inside where the
//! value in 0..1 is above `threshold`.

use std::path::{Path, PathBuf};

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::io::read_npy;
use trisplat_geometry::rng::Rng;
use trisplat_geometry::{Aabb, Camera, TriMesh};

use crate::image_file::{decode_image, is_plane, is_png, per_camera};
use crate::marching_cubes::marching_cubes_dense;
use crate::tsdf::scene_radius;

/// Coarse resolution of the first pass (voxels along the longest side of the cameras' cube).
pub const COARSE_RESOLUTION: usize = 48;

/// Largest number of voxels of one carving pass (a resolution of 1,024 on a cube).
pub const MAX_VOXELS: usize = 1 << 30;

/// Errors of reading masks and carving.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CarveError {
    /// No mask file for a camera.
    #[error(
        "{}: no mask for camera '{camera}' (looked for <name>_mask and <name>_alpha, .npy or .png)",
        dir.display()
    )]
    MissingMask {
        /// The masks folder.
        dir: PathBuf,
        /// The camera's image name.
        camera: String,
    },
    /// A mask file cannot be read or decoded, or has the wrong shape.
    #[error("{}: {message}", path.display())]
    MaskFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A parameter is out of range.
    #[error("{name} = {value}: {expected}")]
    Parameter {
        /// Option name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What is accepted.
        expected: &'static str,
    },
    /// The cameras do not look at a common point and no bounds were given.
    #[error(
        "the optical axes of the {cameras} camera(s) do not meet: give the region to carve \
         (--bounds)"
    )]
    NoBounds {
        /// Number of cameras.
        cameras: usize,
    },
    /// Nothing is left.
    #[error(
        "the masks carve away everything: no voxel projects onto a mask pixel in all {views} \
         views (check that the masks belong to these cameras and that the threshold is right)"
    )]
    Empty {
        /// Number of views.
        views: usize,
    },
    /// The masks and cameras do not pair up.
    #[error("{masks} masks for {cameras} cameras")]
    Count {
        /// Masks given.
        masks: usize,
        /// Cameras given.
        cameras: usize,
    },
}

/// A binary silhouette: `inside[row * width + col]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    width: u32,
    height: u32,
    inside: Vec<bool>,
}

impl Mask {
    /// A mask of `width × height` pixels, row-major; `None` when the sizes disagree.
    #[must_use]
    pub fn new(width: u32, height: u32, inside: Vec<bool>) -> Option<Self> {
        (inside.len() == width as usize * height as usize).then_some(Self {
            width,
            height,
            inside,
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

    /// Number of pixels inside.
    #[must_use]
    pub fn count(&self) -> usize {
        self.inside.iter().filter(|&&b| b).count()
    }

    /// Whether the pixel at pixel coordinates `(u, v)` (pixel `(row, col)` covers
    /// `[col, col + 1) × [row, row + 1)`) is inside; outside the image is not.
    #[must_use]
    pub fn contains(&self, u: f64, v: f64) -> bool {
        if !(u >= 0.0 && v >= 0.0) {
            return false;
        }
        // Truncation is the floor for non-negative values; NaN was refused above.
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "u, v >= 0"
        )]
        let (col, row) = (u as usize, v as usize);
        col < self.width as usize
            && row < self.height as usize
            && self.inside[row * self.width as usize + col]
    }
}

/// The mask file of `camera` in `dir`: the first of `<name>_mask.npy`, `<name>_mask.png`,
/// `<name>_alpha.npy`, `<name>_alpha.png` that exists.
///
/// # Errors
/// [`CarveError::MissingMask`].
pub fn find_mask(dir: &Path, camera: &Camera) -> Result<PathBuf, CarveError> {
    for suffix in ["mask", "alpha"] {
        for ext in ["npy", "png"] {
            let path = dir.join(format!("{}_{suffix}.{ext}", camera.name));
            if path.is_file() {
                return Ok(path);
            }
        }
    }
    Err(CarveError::MissingMask {
        dir: dir.to_path_buf(),
        camera: camera.name.clone(),
    })
}

/// Reads the mask of `camera` from `path` (see the module documentation): inside where the
/// value in 0..1 is above `threshold`.
///
/// # Errors
/// [`CarveError::MaskFile`] naming the file when it cannot be read or decoded, when its size
/// is not the camera's, or when an `.npy` is not a float `[H, W]` / `[H, W, 1]` array.
pub fn read_mask(path: &Path, camera: &Camera, threshold: f32) -> Result<Mask, CarveError> {
    let bad = |message: String| CarveError::MaskFile {
        path: path.to_path_buf(),
        message,
    };
    let (w, h) = (camera.width, camera.height);
    let size_error = |found: String| {
        bad(format!(
            "mask is {found}, but camera '{}' is {w}x{h}",
            camera.name
        ))
    };
    let values: Vec<f32> = if is_png(path) {
        let img = decode_image(path).map_err(bad)?;
        if (img.width(), img.height()) != (w, h) {
            return Err(size_error(format!("{}x{}", img.width(), img.height())));
        }
        if img.color().has_alpha() {
            img.into_rgba32f()
                .into_raw()
                .chunks_exact(4)
                .map(|p| p[3])
                .collect()
        } else {
            // Grey (or the first channel of RGB): luma as 0..1.
            img.into_rgb32f()
                .into_raw()
                .chunks_exact(3)
                .map(|p| (p[0] + p[1] + p[2]) / 3.0)
                .collect()
        }
    } else {
        let array = read_npy(path).map_err(|e| bad(e.to_string()))?;
        if !is_plane(&array.shape, w as usize, h as usize) {
            return Err(size_error(format!("shape {:?}", array.shape)));
        }
        array.data
    };
    if let Some(i) = values.iter().position(|v| v.is_nan()) {
        return Err(bad(format!(
            "pixel {} (row {}, column {}) is NaN",
            i,
            i / w as usize,
            i % w as usize
        )));
    }
    let inside = values.iter().map(|&v| v > threshold).collect();
    Mask::new(w, h, inside).ok_or_else(|| bad("mask size".to_owned()))
}

/// Reads the mask of every camera from `dir` ([`find_mask`], [`read_mask`]), in parallel; the
/// error reported is the first camera's (in order).
///
/// # Errors
/// As [`find_mask`] and [`read_mask`].
pub fn read_masks(dir: &Path, cameras: &[Camera], threshold: f32) -> Result<Vec<Mask>, CarveError> {
    per_camera(cameras, |c| read_mask(&find_mask(dir, c)?, c, threshold))
}

/// Options of [`carve`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarveOptions {
    /// Voxels along the longest side of the carved region.
    pub resolution: usize,
    /// The region to carve; `None`: found from the cameras (two passes, see the module
    /// documentation).
    pub bounds: Option<Aabb>,
}

impl Default for CarveOptions {
    fn default() -> Self {
        Self {
            resolution: 128,
            bounds: None,
        }
    }
}

/// A carved visual hull: occupancy of a regular grid of voxels.
#[derive(Clone, Debug, PartialEq)]
pub struct VisualHull {
    /// Centre of voxel `(0, 0, 0)`.
    origin: DVec3,
    /// Voxel edge length.
    voxel: f64,
    /// Voxels along x, y, z.
    dims: [usize; 3],
    /// x-fastest occupancy.
    occupied: Vec<bool>,
}

impl VisualHull {
    /// Voxel edge length.
    #[must_use]
    pub fn voxel(&self) -> f64 {
        self.voxel
    }

    /// Voxels along x, y and z.
    #[must_use]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Number of voxels kept.
    #[must_use]
    pub fn occupied_count(&self) -> usize {
        self.occupied.iter().filter(|&&b| b).count()
    }

    /// Volume kept (voxels kept × voxel volume).
    #[must_use]
    pub fn volume(&self) -> f64 {
        self.occupied_count() as f64 * self.voxel.powi(3)
    }

    /// Centre of voxel `(i, j, k)`.
    #[must_use]
    pub fn center(&self, i: usize, j: usize, k: usize) -> DVec3 {
        self.origin + DVec3::new(i as f64, j as f64, k as f64) * self.voxel
    }

    /// Whether the voxel containing `p` is kept (outside the grid: no).
    #[must_use]
    pub fn contains(&self, p: DVec3) -> bool {
        let g = ((p - self.origin) / self.voxel + 0.5).floor();
        if g.is_nan() || g.min_element() < 0.0 {
            return false;
        }
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "g >= 0"
        )]
        let [i, j, k] = g.to_array().map(|x| x as usize);
        let [nx, ny, nz] = self.dims;
        i < nx && j < ny && k < nz && self.occupied[(k * ny + j) * nx + i]
    }

    /// Bounds of the kept voxels (their cubes), or `None` when none is kept.
    #[must_use]
    pub fn kept_bounds(&self) -> Option<Aabb> {
        let [nx, ny, _] = self.dims;
        let half = DVec3::splat(0.5 * self.voxel);
        let mut bounds: Option<Aabb> = None;
        for index in (0..self.occupied.len()).filter(|&i| self.occupied[i]) {
            let c = self.center(index % nx, (index / nx) % ny, index / (nx * ny));
            bounds = Some(match bounds {
                None => Aabb {
                    min: c - half,
                    max: c + half,
                },
                Some(b) => Aabb {
                    min: b.min.min(c - half),
                    max: b.max.max(c + half),
                },
            });
        }
        bounds
    }

    /// `n` points uniformly distributed inside the kept voxels (a voxel drawn uniformly, then a
    /// point uniformly in its cube), from `seed`.
    #[must_use]
    pub fn sample_interior(&self, n: usize, seed: u64) -> Vec<DVec3> {
        let kept: Vec<usize> = (0..self.occupied.len())
            .filter(|&i| self.occupied[i])
            .collect();
        if kept.is_empty() {
            return Vec::new();
        }
        let [nx, ny, _] = self.dims;
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| {
                #[expect(
                    clippy::cast_possible_truncation,
                    clippy::cast_sign_loss,
                    reason = "uniform in [0, 1), scaled below the count"
                )]
                let pick = ((rng.uniform_f64() * kept.len() as f64) as usize).min(kept.len() - 1);
                let index = kept[pick];
                let c = self.center(index % nx, (index / nx) % ny, index / (nx * ny));
                let jitter = DVec3::new(rng.uniform_f64(), rng.uniform_f64(), rng.uniform_f64());
                c + (jitter - 0.5) * self.voxel
            })
            .collect()
    }

    /// The hull's surface: marching cubes of the occupancy (the iso-level halfway between a
    /// kept and a carved voxel centre), closed at the grid's border.
    #[must_use]
    pub fn mesh(&self) -> TriMesh {
        let [nx, ny, nz] = self.dims;
        // One carved layer around the grid so the surface closes.
        let padded = [nx + 2, ny + 2, nz + 2];
        let mut values = vec![0.5f32; padded[0] * padded[1] * padded[2]];
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    if self.occupied[(k * ny + j) * nx + i] {
                        values[((k + 1) * padded[1] + j + 1) * padded[0] + i + 1] = -0.5;
                    }
                }
            }
        }
        marching_cubes_dense(&values, padded, self.origin - self.voxel, self.voxel)
            .unwrap_or_else(|| TriMesh::new_unchecked(Vec::<DVec3>::new(), Vec::new()))
    }
}

/// Carves the visual hull of `masks` (one per camera, in order) seen by `cameras`.
///
/// # Errors
/// [`CarveError::Count`], [`CarveError::Parameter`] for a resolution of 0 or over
/// [`MAX_VOXELS`] voxels, a mask whose size is not its camera's, or empty or non-finite bounds;
/// [`CarveError::NoBounds`] without bounds when the cameras' axes do not meet;
/// [`CarveError::Empty`] when nothing is kept.
pub fn carve(
    cameras: &[Camera],
    masks: &[Mask],
    options: &CarveOptions,
) -> Result<VisualHull, CarveError> {
    if masks.len() != cameras.len() || cameras.is_empty() {
        return Err(CarveError::Count {
            masks: masks.len(),
            cameras: cameras.len(),
        });
    }
    if let Some((c, m)) = cameras
        .iter()
        .zip(masks)
        .find(|(c, m)| (c.width, c.height) != (m.width, m.height))
    {
        return Err(CarveError::MaskFile {
            path: PathBuf::from(&c.name),
            message: format!(
                "mask is {}x{}, but the camera is {}x{}",
                m.width, m.height, c.width, c.height
            ),
        });
    }
    if options.resolution == 0 {
        return Err(CarveError::Parameter {
            name: "resolution",
            value: 0.0,
            expected: "at least 1 voxel along the longest side",
        });
    }
    let bounds = match options.bounds {
        Some(b) => {
            if !(b.min.is_finite() && b.max.is_finite() && (b.max - b.min).min_element() > 0.0) {
                return Err(CarveError::Parameter {
                    name: "bounds",
                    value: b.diagonal(),
                    expected: "a box with finite corners and positive size on every axis",
                });
            }
            b
        }
        None => {
            let (centre, radius) = scene_radius(cameras).ok_or(CarveError::NoBounds {
                cameras: cameras.len(),
            })?;
            let cube = Aabb {
                min: centre - radius,
                max: centre + radius,
            };
            let coarse = carve_box(cameras, masks, cube, COARSE_RESOLUTION)?;
            let kept = coarse.kept_bounds().ok_or(CarveError::Empty {
                views: cameras.len(),
            })?;
            // One coarse voxel of margin: the coarse centres may miss thin parts.
            let pad = DVec3::splat(coarse.voxel);
            Aabb {
                min: (kept.min - pad).max(cube.min),
                max: (kept.max + pad).min(cube.max),
            }
        }
    };
    let hull = carve_box(cameras, masks, bounds, options.resolution)?;
    if hull.occupied_count() == 0 {
        return Err(CarveError::Empty {
            views: cameras.len(),
        });
    }
    Ok(hull)
}

/// One carving pass over `bounds` with `resolution` voxels along its longest side.
fn carve_box(
    cameras: &[Camera],
    masks: &[Mask],
    bounds: Aabb,
    resolution: usize,
) -> Result<VisualHull, CarveError> {
    let size = bounds.max - bounds.min;
    let voxel = size.max_element() / resolution as f64;
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "positive and at most the resolution"
    )]
    let dims = size
        .to_array()
        .map(|s| ((s / voxel).round() as usize).clamp(1, resolution));
    let total = dims[0]
        .checked_mul(dims[1])
        .and_then(|v| v.checked_mul(dims[2]))
        .filter(|&v| v <= MAX_VOXELS)
        .ok_or(CarveError::Parameter {
            name: "resolution",
            value: resolution as f64,
            expected: "at most 2^30 voxels in the carved region",
        })?;
    let origin = bounds.min + DVec3::splat(0.5 * voxel);
    let views: Vec<(&Camera, &Mask)> = cameras.iter().zip(masks).collect();
    let [nx, ny, _] = dims;
    let mut occupied = vec![false; total];
    occupied
        .par_chunks_mut(nx)
        .enumerate()
        .for_each(|(row, out)| {
            let (j, k) = (row % ny, row / ny);
            for (i, o) in out.iter_mut().enumerate() {
                let p = origin + DVec3::new(i as f64, j as f64, k as f64) * voxel;
                *o = views.iter().all(|(camera, mask)| {
                    let c = camera.world_to_camera(p);
                    // Behind the camera (or NaN): not seen inside the mask.
                    if c.z.is_nan() || c.z <= 0.0 {
                        return false;
                    }
                    let uv = camera.project(c);
                    mask.contains(uv.x, uv.y)
                });
            }
        });
    Ok(VisualHull {
        origin,
        voxel,
        dims,
        occupied,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::sphere_rig;

    /// Analytic silhouettes of a ball (centre `c`, radius `r`): a pixel is inside when the
    /// ray through its centre meets the ball.
    fn ball_masks(cameras: &[Camera], c: DVec3, r: f64) -> Vec<Mask> {
        cameras
            .iter()
            .map(|cam| {
                let mut inside = Vec::new();
                for row in 0..cam.height {
                    for col in 0..cam.width {
                        let (o, d) = cam.pixel_ray(row, col);
                        let t = (c - o).dot(d);
                        inside.push((o + d * t - c).length() <= r);
                    }
                }
                Mask::new(cam.width, cam.height, inside).expect("size")
            })
            .collect()
    }

    fn rig(views: usize) -> Vec<Camera> {
        sphere_rig(DVec3::new(0.1, -0.2, 0.3), 0.5, views, (96, 96), 40.0).expect("rig")
    }

    /// Carving never removes the object: every voxel centre inside the ball (less one pixel's
    /// footprint) is kept; with 24 views the hull is close to the ball.
    #[test]
    fn a_ball_is_kept_whole_and_the_hull_comes_close() {
        let (c, r) = (DVec3::new(0.1, -0.2, 0.3), 0.3);
        let cameras = rig(24);
        let masks = ball_masks(&cameras, c, r);
        let hull = carve(&cameras, &masks, &CarveOptions::default()).expect("carve");
        let [nx, ny, nz] = hull.dims();
        let pixel = 2.0 * (cameras[0].position() - c).length() / cameras[0].fx;
        let mut missed = 0;
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let p = hull.center(i, j, k);
                    if (p - c).length() < r - 2.0 * pixel && !hull.contains(p) {
                        missed += 1;
                    }
                }
            }
        }
        assert_eq!(missed, 0, "voxels of the ball carved away");
        let ball = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        let ratio = hull.volume() / ball;
        // Masks sampled at pixel centres lose up to half a pixel at the rim, so the hull may
        // fall a little short of the ball (0.986 measured) as well as exceed it.
        assert!((0.95..1.25).contains(&ratio), "hull / ball volume {ratio}");
        // The two passes found a region about the ball's size.
        assert!(hull.voxel() < 2.5 * r / 100.0, "voxel {}", hull.voxel());
        // Gaussians inside: every sample is in the hull, within the ball's reach.
        for p in hull.sample_interior(2000, 3) {
            assert!(hull.contains(p), "{p}");
            assert!((p - c).length() < 1.2 * r, "{p}");
        }
        let mesh = hull.mesh();
        assert!(mesh.triangle_count() > 1000);
        let stats = trisplat_geometry::mesh_stats::MeshStats::of(&mesh);
        assert!(stats.watertight, "{stats:?}");
    }

    /// Fewer views keep more (the hull only shrinks as views are added).
    #[test]
    fn more_views_carve_more() {
        let (c, r) = (DVec3::new(0.1, -0.2, 0.3), 0.3);
        let bounds = Aabb {
            min: c - 0.45,
            max: c + 0.45,
        };
        let options = CarveOptions {
            resolution: 48,
            bounds: Some(bounds),
        };
        let volumes: Vec<f64> = [3, 8, 24]
            .into_iter()
            .map(|n| {
                let cameras = rig(n);
                let masks = ball_masks(&cameras, c, r);
                carve(&cameras, &masks, &options).expect("carve").volume()
            })
            .collect();
        assert!(
            volumes[0] >= volumes[1] && volumes[1] >= volumes[2],
            "{volumes:?}"
        );
    }

    #[test]
    fn bad_inputs_are_refused_clearly() {
        let cameras = rig(4);
        let masks = ball_masks(&cameras, DVec3::new(0.1, -0.2, 0.3), 0.3);
        let err = carve(&cameras, &masks[..3], &CarveOptions::default()).expect_err("count");
        assert!(err.to_string().contains("3 masks for 4 cameras"), "{err}");
        let empty: Vec<Mask> = cameras
            .iter()
            .map(|c| {
                Mask::new(
                    c.width,
                    c.height,
                    vec![false; (c.width * c.height) as usize],
                )
            })
            .collect::<Option<_>>()
            .expect("size");
        let err = carve(&cameras, &empty, &CarveOptions::default()).expect_err("empty");
        assert!(err.to_string().contains("carve away everything"), "{err}");
        let options = CarveOptions {
            resolution: 0,
            ..CarveOptions::default()
        };
        assert!(carve(&cameras, &masks, &options).is_err());
        let options = CarveOptions {
            resolution: 2000,
            bounds: Some(Aabb {
                min: DVec3::ZERO,
                max: DVec3::ONE,
            }),
        };
        let err = carve(&cameras, &masks, &options).expect_err("too many voxels");
        assert!(err.to_string().contains("2^30"), "{err}");
        let small = Mask::new(2, 2, vec![true; 4]).expect("size");
        let mut wrong = masks.clone();
        wrong[1] = small;
        let err = carve(&cameras, &wrong, &CarveOptions::default()).expect_err("size");
        assert!(err.to_string().contains("2x2"), "{err}");
    }
}
