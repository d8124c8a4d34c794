//! `trisplat opacity-mesh GAUSSIANS.ply [--cameras C.json] -o MESH.ply [--views N]
//! [--resolution R] [--keep-pieces all|major|largest] [--field gof|peak|median [--surface PX]]`: mesh the
//! Gaussians' opacity field
//! (docs/conventions.md §6).

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_extract::opacity::{
    AlphaRules, DEFAULT_BISECTION_STEPS, DEFAULT_CARVE_VIEWS, DEFAULT_LEVEL, DEFAULT_MARGIN,
    DEFAULT_SAMPLE_STRIDE, DEFAULT_SURFACE, DepthRules, KeepPieces, MAX_CARVE_VIEWS,
    OpacityOptions, RayModel, median_depth_mesh, opacity_mesh,
};
use trisplat_geometry::io::{WriteOptions, write_mesh};
use trisplat_pipeline::config::{DEFAULT_RESOLUTION, DEFAULT_VIEWS};
use trisplat_pipeline::opacity::{median_depth_views, opacity_gaussians, opacity_rig};
use trisplat_splat::ParameterSpace;
use trisplat_splat::ply::read_gaussians;

use super::{Context, MAX_IMAGE_PIXELS, parse_max_pixels, read_camera_file, refuse_to_overwrite};

/// Which pieces of the surface `--keep-pieces` keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Pieces {
    /// Every connected piece.
    All,
    /// Every piece with at least 1% of the area.
    Major,
    /// The largest piece by area.
    Largest,
}

/// Arguments of `trisplat opacity-mesh`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Mesh the opacity field of world-space Gaussians (Gaussian Opacity Fields): points at each \
Gaussian's centre and the 8 corners of its 3-sigma box (Gaussians with opacity below 1/255 left \
out), our exact 3D Delaunay over them; the opacity of a point is the smallest, over the views \
that see it, of 1 - prod(1 - alpha_i) along the view's ray up to the point, each Gaussian's \
alpha = opacity x its density at the ray's point of highest density, or at the point itself \
when that lies beyond it (alphas clamped at 0.999, those below 1/255 skipped: the renderer's \
rules); marching tetrahedra at --level with --steps bisection steps on every crossing edge; \
vertex colours: the colours composited up to the vertex in the view where it is least covered. \
Views: --cameras, or the tsdf method's rig (--views cameras of --resolution pixels, 40 degree \
field of view, on a sphere around the bounding sphere of the means and box corners). Views are streamed: memory does \
not grow with their number. --field median: the same points and marching, a point outside when at least \
--carve-views views see it more than --margin pixels in front of their rendered median depth (or see no \
median depth there), then each vertex of a thick part moved along its inward normal to where the field reaches --surface (default 0: onto the median depth; --surface equal to --margin: no move); vertex colours from the renders.")]
pub struct OpacityMeshArgs {
    /// World-space Gaussians (3DGS PLY).
    pub gaussians: PathBuf,
    /// Cameras: a 3DGS cameras.json or a NeRF transforms.json (default: the tsdf rig).
    #[arg(long, conflicts_with_all = ["views", "resolution"])]
    pub cameras: Option<PathBuf>,
    /// Output mesh (.ply, .obj, .gltf, .glb).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Cameras of the default rig.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_VIEWS as u32,
        value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub views: u32,
    /// Side of the default rig's square images, pixels (they bound which points a view sees).
    #[arg(long, value_name = "PX", default_value_t = DEFAULT_RESOLUTION,
        value_parser = clap::value_parser!(u32).range(8..=8192))]
    pub resolution: u32,
    /// Which connected pieces to keep: all, every piece with at least 1% of the area, or the largest.
    #[arg(long, value_enum, default_value_t = Pieces::All)]
    pub keep_pieces: Pieces,
    /// Level of the opacity field the surface lies at, in (0, 1).
    #[arg(long, default_value_t = DEFAULT_LEVEL, value_parser = parse_level)]
    pub level: f32,
    /// Bisection steps on each crossing edge.
    #[arg(long, default_value_t = DEFAULT_BISECTION_STEPS,
        value_parser = clap::value_parser!(u32).range(0..=40))]
    pub steps: u32,
    /// What a Gaussian adds to the opacity along a ray before its peak: its density at the point
    /// (`gof`: Gaussian Opacity Fields' ramp; the level set lies in front of the median depth) or
    /// nothing (`peak`: the level set lies where the renderer's transmittance halves, but
    /// one-layer parts have no inside and vanish).
    /// `median`: a point is outside when --carve-views views see it in front of their rendered
    /// median depth by more than --margin pixels, or see no median depth there (the level set
    /// is the renderer's median depth; --level is not used).
    #[arg(long, value_enum, default_value_t = FieldModel::Gof)]
    pub field: FieldModel,
    /// With `--field median`: how far in front of a view's median depth a point must lie for
    /// that view to carve it, in pixel footprints at the point's depth.
    #[arg(long, value_name = "PX", default_value_t = DEFAULT_MARGIN, value_parser = parse_margin)]
    pub margin: f32,
    /// With `--field median`: where the vertices go, in pixel footprints in front of the
    /// median depth (0..=--margin; each crossing edge is bisected for this level, or its inside
    /// end's value when that is lower; --margin: the margin's own level set).
    #[arg(long, value_name = "PX", default_value_t = DEFAULT_SURFACE, value_parser = parse_margin)]
    pub surface: f32,
    /// With `--field median`: how many views must carve a point for it to be outside.
    #[arg(long, value_name = "K", default_value_t = DEFAULT_CARVE_VIEWS,
        value_parser = clap::value_parser!(u16).range(1..=i64::from(MAX_CARVE_VIEWS)))]
    pub carve_views: u16,
    /// With `--field median`: every Nth pixel of every map adds a point behind and one in front
    /// of its median depth to the tetrahedralisation (0: the Gaussians' points only).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SAMPLE_STRIDE,
        value_parser = clap::value_parser!(u32).range(0..=4096))]
    pub depth_samples: u32,
    /// No vertex colours.
    #[arg(long)]
    pub no_colors: bool,
    /// Most pixels of one camera's image of --cameras.
    #[arg(long, value_name = "N", default_value_t = MAX_IMAGE_PIXELS, value_parser = parse_max_pixels)]
    pub max_pixels: u64,
}

/// `--field`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FieldModel {
    /// The density at the point before the peak (GOF's).
    Gof,
    /// Nothing before the peak (the renderer's median depth).
    Peak,
    /// The views' rendered median-depth maps decide each point's side.
    Median,
}

/// `--margin`: finite and >= 0.
fn parse_margin(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(m) if m.is_finite() && m >= 0.0 => Ok(m),
        _ => Err(format!("expected a finite margin >= 0 (pixels), got '{s}'")),
    }
}

/// `--level`: in (0, 1).
fn parse_level(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(a) if a > 0.0 && a < 1.0 => Ok(a),
        _ => Err(format!("expected an opacity in (0, 1), got '{s}'")),
    }
}

/// Runs `trisplat opacity-mesh`.
///
/// # Errors
/// Unreadable Gaussians or cameras, Gaussians in a local (bound) frame, bad Gaussians (named),
/// no camera seeing them, degenerate points, no surface, an output that is an input, a failed
/// write.
pub fn run(args: OpacityMeshArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.gaussians, &args.output)?;
    let set = read_gaussians(&args.gaussians)?;
    if set.space() != ParameterSpace::World {
        bail!(
            "{}: the Gaussians are in their triangles' local frames; deform them to world space first (trisplat deform)",
            args.gaussians.display()
        );
    }
    let cameras = match &args.cameras {
        Some(path) => {
            refuse_to_overwrite(path, &args.output)?;
            read_camera_file(path, None, args.max_pixels)?
        }
        None => opacity_rig(&set, args.views as usize, args.resolution)
            .with_context(|| format!("{}: no camera rig", args.gaussians.display()))?,
    };
    let options = OpacityOptions {
        level: args.level,
        bisection_steps: args.steps,
        keep: match args.keep_pieces {
            Pieces::All => KeepPieces::All,
            Pieces::Major => KeepPieces::Major,
            Pieces::Largest => KeepPieces::Largest,
        },
        colors: !args.no_colors,
        rules: AlphaRules {
            model: match args.field {
                FieldModel::Peak => RayModel::Peak,
                FieldModel::Gof | FieldModel::Median => RayModel::Gof,
            },
            ..AlphaRules::default()
        },
        ..OpacityOptions::default()
    };
    let spinner = ctx.progress.spinner("meshing the opacity field");
    let gaussians = opacity_gaussians(&set);
    let out = if args.field == FieldModel::Median {
        let views = median_depth_views(&set, &cameras, options.colors, 0)
            .with_context(|| format!("{}: median depth maps", args.gaussians.display()))?;
        let rules = DepthRules {
            margin: args.margin,
            carve_views: args.carve_views,
            sample_stride: args.depth_samples,
            surface: args.surface,
        };
        median_depth_mesh(&gaussians, &views, rules, &options, None)
    } else {
        opacity_mesh(&gaussians, &cameras, &options)
    }
    .with_context(|| format!("{}: opacity mesh failed", args.gaussians.display()))?;
    spinner.finish_and_clear();
    let s = &out.stats;
    if !ctx.quiet && s.pieces > 1 && options.keep != KeepPieces::All {
        eprintln!(
            "{}: the surface has {} pieces; kept {:.2}% of the area (--keep-pieces all keeps every piece)",
            args.gaussians.display(),
            s.pieces,
            100.0 * s.kept_area_fraction
        );
    }
    write_mesh(&args.output, &out.mesh, WriteOptions::default())?;
    ctx.emit(
        "opacity-mesh",
        serde_json::json!({
            "output": args.output,
            "views": cameras.len(),
            "gaussians": s.gaussians,
            "points": s.points,
            "points_seen": s.points_seen,
            "tetrahedra": s.tetrahedra,
            "crossing_edges": s.crossing_edges,
            "vertices": out.mesh.vertex_count(),
            "triangles": out.mesh.triangle_count(),
            "pieces": s.pieces,
            "kept_area_fraction": s.kept_area_fraction,
            "ms": {"field": s.ms[0], "delaunay": s.ms[1], "march": s.ms[2], "colors": s.ms[3]},
        }),
    )
}
