//! `trisplat bind MESH -o GAUSSIANS.ply [--per-triangle N] [--convention gaussianavatars|surfhead]
//! [--gaussians WORLD.ply]`.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use trisplat_pipeline::avatar::{AvatarFolder, Silhouettes, bind_lam, silhouette_iou};
use trisplat_pipeline::input::read_template;
use trisplat_splat::Convention;
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};
use trisplat_splat::{
    AttachLimits, BindOptions, DEFAULT_INITIAL_OPACITY, attach, attach_checked, init_bound,
};
use trisplat_splat::{DeformMode, Deformer};

use super::{Context, refuse_to_overwrite};

/// Triangle frame conventions (docs/conventions.md §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ConventionArg {
    /// GaussianAvatars: frame of the posed triangle (edge, normal, in-plane); for
    /// `deform --mode binding` (and `lbs`).
    Gaussianavatars,
    /// SurFhead/TGA: canonical frame (edge, in-plane, normal); for `deform --mode jacobian`.
    Surfhead,
}

impl From<ConventionArg> for Convention {
    fn from(c: ConventionArg) -> Self {
        match c {
            ConventionArg::Gaussianavatars => Convention::GaussianAvatars,
            ConventionArg::Surfhead => Convention::SurfHead,
        }
    }
}

/// What `bind --gaussians` reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum WorldLayout {
    /// World-space Gaussians (any 3DGS PLY).
    World,
    /// LAM's per-vertex offsets (`offset.ply`): one row per template vertex.
    Lam,
}

/// Arguments of `trisplat bind`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Bind Gaussians to the triangles of a template mesh and write them as \
    a GaussianAvatars-style PLY: local, pre-activation parameters in each triangle's frame plus \
    the float property `binding_0` (the triangle index).\n\n\
    Without --gaussians, new Gaussians are initialised (docs/conventions.md §4): N per triangle, identity \
    rotation, opacity 0.1, grey colour (SH degree 0). With N = 1 the Gaussian sits at the \
    centroid with local scale 1 (log-scale 0). With N > 1 the points are the first N points of \
    the R2 low-discrepancy sequence folded into the triangle (deterministic, evenly spread, the \
    same for every triangle in barycentric terms) and the local log-scale is -ln(N)/2 so that \
    the N Gaussians cover about the area one would.\n\n\
    With --gaussians WORLD.ply, existing world-space Gaussians (any 3DGS PLY) are attached to \
    the triangle whose surface is nearest to their centre (exact closest point, BVH) and \
    expressed in its frame; colours, opacities and extra properties are kept. The result is \
    refused when it is implausible, naming the number: the Gaussians' bounding box more than 3x \
    (or less than 1/3) the template's, a median centre more than 25 mean template edges from its \
    triangle, or over 25% of the Gaussians on one triangle (from 64 Gaussians and 16 triangles) \
    - signs of other units, another coordinate frame, or offsets taken for positions. \
    --unchecked binds anyway.\n\n\
    The convention picks the frame: gaussianavatars (for deform --mode binding or lbs) or \
    surfhead (for deform --mode jacobian). Both use the template's positions as given (its rest \
    shape).\n\n\
    LAM avatars (--avatar DIR, or MESH being such a folder: skin.glb and offset.ply; or \
    --gaussians offset.ply --layout lam beside MESH): row i of offset.ply is the offset of a \
    Gaussian from template vertex i, its f_dc the colour as RGB. Each Gaussian is placed at its \
    vertex plus its offset and bound to the triangle around that vertex nearest to it; the \
    command then renders the bound avatar at rest and the template from --check-views views and \
    prints the silhouette IoU per view (1: the Gaussians cover exactly the template's outline; \
    hair and accessories the mesh lacks lower it)."
)]
pub struct BindArgs {
    /// Template mesh (.ply, .obj, .gltf, .glb; glTF in its rest state), or a LAM avatar
    /// folder (as --avatar).
    #[arg(required_unless_present = "avatar")]
    pub mesh: Option<PathBuf>,
    /// A LAM avatar folder: MESH = DIR/skin.glb, --gaussians DIR/offset.ply --layout lam.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["mesh", "gaussians", "per_triangle"])]
    pub avatar: Option<PathBuf>,
    /// Output Gaussian PLY (bound, local parameters, `binding_0`).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Gaussians per triangle when initialising.
    #[arg(long, default_value_t = 1, value_name = "N",
        value_parser = clap::value_parser!(u32).range(1..))]
    pub per_triangle: u32,
    /// Frame convention.
    #[arg(long, value_enum, default_value_t = ConventionArg::Gaussianavatars)]
    pub convention: ConventionArg,
    /// Attach these world-space Gaussians (a 3DGS PLY) instead of initialising new ones.
    #[arg(long, value_name = "WORLD.ply", conflicts_with = "per_triangle")]
    pub gaussians: Option<PathBuf>,
    /// With --gaussians: bind even when the result looks implausible (see below).
    #[arg(long, requires = "gaussians")]
    pub unchecked: bool,
    /// How --gaussians relates to MESH: world-space 3DGS Gaussians (attached to their nearest
    /// triangle) or LAM's per-vertex offsets.
    #[arg(long, value_enum, default_value_t = WorldLayout::World, requires = "gaussians")]
    pub layout: WorldLayout,
    /// Views of the rest-pose silhouette check of a LAM avatar (0: no check).
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub check_views: usize,
}

/// Runs `trisplat bind`.
///
/// # Errors
/// Unreadable mesh or Gaussians, a mesh without triangles, Gaussians that are already bound, an
/// output equal to an input, a failed write.
pub fn run(args: BindArgs, ctx: &Context) -> anyhow::Result<()> {
    let (mesh_path, gaussians, layout) = match (&args.avatar, &args.mesh) {
        (Some(dir), _) => lam_files(dir)?,
        (None, Some(m)) if m.is_dir() => lam_files(m)?,
        (None, Some(m)) => (m.clone(), args.gaussians.clone(), args.layout),
        (None, None) => anyhow::bail!("a template MESH or --avatar DIR is needed"),
    };
    refuse_to_overwrite(&mesh_path, &args.output)?;
    if let Some(g) = &gaussians {
        refuse_to_overwrite(g, &args.output)?;
    }
    let mesh = read_template(&mesh_path)?;
    let convention = Convention::from(args.convention);
    let spinner = ctx.progress.spinner("binding");
    let bound = match &gaussians {
        None => {
            let options = BindOptions {
                per_triangle: args.per_triangle as usize,
                convention,
                opacity: DEFAULT_INITIAL_OPACITY,
            };
            init_bound(&mesh, &options).with_context(|| format!("{}", mesh_path.display()))?
        }
        Some(path) if layout == WorldLayout::Lam => {
            let identity: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
            bind_lam(path, &mesh, &mesh, &identity, &mesh_path, convention)?
        }
        Some(path) => {
            let world = read_gaussians(path)?;
            if world.binding().is_some() {
                anyhow::bail!(
                    "{}: the Gaussians are already bound to triangles (binding property); \
                     bake them with `trisplat deform` first",
                    path.display()
                );
            }
            let context = || format!("attaching {} to {}", path.display(), mesh_path.display());
            if args.unchecked {
                attach(&world, &mesh, convention).with_context(context)?
            } else {
                attach_checked(&world, &mesh, convention, &AttachLimits::default())
                    .with_context(context)?
                    .0
            }
        }
    };
    spinner.finish_and_clear();
    write_gaussians(&args.output, &bound, &PlyWriteOptions::default())?;
    let mut result = serde_json::json!({
        "output": args.output,
        "template": mesh_path,
        "gaussians": bound.len(),
        "triangles": mesh.triangle_count(),
    });
    if layout == WorldLayout::Lam && gaussians.is_some() && args.check_views > 0 {
        let mode = match convention {
            Convention::GaussianAvatars => DeformMode::Binding,
            Convention::SurfHead => DeformMode::Jacobian,
        };
        let rest = Deformer::new(&mesh, mode)
            .deform(&bound, mesh.positions())
            .with_context(|| format!("deforming {} at rest", args.output.display()))?;
        let views = silhouette_iou(&rest, &mesh, args.check_views, 512, &mesh_path)?;
        let stat = |f: fn(&Silhouettes) -> f64| {
            let values: Vec<f64> = views.iter().map(f).collect();
            let min = values.iter().copied().fold(1.0, f64::min);
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let list: Vec<String> = values.iter().map(|v| format!("{v:.3}")).collect();
            format!("min {min:.3}, mean {mean:.3} ({})", list.join(" "))
        };
        let per_view = |f: fn(&Silhouettes) -> f64| views.iter().map(f).collect::<Vec<f64>>();
        result["rest_pose"] = serde_json::json!({
            "views": views.len(),
            "silhouette_iou": per_view(|s| s.iou),
            "gaussians_on_mesh": per_view(|s| s.inside),
            "mesh_covered": per_view(|s| s.covered),
        });
        if !ctx.json {
            println!(
                "rest pose against {} over {} views (Gaussians: alpha >= 0.5):\n  silhouette \
                 IoU     {}\n  Gaussians on mesh  {}\n  mesh covered       {}",
                mesh_path.display(),
                views.len(),
                stat(|s| s.iou),
                stat(|s| s.inside),
                stat(|s| s.covered)
            );
        }
    }
    ctx.emit("bind", result)
}

/// The template and Gaussians of the LAM avatar folder `dir`.
fn lam_files(dir: &Path) -> anyhow::Result<(PathBuf, Option<PathBuf>, WorldLayout)> {
    let avatar = AvatarFolder::open(dir)?;
    Ok((avatar.template, Some(avatar.gaussians), WorldLayout::Lam))
}
