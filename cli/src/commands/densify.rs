//! `trisplat densify G.ply -o OUT.ply [--template T] [--convention ...] [--mask FILE]
//! [--op split|clone] [--split-above S] [--children N] [--shrink F] [--seed S]
//! [--gate seed|stable] [--w2-threshold W] [--w2-to children|nearest]`, and the helpers `prune`
//! and `refine` share: the gate argument, checking thresholds, reading masks and baking a bound
//! set to world space at the template's rest.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_pipeline::input::read_template;
use trisplat_splat::GaussianSet;
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};
use trisplat_splat::{
    DEFAULT_SPLIT_CHILDREN, DEFAULT_SPLIT_SHRINK, SEED_W2_SQ, SplitOptions, TriangleCounts,
    W2Pairs, clone_selected, seed_w2_gate, split_selected, w2_gate, w2_sq_to_children,
    w2_sq_to_nearest,
};
use trisplat_splat::{DeformMode, Deformer};
use trisplat_splat::{FrameOptions, corners_of, frame};

use super::bind::ConventionArg;
use super::{Context, UsageError, refuse_to_overwrite};

/// The template options shared by `densify` and `prune`.
#[derive(Debug, clap::Args)]
pub struct TemplateArgs {
    /// Template mesh of a bound set (needed for world-space criteria and triangle counts).
    #[arg(long, value_name = "T")]
    pub template: Option<PathBuf>,
    /// Convention of the bound set's local parameters (how to bake them at the template's
    /// rest shape).
    #[arg(long, value_enum, default_value_t = ConventionArg::Gaussianavatars)]
    pub convention: ConventionArg,
}

/// The form of the densification and pruning criteria (`splat::Gate`,
/// docs/conventions.md §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum GateArg {
    /// GSDHuman's absolute thresholds and defaults: split where W² > ε_w (0.012), prune
    /// outliers above ε_o (0.015) and normal deviations 1 - |cos| above ε_n (0.3), k = 5.
    Seed,
    /// Scale-free thresholds: split where W2 > W × k (triangle scale), no defaults.
    Stable,
}

/// What the Wasserstein gate measures a Gaussian against.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum W2PairsArg {
    /// Its own split children (the mean W² over them; GSDHuman).
    Children,
    /// Its nearest other Gaussian by position.
    Nearest,
}

/// A Gaussian set with what the criteria need: the world-space set (baked at rest when bound),
/// each Gaussian's frame scale `k` (1 when not bound), and the triangle count.
pub struct Loaded {
    /// The set as read.
    pub set: GaussianSet,
    /// World-space version of the set.
    pub world: GaussianSet,
    /// Frame scale of each Gaussian's triangle at rest (1 for unbound sets).
    pub scale: Vec<f64>,
    /// Triangles of the template (bound sets).
    pub triangles: Option<usize>,
    /// The template and deformer that bake the set (bound sets).
    pub baker: Option<(trisplat_geometry::TriMesh, Deformer)>,
}

impl Loaded {
    /// `set` (in the frame of the loaded set: local parameters on the same template when
    /// bound) in world space.
    ///
    /// # Errors
    /// A binding past the template, a failed deformation.
    pub fn bake(&self, set: &GaussianSet) -> anyhow::Result<GaussianSet> {
        match &self.baker {
            Some((mesh, deformer)) => Ok(deformer.deform(set, mesh.positions())?),
            None => Ok(set.clone()),
        }
    }
}

/// Reads `path` and, for a bound set, bakes it with the template at rest.
///
/// # Errors
/// Unreadable files, a bound set without `--template`, bindings past the template.
pub fn load(path: &Path, template: &TemplateArgs) -> anyhow::Result<Loaded> {
    let set = read_gaussians(path)?;
    let name = path.display().to_string();
    let Some(binding) = set.binding() else {
        return Ok(Loaded {
            world: set.clone(),
            scale: vec![1.0; set.len()],
            set,
            triangles: None,
            baker: None,
        });
    };
    let Some(t_path) = &template.template else {
        bail!("{name}: the Gaussians are bound to triangles: give --template T");
    };
    let mesh = read_template(t_path)?;
    let mode = match template.convention {
        ConventionArg::Gaussianavatars => DeformMode::Binding,
        ConventionArg::Surfhead => DeformMode::Jacobian,
    };
    let deformer = Deformer::new(&mesh, mode);
    let world = deformer
        .deform(&set, mesh.positions())
        .with_context(|| format!("{name} (template {})", t_path.display()))?;
    let fo = FrameOptions::for_positions(mesh.positions());
    let scales: Vec<f64> = mesh
        .triangles()
        .iter()
        .map(|t| {
            frame(
                template.convention.into(),
                corners_of(mesh.positions(), *t),
                &fo,
            )
            .scale
        })
        .collect();
    let scale = binding
        .triangles
        .iter()
        .map(|t| scales.get(t.index()).copied().unwrap_or(1.0))
        .collect();
    Ok(Loaded {
        set,
        world,
        scale,
        triangles: Some(mesh.triangle_count()),
        baker: Some((mesh, deformer)),
    })
}

/// Reads a selection mask: one value per Gaussian, whitespace-separated, `1`/`0` or
/// `true`/`false`.
///
/// # Errors
/// Unreadable file, a token that is not a flag, a count that differs from `n`.
pub fn read_mask(path: &Path, n: usize) -> anyhow::Result<Vec<bool>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read the mask", path.display()))?;
    let mut mask = Vec::with_capacity(n.min(text.len()));
    for (i, token) in text.split_whitespace().enumerate() {
        mask.push(match token {
            "1" | "true" => true,
            "0" | "false" => false,
            _ => bail!(
                "{}: entry {i}: `{token}` is not 0/1/true/false",
                path.display()
            ),
        });
    }
    if mask.len() != n {
        bail!(
            "{}: the mask has {} entries for {n} Gaussians",
            path.display(),
            mask.len()
        );
    }
    Ok(mask)
}

/// [`load`], with a per-Gaussian selection: read from `mask` ([`read_mask`]), else `unmasked`
/// for every Gaussian.
///
/// # Errors
/// As [`load`] and [`read_mask`].
pub fn load_masked(
    path: &Path,
    template: &TemplateArgs,
    mask: Option<&Path>,
    unmasked: bool,
) -> anyhow::Result<(Loaded, Vec<bool>)> {
    let loaded = load(path, template)?;
    let n = loaded.set.len();
    let selection = match mask {
        Some(p) => read_mask(p, n)?,
        None => vec![unmasked; n],
    };
    Ok((loaded, selection))
}

/// Checks the thresholds given, `(flag, value)`: each must be a non-negative number.
///
/// # Errors
/// The first that is not, named by its flag.
pub fn check_non_negative(thresholds: &[(&str, Option<f64>)]) -> anyhow::Result<()> {
    for &(flag, v) in thresholds {
        if v.is_some_and(|v| !v.is_finite() || v < 0.0) {
            bail!("{flag}: must be a non-negative number");
        }
    }
    Ok(())
}

/// Densify operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OpArg {
    /// Replace each selected Gaussian by children sampled from it (scales shrunk).
    Split,
    /// Add a copy of each selected Gaussian.
    Clone,
}

/// Arguments of `trisplat densify`.
#[derive(Debug, clap::Args)]
#[command(
    after_long_help = "Densify Gaussians: clone or split a selection (3DGS / GaussianAvatars \
    rules). On a bound set, clones and children keep the parent's triangle (binding \
    inheritance) and its local frame; the output stays bound (local parameters, binding_0).\n\n\
    Selection: --mask FILE (one 0/1 per Gaussian; default every Gaussian), narrowed by the \
    Wasserstein gate in one of two forms (docs/conventions.md §4). --gate stable (default): \
    only with --w2-threshold W, a Gaussian may densify only if the 2-Wasserstein distance W2 \
    (not squared) to its nearest neighbour (--w2-to nearest, the default here) exceeds W times \
    its triangle's frame scale k (scene units for an unbound set). --gate seed (GSDHuman): a \
    Gaussian may densify only if the squared distance W² to its split children (--w2-to \
    children, the default here: the mean over the --children children the split draws, the \
    same ones it then makes) exceeds the absolute --w2-threshold ε_w (default 0.012, scene \
    units squared). The forms agree for W = √ε_w / k. Distances are measured in world space, a \
    bound set baked at the template's rest (--template, --convention).\n\n\
    Operation: --op split (default) or clone; or --split-above S: selected Gaussians whose \
    largest world-space scale exceeds S are split, the others cloned (the 3DGS rule without \
    gradients). A split makes --children N children (default 2) at positions drawn from the \
    parent Gaussian (seeded, one stream per parent) with scales divided by shrink × N \
    (default 0.8 × N).\n\n\
    Prints one summary line on stdout."
)]
pub struct DensifyArgs {
    /// Input Gaussian PLY.
    pub gaussians: PathBuf,
    /// Output Gaussian PLY.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Template (bound sets).
    #[command(flatten)]
    pub template: TemplateArgs,
    /// Selection mask file (one 0/1 per Gaussian); default: every Gaussian.
    #[arg(long, value_name = "FILE")]
    pub mask: Option<PathBuf>,
    /// Operation on the selection.
    #[arg(long, value_enum, default_value_t = OpArg::Split, conflicts_with = "split_above")]
    pub op: OpArg,
    /// Split selected Gaussians whose largest world scale exceeds S, clone the others.
    #[arg(long, value_name = "S")]
    pub split_above: Option<f64>,
    /// Children per split.
    #[arg(long, default_value_t = DEFAULT_SPLIT_CHILDREN as u32, value_name = "N",
        value_parser = clap::value_parser!(u32).range(1..))]
    pub children: u32,
    /// Split scale shrink factor (children's scales are divided by shrink × N).
    #[arg(long, default_value_t = DEFAULT_SPLIT_SHRINK, value_name = "F")]
    pub shrink: f64,
    /// Seed of the split sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Form of the Wasserstein gate: seed (W² > ε_w, absolute) or stable (W2 > W × k).
    #[arg(long, value_enum, default_value_t = GateArg::Stable)]
    pub gate: GateArg,
    /// Wasserstein gate threshold: stable W (relative to the triangle scale k; no gate when
    /// absent), seed ε_w (scene units squared; default 0.012).
    #[arg(long, value_name = "W")]
    pub w2_threshold: Option<f64>,
    /// What the gate measures a Gaussian against (default: children for seed, nearest for
    /// stable; needs a gate).
    #[arg(long, value_enum, value_name = "PAIRS")]
    pub w2_to: Option<W2PairsArg>,
}

/// Runs `trisplat densify`.
///
/// # Errors
/// Unreadable inputs, bad masks or options, an output equal to an input, a failed write.
pub fn run(args: DensifyArgs, ctx: &Context) -> anyhow::Result<()> {
    refuse_to_overwrite(&args.gaussians, &args.output)?;
    if let Some(t) = &args.template.template {
        refuse_to_overwrite(t, &args.output)?;
    }
    if !(args.shrink.is_finite() && args.shrink > 0.0) {
        bail!("--shrink {}: must be a positive number", args.shrink);
    }
    check_non_negative(&[
        ("--split-above", args.split_above),
        ("--w2-threshold", args.w2_threshold),
    ])?;
    if args.gate == GateArg::Stable && args.w2_threshold.is_none() && args.w2_to.is_some() {
        return Err(UsageError(
            "--w2-to needs a Wasserstein gate: give --w2-threshold W or --gate seed".into(),
        )
        .into());
    }
    let spinner = ctx.progress.spinner("densifying");
    let (loaded, mut selected) =
        load_masked(&args.gaussians, &args.template, args.mask.as_deref(), true)?;
    let name = args.gaussians.display().to_string();
    let n = loaded.set.len();
    let n_selected_before_gate = selected.iter().filter(|&&s| s).count();
    let options = SplitOptions {
        children: args.children as usize,
        shrink: args.shrink,
        seed: args.seed,
    };
    let threshold = match args.gate {
        GateArg::Seed => Some(args.w2_threshold.unwrap_or(SEED_W2_SQ)),
        GateArg::Stable => args.w2_threshold,
    };
    let pairs = match (args.w2_to, args.gate) {
        (Some(W2PairsArg::Children), _) | (None, GateArg::Seed) => W2Pairs::Children,
        (Some(W2PairsArg::Nearest), _) | (None, GateArg::Stable) => W2Pairs::Nearest,
    };
    if let Some(w) = threshold {
        let w2_sq = match pairs {
            W2Pairs::Nearest => w2_sq_to_nearest(&loaded.world).with_context(|| name.clone())?,
            W2Pairs::Children => {
                // The children the split below makes for these parents (same seed, same
                // stream per parent index), baked like the parents.
                let trial = split_selected(&loaded.set, &vec![true; n], &options, None)
                    .with_context(|| name.clone())?;
                let children = loaded.bake(&trial.set).with_context(|| name.clone())?;
                w2_sq_to_children(&loaded.world, &children, &trial.sources)
                    .with_context(|| name.clone())?
            }
        };
        let gate = match args.gate {
            GateArg::Seed => seed_w2_gate(&w2_sq, w),
            GateArg::Stable => {
                let w2: Vec<f64> = w2_sq.iter().map(|d| d.sqrt()).collect();
                w2_gate(&w2, &loaded.scale, w).with_context(|| name.clone())?
            }
        };
        selected.iter_mut().zip(gate).for_each(|(s, g)| *s &= g);
    }
    let (split, clone): (Vec<bool>, Vec<bool>) = match (args.split_above, args.op) {
        (Some(s), _) => {
            let big: Vec<bool> = (0..n)
                .map(|i| f64::from(loaded.world.scale(i).max_element()) > s)
                .collect();
            (
                selected.iter().zip(&big).map(|(a, b)| *a && *b).collect(),
                selected.iter().zip(&big).map(|(a, b)| *a && !*b).collect(),
            )
        }
        (None, OpArg::Split) => (selected.clone(), vec![false; n]),
        (None, OpArg::Clone) => (vec![false; n], selected.clone()),
    };
    let mut counts = match loaded.triangles {
        Some(t) => Some(TriangleCounts::from_set(&loaded.set, t).with_context(|| name.clone())?),
        None => None,
    };
    // Clone first (clones go to the end), then split (the mask grows with the clones, which
    // are not split).
    let cloned =
        clone_selected(&loaded.set, &clone, counts.as_mut()).with_context(|| name.clone())?;
    let mut split_mask = split;
    split_mask.resize(cloned.set.len(), false);
    let result = split_selected(&cloned.set, &split_mask, &options, counts.as_mut())
        .with_context(|| name.clone())?;
    spinner.finish_and_clear();
    write_gaussians(&args.output, &result.set, &PlyWriteOptions::default())?;
    let n_split = split_mask.iter().filter(|&&s| s).count();
    let n_gated = n_selected_before_gate - selected.iter().filter(|&&s| s).count();
    let n_clone = clone.iter().filter(|&&s| s).count();
    if !ctx.json {
        let gated = match threshold {
            Some(w) => format!("; {n_gated} held back by the W2 gate at {w}"),
            None => String::new(),
        };
        println!(
            "densify: {n} -> {} Gaussians ({n_clone} cloned, {n_split} split into {} each{gated})",
            result.set.len(),
            args.children
        );
    }
    ctx.emit(
        "densify",
        serde_json::json!({
            "output": args.output,
            "before": n,
            "after": result.set.len(),
            "cloned": n_clone,
            "split": n_split,
            "children": args.children,
            "gate": match args.gate {
                GateArg::Seed => "seed",
                GateArg::Stable => "stable",
            },
            "w2_threshold": threshold,
            "gated": n_gated,
        }),
    )
}
