//! `trisplat eval`: geometry metrics of a prediction against a ground truth (docs/conventions.md §8, §10).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::mesh_stats::MeshStats;
use trisplat_geometry::metrics::{Relation, SELF_CONSISTENCY_MIN_SHARED};
use trisplat_pipeline::eval::{self, EvalError, EvalInput, EvalOptions, EvalReport};

use super::gaussian_io::{GaussianFormatArgs, parse_axes, read_gaussian_file};
use super::{Context, MAX_IMAGE_PIXELS, read_camera_file};
use trisplat_pipeline::config::DEFAULT_MAX_SAMPLES;
use trisplat_pipeline::consistency::{
    CONSISTENCY_RESOLUTION, CONSISTENCY_VIEWS, GaussianViews, RenderConsistency, held_out_rig,
};

/// Samples drawn on each mesh input unless `--samples` says otherwise.
pub const DEFAULT_SAMPLES: usize = eval::DEFAULT_SAMPLES;

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
    /// Ground truth: mesh or point cloud (not needed with --gaussians alone).
    #[arg(required_unless_present = "gaussians")]
    pub gt: Option<PathBuf>,
    /// Render consistency against these Gaussians (world space: .ply, .spz, .glb, .gltf): the
    /// mesh seen from --cameras (or a held-out sphere rig) against the Gaussians' alpha, median
    /// depth and normals.
    #[arg(long, value_name = "G")]
    pub gaussians: Option<PathBuf>,
    /// Cameras of the render consistency (3DGS cameras.json or NeRF transforms.json)
    /// [default: a sphere rig of --views views at --resolution, turned away from the
    /// extraction rig].
    #[arg(long, value_name = "C.json", requires = "gaussians")]
    pub cameras: Option<PathBuf>,
    /// Views of the default render-consistency rig.
    #[arg(long, value_name = "N", default_value_t = CONSISTENCY_VIEWS,
          value_parser = parse_samples, requires = "gaussians", conflicts_with = "cameras")]
    pub views: usize,
    /// Width and height of the default render-consistency rig's images, pixels.
    #[arg(long, value_name = "PX", default_value_t = CONSISTENCY_RESOLUTION,
          value_parser = clap::value_parser!(u32).range(8..=4096), requires = "gaussians",
          conflicts_with = "cameras")]
    pub resolution: u32,
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

/// Runs `trisplat eval`.
///
/// # Errors
/// Unreadable inputs, empty inputs (no points or zero area), `--surface` with no mesh input,
/// coordinates beyond 1e18.
pub fn run(args: EvalArgs, ctx: &Context) -> anyhow::Result<()> {
    let consistency = match &args.gaussians {
        Some(g) => Some(render_consistency(&args, g, ctx)?),
        None => None,
    };
    let Some(gt_path) = args.gt.clone() else {
        let c = consistency
            .ok_or_else(|| anyhow::anyhow!("a ground truth or --gaussians is needed"))?;
        if ctx.json {
            ctx.emit("eval", serde_json::json!({ "render_consistency": c }))?;
        } else {
            print_consistency(&args, &c);
        }
        return Ok(());
    };
    if args.samples > args.max_samples {
        bail!(
            "--samples {}: over the limit of {} samples per mesh (raise it with --max-samples)",
            args.samples,
            args.max_samples
        );
    }
    let spinner = ctx.progress.spinner("eval: loading");
    let (pred, gt) = rayon::join(|| EvalInput::read(&args.pred), || EvalInput::read(&gt_path));
    let (pred, gt) = (pred?, gt?);
    spinner.set_message("eval: computing");
    let options = EvalOptions {
        samples: args.samples,
        seed: args.seed,
        // `--tau` then `--tau-fraction`, or the default fractions.
        taus: eval::thresholds(&args.taus, &args.tau_fractions),
        surface: args.surface,
    };
    let names = (
        args.pred.display().to_string(),
        gt_path.display().to_string(),
    );
    let done = eval::evaluate(pred, gt, (&names.0, &names.1), &options).map_err(|e| match e {
        // The command's own option names.
        EvalError::SurfaceWithoutMesh { gt } => anyhow::anyhow!(
            "{gt}: --surface needs a mesh input (a file with faces), but both inputs are point \
             clouds"
        ),
        EvalError::NoScale { gt, diagonal } => anyhow::anyhow!(
            "{gt}: the ground truth's bounding-box diagonal is {diagonal}, so thresholds \
             relative to it (--tau-fraction, the default) are not positive; give absolute ones \
             with --tau"
        ),
        e => e.into(),
    })?;
    spinner.finish_and_clear();
    if ctx.json {
        let mut value = serde_json::to_value(&done.report)?;
        if let (Some(c), Some(object)) = (consistency, value.as_object_mut()) {
            object.insert("render_consistency".to_owned(), serde_json::to_value(c)?);
        }
        ctx.emit("eval", value)?;
    } else {
        print_table(&args, &gt_path, &done.pred, &done.gt, &done.report);
        if let Some(c) = consistency {
            println!();
            print_consistency(&args, &c);
        }
    }
    Ok(())
}

/// `--gaussians`: the prediction's render consistency against them.
fn render_consistency(
    args: &EvalArgs,
    gaussians: &Path,
    ctx: &Context,
) -> anyhow::Result<RenderConsistency> {
    let spinner = ctx.progress.spinner("eval: render consistency");
    // SPZ in the 3DGS training frame, as `render` reads it by default.
    let format = GaussianFormatArgs {
        axes: parse_axes("rdf").map_err(anyhow::Error::msg)?,
        spz_version: 3,
    };
    let set = read_gaussian_file(gaussians, &format)?.set;
    let cameras = match &args.cameras {
        Some(path) => read_camera_file(path, None, MAX_IMAGE_PIXELS)?,
        None => held_out_rig(&set, args.views, args.resolution)
            .with_context(|| format!("{}", gaussians.display()))?,
    };
    let views = GaussianViews::render(&set, &cameras)
        .with_context(|| format!("{}", gaussians.display()))?;
    let mesh = read_mesh(&args.pred)?;
    if mesh.triangles().is_empty() {
        bail!(
            "{}: render consistency (--gaussians) needs a mesh, a file with faces",
            args.pred.display()
        );
    }
    let c = views
        .score(&mesh)
        .with_context(|| format!("{}", args.pred.display()))?;
    spinner.finish_and_clear();
    Ok(c)
}

/// The render-consistency lines of the table.
fn print_consistency(args: &EvalArgs, c: &RenderConsistency) {
    let mm = |v: Option<f64>| {
        v.map_or_else(
            || "n/a (no pixel covered by both)".to_owned(),
            |x| format!("{x:.6e}"),
        )
    };
    println!(
        "render consistency of {} against {} ({} views)",
        args.pred.display(),
        args.gaussians
            .as_deref()
            .map_or_else(String::new, |g| g.display().to_string()),
        c.views
    );
    println!(
        "silhouette IoU      {:.4}  (mesh {} px, Gaussians {} px, both {} px)",
        c.iou, c.mesh_pixels, c.gaussian_pixels, c.both_pixels
    );
    println!("depth error median  {}", mm(c.depth_error_median));
    println!("depth error p90     {}", mm(c.depth_error_p90));
    println!(
        "normal angle median {}",
        c.normal_angle_deg
            .map_or_else(|| "n/a".to_owned(), |a| format!("{a:.2} deg"))
    );
}

fn describe(input: &EvalInput) -> &'static str {
    match input {
        EvalInput::Mesh(..) => "mesh, sampled",
        EvalInput::Points(p) if p.normals().is_some() => "points with normals",
        EvalInput::Points(_) => "points",
    }
}

fn print_table(args: &EvalArgs, gt_path: &Path, pred: &EvalInput, gt: &EvalInput, r: &EvalReport) {
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
        gt_path.display(),
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
fn print_structure(r: &EvalReport) {
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
