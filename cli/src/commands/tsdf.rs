//! `trisplat tsdf --cameras CAMS.json --depth DIR [--voxel V] [--trunc T] [--depth-trunc D]
//! [--keep-clusters K] -o MESH.ply`: fuse depth maps into a mesh (docs/conventions.md §6).

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use trisplat_extract::tsdf::{
    DEFAULT_DEPTH_SCALE, DepthImage, TsdfOptions, find_image, fuse, fuse_streamed, read_color,
    read_depth,
};
use trisplat_geometry::Camera;
use trisplat_geometry::io::{WriteOptions, write_mesh};
use trisplat_pipeline::config::{DepthKind, RENDERED_ALPHA_MIN, SplatDepthRule};
use trisplat_pipeline::methods::{DepthRules, rendered_depth};
use trisplat_splat::ply::read_gaussians;

use super::{Context, MAX_IMAGE_PIXELS, parse_max_pixels, read_camera_file, refuse_to_overwrite};

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
Depth maps without any valid pixel give an empty mesh.

With --gaussians G.ply instead of --depth, the depth maps are rendered from the (world-space) \
Gaussians first: 3DGS splatting with gsplat's rules, median depth (where the accumulated alpha \
reaches 1/2; --depth-kind expected: the alpha-weighted mean depth), set to 0 where the rendered \
alpha is below --alpha-cut (0.5).")]
pub struct TsdfArgs {
    /// Cameras: a 3DGS cameras.json or a NeRF transforms.json (with w and h).
    #[arg(long)]
    pub cameras: PathBuf,
    /// Folder of depth maps named <img_name>_depth.npy or <img_name>_depth.png.
    #[arg(
        long,
        required_unless_present = "gaussians",
        conflicts_with = "gaussians"
    )]
    pub depth: Option<PathBuf>,
    /// World-space Gaussians (3DGS PLY) to render the depth maps from, instead of --depth.
    #[arg(long)]
    pub gaussians: Option<PathBuf>,
    /// Output mesh (.ply, .obj, .gltf, .glb).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Divisor of 16-bit PNG depth values (1000: millimetres to metres).
    #[arg(long = "depth-scale", default_value_t = DEFAULT_DEPTH_SCALE)]
    pub depth_scale: f64,
    /// Also read <img_name>_rgb.npy/.png from the depth folder and colour the vertices.
    #[arg(long)]
    pub colors: bool,
    /// Most pixels of one camera's image (a limit checked before any image exists; at most
    /// 16384 x 16384).
    #[arg(long, value_name = "N", default_value_t = MAX_IMAGE_PIXELS, value_parser = parse_max_pixels)]
    pub max_pixels: u64,
    /// With --gaussians: which rendered depth to fuse (median: where the accumulated alpha
    /// reaches 1/2; expected: the alpha-weighted mean depth).
    #[arg(long, value_enum, default_value_t = DepthKind::default(), requires = "gaussians")]
    pub depth_kind: DepthKind,
    /// With --gaussians: each Gaussian's depth over its footprint (ray: the point of highest
    /// density on the pixel's ray, RaDe-GS/GOF, so a flat Gaussian gives its own plane; mean:
    /// its centre's depth everywhere, as 3DGS).
    #[arg(long, value_enum, default_value_t = SplatDepthRule::default(), requires = "gaussians")]
    pub splat_depth: SplatDepthRule,
    /// With --gaussians: pixels whose rendered alpha is below A carry no depth (0 < A <= 1).
    #[arg(long, value_name = "A", default_value_t = RENDERED_ALPHA_MIN, requires = "gaussians",
        value_parser = parse_alpha_cut)]
    pub alpha_cut: f32,
    /// Voxel size, truncations, clusters kept.
    #[command(flatten)]
    pub options: TsdfOptions,
}

/// Runs `trisplat tsdf`.
///
/// # Errors
/// Unreadable cameras, a missing or mis-sized depth map (named), invalid sizes, an output that
/// is an input, a failed write.
pub fn run(args: TsdfArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.cameras, &args.output)?;
    let cameras = read_camera_file(&args.cameras, None, args.max_pixels)?;
    let spinner = ctx.progress.spinner("fusing");
    let fused = match (&args.depth, &args.gaussians) {
        (_, Some(gaussians)) => {
            refuse_to_overwrite(gaussians, &args.output)?;
            spinner.set_message("rendering depth maps");
            let rules = DepthRules {
                kind: args.depth_kind,
                splat: args.splat_depth,
                alpha_cut: args.alpha_cut,
                ..DepthRules::default()
            };
            let depths = render_depths(gaussians, &cameras, &rules)?;
            spinner.set_message("fusing");
            fuse(&cameras, &depths, None, &args.options).with_context(|| {
                format!(
                    "{} seen by the cameras of {}: fusion failed",
                    gaussians.display(),
                    args.cameras.display()
                )
            })?
        }
        (Some(dir), None) => {
            // Read a batch of views at a time, twice (allocation, integration): memory does
            // not grow with the number of views.
            let load = |i: usize| {
                let camera = &cameras[i];
                let depth =
                    read_depth(&find_image(dir, camera, "depth")?, camera, args.depth_scale)?;
                let color = if args.colors {
                    Some(read_color(&find_image(dir, camera, "rgb")?, camera)?)
                } else {
                    None
                };
                Ok((depth, color))
            };
            fuse_streamed(&cameras, load, args.colors, &args.options).with_context(|| {
                format!(
                    "{} with the cameras of {}: fusion failed",
                    dir.display(),
                    args.cameras.display()
                )
            })?
        }
        (None, None) => anyhow::bail!("give --depth DIR or --gaussians G.ply"),
    };
    spinner.finish_and_clear();
    write_mesh(&args.output, &fused.mesh, WriteOptions::default())?;
    ctx.emit(
        "tsdf",
        serde_json::json!({
            "output": args.output,
            "views": cameras.len(),
            "vertices": fused.mesh.vertex_count(),
            "triangles": fused.mesh.triangle_count(),
        }),
    )
}

/// `--alpha-cut`: a rendered alpha in (0, 1].
fn parse_alpha_cut(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(a) if a > 0.0 && a <= 1.0 => Ok(a),
        _ => Err(format!("expected a rendered alpha in (0, 1], got '{s}'")),
    }
}

/// Depth maps of world-space Gaussians by `rules` (the pipeline's tsdf method renders the same
/// maps).
fn render_depths(
    path: &Path,
    cameras: &[Camera],
    rules: &DepthRules,
) -> anyhow::Result<Vec<DepthImage>> {
    let set = read_gaussians(path)?;
    cameras
        .iter()
        .map(|camera| {
            rendered_depth(&set, camera, rules)
                .with_context(|| format!("{}: camera '{}'", path.display(), camera.name))
        })
        .collect()
}
