//! `trisplat eval`: geometry metrics of a prediction against a ground truth (docs/conventions.md §8, §10).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::glam::DVec3;
use trisplat_geometry::io::{self, Format, ply};
use trisplat_geometry::mesh_stats::MeshStats;
use trisplat_geometry::metrics::{
    self, DEFAULT_TAU_FRACTIONS, Metrics, MetricsOptions, Relation, SELF_CONSISTENCY_MIN_SHARED,
    Shape, Tau,
};
use trisplat_geometry::rng::splitmix64;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::{PointCloud, TriMesh};

use super::Context;
use trisplat_pipeline::config::DEFAULT_MAX_SAMPLES;

/// Samples drawn on each mesh input unless `--samples` says otherwise.
pub const DEFAULT_SAMPLES: usize = 100_000;

/// Arguments of `trisplat eval`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
Compare a prediction P with a ground truth G: Chamfer distances, normal consistency and \
angle, precision / recall / F-score at thresholds relative to G's size, the structure of each \
mesh (area, pieces, holes, watertight), and whether P contains G (self-consistency).

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

Thresholds: by default tau = 0.001, 0.0025, 0.005 and 0.01 times the diagonal of G's \
bounding box (--tau-fraction F, repeatable, sets other fractions), so a threshold means the \
same on a 2 m body and a 20 cm head; --tau T (repeatable) gives absolute thresholds in the \
input's unit instead (e.g. 0.0025 for Recall@2.5mm on data in metres); with either option \
the default fractions are dropped. JSON: every threshold has tau (absolute) and tau_fraction \
(null when given absolutely); gt_bbox_diagonal is the diagonal used.

Structure of each mesh side (null for a point cloud; docs/conventions.md §8): area (f64 sum \
of the triangle areas); components: pieces of triangles connected through shared edges (as \
Open3D's cluster_connected_triangles; trimesh's split counts the pieces around an edge of \
3+ triangles separately); largest_component_area_fraction; boundary_edges: edges used by \
one triangle side (the rims of holes); non_manifold_edges: edges used by more than two; \
watertight: every edge used by exactly two (trimesh is_watertight); winding_consistent: \
every such edge traversed once each way (trimesh is_winding_consistent). area_ratio = \
area(P) / area(G) when both are meshes.

Self-consistency: shared_vertex_fraction is the fraction of G's mesh vertices whose exact \
f32 position is also a vertex (or point) of P (G must be a mesh). When it is at least 0.5, \
P contains the mesh it is scored against (e.g. it was made from it), the scores measure \
self-consistency, not accuracy: the table says so and relation is \"self-consistency\" \
(else \"accuracy\").

Other tools differ: PyTorch3D sums the two squared means without halving; DTU's script \
drops distances above 20 mm.")]
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
    /// Absolute F-score threshold in the input's unit, repeatable (replaces the default
    /// fractions).
    #[arg(long = "tau", value_name = "T", value_parser = parse_tau)]
    pub taus: Vec<f64>,
    /// F-score threshold as a fraction of the ground truth's bounding-box diagonal,
    /// repeatable [default: 0.001 0.0025 0.005 0.01 without --tau].
    #[arg(long = "tau-fraction", value_name = "F", value_parser = parse_tau)]
    pub tau_fractions: Vec<f64>,
    /// Exact point-to-triangle distances to the mesh side(s) instead of to their samples.
    #[arg(long)]
    pub surface: bool,
    /// Most samples per mesh (a limit checked before sampling).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_SAMPLES)]
    pub max_samples: usize,
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

    fn mesh(&self) -> Option<&TriMesh> {
        match self {
            Self::Mesh(mesh, _) => Some(mesh),
            Self::Points(_) => None,
        }
    }

    /// The diagonal of the bounding box of the mesh's vertices or of the points.
    fn extent(&self) -> f64 {
        match self {
            Self::Mesh(mesh, _) => mesh.bounds().map_or(0.0, |b| b.diagonal()),
            Self::Points(points) => metrics::bbox_diagonal(points.positions()),
        }
    }

    /// Fraction of `gt`'s vertices that are vertices (or points) of `self`; `None` unless
    /// `gt` is a mesh.
    fn shared_with(&self, gt: &Self) -> Option<f64> {
        let gt = gt.mesh()?.positions();
        match self {
            Self::Mesh(mesh, _) => metrics::shared_vertex_fraction(gt, mesh.positions()),
            Self::Points(points) => {
                let widened: Vec<_> = points.positions().iter().map(|p| p.as_dvec3()).collect();
                metrics::shared_vertex_fraction(gt, &widened)
            }
        }
    }
}

/// The thresholds asked for: absolute ones (`--tau`) then fractions (`--tau-fraction`), or the
/// default fractions.
fn thresholds(args: &EvalArgs) -> Vec<Tau> {
    if args.taus.is_empty() && args.tau_fractions.is_empty() {
        return DEFAULT_TAU_FRACTIONS.map(Tau::Fraction).to_vec();
    }
    let absolute = args.taus.iter().map(|&t| Tau::Absolute(t));
    absolute
        .chain(args.tau_fractions.iter().map(|&f| Tau::Fraction(f)))
        .collect()
}

/// What `eval` reports beyond [`Metrics`] (docs/conventions.md §8).
#[derive(Debug, serde::Serialize)]
struct Report {
    #[serde(flatten)]
    metrics: Metrics,
    /// Diagonal of the ground truth's bounding box (scales relative thresholds).
    gt_bbox_diagonal: f64,
    /// Structure of the prediction when it is a mesh.
    pred_structure: Option<MeshStats>,
    /// Structure of the ground truth when it is a mesh.
    gt_structure: Option<MeshStats>,
    /// area(P) / area(G) when both are meshes and G has area.
    area_ratio: Option<f64>,
    /// Fraction of the ground truth's mesh vertices found bit for bit among P's vertices.
    shared_vertex_fraction: Option<f64>,
    /// `accuracy`, or `self-consistency` when P contains G.
    relation: Relation,
}

/// Reads `path` as a mesh when it has faces, else as a point cloud; samples meshes.
/// Reads `path` as a mesh (its samples left empty, see [`sample`]) or a point cloud.
fn read_input(path: &Path) -> anyhow::Result<Input> {
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
        let positions = mesh.positions_f32();
        let mut points = PointCloud::try_new(positions)
            .with_context(|| format!("{}: vertices", path.display()))?;
        if let Some(n) = normals {
            points = points
                .with_normals(n)
                .with_context(|| format!("{}: normals", path.display()))?;
        }
        return Ok(Input::Points(points));
    }
    Ok(Input::Mesh(mesh, PointCloud::default()))
}

/// Samples a mesh input (`samples` points, seeded); point clouds pass through.
fn sample(input: Input, path: &Path, samples: usize, seed: u64) -> anyhow::Result<Input> {
    let Input::Mesh(mesh, _) = input else {
        return Ok(input);
    };
    let sampled = sample_uniform(&mesh, samples, seed);
    if sampled.is_empty() {
        bail!(
            "{}: the mesh has zero surface area, nothing to sample",
            path.display()
        );
    }
    Ok(Input::Mesh(mesh, sampled))
}

/// Centre of the bounding box of a mesh's vertices (f64) or of the points.
fn centre(input: &Input) -> Option<DVec3> {
    match input {
        Input::Mesh(mesh, _) => mesh.bounds().map(|b| b.center()),
        Input::Points(points) => points.bounds().map(|b| b.center()),
    }
}

/// Moves an input by `offset` (meshes in f64, points computed in f64 and stored as f32).
fn translate(input: &mut Input, offset: DVec3) {
    match input {
        Input::Mesh(mesh, _) => mesh.translate(offset),
        Input::Points(points) => points.translate(offset),
    }
}

/// Runs `trisplat eval`.
///
/// # Errors
/// Unreadable inputs, empty inputs (no points or zero area), `--surface` with no mesh input,
/// coordinates beyond 1e18.
pub fn run(args: EvalArgs, ctx: &Context) -> anyhow::Result<()> {
    if args.samples > args.max_samples {
        bail!(
            "--samples {}: over the limit of {} samples per mesh (raise it with --max-samples)",
            args.samples,
            args.max_samples
        );
    }
    let spinner = ctx.progress.spinner("eval: loading");
    let gt_seed = splitmix64(args.seed);
    let (pred, gt) = rayon::join(|| read_input(&args.pred), || read_input(&args.gt));
    let (mut pred, mut gt) = (pred?, gt?);
    // Shared vertices are compared where they are, before moving anything.
    let shared_vertex_fraction = pred.shared_with(&gt);
    // Both sides move to the ground truth's centre in f64 before any sample is stored in
    // f32: the scores do not depend on how far from the origin the files are
    // (docs/conventions.md §8).
    if let Some(c) = centre(&gt) {
        translate(&mut pred, -c);
        translate(&mut gt, -c);
    }
    let (pred, gt) = rayon::join(
        || sample(pred, &args.pred, args.samples, args.seed),
        || sample(gt, &args.gt, args.samples, gt_seed),
    );
    let (pred, gt) = (pred?, gt?);
    if args.surface && !pred.is_mesh() && !gt.is_mesh() {
        bail!(
            "{}: --surface needs a mesh input (a file with faces), but both inputs are point \
             clouds",
            args.gt.display()
        );
    }
    let taus = thresholds(&args);
    let diagonal = gt.extent();
    let options = MetricsOptions {
        taus: metrics::resolve_taus(&taus, diagonal).map_err(|_| {
            anyhow::anyhow!(
                "{}: the ground truth's bounding-box diagonal is {diagonal}, so thresholds \
                 relative to it (--tau-fraction, the default) are not positive; give \
                 absolute ones with --tau",
                args.gt.display()
            )
        })?,
        surface: args.surface,
    };
    spinner.set_message("eval: computing");
    let (result, (pred_structure, gt_structure)) = rayon::join(
        || metrics::evaluate(pred.shape(), gt.shape(), &options),
        || {
            rayon::join(
                || pred.mesh().map(MeshStats::of),
                || gt.mesh().map(MeshStats::of),
            )
        },
    );
    let result = result.map_err(|e| {
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
    let area_ratio = match (&pred_structure, &gt_structure) {
        (Some(p), Some(g)) if g.area > 0.0 => Some(p.area / g.area),
        _ => None,
    };
    let report = Report {
        metrics: result.with_tau_fractions(&taus),
        gt_bbox_diagonal: diagonal,
        pred_structure,
        gt_structure,
        area_ratio,
        shared_vertex_fraction,
        relation: Relation::from_shared_fraction(shared_vertex_fraction),
    };
    spinner.finish_and_clear();
    if ctx.json {
        ctx.emit("eval", serde_json::to_value(&report)?)?;
    } else {
        print_table(&args, &pred, &gt, &report);
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

fn print_table(args: &EvalArgs, pred: &Input, gt: &Input, r: &Report) {
    let m = &r.metrics;
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
    println!("gt bbox diagonal  {}", r.gt_bbox_diagonal);
    match (r.relation, r.shared_vertex_fraction) {
        (Relation::SelfConsistency, Some(f)) => {
            println!(
                "relation    SELF-CONSISTENCY, NOT ACCURACY: {:.1}% (>= {:.0}%) of the truth's \
                 vertices are vertices of the\n            prediction, which contains the mesh \
                 it is scored against: the scores below say how well it\n            reproduces \
                 its own input, not how accurate it is.",
                100.0 * f,
                100.0 * SELF_CONSISTENCY_MIN_SHARED
            );
        }
        (_, Some(f)) => println!(
            "relation    accuracy ({:.1}% of the truth's vertices are vertices of the prediction)",
            100.0 * f
        ),
        (_, None) => println!(
            "relation    accuracy (the truth is a point cloud: shared vertices not checked)"
        ),
    }
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
        "{:>12}  {:>10}  {:>9}  {:>9}  {:>9}",
        "tau", "of diag", "precision", "recall", "fscore"
    );
    for t in &m.thresholds {
        println!(
            "{:>12}  {:>10}  {:>9.4}  {:>9.4}  {:>9.4}",
            if t.tau_fraction.is_some() {
                format!("{:.4e}", t.tau)
            } else {
                format!("{}", t.tau)
            },
            t.tau_fraction
                .map_or_else(|| "-".to_owned(), |f| format!("{f}")),
            t.precision,
            t.recall,
            t.fscore
        );
    }
    if r.pred_structure.is_some() || r.gt_structure.is_some() {
        println!();
        print_structure(r);
    }
    println!();
    println!("computed in {:.3} s", m.seconds);
}

/// The structure of both sides, side by side (`-` for a point cloud).
fn print_structure(r: &Report) {
    let (p, g) = (r.pred_structure.as_ref(), r.gt_structure.as_ref());
    let row = |name: &str, f: &dyn Fn(&MeshStats) -> String| {
        let cell = |s: Option<&MeshStats>| s.map_or_else(|| "-".to_owned(), f);
        println!("{name:<20}  {:>14}  {:>14}", cell(p), cell(g));
    };
    let yes = |b: bool| if b { "yes" } else { "no" }.to_owned();
    println!("{:<20}  {:>14}  {:>14}", "structure", "prediction", "truth");
    row("triangles", &|s| s.triangles.to_string());
    row("area", &|s| format!("{:.6e}", s.area));
    row("components", &|s| s.components.to_string());
    row("largest component", &|s| {
        s.largest_component_area_fraction
            .map_or_else(|| "-".to_owned(), |f| format!("{:.2}% area", 100.0 * f))
    });
    row("boundary edges", &|s| s.boundary_edges.to_string());
    row("non-manifold edges", &|s| s.non_manifold_edges.to_string());
    row("watertight", &|s| yes(s.watertight));
    row("winding consistent", &|s| yes(s.winding_consistent));
    if let Some(ratio) = r.area_ratio {
        println!("area ratio (P / G)    {ratio:.4}");
    }
}
