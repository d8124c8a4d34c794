//! `trisplat fit G.ply --template T --cameras CAMS.json -o OUT.ply [--eval-cameras EVAL.json]
//! [--animation A [--frames A..B] [--clip C] [--fps F] | --images DIR [--eval-images DIR]]
//! [--iterations N] [--refine-every N] ...`: fits bound Gaussians to target images
//! (`pipeline::fit`).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use trisplat_pipeline::config::AnimationOptions;

use anyhow::{Context as _, bail};
use trisplat_extract::tsdf::DEFAULT_DEPTH_SCALE;
use trisplat_geometry::glam::DVec3;
use trisplat_geometry::io::{Format, IoError, read_gltf_base_color};
use trisplat_geometry::{Camera, TriMesh};
use trisplat_pipeline::config::{ExtractConfig, ExtractOptions};
use trisplat_pipeline::fit::{
    FitFrame, FitOptions, TargetColor, fit, mesh_targets, read_image_targets,
};
use trisplat_pipeline::input::{read_bound, read_template};
use trisplat_pipeline::refine::{PruneCriteria, RefineOptions};
use trisplat_pipeline::{Session, SessionOptions};
use trisplat_splat::fit::adam::LearningRates;
use trisplat_splat::fit::density::{self, DensifyOptions};
use trisplat_splat::fit::loss::DEFAULT_LAMBDA_DSSIM;
use trisplat_splat::neural::NeuralLearningRates;
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};
use trisplat_splat::render::SURFEL_NEAR;
use trisplat_splat::render::{RenderMode, RenderOptions};

use super::fit_brdf::{BrdfArgs, open_environment, run_brdf};
use super::fit_neural::run_mlp;
use super::fit_run::{MlpPaths, out_of_time_note, with_progress};
use super::render::parse_rgb;
use super::{
    Context, MAX_IMAGE_PIXELS, UsageError, parse_max_pixels, read_camera_file, refuse_to_overwrite,
};

/// Default of `--max-views`: target views (cameras times frames) held in memory.
pub const DEFAULT_MAX_VIEWS: u64 = 4096;

/// Arguments of `trisplat fit`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Fit bound Gaussians (a GaussianAvatars-bound PLY, as `bind` \
    writes) to target images, on the CPU, and write the fitted bound set.\n\n\
    Targets: mesh renders of the template (default; ray cast from --cameras: rgb per --color: \
    auto is the glTF base-colour texture when the template's material has one, else the \
    mesh's vertex colours, else its world normal as colour (n+1)/2; texture insists on the \
    texture (an error without one); normal forces the normal colour. The texture is sampled \
    at the hit's uv (TEXCOORD_0, interpolated per triangle corner, so uv seams stay sharp), \
    bilinear, with the sampler's wrap modes, no mipmaps, and kept in the image's own encoding \
    (sRGB), times the material's baseColorFactor and COLOR_0 (multiplied in linear, encoded \
    again), its alpha ignored; the hit mask as alpha, z-depth), at its rest pose or, with \
    --animation, at each \
    frame of --frames (each frame's views all train); or user images with --images DIR \
    (DIR/<img_name>.png per camera, an alpha channel or DIR/<img_name>_mask.png as mask, and \
    for RGB-D captures DIR/<img_name>_depth.npy or 16-bit _depth.png divided by --depth-scale, \
    as tsdf reads them, which --depth-weight then fits and the held-out views score). \
    Held-out views (--eval-cameras, --eval-images) are scored by PSNR and SSIM at every \
    --eval-every iterations and, where the targets have depth, normals and a mask (mesh \
    targets; RGB-D images give depth), by the mean absolute depth error and the mean normal \
    angle inside the target mask (2dgs: the rendered normals; 3dgs: normals of the \
    rendered depth); they never train.\n\n\
    One iteration: a seeded random (frame, view); the bound set placed with that frame's \
    triangle frames; the 3DGS render (gsplat rules) and its backward pass; loss (1 - \
    lambda) L1 + lambda D-SSIM on rgb (lambda 0.2, 3DGS's SSIM: 11x11 Gaussian window, sigma \
    1.5), + --depth-weight x the depth L1 weighted by the target's alpha, + --alpha-weight x \
    the alpha L1 against the mask; the gradient carried to the local parameters and one Adam \
    step (GaussianAvatars' learning rates: means 0.005 in triangle scales, decaying to 0.01x \
    over the run, log-scales 0.017, rotations 0.001, opacities 0.05, SH DC 0.0025, SH rest \
    0.0025/20). --time-budget S stops after the iteration that spends S seconds of \
    optimisation (scoring excluded; the decay then follows the larger of the iterations' and \
    the time's share). --refine-every N runs one round of `trisplat refine` (alpha shape of the \
    centres, smoothing, resampling, binding inheritance, pruning by the seed's gate) every N \
    iterations and restarts Adam's state. --mode 2dgs fits surfels with the 2DGS backward \
    pass; there --normal-weight adds 2DGS's depth-normal consistency (the rendered normals \
    against the normals of the rendered depth, weighted by the rendered alpha) and \
    --distortion-weight its depth distortion (mean over the pixels).\n\n\
    --densify turns on 3DGS's adaptive density control as GaussianAvatars runs it on a bound \
    set. Per Gaussian, over the views where it is visible, the mean of |d loss / d ndc|, the \
    screen-space gradient of its projected mean in NDC units (pixels x (W/2, H/2)), 3DGS's \
    units. Every --densify-every iterations after --densify-from and before --densify-until \
    (3DGS's 100, 500, 15000; the statistics then start again): where that mean is >= \
    --densify-grad (3DGS's 0.0002) a Gaussian is cloned if its largest world scale at the \
    template's rest pose, max exp(log s') k_f, is <= --percent-dense x extent (0.01; extent = \
    1.1 x the largest distance of a training camera from their mean, 3DGS's), else split into \
    2 children sampled from it in its triangle's frame with scales / 1.6; then Gaussians with \
    opacity < --prune-opacity (0.005) are pruned (and, with --max-world-size F, after the \
    first opacity reset those larger than F x extent), never a triangle's last. New Gaussians \
    keep their parent's triangle and attributes and start with zero Adam moments; survivors \
    keep theirs. Every --opacity-reset-every iterations (3000; 0 never) before \
    --densify-until every opacity becomes min(opacity, 0.01) and its moments are zeroed. \
    Nothing happens after the last iteration. --sh-up-every N renders SH bands up to an active \
    degree that starts at 0 and rises by one every N iterations (3DGS: 1000) up to the set's; \
    inactive bands get no gradient and are kept as they are.\n\n\
    --json prints one object: every checkpoint (iteration, loss, train_l1, train_psnr, \
    eval_psnr, eval_ssim, eval_depth_l1, eval_normal_deg, gaussians, sh_degree, seconds), \
    every refine round, every densify step (iteration, cloned, split, pruned, spared, \
    gaussians after, ms) and the iterations of the opacity resets."
)]
pub struct FitArgs {
    /// Bound Gaussian PLY (local parameters, binding_0).
    pub gaussians: PathBuf,
    /// The template the Gaussians are bound to (its rest state).
    #[arg(long, value_name = "T")]
    pub template: PathBuf,
    /// Training cameras: a 3DGS cameras.json or a NeRF transforms.json.
    #[arg(long, value_name = "CAMS.json")]
    pub cameras: PathBuf,
    /// Held-out cameras, scored and never trained on.
    #[arg(long, value_name = "CAMS.json")]
    pub eval_cameras: Option<PathBuf>,
    /// Output Gaussian PLY (bound like the input).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Target images instead of mesh renders: DIR/<img_name>.png per training camera.
    #[arg(long, value_name = "DIR", conflicts_with = "animation")]
    pub images: Option<PathBuf>,
    /// Divisor of 16-bit PNG depth maps beside the images (1000: millimetres to metres).
    #[arg(long, value_name = "S", default_value_t = DEFAULT_DEPTH_SCALE, requires = "images")]
    pub depth_scale: f64,
    /// Images of the held-out cameras (with --images).
    #[arg(long, value_name = "DIR", requires = "images")]
    pub eval_images: Option<PathBuf>,
    /// Animation whose frames are the targets (default: the template's rest pose).
    #[arg(long, value_name = "A")]
    pub animation: Option<String>,
    /// Animation frames to fit (`A..B`, `A..=B`, `A..`, `..B`, `A`).
    #[arg(long, value_name = "RANGE", requires = "animation")]
    pub frames: Option<String>,
    /// glTF clip (name or index).
    #[arg(long, value_name = "NAME|INDEX", requires = "animation")]
    pub clip: Option<String>,
    /// Frames per second a glTF clip is sampled at.
    #[arg(long, value_name = "F", default_value_t = 30.0, requires = "animation")]
    pub fps: f64,
    /// Colour of mesh targets: auto (the glTF base-colour texture, else vertex colours, else
    /// normal), normal (world normal as colour), texture (the base-colour texture, required).
    #[arg(long, value_enum, default_value_t = TargetColor::Auto)]
    pub color: TargetColor,
    /// Splatting model fitted: 3dgs (gsplat's rules) or 2dgs (surfels; needed by
    /// --normal-weight and --distortion-weight, and for 2-scale sets).
    #[arg(long, value_enum, default_value_t = FitMode::Gaussian3d)]
    pub mode: FitMode,
    /// Background colour r,g,b in 0..1 (renders and mesh targets).
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb, default_value = "0,0,0")]
    pub background: [f32; 3],
    /// Optimisation steps (one view each).
    #[arg(long, value_name = "N", default_value_t = 1000,
        value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    pub iterations: u64,
    /// Stop once this many seconds of optimisation are spent (scoring excluded), or at
    /// --iterations, whichever comes first: fits compared at a fixed time.
    #[arg(long, value_name = "SECONDS")]
    pub time_budget: Option<f64>,
    /// Learning rate of the local means (triangle scales).
    #[arg(long, value_name = "LR", default_value_t = LearningRates::BOUND.means)]
    pub lr_means: f64,
    /// The means' learning rate at the end, as a fraction of --lr-means.
    #[arg(long, value_name = "F", default_value_t = 0.01)]
    pub lr_means_final: f64,
    /// Learning rate of the log-scales.
    #[arg(long, value_name = "LR", default_value_t = LearningRates::BOUND.log_scales)]
    pub lr_scales: f64,
    /// Learning rate of the quaternions.
    #[arg(long, value_name = "LR", default_value_t = LearningRates::BOUND.rotations)]
    pub lr_rotations: f64,
    /// Learning rate of the opacity logits.
    #[arg(long, value_name = "LR", default_value_t = LearningRates::BOUND.opacities)]
    pub lr_opacities: f64,
    /// Learning rate of the SH DC coefficients.
    #[arg(long, value_name = "LR", default_value_t = LearningRates::BOUND.sh_dc)]
    pub lr_sh: f64,
    /// Learning rate of the higher SH coefficients.
    #[arg(long, value_name = "LR", default_value_t = LearningRates::BOUND.sh_rest)]
    pub lr_sh_rest: f64,
    /// Weight of D-SSIM in the rgb loss.
    #[arg(long, value_name = "L", default_value_t = DEFAULT_LAMBDA_DSSIM)]
    pub lambda_dssim: f64,
    /// Weight of the depth L1 (mesh targets).
    #[arg(long, value_name = "W", default_value_t = 0.0)]
    pub depth_weight: f64,
    /// Weight of the alpha L1 against the target mask.
    #[arg(long, value_name = "W", default_value_t = 0.0)]
    pub alpha_weight: f64,
    /// Weight of 2DGS's depth-normal consistency (--mode 2dgs).
    #[arg(long, value_name = "W", default_value_t = 0.0)]
    pub normal_weight: f64,
    /// Weight of 2DGS's depth distortion, a mean over the pixels (--mode 2dgs).
    #[arg(long, value_name = "W", default_value_t = 0.0)]
    pub distortion_weight: f64,
    /// Run one refine round every N iterations (not after the last).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub refine_every: Option<u64>,
    /// Refine's alpha radius in mean spacings of the centres.
    #[arg(long, value_name = "F", default_value_t = trisplat_pipeline::config::DEFAULT_ALPHA_SPACINGS)]
    pub refine_alpha_spacings: f64,
    /// No pruning in the refine rounds.
    #[arg(long)]
    pub refine_no_prune: bool,
    /// Seed of the view order (and of refine's sampling).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Largest image (pixels) of any camera, checked before anything is rendered or read.
    #[arg(long, value_name = "N", default_value_t = MAX_IMAGE_PIXELS, value_parser = parse_max_pixels)]
    pub max_pixels: u64,
    /// Most target views held in memory (training and held-out cameras times frames).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_VIEWS,
        value_parser = clap::value_parser!(u64).range(1..))]
    pub max_views: u64,
    /// Score held-out views every N iterations.
    #[arg(long, value_name = "N", default_value_t = 100,
        value_parser = clap::value_parser!(u64).range(1..))]
    pub eval_every: u64,
    /// Adaptive density control: clone, split, prune, opacity resets (3DGS, GaussianAvatars).
    #[arg(long)]
    pub densify: bool,
    /// Densify only after this iteration.
    #[arg(long, value_name = "N", default_value_t = density::DEFAULT_DENSIFY_FROM as u64, requires = "densify")]
    pub densify_from: u64,
    /// Densify and reset opacities only before this iteration.
    #[arg(long, value_name = "N", default_value_t = density::DEFAULT_DENSIFY_UNTIL as u64, requires = "densify")]
    pub densify_until: u64,
    /// Densify every N iterations.
    #[arg(long, value_name = "N", default_value_t = density::DEFAULT_DENSIFY_EVERY as u64, requires = "densify")]
    pub densify_every: u64,
    /// Mean NDC screen-space gradient norm at or above which a Gaussian densifies.
    #[arg(long, value_name = "T", default_value_t = density::DEFAULT_GRAD_THRESHOLD, requires = "densify")]
    pub densify_grad: f64,
    /// Clone at or below this fraction of the camera extent (largest world scale at rest),
    /// split above.
    #[arg(long, value_name = "F", default_value_t = density::DEFAULT_PERCENT_DENSE, requires = "densify")]
    pub percent_dense: f64,
    /// Prune below this opacity (never a triangle's last Gaussian).
    #[arg(long, value_name = "F", default_value_t = density::DEFAULT_PRUNE_OPACITY, requires = "densify")]
    pub prune_opacity: f64,
    /// Reset opacities to at most 0.01 every N iterations (0: never).
    #[arg(long, value_name = "N", default_value_t = density::DEFAULT_OPACITY_RESET_EVERY as u64, requires = "densify")]
    pub opacity_reset_every: u64,
    /// Also prune Gaussians larger than F x the camera extent after the first opacity reset
    /// (3DGS: 0.1).
    #[arg(long, value_name = "F", requires = "densify")]
    pub max_world_size: Option<f64>,
    /// Raise the active SH degree by one every N iterations, from 0 (3DGS: 1000).
    #[arg(long, value_name = "N")]
    pub sh_up_every: Option<u64>,
    /// Appearance fitted: sh (the set's SH colour and opacities, with its geometry), mlp (a
    /// hash-grid MLP's colour and opacity, geometry held fixed; the weights are written to
    /// OUT.safetensors beside the output PLY, which `render` reads) or brdf (each Gaussian's
    /// albedo, roughness and F0 under --env, written into the PLY; with --fit-normals also its
    /// rotation and scales).
    #[arg(long, value_enum, default_value_t = Appearance::Sh)]
    pub appearance: Appearance,
    /// --appearance mlp: Adam's learning rate of the MLP weights.
    #[arg(long, value_name = "LR", default_value_t = NeuralLearningRates::default().mlp)]
    pub mlp_lr: f64,
    /// --appearance brdf: the environment and the material fit's options.
    #[command(flatten)]
    pub brdf: BrdfArgs,
    /// --appearance mlp: Adam's learning rate of the hash tables.
    #[arg(long, value_name = "LR", default_value_t = NeuralLearningRates::default().tables)]
    pub hash_lr: f64,
}

/// What `fit` optimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Appearance {
    /// Spherical harmonics and opacities per Gaussian, with the geometry.
    Sh,
    /// A hash-grid MLP (docs/conventions.md §5 "Neural appearance"); geometry fixed.
    Mlp,
    /// Relightable materials (albedo, roughness, F0) under a known environment map
    /// (docs/conventions.md §5 "Relighting"); geometry fixed unless --fit-normals.
    Brdf,
}

/// The template mesh targets are rendered from: `template` with the base colour (materials,
/// base-colour textures, corner uvs) of its glTF/GLB file `path` attached when `color` may use
/// it. With `auto`, a texture this reader does not support (another uv set, a texture
/// transform, another image format) is a warning and the targets fall back to vertex colours
/// or normals; with `texture` it is an error, as is a template without a base-colour texture.
fn target_template(template: &TriMesh, path: &Path, color: TargetColor) -> anyhow::Result<TriMesh> {
    let gltf = matches!(Format::from_path(path), Ok(Format::Gltf | Format::Glb));
    if color == TargetColor::Normal || (!gltf && color == TargetColor::Auto) {
        return Ok(template.clone());
    }
    if !gltf {
        bail!(
            "{}: --color texture needs a glTF/GLB template with a base-colour texture",
            path.display()
        );
    }
    let base = match read_gltf_base_color(path) {
        Ok(base) => base,
        Err(e @ IoError::Unsupported { .. }) if color == TargetColor::Auto => {
            eprintln!("warning: {e}; --color auto renders the targets without the texture");
            return Ok(template.clone());
        }
        Err(e) => return Err(e.into()),
    };
    if color == TargetColor::Texture && !base.has_texture() {
        bail!(
            "{}: --color texture: no material of the template has a baseColorTexture",
            path.display()
        );
    }
    template
        .clone()
        .with_base_color(Arc::new(base))
        .with_context(|| format!("{}: the base colour", path.display()))
}

fn cameras_of(path: &Path, origin: DVec3, max_pixels: u64) -> anyhow::Result<Vec<Camera>> {
    let cams = read_camera_file(path, None, max_pixels)?;
    Ok(cams.iter().map(|c| c.translated(-origin)).collect())
}

/// Runs `trisplat fit`.
///
/// # Errors
/// Unreadable or mismatched inputs (named), options out of range, a failed fit or write.
pub fn run(args: FitArgs, ctx: &Context) -> anyhow::Result<()> {
    for input in [&args.gaussians, &args.template, &args.cameras] {
        refuse_to_overwrite(input, &args.output)?;
    }
    if args.eval_cameras.is_none() && args.eval_images.is_some() {
        return Err(UsageError("--eval-images needs --eval-cameras".into()).into());
    }
    // The environment of a brdf fit, read first: a bad map fails before any work.
    let env = open_environment(&args.brdf, args.appearance == Appearance::Brdf)?;
    let started = std::time::Instant::now();
    // The template, the set and the frames' positions.
    let (template, set, positions, origin) = match &args.animation {
        None => {
            let template = read_template(&args.template)?;
            let set = read_bound(&args.gaussians, &template, &args.template)?;
            let rest = template.positions().to_vec();
            (template, set, vec![(0usize, rest)], DVec3::ZERO)
        }
        Some(animation) => {
            let config = ExtractConfig {
                template: args.template.clone(),
                animation: Some(animation.clone()),
                gaussians: Some(args.gaussians.clone()),
                methods: Vec::new(),
                output: args.output.with_extension("fit-unused"),
                frames: args.frames.clone(),
                gt: None,
                options: ExtractOptions {
                    animation: AnimationOptions {
                        clip: args.clip.clone(),
                        fps: args.fps,
                        ..Default::default()
                    },
                    ..ExtractOptions::default()
                },
            };
            let mut session = Session::open_with(
                &config,
                &SessionOptions {
                    weld: false,
                    ..SessionOptions::default()
                },
            )?;
            let mut positions = Vec::new();
            for f in session.frames() {
                positions.push((f, session.positions(f)?));
            }
            (
                session.template().clone(),
                session.gaussians().clone(),
                positions,
                session.origin(),
            )
        }
    };
    let train_cams = cameras_of(&args.cameras, origin, args.max_pixels)?;
    let eval_cams = match &args.eval_cameras {
        Some(p) => cameras_of(p, origin, args.max_pixels)?,
        None => Vec::new(),
    };
    let frame_count = if args.images.is_some() {
        1
    } else {
        positions.len()
    };
    let views = (train_cams.len() + eval_cams.len()) as u64 * frame_count as u64;
    if views > args.max_views {
        bail!(
            "{views} target views ({} + {} cameras x {frame_count} frame(s)): over the limit of \
             {} views (raise it with --max-views)",
            train_cams.len(),
            eval_cams.len(),
            args.max_views
        );
    }
    let target_template = if args.images.is_none() {
        target_template(&template, &args.template, args.color)?
    } else {
        template.clone()
    };
    let make = |cams: &[Camera], images: Option<&PathBuf>| -> anyhow::Result<Vec<FitFrame>> {
        if cams.is_empty() {
            return Ok(Vec::new());
        }
        match images {
            Some(dir) => Ok(vec![FitFrame {
                frame: 0,
                positions: positions[0].1.clone(),
                targets: read_image_targets(dir, cams, args.depth_scale)?,
            }]),
            None => positions
                .iter()
                .map(|(f, p)| {
                    Ok(FitFrame {
                        frame: *f,
                        positions: p.clone(),
                        targets: mesh_targets(
                            &target_template,
                            p,
                            cams,
                            args.color,
                            args.background,
                        )
                        .with_context(|| format!("frame {f}"))?,
                    })
                })
                .collect(),
        }
    };
    let frames = make(&train_cams, args.images.as_ref())?;
    let eval_images = args.eval_images.as_ref().or(args.images.as_ref());
    let held_out = make(&eval_cams, eval_images)?;
    let options = FitOptions {
        iterations: usize::try_from(args.iterations)?,
        lr: LearningRates {
            means: args.lr_means,
            log_scales: args.lr_scales,
            rotations: args.lr_rotations,
            opacities: args.lr_opacities,
            sh_dc: args.lr_sh,
            sh_rest: args.lr_sh_rest,
        },
        means_lr_final: args.lr_means_final,
        lambda_dssim: args.lambda_dssim,
        depth_weight: args.depth_weight,
        alpha_weight: args.alpha_weight,
        normal_weight: args.normal_weight,
        distortion_weight: args.distortion_weight,
        refine_every: args.refine_every.map(usize::try_from).transpose()?,
        refine: RefineOptions {
            alpha_spacings: args.refine_alpha_spacings,
            prune: if args.refine_no_prune {
                PruneCriteria::none()
            } else {
                PruneCriteria::seed()
            },
            sample: trisplat_geometry::sampling::SampleOptions {
                seed: args.seed,
                ..Default::default()
            },
            ..RefineOptions::default()
        },
        render: match args.mode {
            FitMode::Gaussian3d => RenderOptions {
                background: args.background,
                ..RenderOptions::default()
            },
            FitMode::Surfel2d => RenderOptions {
                background: args.background,
                mode: RenderMode::Surfel2d,
                near: SURFEL_NEAR,
                ..RenderOptions::default()
            },
        },
        seed: args.seed,
        eval_every: usize::try_from(args.eval_every)?,
        densify: if args.densify {
            Some(DensifyOptions {
                from: usize::try_from(args.densify_from)?,
                until: usize::try_from(args.densify_until)?,
                every: usize::try_from(args.densify_every)?,
                grad_threshold: args.densify_grad,
                percent_dense: args.percent_dense,
                prune_opacity: args.prune_opacity,
                opacity_reset_every: match args.opacity_reset_every {
                    0 => None,
                    n => Some(usize::try_from(n)?),
                },
                max_world_size: args.max_world_size,
            })
        } else {
            None
        },
        sh_up_every: args.sh_up_every.map(usize::try_from).transpose()?,
        time_budget: args.time_budget,
    };
    let paths = MlpPaths {
        gaussians: &args.gaussians,
        template: &args.template,
        cameras: &args.cameras,
        output: &args.output,
    };
    if let Some(env) = &env {
        return run_brdf(
            &paths, &args.brdf, env, ctx, &set, &template, &frames, &held_out, &options,
        );
    }
    if args.appearance == Appearance::Mlp {
        let lr = NeuralLearningRates {
            mlp: args.mlp_lr,
            tables: args.hash_lr,
        };
        return run_mlp(
            &paths, lr, ctx, &set, &template, &frames, &held_out, &options, origin,
        );
    }
    let fitted = with_progress(
        ctx,
        args.iterations,
        "fitting",
        &args.gaussians,
        &args.template,
        |on_checkpoint| fit(&set, &template, &frames, &held_out, &options, on_checkpoint),
    )?;
    if !fitted.set.is_empty() && fitted.set.binding().is_none() {
        bail!("internal: the fitted set lost its binding");
    }
    write_gaussians(&args.output, &fitted.set, &PlyWriteOptions::default())?;
    let seconds = started.elapsed().as_secs_f64();
    let views: usize = frames.iter().map(|f| f.targets.len()).sum();
    let eval_views: usize = held_out.iter().map(|f| f.targets.len()).sum();
    if !ctx.json {
        for r in &fitted.refines {
            println!(
                "refine after iteration {}: {} -> {} Gaussians ({:.0} ms)",
                r.iteration, r.before, r.after, r.ms
            );
        }
        for d in &fitted.densify {
            println!(
                "densify after iteration {}: {} cloned, {} split, {} pruned ({} spared as their \
                 triangle's last) -> {} Gaussians ({:.0} ms)",
                d.iteration, d.cloned, d.split, d.pruned, d.spared, d.gaussians, d.ms
            );
        }
        for i in &fitted.opacity_resets {
            println!("opacities reset after iteration {i}");
        }
        println!(
            "fit: {} -> {} Gaussians, {} iterations{} on {views} view(s) of {} frame(s), {:.1} ms \
             per iteration, {seconds:.2} s; wrote {}",
            set.len(),
            fitted.set.len(),
            fitted.iterations,
            out_of_time_note(fitted.out_of_time),
            frames.len(),
            fitted.seconds_per_iteration * 1e3,
            args.output.display()
        );
    }
    ctx.emit(
        "fit",
        serde_json::json!({
            "output": args.output,
            "template": args.template,
            "before": set.len(),
            "gaussians": fitted.set.len(),
            "iterations": fitted.iterations,
            "out_of_time": fitted.out_of_time,
            "frames": frames.iter().map(|f| f.frame).collect::<Vec<_>>(),
            "views": views,
            "eval_views": eval_views,
            "target": if args.images.is_some() { "images" } else { "mesh" },
            "ms_per_iteration": fitted.seconds_per_iteration * 1e3,
            "stage_ms": fitted.stage_ms,
            "seconds": seconds,
            "checkpoints": fitted.checkpoints,
            "refines": fitted.refines,
            "densify": fitted.densify,
            "opacity_resets": fitted.opacity_resets,
        }),
    )
}

/// The splatting models `fit` can differentiate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FitMode {
    /// 3DGS EWA splatting with gsplat's rules.
    #[value(name = "3dgs")]
    Gaussian3d,
    /// 2DGS surfels (hbb1's ray-splat intersection, near plane 0.2 as hbb1).
    #[value(name = "2dgs")]
    Surfel2d,
}
