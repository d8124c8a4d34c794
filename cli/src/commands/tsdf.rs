//! `trisplat tsdf --cameras CAMS.json --depth DIR [--voxel V] [--trunc T] [--depth-trunc D]
//! [--keep-clusters K] -o MESH.ply`: fuse depth maps into a mesh (SPEC §6).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_extract::tsdf::{
    DEFAULT_DEPTH_SCALE, TsdfOptions, fuse, read_color_dir, read_depth_dir,
};
use trisplat_geometry::Camera;
use trisplat_geometry::camera::{read_cameras_json, read_transforms_json};
use trisplat_geometry::io::{WriteOptions, write_mesh};

use super::{Context, refuse_to_overwrite};

/// Arguments of `trisplat tsdf`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Fuse depth maps into a triangle mesh: TSDF integration on sparse 8^3 voxel blocks with Open3D's \
legacy per-voxel rules (voxel centres at (index + 1/2) * voxel, nearest pixel, sdf = depth \
difference times the ray-length factor, integrated only when sdf > -trunc, tsdf = min(1, \
sdf / trunc), unit weights), marching cubes (welded vertices, faces toward free space), then \
2DGS's clean-up: keep the connected pieces at least as large as the K-th largest, drop \
degenerate triangles and unused vertices.

Inputs: for every camera of CAMS.json (3DGS layout, or a NeRF transforms.json), DIR holds \
<img_name>_depth.npy (float32 z-depth [H, W], 0 = no surface; NaN, infinite and negative values \
count as no surface) or <img_name>_depth.png (16-bit, millimetres: divided by --depth-scale). \
With --colors, <img_name>_rgb.npy ([H, W, 3] in 0..1) or <img_name>_rgb.png give vertex colours.

Defaults as 2DGS: depth truncation = 2 x the scene radius (the smallest distance from a camera \
to the point nearest every optical axis), voxel = depth truncation / 1024, trunc = 5 voxels. \
Depth maps without any valid pixel give an empty mesh.")]
pub struct TsdfArgs {
    /// Cameras: a 3DGS cameras.json or a NeRF transforms.json (with w and h).
    #[arg(long)]
    pub cameras: PathBuf,
    /// Folder of depth maps named <img_name>_depth.npy or <img_name>_depth.png.
    #[arg(long)]
    pub depth: PathBuf,
    /// Output mesh (.ply, .obj, .gltf, .glb).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Divisor of 16-bit PNG depth values (1000: millimetres to metres).
    #[arg(long = "depth-scale", default_value_t = DEFAULT_DEPTH_SCALE)]
    pub depth_scale: f64,
    /// Also read <img_name>_rgb.npy/.png from the depth folder and colour the vertices.
    #[arg(long)]
    pub colors: bool,
    /// Voxel size, truncations, clusters kept.
    #[command(flatten)]
    pub options: TsdfOptions,
}

/// Reads a 3DGS cameras.json (a JSON list) or a NeRF transforms.json (an object).
fn read_cameras(path: &Path) -> anyhow::Result<Vec<Camera>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let cameras = if text.trim_start().starts_with('{') {
        read_transforms_json(path, None)?
    } else {
        read_cameras_json(path)?
    };
    if cameras.is_empty() {
        bail!("{}: no cameras", path.display());
    }
    Ok(cameras)
}

/// Runs `trisplat tsdf`.
///
/// # Errors
/// Unreadable cameras, a missing or mis-sized depth map (named), invalid sizes, an output that
/// is an input, a failed write.
pub fn run(args: TsdfArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.cameras, &args.output)?;
    let cameras = read_cameras(&args.cameras)?;
    let spinner = ctx.progress.spinner("reading depth maps");
    let depths = read_depth_dir(&args.depth, &cameras, args.depth_scale)?;
    let colors = if args.colors {
        Some(read_color_dir(&args.depth, &cameras)?)
    } else {
        None
    };
    spinner.set_message("fusing");
    let fused = fuse(&cameras, &depths, colors.as_deref(), &args.options)
        .with_context(|| format!("{}: fusion failed", args.depth.display()))?;
    spinner.finish_and_clear();
    write_mesh(&args.output, &fused.mesh, WriteOptions::default())?;
    Ok(())
}
