//! `trisplat refine (G.ply --template T | --avatar DIR) -o OUT.ply [--rounds N] [--alpha A |
//! --alpha-spacings F] [--keep-clusters K] [--smooth-method M] [--smooth-iterations N]
//! [--lambda L] [--mu M] [--samples N] [--sample-method M] [--seed S] [--rebind inherit|nearest]
//! [--gate seed|stable] [--outlier-threshold D] [--normal-threshold C] [--neighbours K]
//! [--no-prune] [--surfaces DIR]`: the VGA/GVA surface-guided re-initialisation loop (`pipeline::refine`).

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_geometry::io::{WriteOptions, write_mesh};
use trisplat_geometry::sampling::{DEFAULT_CURVATURE_STRENGTH, SampleMethod, SampleOptions};
use trisplat_geometry::smoothing::{
    DEFAULT_ITERATIONS, DEFAULT_LAMBDA, DEFAULT_MU, SmoothMethod, SmoothOptions,
};
use trisplat_pipeline::avatar::{AvatarFolder, bind_lam};
use trisplat_pipeline::config::DEFAULT_ALPHA_SPACINGS;
use trisplat_pipeline::input::read_template;
use trisplat_pipeline::refine::{
    DEFAULT_CHAMFER_SAMPLES, DEFAULT_ROUNDS, PruneCriteria, Rebind, RefineOptions, RoundReport,
    refine,
};
use trisplat_splat::Convention;
use trisplat_splat::DeformMode;
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};
use trisplat_splat::{DEFAULT_NEIGHBOURS, Gate, SEED_NORMAL, SEED_OUTLIER};

use super::bind::ConventionArg;
use super::densify::GateArg;
use super::sample::DEFAULT_MAX_POINTS;
use super::{Context, refuse_to_overwrite};

/// How the new Gaussians choose their triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RebindArg {
    /// The triangle of the old Gaussian each new one copies (binding inheritance).
    Inherit,
    /// The template triangle nearest the new centre.
    Nearest,
}

/// Arguments of `trisplat refine`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Surface-guided re-initialisation of a bound avatar (VGA/GVA's \
    Re-Gaussian step), --rounds times. One round: the bound Gaussians baked at the template's \
    rest; the alpha shape of their centres (--alpha, default --alpha-spacings 6 x the centres' \
    mean nearest-neighbour spacing; --keep-clusters K keeps the K largest pieces); that surface \
    smoothed (--smooth-method laplacian, --smooth-iterations 10, --lambda 0.5); --samples \
    points on it (default: as many as there are Gaussians less those refilled below, so the \
    count grows only by what that draw empties; --sample-method uniform, seed --seed + round); each point a new Gaussian copying every attribute of the old Gaussian \
    nearest to it (rotation, scales, opacity, SH, extra properties, in world space); the new \
    Gaussians bound to the triangle of the old Gaussian they copy (--rebind inherit) or to the \
    nearest template triangle (--rebind nearest); a triangle that had Gaussians and would be \
    left without any keeps its first old Gaussian. Then pruning with the gate's criteria in \
    world space, never emptying a triangle: --gate seed (default; GSDHuman) prunes where the \
    mean distance to the --neighbours 5 nearest Gaussians exceeds --outlier-threshold 0.015 \
    (scene units) or the mean normal deviation 1 - |cos| exceeds --normal-threshold 0.3; \
    --gate stable prunes only by the thresholds given, the normal criterion as prune's (mean \
    |cos| below C). --no-prune skips the stage. --surfaces DIR writes each round's alpha shape and \
    smoothed surface (round_NN_alpha.ply, round_NN_smoothed.ply).\n\n\
    Prints per round the Gaussian count, the Chamfer distance of the centres to the template \
    (surface mode: centres to the exact surface, --chamfer-samples template samples to the \
    nearest centre) and the milliseconds of each stage; --json prints them as `rounds`. The \
    output is bound like the input (local parameters, binding_0)."
)]
pub struct RefineArgs {
    /// Bound Gaussian PLY (local parameters, binding_0), e.g. from `trisplat bind`.
    #[arg(required_unless_present = "avatar")]
    pub gaussians: Option<PathBuf>,
    /// Template mesh the Gaussians are bound to (its rest state).
    #[arg(long, value_name = "T", required_unless_present = "avatar")]
    pub template: Option<PathBuf>,
    /// A LAM avatar folder, bound as `bind --avatar DIR` does (instead of G.ply --template T).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["gaussians", "template"])]
    pub avatar: Option<PathBuf>,
    /// Output Gaussian PLY (bound).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Frame convention of the bound set.
    #[arg(long, value_enum, default_value_t = ConventionArg::Gaussianavatars)]
    pub convention: ConventionArg,
    /// Rounds of re-initialisation.
    #[arg(long, default_value_t = DEFAULT_ROUNDS as u32, value_name = "N",
        value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub rounds: u32,
    /// Alpha-shape radius (scene units); default: --alpha-spacings x the mean spacing.
    #[arg(long, value_name = "A")]
    pub alpha: Option<f64>,
    /// Alpha radius in mean nearest-neighbour spacings of the centres (without --alpha).
    #[arg(long, value_name = "F", default_value_t = DEFAULT_ALPHA_SPACINGS, conflicts_with = "alpha")]
    pub alpha_spacings: f64,
    /// Keep only the alpha shape's pieces at least as large as the K-th largest (0: all).
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub keep_clusters: usize,
    /// Smoothing of the alpha shape.
    #[arg(long, value_enum, default_value_t = SmoothMethod::Laplacian)]
    pub smooth_method: SmoothMethod,
    /// Smoothing iterations.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_ITERATIONS)]
    pub smooth_iterations: usize,
    /// Smoothing step λ.
    #[arg(long, value_name = "L", default_value_t = DEFAULT_LAMBDA, allow_negative_numbers = true)]
    pub lambda: f64,
    /// Taubin's second step μ.
    #[arg(long, value_name = "M", default_value_t = DEFAULT_MU, allow_negative_numbers = true)]
    pub mu: f64,
    /// Points sampled on the smoothed surface (new Gaussians); default: the current count less
    /// the old Gaussians kept to refill emptied triangles.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub samples: Option<u64>,
    /// Largest --samples accepted, checked before anything is allocated.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_POINTS)]
    pub max_samples: u64,
    /// Sampling method.
    #[arg(long, value_enum, default_value_t = SampleMethod::Uniform)]
    pub sample_method: SampleMethod,
    /// Curvature weighting of --sample-method curvature.
    #[arg(long, value_name = "C", default_value_t = DEFAULT_CURVATURE_STRENGTH)]
    pub curvature_strength: f64,
    /// Seed of the sampling (round r uses seed + r).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// How the new Gaussians choose their triangle.
    #[arg(long, value_enum, default_value_t = RebindArg::Inherit)]
    pub rebind: RebindArg,
    /// Form and defaults of the pruning criteria.
    #[arg(long, value_enum, default_value_t = GateArg::Seed)]
    pub gate: GateArg,
    /// Outlier threshold: mean distance to the nearest Gaussians (scene units; seed: 0.015).
    #[arg(long, value_name = "D")]
    pub outlier_threshold: Option<f64>,
    /// Normal threshold (seed: deviation 1 - |cos| above, default 0.3; stable: |cos| below).
    #[arg(long, value_name = "C")]
    pub normal_threshold: Option<f64>,
    /// Neighbours of both pruning criteria.
    #[arg(long, value_name = "K", default_value_t = DEFAULT_NEIGHBOURS as u32,
        value_parser = clap::value_parser!(u32).range(1..))]
    pub neighbours: u32,
    /// No pruning stage.
    #[arg(long, conflicts_with_all = ["outlier_threshold", "normal_threshold"])]
    pub no_prune: bool,
    /// Write each round's alpha shape and smoothed surface into this folder
    /// (round_NN_alpha.ply, round_NN_smoothed.ply; created if missing).
    #[arg(long, value_name = "DIR")]
    pub surfaces: Option<PathBuf>,
    /// Template samples of the Chamfer distance.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_CHAMFER_SAMPLES as u64,
        value_parser = clap::value_parser!(u64).range(1..))]
    pub chamfer_samples: u64,
}

/// Runs `trisplat refine`.
///
/// # Errors
/// Unreadable inputs, an unbound set or one bound past the template, options out of range, a
/// round that fails (named, with its stage), an output equal to an input, a failed write.
pub fn run(args: RefineArgs, ctx: &Context) -> anyhow::Result<()> {
    let convention = Convention::from(args.convention);
    for (name, n) in [
        ("--samples", args.samples.unwrap_or(0)),
        ("--chamfer-samples", args.chamfer_samples),
    ] {
        if n > args.max_samples {
            bail!(
                "{name} {n}: over the limit of {} points (raise it with --max-samples)",
                args.max_samples
            );
        }
    }
    let to_usize = |n: u64| usize::try_from(n).context("the number does not fit this machine");
    let (template_path, set) = match (&args.avatar, &args.gaussians, &args.template) {
        (Some(dir), _, _) => {
            let avatar = AvatarFolder::open(dir)?;
            refuse_to_overwrite(&avatar.template, &args.output)?;
            refuse_to_overwrite(&avatar.gaussians, &args.output)?;
            let mesh = read_template(&avatar.template)?;
            let identity: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
            let set = bind_lam(
                &avatar.gaussians,
                &mesh,
                &mesh,
                &identity,
                &avatar.template,
                convention,
            )?;
            (avatar.template, set)
        }
        (None, Some(g), Some(t)) => {
            refuse_to_overwrite(g, &args.output)?;
            refuse_to_overwrite(t, &args.output)?;
            let set = read_gaussians(g)?;
            if set.binding().is_none() {
                bail!(
                    "{}: the Gaussians are not bound to triangles (no binding property): bind \
                     them with `trisplat bind {} --gaussians {}` first",
                    g.display(),
                    t.display(),
                    g.display()
                );
            }
            (t.clone(), set)
        }
        _ => bail!("refine needs G.ply --template T, or --avatar DIR"),
    };
    let name = args
        .gaussians
        .as_ref()
        .or(args.avatar.as_ref())
        .map_or_else(String::new, |p| p.display().to_string());
    let template = read_template(&template_path)?;
    let prune = if args.no_prune {
        PruneCriteria::none()
    } else {
        let k = args.neighbours as usize;
        match args.gate {
            GateArg::Seed => PruneCriteria {
                gate: Gate::Seed,
                outlier: Some(args.outlier_threshold.unwrap_or(SEED_OUTLIER)),
                normal: Some(args.normal_threshold.unwrap_or(SEED_NORMAL)),
                k,
            },
            GateArg::Stable => PruneCriteria {
                gate: Gate::Stable,
                outlier: args.outlier_threshold,
                normal: args.normal_threshold,
                k,
            },
        }
    };
    let options = RefineOptions {
        rounds: args.rounds as usize,
        alpha: args.alpha,
        alpha_spacings: args.alpha_spacings,
        keep_clusters: args.keep_clusters,
        smooth: SmoothOptions {
            method: args.smooth_method,
            iterations: args.smooth_iterations,
            lambda: args.lambda,
            mu: args.mu,
        },
        samples: args.samples.map(to_usize).transpose()?,
        sample: SampleOptions {
            method: args.sample_method,
            seed: args.seed,
            curvature_strength: args.curvature_strength,
        },
        rebind: match args.rebind {
            RebindArg::Inherit => Rebind::Inherit,
            RebindArg::Nearest => Rebind::Nearest,
        },
        prune,
        mode: match convention {
            Convention::GaussianAvatars => DeformMode::Binding,
            Convention::SurfHead => DeformMode::Jacobian,
        },
        chamfer_samples: to_usize(args.chamfer_samples)?,
    };
    let started = std::time::Instant::now();
    let spinner = ctx.progress.spinner("refining");
    let json = ctx.json;
    let created_dir = match &args.surfaces {
        Some(dir) if !dir.is_dir() => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create the folder", dir.display()))?;
            Some(dir.clone())
        }
        _ => None,
    };
    let mut written: Vec<PathBuf> = Vec::new();
    let mut write_error: Option<anyhow::Error> = None;
    let result = refine(&set, &template, &options, |r, surfaces| {
        if !json {
            spinner.suspend(|| print_round(r));
        }
        if let (Some(dir), None) = (&args.surfaces, &write_error) {
            for (kind, mesh) in [("alpha", surfaces.alpha), ("smoothed", surfaces.smoothed)] {
                let path = dir.join(format!("round_{:02}_{kind}.ply", r.round));
                match write_mesh(&path, mesh, WriteOptions::default()) {
                    Ok(()) => written.push(path),
                    Err(e) => write_error = Some(e.into()),
                }
            }
        }
    })
    .with_context(|| format!("{name} (template {})", template_path.display()))
    .and_then(|refined| match write_error.take() {
        Some(e) => Err(e),
        None => Ok(refined),
    })
    .and_then(|refined| {
        write_gaussians(&args.output, &refined.set, &PlyWriteOptions::default())?;
        Ok(refined)
    });
    spinner.finish_and_clear();
    let refined = match result {
        Ok(r) => r,
        Err(e) => {
            // A failed run leaves none of the surfaces it wrote.
            for path in &written {
                let _ = std::fs::remove_file(path);
            }
            if let Some(dir) = created_dir {
                // Only if empty: nothing but what this run created is removed.
                let _ = std::fs::remove_dir(dir);
            }
            return Err(e);
        }
    };
    let seconds = started.elapsed().as_secs_f64();
    if !json {
        println!(
            "refine: {} -> {} Gaussians in {} round(s), {seconds:.2} s; wrote {}",
            set.len(),
            refined.set.len(),
            refined.rounds.len(),
            args.output.display()
        );
    }
    ctx.emit(
        "refine",
        serde_json::json!({
            "output": args.output,
            "template": template_path,
            "before": set.len(),
            "gaussians": refined.set.len(),
            "triangles": template.triangle_count(),
            "rounds": refined.rounds,
            "seconds": seconds,
            "surfaces": written,
        }),
    )
}

/// One round's line of the text output.
fn print_round(r: &RoundReport) {
    let m = &r.ms;
    println!(
        "round {}: {} -> {} Gaussians (alpha {:.4}: {} triangles in {} piece(s); {} sampled, {} \
         refilled, {} flagged, {} pruned, {} spared); Chamfer L1 to the template {:.6} -> {:.6}; \
         ms: bake {:.1}, alpha {:.1}, smooth {:.1}, sample {:.1}, inherit {:.1}, bind {:.1}, \
         prune {:.1}, chamfer {:.1}, round {:.1}",
        r.round,
        r.before,
        r.after,
        r.alpha,
        r.alpha_triangles,
        r.kept_pieces,
        r.samples,
        r.refilled,
        r.flagged,
        r.pruned,
        r.spared,
        r.chamfer_before.chamfer_l1,
        r.chamfer_after.chamfer_l1,
        m.bake,
        m.alpha,
        m.smooth,
        m.sample,
        m.inherit,
        m.bind,
        m.prune,
        m.chamfer,
        r.total_ms
    );
}
