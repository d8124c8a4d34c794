//! `trisplat cameras MESH -o CAMS.json [--rig sphere|orbit] [--views N] [--size WxH]
//! [--fov DEG] [--elevation DEG]`: a camera rig around a mesh's bounding sphere, written as a
//! 3DGS cameras.json (for `render` and `tsdf`).

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_geometry::glam::DVec3;
use trisplat_geometry::io::read_points;
use trisplat_geometry::{orbit_rig, sphere_rig, write_cameras_json};
use trisplat_pipeline::avatar::AvatarFolder;
use trisplat_pipeline::input::read_template;

use super::{Context, refuse_to_overwrite};

/// The rig's layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RigArg {
    /// Views spread evenly over the whole sphere (a Fibonacci lattice).
    Sphere,
    /// Views on a horizontal circle (world up +y) at `--elevation`.
    Orbit,
}

/// Default of `cameras --max-views`.
pub const DEFAULT_MAX_VIEWS: u32 = 100_000;

/// Arguments of `trisplat cameras`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Cameras look at the centre of the mesh's bounding box from a distance at which the bounding \
sphere (radius: the farthest vertex from that centre) fills the vertical field of view with a \
10% margin. A glTF is framed at its rest state as the main job, fit and render --mesh pose it \
(node transforms, skins and default morph weights applied: a skinned mesh under a scaled node is \
framed at the size its skin gives it, not as stored); a LAM avatar folder by its skin.glb. \
OpenCV axes, principal point at the image centre, square pixels; names view_000, view_001, ...")]
pub struct CamerasArgs {
    /// Mesh or point cloud to frame (.ply, .obj, .gltf, .glb; a glTF at its rest state as the
    /// main job poses it), or a LAM avatar folder.
    pub mesh: PathBuf,
    /// Output cameras.json.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Layout of the views.
    #[arg(long, value_enum, default_value_t = RigArg::Sphere)]
    pub rig: RigArg,
    /// Number of views (at most --max-views).
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(1..))]
    pub views: u32,
    /// Most views written (a limit checked before the rig is made).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_VIEWS)]
    pub max_views: u32,
    /// Image size WxH in pixels.
    #[arg(long, default_value = "512x512", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 40.0)]
    pub fov: f64,
    /// Elevation of an orbit above the horizontal plane, in degrees.
    #[arg(long, default_value_t = 15.0, allow_negative_numbers = true)]
    pub elevation: f64,
}

/// Parses `WxH` with positive integers.
fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or("expected WxH")?;
    match (w.parse::<u32>(), h.parse::<u32>()) {
        (Ok(w), Ok(h)) if w > 0 && h > 0 => Ok((w, h)),
        _ => Err(format!("expected positive WxH, got '{s}'")),
    }
}

/// The points `cameras` frames: a glTF as the main job, `fit` and `render --mesh` pose it (its
/// rest state: node transforms, skins and default morph weights applied; a skinned head whose
/// node carries a cm-to-m scale is framed at the size its skin gives it), a LAM avatar folder
/// by its template, anything else as read (mesh vertices or points). A glTF whose skin or
/// animation the template reader refuses is framed as stored, with a note.
fn framed_positions(path: &std::path::Path) -> anyhow::Result<Vec<DVec3>> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if path.is_dir() {
        let avatar = AvatarFolder::open(path)?;
        return Ok(read_template(&avatar.template)?.positions().to_vec());
    }
    if matches!(ext.as_deref(), Some("gltf" | "glb")) {
        match read_template(path) {
            Ok(t) => return Ok(t.positions().to_vec()),
            // The static reader takes files whose skins or animations the template reader
            // refuses; frame those as stored.
            Err(e) => eprintln!(
                "note: {}: framing the mesh as stored (node transforms only): {e}",
                path.display()
            ),
        }
    }
    Ok(read_points(path)?
        .positions()
        .iter()
        .map(|p| p.as_dvec3())
        .collect())
}

/// Runs `trisplat cameras`.
///
/// # Errors
/// An unreadable or empty mesh, an invalid rig, an output equal to the input, a failed write.
pub fn run(args: CamerasArgs, ctx: &Context) -> anyhow::Result<()> {
    if args.views > args.max_views {
        bail!(
            "--views {}: over the limit of {} views (raise it with --max-views)",
            args.views,
            args.max_views
        );
    }
    refuse_to_overwrite(&args.mesh, &args.output)?;
    let positions = framed_positions(&args.mesh)?;
    let Some((lo, hi)) = positions
        .iter()
        .fold(None, |b: Option<(DVec3, DVec3)>, &p| {
            Some(b.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p))))
        })
    else {
        bail!("{}: no vertices to frame", args.mesh.display());
    };
    let center = (lo + hi) * 0.5;
    let radius = positions
        .iter()
        .map(|&p| (p - center).length())
        .fold(0.0, f64::max);
    // A single point still gets a rig: frame a ball of a tiny but non-zero radius.
    let radius = if radius > 0.0 {
        radius
    } else {
        f64::from(f32::EPSILON) * center.length().max(1.0)
    };
    let cameras = match args.rig {
        RigArg::Sphere => sphere_rig(center, radius, args.views as usize, args.size, args.fov),
        RigArg::Orbit => orbit_rig(
            center,
            radius,
            args.views as usize,
            args.elevation,
            args.size,
            args.fov,
        ),
    }
    .with_context(|| format!("{}: cannot build the camera rig", args.mesh.display()))?;
    write_cameras_json(&args.output, &cameras)?;
    ctx.emit(
        "cameras",
        serde_json::json!({
            "output": args.output,
            "views": cameras.len(),
            "center": center.to_array(),
            "radius": radius,
        }),
    )
}
