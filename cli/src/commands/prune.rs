//! `trisplat prune G.ply -o OUT.ply [--template T] [--convention ...] [--min-opacity O]
//! [--outlier-threshold D] [--outlier-k K] [--normal-threshold C] [--normal-k K] [--mask FILE]
//! [--gate seed|stable]`.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};
use trisplat_splat::{
    DEFAULT_NEIGHBOURS, SEED_NORMAL, SEED_OUTLIER, TriangleCounts, normal_deviation_mask,
    normal_inconsistency_mask, outlier_mask, prune,
};

use super::densify::{GateArg, TemplateArgs, check_non_negative, load_masked};
use super::{Context, refuse_to_overwrite};

/// Arguments of `trisplat prune`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Remove Gaussians that meet any of the given criteria (at least one is \
    needed):\n  \
    --min-opacity O: opacity (sigmoid of the stored logit) below O (3DGS prunes below 0.005);\n  \
    --outlier-threshold D: mean distance to the --outlier-k nearest other Gaussians (default \
    5) above D, in scene units;\n  \
    --normal-threshold C: mean |cos| between the Gaussian's normal (its shortest axis) and \
    those of its --normal-k nearest Gaussians (default 5) below C (0..1);\n  \
    --mask FILE: one 0/1 per Gaussian, 1 = remove.\n\n\
    --gate seed (GSDHuman) turns on its defaults, each overridable: --outlier-threshold 0.015 \
    (scene units), and --normal-threshold 0.3 read as the seed's ε_n on the mean normal \
    deviation 1 - |cos| (removed above it; the same as --gate stable with C = 1 - ε_n), both \
    with k = 5 neighbours. --gate stable (default) uses only the criteria given.\n\n\
    Distances and normals are measured in world space; a bound set is baked at the template's \
    rest (--template, --convention) and written back bound (local parameters, binding_0). A \
    bound set never loses the last Gaussians of a triangle (GaussianAvatars): when every \
    Gaussian of a triangle is flagged, none of them is removed. Prints one summary line on \
    stdout."
)]
pub struct PruneArgs {
    /// Input Gaussian PLY.
    pub gaussians: PathBuf,
    /// Output Gaussian PLY.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Template (bound sets).
    #[command(flatten)]
    pub template: TemplateArgs,
    /// Remove Gaussians with opacity below this.
    #[arg(long, value_name = "O")]
    pub min_opacity: Option<f64>,
    /// Remove Gaussians whose mean k-NN distance is above this (scene units).
    #[arg(long, value_name = "D")]
    pub outlier_threshold: Option<f64>,
    /// Neighbours of the outlier criterion.
    #[arg(long, value_name = "K", default_value_t = DEFAULT_NEIGHBOURS as u32,
        value_parser = clap::value_parser!(u32).range(1..))]
    pub outlier_k: u32,
    /// Remove Gaussians whose mean |cos| with their neighbours' normals is below this.
    #[arg(long, value_name = "C")]
    pub normal_threshold: Option<f64>,
    /// Neighbours of the normal-consistency criterion.
    #[arg(long, value_name = "K", default_value_t = DEFAULT_NEIGHBOURS as u32,
        value_parser = clap::value_parser!(u32).range(1..))]
    pub normal_k: u32,
    /// Mask file: one 0/1 per Gaussian, 1 = remove.
    #[arg(long, value_name = "FILE")]
    pub mask: Option<PathBuf>,
    /// Form and defaults of the criteria: seed (GSDHuman's ε_o 0.015 and ε_n 0.3 on) or stable
    /// (only the criteria given).
    #[arg(long, value_enum, default_value_t = GateArg::Stable)]
    pub gate: GateArg,
}

/// Runs `trisplat prune`.
///
/// # Errors
/// No criterion, unreadable inputs, bad masks or thresholds, an output equal to an input, a
/// failed write.
pub fn run(mut args: PruneArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.gaussians, &args.output)?;
    if args.gate == GateArg::Seed {
        args.outlier_threshold.get_or_insert(SEED_OUTLIER);
        args.normal_threshold.get_or_insert(SEED_NORMAL);
    }
    if let Some(t) = &args.template.template {
        refuse_to_overwrite(t, &args.output)?;
    }
    if args.min_opacity.is_none()
        && args.outlier_threshold.is_none()
        && args.normal_threshold.is_none()
        && args.mask.is_none()
    {
        bail!(
            "prune needs a criterion: --min-opacity, --outlier-threshold, --normal-threshold \
             or --mask"
        );
    }
    check_non_negative(&[
        ("--min-opacity", args.min_opacity),
        ("--outlier-threshold", args.outlier_threshold),
        ("--normal-threshold", args.normal_threshold),
    ])?;
    let spinner = ctx.progress.spinner("pruning");
    let (loaded, mut flagged) =
        load_masked(&args.gaussians, &args.template, args.mask.as_deref(), false)?;
    let name = args.gaussians.display().to_string();
    let n = loaded.set.len();
    if let Some(o) = args.min_opacity {
        for (i, f) in flagged.iter_mut().enumerate() {
            *f |= f64::from(loaded.set.opacity(i)) < o;
        }
    }
    if let Some(d) = args.outlier_threshold {
        let m = outlier_mask(&loaded.world, args.outlier_k as usize, d)
            .with_context(|| name.clone())?;
        flagged.iter_mut().zip(m).for_each(|(f, m)| *f |= m);
    }
    if let Some(c) = args.normal_threshold {
        let m = match args.gate {
            GateArg::Seed => normal_deviation_mask(&loaded.world, args.normal_k as usize, c),
            GateArg::Stable => normal_inconsistency_mask(&loaded.world, args.normal_k as usize, c),
        }
        .with_context(|| name.clone())?;
        flagged.iter_mut().zip(m).for_each(|(f, m)| *f |= m);
    }
    let mut counts = match loaded.triangles {
        Some(t) => Some(TriangleCounts::from_set(&loaded.set, t).with_context(|| name.clone())?),
        None => None,
    };
    let pruned = prune(&loaded.set, &flagged, counts.as_mut()).with_context(|| name.clone())?;
    spinner.finish_and_clear();
    write_gaussians(
        &args.output,
        &pruned.result.set,
        &PlyWriteOptions::default(),
    )?;
    let n_flagged = flagged.iter().filter(|&&f| f).count();
    if !ctx.json {
        println!(
            "prune: {n} -> {} Gaussians ({n_flagged} flagged, {} kept so no triangle is emptied)",
            pruned.result.set.len(),
            pruned.spared
        );
    }
    ctx.emit(
        "prune",
        serde_json::json!({
            "output": args.output,
            "before": n,
            "after": pruned.result.set.len(),
            "flagged": n_flagged,
            "spared": pruned.spared,
            "gate": match args.gate {
                GateArg::Seed => "seed",
                GateArg::Stable => "stable",
            },
        }),
    )
}
