//! The whole fusion: default parameters as 2DGS, integration, marching cubes, clean-up.

use std::time::Instant;

use glam::{DMat3, DVec3};
use trisplat_geometry::cleanup::{
    keep_largest_clusters, remove_degenerate_triangles, remove_unreferenced_vertices,
};
use trisplat_geometry::{Camera, TriMesh};

use super::error::TsdfError;
use super::frame::Frame;
use super::image::{ColorImage, DepthImage};
use super::params::{DepthLookup, TsdfParams};
use super::volume::{DEFAULT_MAX_BLOCKS, TsdfVolume};

/// Default truncation in voxels (2DGS: `sdf_trunc = 5 * voxel_size`).
pub const DEFAULT_TRUNC_VOXELS: f64 = 5.0;
/// Default voxel as a fraction of the depth truncation (2DGS: `voxel_size = depth_trunc / 1024`).
pub const DEFAULT_VOXELS_PER_DEPTH_TRUNC: f64 = 1024.0;
/// Default depth truncation in scene radii (2DGS: `depth_trunc = 2 * radius`).
pub const DEFAULT_DEPTH_TRUNC_RADII: f64 = 2.0;
/// Default number of clusters kept: those at least as large as the k-th largest.
pub const DEFAULT_KEEP_CLUSTERS: usize = 1;

/// The optical axes are taken not to meet when the determinant of the mean of their
/// orthogonal projectors, `det(mean(I − d dᵀ))` (1 for three orthogonal axes, 0 for parallel
/// ones), is below this.
const MIN_AXIS_SPREAD: f64 = 1e-9;

/// Options of [`fuse`]; unset sizes follow 2DGS's defaults (see each field).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct TsdfOptions {
    /// Voxel size in scene units [default: depth truncation / 1024, as 2DGS].
    #[cfg_attr(feature = "cli", arg(long))]
    pub voxel: Option<f64>,
    /// Truncation distance of the signed distance [default: 5 voxels, as 2DGS].
    #[cfg_attr(feature = "cli", arg(long))]
    pub trunc: Option<f64>,
    /// Ignore depths beyond this [default: 2 x the scene radius, as 2DGS: the smallest
    /// distance from a camera to the point nearest all optical axes; no limit when --voxel is
    /// given and the axes do not meet].
    #[cfg_attr(feature = "cli", arg(long = "depth-trunc"))]
    pub depth_trunc: Option<f64>,
    /// Keep the connected pieces at least as large (in triangles) as the K-th largest (2DGS
    /// post-processing); 0 keeps everything.
    #[cfg_attr(feature = "cli", arg(long = "keep-clusters", default_value_t = DEFAULT_KEEP_CLUSTERS))]
    pub keep_clusters: usize,
    /// Most voxel blocks of 8^3 (memory cap: about 4 KiB per block).
    #[cfg_attr(feature = "cli", arg(long = "max-blocks", default_value_t = DEFAULT_MAX_BLOCKS))]
    pub max_blocks: usize,
    /// How a voxel reads the depth at its projection: bilinear between the four pixel centres
    /// around it where they agree (else the nearest pixel), or nearest (Open3D's rule, which
    /// stops improving once the voxel is below about a third of a pixel's footprint).
    #[cfg_attr(feature = "cli", arg(long = "depth-lookup", value_enum, value_name = "RULE",
        default_value_t = DepthLookup::default()))]
    pub depth_lookup: DepthLookup,
}

impl Default for TsdfOptions {
    fn default() -> Self {
        Self {
            voxel: None,
            trunc: None,
            depth_trunc: None,
            keep_clusters: DEFAULT_KEEP_CLUSTERS,
            max_blocks: DEFAULT_MAX_BLOCKS,
            depth_lookup: DepthLookup::default(),
        }
    }
}

impl TsdfOptions {
    /// The parameters for `cameras`: given values, else 2DGS's defaults.
    ///
    /// # Errors
    /// [`TsdfError::Parameter`] for a given value that is not finite and positive,
    /// [`TsdfError::NoScale`] when a default needs the scene radius and the cameras' axes do
    /// not meet.
    pub fn resolve(&self, cameras: &[Camera]) -> Result<TsdfParams, TsdfError> {
        for (name, value) in [
            ("voxel", self.voxel),
            ("trunc", self.trunc),
            ("depth_trunc", self.depth_trunc),
        ] {
            if let Some(value) = value
                && !(value.is_finite() && value > 0.0)
            {
                return Err(TsdfError::Parameter { name, value });
            }
        }
        let radius = || {
            scene_radius(cameras)
                .map(|(_, r)| r)
                .ok_or(TsdfError::NoScale {
                    cameras: cameras.len(),
                })
        };
        let depth_trunc = match (self.depth_trunc, self.voxel) {
            (Some(d), _) => d,
            (None, None) => DEFAULT_DEPTH_TRUNC_RADII * radius()?,
            (None, Some(_)) => radius().map_or(f64::INFINITY, |r| DEFAULT_DEPTH_TRUNC_RADII * r),
        };
        let voxel = match self.voxel {
            Some(v) => v,
            None if depth_trunc.is_finite() => depth_trunc / DEFAULT_VOXELS_PER_DEPTH_TRUNC,
            None => {
                return Err(TsdfError::NoScale {
                    cameras: cameras.len(),
                });
            }
        };
        let params = TsdfParams {
            voxel,
            trunc: self.trunc.unwrap_or(DEFAULT_TRUNC_VOXELS * voxel),
            depth_trunc,
        };
        params.validate()?;
        Ok(params)
    }
}

/// 2DGS's scene bound: the point nearest (least squares) to every camera's optical axis, and
/// the smallest distance from a camera centre to it. `None` without cameras, when the axes do
/// not meet (one camera, or parallel axes), or when a camera sits on the point.
#[must_use]
pub fn scene_radius(cameras: &[Camera]) -> Option<(DVec3, f64)> {
    if cameras.is_empty() {
        return None;
    }
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    for cam in cameras {
        let d = cam.rotation().z_axis;
        let projector = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += projector;
        b += projector * cam.position();
    }
    let n = cameras.len() as f64;
    let mean = a * (1.0 / n);
    let det = mean.determinant();
    if det.is_nan() || det <= MIN_AXIS_SPREAD {
        return None;
    }
    let center = mean.inverse() * (b / n);
    let radius = cameras
        .iter()
        .map(|c| (c.position() - center).length())
        .fold(f64::INFINITY, f64::min);
    (center.is_finite() && radius.is_finite() && radius > 0.0).then_some((center, radius))
}

/// 2DGS's `post_process_mesh`: keep the edge-connected clusters at least as large as the
/// `keep_clusters`-th largest (0: all), then drop degenerate triangles (repeated index or zero
/// area) and unreferenced vertices.
#[must_use]
pub fn post_process(mesh: &TriMesh, keep_clusters: usize) -> TriMesh {
    let kept = keep_largest_clusters(mesh, keep_clusters);
    remove_unreferenced_vertices(&remove_degenerate_triangles(&kept))
}

/// The result of [`fuse`].
#[derive(Clone, Debug)]
pub struct Fused {
    /// The cleaned mesh.
    pub mesh: TriMesh,
    /// The parameters used.
    pub params: TsdfParams,
    /// Voxel blocks allocated.
    pub blocks: usize,
    /// Triangles before clean-up.
    pub raw_triangles: usize,
    /// Seconds spent preparing the frames (depth and ray tables) and creating the blocks near
    /// the observed depth.
    pub allocate_seconds: f64,
    /// Seconds spent integrating.
    pub integrate_seconds: f64,
    /// Seconds spent in marching cubes.
    pub marching_cubes_seconds: f64,
    /// Seconds spent in marching cubes and clean-up.
    pub extract_seconds: f64,
}

/// Fuses depth maps (and optionally colours) seen by `cameras` into a cleaned mesh: 2DGS's
/// defaults, allocation for every frame, integration, marching cubes, [`post_process`].
/// Depth maps with no valid pixel give an empty mesh (not an error).
///
/// # Errors
/// [`TsdfError::FrameCount`] when the image lists do not match the cameras, and the errors of
/// [`TsdfOptions::resolve`] and [`TsdfVolume::integrate`].
pub fn fuse(
    cameras: &[Camera],
    depths: &[DepthImage],
    colors: Option<&[ColorImage]>,
    options: &TsdfOptions,
) -> Result<Fused, TsdfError> {
    if depths.len() != cameras.len() {
        return Err(TsdfError::FrameCount {
            what: "depth",
            images: depths.len(),
            cameras: cameras.len(),
        });
    }
    if let Some(colors) = colors
        && colors.len() != cameras.len()
    {
        return Err(TsdfError::FrameCount {
            what: "colour",
            images: colors.len(),
            cameras: cameras.len(),
        });
    }
    let params = options.resolve(cameras)?;
    let frames: Vec<Frame<'_>> = cameras
        .iter()
        .zip(depths)
        .enumerate()
        .map(|(i, (camera, depth))| Frame {
            camera,
            depth,
            color: colors.map(|c| &c[i]),
        })
        .collect();
    let mut volume = TsdfVolume::new(params, colors.is_some())?
        .with_max_blocks(options.max_blocks)
        .with_depth_lookup(options.depth_lookup);
    let seconds = volume.integrate_timed(&frames)?;
    Ok(finish(&volume, options, seconds))
}

/// [`fuse`] with the views produced on demand by `load(i)` (view `i`'s depth image, and its
/// colour image when `with_color`), a batch at a time ([`TsdfVolume::integrate_streamed`]):
/// memory does not grow with the number of views, and reading is timed with the fusion. The
/// mesh is [`fuse`]'s on the same images.
///
/// # Errors
/// `load`'s errors; as [`fuse`].
pub fn fuse_streamed<L>(
    cameras: &[Camera],
    load: L,
    with_color: bool,
    options: &TsdfOptions,
) -> Result<Fused, TsdfError>
where
    L: Fn(usize) -> Result<(DepthImage, Option<ColorImage>), TsdfError> + Sync,
{
    let params = options.resolve(cameras)?;
    let mut volume = TsdfVolume::new(params, with_color)?
        .with_max_blocks(options.max_blocks)
        .with_depth_lookup(options.depth_lookup);
    let seconds = volume.integrate_streamed(cameras, |i| {
        let (depth, color) = load(i)?;
        if with_color && color.is_none() {
            return Err(TsdfError::NoColor {
                camera: cameras[i].name.clone(),
            });
        }
        Ok((depth, color.filter(|_| with_color)))
    })?;
    Ok(finish(&volume, options, seconds))
}

/// Marching cubes and clean-up of an integrated volume; `seconds` = (allocation,
/// integration).
fn finish(volume: &TsdfVolume, options: &TsdfOptions, seconds: (f64, f64)) -> Fused {
    let start = Instant::now();
    let raw = volume.extract_mesh();
    let mc_seconds = start.elapsed().as_secs_f64();
    let mesh = post_process(&raw, options.keep_clusters);
    Fused {
        mesh,
        params: volume.params(),
        blocks: volume.grid().block_count(),
        raw_triangles: raw.triangle_count(),
        allocate_seconds: seconds.0,
        integrate_seconds: seconds.1,
        marching_cubes_seconds: mc_seconds,
        extract_seconds: start.elapsed().as_secs_f64(),
    }
}
