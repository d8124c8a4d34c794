//! `trisplat render GAUSSIANS.ply --cameras CAMS.json -o DIR [--mode 3dgs|2dgs|perspective]
//! [--outputs rgb,alpha,depth,median_depth,normal] [--background r,g,b] [--compat-3dgs]
//! [--antialiased] [--ray-depth] [--env MAP.hdr [--env-rotation DEG] [--env-intensity X]
//! [--albedo-scale X] [--roughness R] [--f0 F] [--material-maps LIST]]` and
//! `trisplat render --mesh MESH --cameras CAMS.json -o DIR`.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::Camera;
use trisplat_geometry::glam::DVec3;
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::mesh_render::{MeshRenderOptions, MeshRenderer, NormalFrame};
use trisplat_splat::ply::read_gaussians_local;
use trisplat_splat::render::{
    DEFAULT_FAR, Outputs, RenderImages, RenderMode, RenderOptions, SplatDepth, render,
};
use trisplat_splat::render::{file_stem, image_files};

use trisplat_geometry::envmap::EnvMap;
use trisplat_splat::GaussianSet;
use trisplat_splat::material::{
    EnvOptions, Environment, Material, MaterialEdits, MaterialMaps, effective_material,
    material_image_files, render_relit, write_material_maps,
};

use super::render_neural::NeuralRender;
use super::{
    Context, MAX_IMAGE_PIXELS, UsageError, parse_max_pixels, read_camera_file, refuse_to_overwrite,
};

/// Splatting models.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// 3DGS EWA splatting with gsplat's rules.
    #[value(name = "3dgs")]
    Gaussian3d,
    /// 2DGS surfels (hbb1's ray-splat intersection).
    #[value(name = "2dgs")]
    Surfel2d,
    /// Perspective-aware evaluation along each pixel ray (TGA).
    Perspective,
}

/// Frames of the normal map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FrameArg {
    /// World coordinates.
    World,
    /// Camera coordinates (OpenCV axes).
    Camera,
}

/// Arguments of `trisplat render`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Render Gaussians (a world-space 3DGS PLY) or a mesh (--mesh) with the cameras \
    of a 3DGS cameras.json or a NeRF transforms.json, on the CPU.\n\n\
    Writes DIR/<img_name>_rgb.npy [H,W,3], _alpha.npy, _depth.npy (expected z-depth, 0 where \
    nothing), _median_depth.npy, _normal.npy [H,W,3] (alpha-composited unit normals facing the \
    camera) as float32, each with a PNG picture (depths colour-mapped with turbo over each \
    image's own depth range, near = red; normals as (n+1)/2).\n\n\
    3dgs mode follows gsplat 1.5.3 (docs/conventions.md §5); --compat-3dgs switches to the original 3DGS \
    rasterizer's rules (alpha clamp 0.99, strict stop test, integer pixel centres, near 0.2, one \
    3-sigma radius). With neural appearance weights (`fit --appearance mlp`: \
    <name>.safetensors beside the PLY, or --weights FILE) each Gaussian's colour and opacity \
    come from the model, per camera; a weights file that does not match the PLY is an error \
    and nothing is written. Bound GaussianAvatars files (local parameters) must be baked to world space \
    first with `trisplat deform`.\n\n\
    With --mesh the mesh is ray cast instead: depth, normal and alpha (the hit mask) maps.\n\n\
    With --env MAP.hdr (an equirectangular Radiance map, 2:1, +Y up) the Gaussians are relit: \
    each Gaussian's material (albedo_0..2, roughness, reflectance in the PLY, as HRAvatar's; \
    without them the SH colour as albedo, roughness 0.9, F0 0.04) shaded by the split sum \
    (docs/conventions.md §5) per view replaces the SH colour. --material-maps writes \
    DIR/<img_name>_albedo.npy [H,W,3], _roughness.npy [H,W], _specular.npy [H,W,3] (composited \
    like the normal map: weighted sums, black where nothing), each with a PNG."
)]
pub struct RenderArgs {
    /// Gaussians: a 3DGS PLY in world space.
    #[arg(required_unless_present = "mesh", conflicts_with = "mesh")]
    pub gaussians: Option<PathBuf>,
    /// Render this mesh (.ply, .obj, .gltf, .glb) by ray casting instead of Gaussians.
    #[arg(long, value_name = "MESH")]
    pub mesh: Option<PathBuf>,
    /// Cameras: a 3DGS cameras.json or a NeRF transforms.json.
    #[arg(long, value_name = "CAMS.json")]
    pub cameras: PathBuf,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Splatting model.
    #[arg(long, value_enum, default_value_t = ModeArg::Gaussian3d)]
    pub mode: ModeArg,
    /// Images to write: comma-separated rgb, alpha, depth, median_depth, normal (or all).
    /// Default: rgb,alpha,depth (depth,normal,alpha with --mesh).
    #[arg(long, value_name = "LIST", value_parser = parse_outputs)]
    pub outputs: Option<Outputs>,
    /// Background colour r,g,b in 0..1.
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb, default_value = "0,0,0")]
    pub background: [f32; 3],
    /// The original 3DGS rasterizer's rules instead of gsplat's.
    #[arg(long)]
    pub compat_3dgs: bool,
    /// gsplat's antialiased mode (opacity times the dilation compensation).
    #[arg(long)]
    pub antialiased: bool,
    /// 3DGS mode: each splat's depth (depth, median_depth) at the point of highest density on
    /// the pixel's ray (RaDe-GS, GOF; a flat Gaussian gives its own plane) instead of its
    /// mean's depth over the whole footprint.
    #[arg(long)]
    pub ray_depth: bool,
    /// Near plane (camera z); default 0.01 (0.2 with --compat-3dgs or --mode 2dgs, as the
    /// original 3DGS and 2DGS code).
    #[arg(long, value_name = "Z")]
    pub near: Option<f32>,
    /// Far plane (camera z).
    #[arg(long, value_name = "Z", default_value_t = DEFAULT_FAR)]
    pub far: f32,
    /// Frame of the normal maps.
    #[arg(long, value_enum, default_value_t = FrameArg::World)]
    pub normal_frame: FrameArg,
    /// Image size WxH for a transforms.json that does not give one.
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub image_size: Option<(u32, u32)>,
    /// Relight under this equirectangular environment map (Radiance .hdr, 2:1, +Y up)
    /// instead of the SH colour.
    #[arg(long, value_name = "MAP.hdr", conflicts_with = "mesh")]
    pub env: Option<PathBuf>,
    /// Turn of the environment about +Y, degrees (90 moves what was towards +X to -Z).
    #[arg(long, value_name = "DEG", requires = "env", default_value_t = 0.0, allow_negative_numbers = true, value_parser = parse_finite)]
    pub env_rotation: f64,
    /// Factor on the environment's radiance.
    #[arg(long, value_name = "X", requires = "env", default_value_t = 1.0, value_parser = parse_non_negative)]
    pub env_intensity: f32,
    /// Factor on every albedo (the product clamped to 0..1).
    #[arg(long, value_name = "X", requires = "env", default_value_t = 1.0, value_parser = parse_non_negative)]
    pub albedo_scale: f32,
    /// Roughness of every Gaussian (0..1) in place of its own.
    #[arg(long, value_name = "R", requires = "env", value_parser = parse_unit)]
    pub roughness: Option<f32>,
    /// Fresnel reflectance F0 of every Gaussian (0..1) in place of its own.
    #[arg(long, value_name = "F", requires = "env", value_parser = parse_unit)]
    pub f0: Option<f32>,
    /// Material maps to write beside the images: comma-separated albedo, roughness, specular
    /// (or all).
    #[arg(long, value_name = "LIST", requires = "env", value_parser = parse_material_maps)]
    pub material_maps: Option<MaterialMaps>,
    /// Most pixels of one camera's image (a limit checked before any image exists; at most
    /// 16384 x 16384).
    #[arg(long, value_name = "N", default_value_t = MAX_IMAGE_PIXELS, value_parser = parse_max_pixels)]
    pub max_pixels: u64,
    /// Neural appearance weights (safetensors, `fit --appearance mlp`); default:
    /// <name>.safetensors beside the PLY when it exists.
    #[arg(long, value_name = "FILE", conflicts_with = "mesh")]
    pub weights: Option<PathBuf>,
}

fn parse_outputs(s: &str) -> Result<Outputs, String> {
    let o = Outputs::parse_list(s)?;
    if o.is_empty() {
        return Err("no output named".into());
    }
    Ok(o)
}

pub(crate) fn parse_rgb(s: &str) -> Result<[f32; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected r,g,b (three numbers), got '{s}'"));
    }
    let mut rgb = [0.0f32; 3];
    for (v, p) in rgb.iter_mut().zip(&parts) {
        *v = p
            .parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("'{p}' is not a finite number"))?;
    }
    Ok(rgb)
}

fn parse_finite(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("'{s}' is not a finite number"))
}

fn parse_non_negative(s: &str) -> Result<f32, String> {
    s.trim()
        .parse::<f32>()
        .ok()
        .filter(|v| v.is_finite() && *v >= 0.0)
        .ok_or_else(|| format!("'{s}' is not a finite number >= 0"))
}

fn parse_unit(s: &str) -> Result<f32, String> {
    s.trim()
        .parse::<f32>()
        .ok()
        .filter(|v| (0.0..=1.0).contains(v))
        .ok_or_else(|| format!("'{s}' is not a number in 0..1"))
}

fn parse_material_maps(s: &str) -> Result<MaterialMaps, String> {
    let mut maps = MaterialMaps::default();
    for name in s.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        match name {
            "albedo" => maps.albedo = true,
            "roughness" => maps.roughness = true,
            "specular" => maps.specular = true,
            "all" => {
                maps = MaterialMaps {
                    albedo: true,
                    roughness: true,
                    specular: true,
                };
            }
            other => {
                return Err(format!(
                    "unknown material map '{other}' (albedo, roughness, specular, all)"
                ));
            }
        }
    }
    if maps == MaterialMaps::default() {
        return Err("no material map named".into());
    }
    Ok(maps)
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, got '{s}'"))?;
    let parse = |v: &str| v.trim().parse::<u32>().ok().filter(|&v| v > 0);
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("expected positive WxH, got '{s}'")),
    }
}

/// Runs `trisplat render`.
///
/// # Errors
/// Unreadable inputs, bound (local) Gaussians, bad options, an output
/// folder equal to an input, a failed write.
pub fn run(args: RenderArgs, ctx: &Context) -> anyhow::Result<()> {
    let cameras = read_camera_file(&args.cameras, args.image_size, args.max_pixels)?;
    refuse_shared_names(&args.cameras, &cameras)?;
    // Image files that exist before the run are left alone; on failure the ones this run
    // wrote are removed (nothing half-done is left behind).
    let files: Vec<PathBuf> = cameras
        .iter()
        .flat_map(|c| {
            let mut files = image_files(&args.output, &c.name);
            if args.material_maps.is_some() {
                files.extend(material_image_files(&args.output, &c.name));
            }
            files
        })
        .collect();
    let existed: HashSet<PathBuf> = files.iter().filter(|p| p.exists()).cloned().collect();
    let result = render_all(&args, &cameras, ctx);
    if result.is_err() {
        for file in files.iter().filter(|f| !existed.contains(*f)) {
            let _ = std::fs::remove_file(file);
        }
    }
    result?;
    let written: Vec<&PathBuf> = files.iter().filter(|f| f.exists()).collect();
    ctx.emit(
        "render",
        serde_json::json!({
            "output": args.output,
            "views": cameras.len(),
            "files": written,
        }),
    )
}

/// Refuses two cameras whose images would have the same file names (`render` would write one
/// over the other), before anything is written.
fn refuse_shared_names(path: &Path, cameras: &[Camera]) -> anyhow::Result<()> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    for (i, camera) in cameras.iter().enumerate() {
        if let Some(first) = seen.insert(file_stem(&camera.name), i) {
            bail!(
                "{}: cameras {first} ('{}') and {i} ('{}') would write the same image files \
                 ({}_*.npy/png); give each camera its own name",
                path.display(),
                cameras[first].name,
                camera.name,
                file_stem(&camera.name)
            );
        }
    }
    Ok(())
}

/// Renders every camera and writes its images (see [`run`]).
fn render_all(args: &RenderArgs, cameras: &[Camera], ctx: &Context) -> anyhow::Result<()> {
    let input = args.gaussians.as_deref().or(args.mesh.as_deref());
    let Some(input) = input else {
        bail!("give a Gaussian PLY or --mesh MESH");
    };
    refuse_to_overwrite(input, &args.output)?;
    refuse_to_overwrite(&args.cameras, &args.output)?;
    let frame = match args.normal_frame {
        FrameArg::World => NormalFrame::World,
        FrameArg::Camera => NormalFrame::Camera,
    };
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("{}: cannot create the folder", args.output.display()))?;
    let bar = ctx.progress.bar(cameras.len() as u64, "render");
    if let Some(mesh_path) = &args.mesh {
        let outputs = args.outputs.unwrap_or(Outputs {
            depth: true,
            normal: true,
            alpha: true,
            ..Outputs::NONE
        });
        if outputs.rgb || outputs.median_depth {
            bail!("--mesh renders only depth, normal and alpha (the hit mask)");
        }
        // A mesh far from the world origin is ray cast at its local origin, the cameras
        // moved with it (f64).
        let mut mesh = read_mesh(mesh_path)?;
        let origin = mesh.bounds().map_or(DVec3::ZERO, |b| b.local_origin());
        mesh.translate(-origin);
        let renderer = MeshRenderer::new(
            &mesh,
            MeshRenderOptions {
                frame,
                ..MeshRenderOptions::default()
            },
        )
        .with_context(|| format!("{}: cannot build the ray-casting BVH", mesh_path.display()))?;
        for camera in cameras {
            let maps = renderer.render(&camera.translated(-origin));
            let mut images = RenderImages::new(camera.width, camera.height, outputs);
            if outputs.depth {
                images.depth = Some(maps.depth.clone());
            }
            if outputs.alpha {
                images.alpha = Some(maps.mask.clone());
            }
            if outputs.normal {
                images.normal = Some(maps.normal_flat());
            }
            images.write(&args.output, &camera.name)?;
            bar.inc(1);
        }
        bar.finish_and_clear();
        return Ok(());
    }
    // Gaussians far from the world origin are stored relative to their local origin (f64
    // before f32), and the cameras moved with them.
    let (set, origin) = read_gaussians_local(input)?;
    let mut neural = NeuralRender::open(args.weights.as_deref(), input, &set, origin)?;
    let mut options = if args.compat_3dgs {
        RenderOptions::original_3dgs()
    } else {
        RenderOptions::default()
    };
    options.mode = match args.mode {
        ModeArg::Gaussian3d => RenderMode::Gaussian3d,
        ModeArg::Surfel2d => RenderMode::Surfel2d,
        ModeArg::Perspective => RenderMode::Perspective,
    };
    options.antialiased = args.antialiased;
    if args.ray_depth {
        options.splat_depth = SplatDepth::Ray;
    }
    options.outputs = args.outputs.unwrap_or_default();
    options.background = args.background;
    if let Some(near) = args.near {
        options.near = near;
    } else if options.mode == RenderMode::Surfel2d {
        options.near = trisplat_splat::render::SURFEL_NEAR;
    }
    options.far = args.far;
    options.normal_frame = frame;
    if let Some(env_path) = &args.env {
        if let Some(weights) = neural.as_ref().map(NeuralRender::path) {
            return Err(UsageError(format!(
                "--env relights the Gaussians' materials (or their SH colour as albedo); it does \
                 not take neural appearance weights ({})",
                weights.display()
            ))
            .into());
        }
        let relight = Relight::open(args, env_path, &set)?;
        for camera in cameras {
            let camera = camera.translated(-origin);
            let out = render_relit(
                &set,
                None,
                &relight.material,
                &camera,
                &relight.env,
                &options,
                args.material_maps.unwrap_or_default(),
            )
            .with_context(|| format!("{}: camera '{}'", input.display(), camera.name))?;
            out.output.images.write(&args.output, &camera.name)?;
            write_material_maps(&out, &args.output, &camera.name)?;
            bar.inc(1);
        }
        bar.finish_and_clear();
        return Ok(());
    }
    for camera in cameras {
        let baked = neural.as_mut().map(|n| n.bake(&set, camera.position()));
        let out = render(
            baked.as_ref().unwrap_or(&set),
            &camera.translated(-origin),
            &options,
        )
        .with_context(|| format!("{}: camera '{}'", input.display(), camera.name))?;
        out.images.write(&args.output, &camera.name)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(())
}

/// What `render --env` shades with: the environment, prepared once, and the edited materials.
struct Relight {
    env: Environment,
    material: Material,
}

impl Relight {
    /// Reads the map (errors name it), prepares it and applies the material edits.
    fn open(args: &RenderArgs, env_path: &Path, set: &GaussianSet) -> anyhow::Result<Self> {
        let map = EnvMap::read(env_path)?;
        let env = Environment::new(
            &map,
            EnvOptions {
                rotation_deg: args.env_rotation,
                intensity: args.env_intensity,
            },
        )
        .with_context(|| {
            format!(
                "{}: --env-intensity {}",
                env_path.display(),
                args.env_intensity
            )
        })?;
        let edits = MaterialEdits {
            albedo_scale: args.albedo_scale,
            roughness: args.roughness,
            f0: args.f0,
        };
        edits.check().map_err(anyhow::Error::msg)?;
        Ok(Self {
            env,
            material: effective_material(set, &edits),
        })
    }
}
