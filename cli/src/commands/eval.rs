//! `trisplat eval`: geometry metrics of a prediction against a ground truth (docs/conventions.md §8, §10).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::io::{self, Format, ply};
use trisplat_geometry::metrics::{self, DEFAULT_TAUS, Metrics, MetricsOptions, Shape};
use trisplat_geometry::rng::splitmix64;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::{PointCloud, TriMesh};

use super::Context;

/// Samples drawn on each mesh input unless `--samples` says otherwise.
pub const DEFAULT_SAMPLES: usize = 100_000;

/// Arguments of `trisplat eval`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Compare a prediction P with a ground truth G: Chamfer distances, normal consistency and \
F-score.

Inputs: a file with faces (.ply with a face element, .obj, .gltf, .glb) is a mesh and is \
sampled area-uniformly (--samples points, each with its triangle's unit normal); a .ply \
without faces is a point cloud, used as it is (with its normals nx ny nz if present).

Definitions (d(x, S) = Euclidean distance from x to the nearest point of S):
  accuracy           = mean over p in P of d(p, G)
  completeness       = mean over g in G of d(g, P)
  chamfer_l1         = (accuracy + completeness) / 2
  chamfer_l2         = (mean d(p, G)^2 + mean d(g, P)^2) / 2
  normal_consistency = (mean |n_p . n_nn(p)| + mean |n_g . n_nn(g)|) / 2
  normal_angle_deg   = (mean acos|n_p . n_nn(p)| + mean acos|n_g . n_nn(g)|) / 2, degrees
  precision@tau      = fraction of p with d(p, G) < tau
  recall@tau         = fraction of g with d(g, P) < tau
  fscore@tau         = 2 P R / (P + R), 0 when both are 0
where nn(x) is the neighbour that realises d. Normal metrics are null when either side has \
no normals. By default d is point-to-point (k-d tree). With --surface, d(x, S) is the exact \
distance to the triangles of S when S is a mesh (n_nn is then the closest triangle's \
normal), removing the sampling floor of about 0.5 sqrt(area / N).

Other tools differ: PyTorch3D sums the two squared means without halving; DTU's script \
drops distances above 20 mm. Thresholds are in the input's unit (metres for most data: \
the default taus are 1, 2.5, 5 and 10 mm; Recall@2.5mm is recall at 0.0025).")]
pub struct EvalArgs {
    /// Prediction: mesh (.ply/.obj/.gltf/.glb) or point cloud (.ply without faces).
    pub pred: PathBuf,
    /// Ground truth: mesh or point cloud.
    pub gt: PathBuf,
    /// Points sampled on each mesh input.
    #[arg(long, default_value_t = DEFAULT_SAMPLES, value_name = "N",
          value_parser = parse_samples)]
    pub samples: usize,
    /// Seed of the surface sampling (the ground truth uses an independent stream of it).
    #[arg(long, default_value_t = 0, value_name = "S")]
    pub seed: u64,
    /// F-score threshold, repeatable (default: 0.001 0.0025 0.005 0.01).
    #[arg(long = "tau", value_name = "T", value_parser = parse_tau)]
    pub taus: Vec<f64>,
    /// Exact point-to-triangle distances to the mesh side(s) instead of to their samples.
    #[arg(long)]
    pub surface: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

fn parse_samples(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("expected a positive integer, got {s:?}")),
    }
}

fn parse_tau(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(t) if t.is_finite() && t > 0.0 => Ok(t),
        _ => Err(format!("expected a finite positive number, got {s:?}")),
    }
}

/// An input file: a mesh (with its samples) or a point cloud.
enum Input {
    Mesh(TriMesh, PointCloud),
    Points(PointCloud),
}

impl Input {
    fn shape(&self) -> Shape<'_> {
        match self {
            Self::Mesh(mesh, samples) => Shape::mesh(mesh, samples),
            Self::Points(points) => Shape::points(points),
        }
    }

    fn is_mesh(&self) -> bool {
        matches!(self, Self::Mesh(..))
    }
}

/// Reads `path` as a mesh when it has faces, else as a point cloud; samples meshes.
fn load(path: &Path, samples: usize, seed: u64) -> anyhow::Result<Input> {
    let mesh = if Format::from_path(path)? == Format::Ply {
        let doc = ply::read_ply_document(path)?;
        let has_faces = doc.element("face").is_some_and(|f| f.count > 0)
            || doc.element("tristrips").is_some_and(|f| f.count > 0);
        if !has_faces {
            let (points, _) = ply::ply_to_points(path, &doc)?;
            return Ok(Input::Points(points));
        }
        ply::ply_to_mesh(path, &doc)?.0
    } else {
        io::read_mesh(path)?
    };
    if mesh.triangle_count() == 0 {
        let normals = mesh.normals().map(<[_]>::to_vec);
        let (positions, ..) = mesh.into_parts();
        let mut points = PointCloud::try_new(positions)
            .with_context(|| format!("{}: vertices", path.display()))?;
        if let Some(n) = normals {
            points = points
                .with_normals(n)
                .with_context(|| format!("{}: normals", path.display()))?;
        }
        return Ok(Input::Points(points));
    }
    let sampled = sample_uniform(&mesh, samples, seed);
    if sampled.is_empty() {
        bail!(
            "{}: the mesh has zero surface area, nothing to sample",
            path.display()
        );
    }
    Ok(Input::Mesh(mesh, sampled))
}

/// Runs `trisplat eval`.
///
/// # Errors
/// Unreadable inputs, empty inputs (no points or zero area), `--surface` with no mesh input,
/// coordinates beyond 1e18.
pub fn run(args: EvalArgs, ctx: &Context) -> anyhow::Result<()> {
    let spinner = ctx.progress.spinner("eval: loading");
    let gt_seed = splitmix64(args.seed);
    let (pred, gt) = rayon::join(
        || load(&args.pred, args.samples, args.seed),
        || load(&args.gt, args.samples, gt_seed),
    );
    let (pred, gt) = (pred?, gt?);
    if args.surface && !pred.is_mesh() && !gt.is_mesh() {
        bail!(
            "{}: --surface needs a mesh input (a file with faces), but both inputs are point \
             clouds",
            args.gt.display()
        );
    }
    let options = MetricsOptions {
        taus: if args.taus.is_empty() {
            DEFAULT_TAUS.to_vec()
        } else {
            args.taus.clone()
        },
        surface: args.surface,
    };
    spinner.set_message("eval: computing");
    let result = metrics::evaluate(pred.shape(), gt.shape(), &options).map_err(|e| {
        let file = match &e {
            metrics::MetricsError::Empty(metrics::Side::Prediction)
            | metrics::MetricsError::Spatial {
                side: metrics::Side::Prediction,
                ..
            } => &args.pred,
            _ => &args.gt,
        };
        anyhow::anyhow!("{}: {e}", file.display())
    })?;
    spinner.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string(&result)?);
    } else {
        print_table(&args, &pred, &gt, &result);
    }
    Ok(())
}

fn describe(input: &Input) -> &'static str {
    match input {
        Input::Mesh(..) => "mesh, sampled",
        Input::Points(p) if p.normals().is_some() => "points with normals",
        Input::Points(_) => "points",
    }
}

fn print_table(args: &EvalArgs, pred: &Input, gt: &Input, m: &Metrics) {
    let mode = if args.surface {
        "surface (exact distance to mesh triangles)"
    } else {
        "point (nearest sample)"
    };
    println!(
        "prediction  {}  ({}, {} points)",
        args.pred.display(),
        describe(pred),
        m.n_pred
    );
    println!(
        "truth       {}  ({}, {} points)",
        args.gt.display(),
        describe(gt),
        m.n_gt
    );
    println!("mode        {mode}");
    println!();
    let opt =
        |v: Option<f64>| v.map_or_else(|| "n/a (no normals)".to_owned(), |x| format!("{x:.6}"));
    println!("accuracy            {:.6e}", m.accuracy);
    println!("completeness        {:.6e}", m.completeness);
    println!("chamfer_l1          {:.6e}", m.chamfer_l1);
    println!("chamfer_l2          {:.6e}", m.chamfer_l2);
    println!("normal_consistency  {}", opt(m.normal_consistency));
    println!("normal_angle_deg    {}", opt(m.normal_angle_deg));
    println!();
    println!(
        "{:>12}  {:>9}  {:>9}  {:>9}",
        "tau", "precision", "recall", "fscore"
    );
    for t in &m.thresholds {
        println!(
            "{:>12}  {:>9.4}  {:>9.4}  {:>9.4}",
            format!("{}", t.tau),
            t.precision,
            t.recall,
            t.fscore
        );
    }
    println!();
    println!("computed in {:.3} s", m.seconds);
}
