//! `trisplat init --cameras CAMS.json --masks DIR -o GAUSSIANS.ply [-n N] [--resolution R]
//! [--threshold T] [--bounds X0,Y0,Z0,X1,Y1,Z1] [--hull MESH] [--seed S]`: Gaussians
//! initialised inside the visual hull carved from silhouettes (`extract::carve`).

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_extract::carve::{CarveOptions, carve, read_masks};
use trisplat_geometry::Aabb;
use trisplat_geometry::glam::{DVec3, Vec3};
use trisplat_geometry::io::{WriteOptions, write_mesh};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};
use trisplat_splat::{GaussianParts, GaussianSet, ParameterSpace, logit};

use super::sample::DEFAULT_MAX_POINTS;
use super::{Context, MAX_IMAGE_PIXELS, read_camera_file, refuse_to_overwrite};

/// Opacity of the new Gaussians (3DGS initialises at 0.1).
pub const INITIAL_OPACITY: f32 = 0.1;

/// Arguments of `trisplat init`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Carve the visual hull of the masks and initialise Gaussians inside it (the mask-carved \
initialisation of static-head avatars). A voxel is kept when its centre projects in front of \
every camera, inside its image and onto a mask pixel; the region is the cube the cameras look \
at (the point nearest every optical axis, out to the nearest camera), carved coarsely first \
and then at --resolution over what that kept, or --bounds.

Masks: for every camera of CAMS.json, DIR holds <img_name>_mask.npy or .png, or \
<img_name>_alpha.npy or .png as `trisplat render --outputs alpha` writes them: a float [H, W] \
array or a PNG (its alpha channel if it has one, else its grey level), inside where the value \
in 0..1 is above --threshold.

The Gaussians are spread uniformly inside the hull: isotropic, of radius half the mean spacing \
(the cube root of hull volume / N), opacity 0.1, grey (SH degree 0), world space; --hull also \
writes the hull's surface (marching cubes of the occupancy).")]
pub struct InitArgs {
    /// Cameras: a 3DGS cameras.json or a NeRF transforms.json (with w and h).
    #[arg(long)]
    pub cameras: PathBuf,
    /// Folder of masks named <img_name>_mask or <img_name>_alpha (.npy or .png).
    #[arg(long)]
    pub masks: PathBuf,
    /// Output Gaussians (.ply, INRIA layout).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Number of Gaussians (at least 1, at most --max-points).
    #[arg(short = 'n', long = "number", default_value_t = 100_000,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub n: u64,
    /// Largest -n accepted, checked before anything is allocated.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_POINTS)]
    pub max_points: u64,
    /// Voxels along the longest side of the carved region (at most 1024).
    #[arg(long, default_value_t = 128,
          value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub resolution: u64,
    /// A mask pixel is inside where its value (0..1) is above this.
    #[arg(long, default_value_t = 0.5)]
    pub threshold: f32,
    /// The region to carve, `xmin,ymin,zmin,xmax,ymax,zmax` (default: found from the cameras).
    #[arg(long, value_delimiter = ',', num_args = 6, allow_hyphen_values = true)]
    pub bounds: Option<Vec<f64>>,
    /// Also write the hull's surface here (.ply, .obj, .gltf, .glb).
    #[arg(long)]
    pub hull: Option<PathBuf>,
    /// Seed of the placement.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Runs `trisplat init`.
///
/// # Errors
/// Unreadable cameras or masks (naming the file), masks that carve everything, bad options, an
/// output that is an input, a failed write.
pub fn run(args: InitArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.cameras, &args.output)?;
    if let Some(hull) = &args.hull {
        refuse_to_overwrite(&args.cameras, hull)?;
        if hull == &args.output {
            bail!("--hull {}: the same file as -o", hull.display());
        }
    }
    if args.n > args.max_points {
        bail!(
            "-n {}: more than --max-points {} (raise --max-points for more Gaussians)",
            args.n,
            args.max_points
        );
    }
    if !(args.threshold.is_finite() && (0.0..1.0).contains(&args.threshold)) {
        bail!("--threshold {}: expected a value in [0, 1)", args.threshold);
    }
    let bounds = match args.bounds.as_deref() {
        None => None,
        Some([x0, y0, z0, x1, y1, z1]) => Some(Aabb {
            min: DVec3::new(*x0, *y0, *z0),
            max: DVec3::new(*x1, *y1, *z1),
        }),
        Some(other) => bail!("--bounds: expected 6 numbers, got {}", other.len()),
    };
    let n = usize::try_from(args.n).context("-n does not fit in memory")?;
    let resolution = usize::try_from(args.resolution).context("--resolution")?;
    let cameras = read_camera_file(&args.cameras, None, MAX_IMAGE_PIXELS)?;
    let spinner = ctx.progress.spinner("carving");
    let masks = read_masks(&args.masks, &cameras, args.threshold)?;
    let hull =
        carve(&cameras, &masks, &CarveOptions { resolution, bounds }).with_context(|| {
            format!(
                "{} with the cameras of {}",
                args.masks.display(),
                args.cameras.display()
            )
        })?;
    spinner.finish_and_clear();
    let volume = hull.volume();
    let spacing = (volume / n as f64).cbrt();
    #[expect(clippy::cast_possible_truncation, reason = "f32 storage of Gaussians")]
    let log_scale = (0.5 * spacing).ln() as f32;
    let means: Vec<Vec3> = hull
        .sample_interior(n, args.seed)
        .into_iter()
        .map(|p| p.as_vec3())
        .collect();
    let set = GaussianSet::try_new(GaussianParts {
        log_scales: vec![Vec3::splat(log_scale); means.len()],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; means.len()],
        opacity_logits: vec![logit(INITIAL_OPACITY); means.len()],
        sh: vec![0.0; 3 * means.len()],
        space: ParameterSpace::World,
        means,
        ..GaussianParts::default()
    })
    .context("building the Gaussians")?;
    write_gaussians(&args.output, &set, &PlyWriteOptions::default())?;
    if let Some(path) = &args.hull {
        write_mesh(path, &hull.mesh(), WriteOptions::default())?;
    }
    if !ctx.quiet && !ctx.json {
        eprintln!(
            "{}: {} Gaussians in a visual hull of {:.4e} (voxel {:.3e}, {} of {} voxels kept)",
            args.output.display(),
            set.len(),
            volume,
            hull.voxel(),
            hull.occupied_count(),
            hull.dims().iter().product::<usize>()
        );
    }
    ctx.emit(
        "init",
        serde_json::json!({
            "output": args.output,
            "gaussians": set.len(),
            "views": cameras.len(),
            "voxel": hull.voxel(),
            "dims": hull.dims(),
            "voxels_kept": hull.occupied_count(),
            "volume": volume,
            "hull": args.hull,
        }),
    )
}
