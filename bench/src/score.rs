//! `score`: what scoring one frame of the main job costs, stage by stage (issue #32 item 3),
//! on the meshes `trisplat extract --gt gaussians` makes of a LAM avatar.
//!
//! The pipeline's own session meshes each frame (its own scoring included); then each stage of
//! the scoring is timed again on those meshes, best of `--repeats`, on one thread (its CPU
//! cost) and on the global pool: the ground truth (`GtSamples::new`: sampling and indexing the
//! surface of the Gaussians' centres), and per method its structure (`MeshStats::of`), its
//! surface index (`SurfaceIndex::new`), its samples (`sample_uniform`) and the whole
//! `measure_with`. trisplat only.

use std::path::PathBuf;

use trisplat_geometry::TriMesh;
use trisplat_geometry::mesh_stats::MeshStats;
use trisplat_geometry::metrics::Tau;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::spatial::SurfaceIndex;
use trisplat_pipeline::avatar::AvatarFolder;
use trisplat_pipeline::config::{GaussianLayout, GroundTruth};
use trisplat_pipeline::metrics::{GtSamples, measure_with};
use trisplat_pipeline::{ExtractConfig, ExtractOptions, Method, Session};

use crate::harness::time_best;

/// Options of the scoring benchmark.
#[derive(Debug, clap::Args)]
pub struct ScoreArgs {
    /// A LAM avatar folder (its `test_expression_1s.json` drives it).
    #[arg(long)]
    pub avatar: PathBuf,
    /// Frames to mesh and score (`A..B`).
    #[arg(long, default_value = "0..2")]
    pub frames: String,
    /// Timings per stage (the best is printed).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Time only the stages whose name contains this (e.g. `tsdf index`), for a profiler.
    #[arg(long)]
    pub only: Option<String>,
    /// Write each frame's ground truth and meshes here (`<frame>_gt.ply`,
    /// `<frame>_<method>.ply`), for benchmarks of the geometry crate alone.
    #[arg(long)]
    pub dump: Option<PathBuf>,
    /// Score the meshes a `--dump` wrote to this folder instead of meshing the avatar (no
    /// extraction: quick to repeat, and the same input every time); `--avatar` is then unused.
    #[arg(long)]
    pub from: Option<PathBuf>,
}

/// Runs the benchmark.
///
/// # Errors
/// When the avatar cannot be read or a frame fails.
pub fn run(args: &ScoreArgs) -> anyhow::Result<()> {
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    if let Some(dir) = &args.from {
        return run_from(args, dir, &one);
    }
    let avatar = AvatarFolder::open(&args.avatar)?;
    let mut options = ExtractOptions::default();
    options.bind.layout = GaussianLayout::Lam;
    options.metrics.consistency_views = 0;
    let samples = options.metrics.samples;
    let tau = options.metrics.threshold();
    let config = ExtractConfig {
        template: avatar.template.clone(),
        animation: Some(
            args.avatar
                .join("test_expression_1s.json")
                .display()
                .to_string(),
        ),
        gaussians: Some(avatar.gaussians.clone()),
        methods: vec![Method::Tsdf, Method::Delaunay, Method::Alpha],
        output: std::env::temp_dir(),
        frames: Some(args.frames.clone()),
        gt: Some(GroundTruth::Gaussians),
        options,
    };
    let mut session = Session::open(&config)?;
    let frames = session.frames();
    println!(
        "{:<10} {:<28} {:>10} {:>10}",
        "frame", "stage", "1 thread", "pool"
    );
    for f in frames {
        session
            .frame_with(f, |result, gt| -> anyhow::Result<()> {
                let Some(gt) = gt else {
                    anyhow::bail!("frame {f}: no ground truth");
                };
                if let Some(dir) = &args.dump {
                    let opts = trisplat_geometry::io::WriteOptions::default();
                    let path = dir.join(format!("{f}_gt.ply"));
                    trisplat_geometry::io::write_mesh(&path, &gt.mesh, opts)?;
                    for m in &result.methods {
                        let path = dir.join(format!("{f}_{}.ply", m.method.name()));
                        trisplat_geometry::io::write_mesh(&path, &m.output.mesh, opts)?;
                    }
                }
                let methods: Vec<(&str, &TriMesh)> = result
                    .methods
                    .iter()
                    .map(|m| (m.method.name(), &m.output.mesh))
                    .collect();
                score_frame(args, &one, &f.to_string(), gt, &methods, samples, tau)
            })?
            .1?;
    }
    Ok(())
}

/// Times each scoring stage of one frame: the ground truth `gt`, then each `(name, mesh)`.
fn score_frame(
    args: &ScoreArgs,
    one: &rayon::ThreadPool,
    f: &str,
    gt: &GtSamples,
    methods: &[(&str, &TriMesh)],
    samples: usize,
    tau: Tau,
) -> anyhow::Result<()> {
    let row = |stage: String, work: &(dyn Fn() + Sync)| {
        if args
            .only
            .as_ref()
            .is_some_and(|o| !stage.contains(o.as_str()))
        {
            return 0.0;
        }
        let (serial, ()) = one.install(|| time_best(args.repeats, work));
        let (pool, ()) = time_best(args.repeats, work);
        println!("{f:<10} {stage:<28} {serial:>10.4} {pool:>10.4}");
        serial
    };
    let mut total = row("ground truth".to_owned(), &|| {
        std::hint::black_box(GtSamples::new(gt.mesh.clone(), samples));
    });
    // The two query sweeps of a comparison, on the meshes moved as `measure_with`
    // moves them (to the ground truth's centre).
    let centre = gt.mesh.bounds().map_or(glam::DVec3::ZERO, |b| b.center());
    let mut gt_local = gt.mesh.clone();
    gt_local.translate(-centre);
    let gt_index = SurfaceIndex::new(gt_local.positions(), gt_local.triangles())?;
    let gt_points = sample_uniform(&gt_local, samples, 1);
    for &(name, mesh) in methods {
        let mut local = mesh.clone();
        local.translate(-centre);
        let points = sample_uniform(&local, samples, 0);
        let index = SurfaceIndex::new(local.positions(), local.triangles())?;
        row(format!("{} to gt queries", name), &|| {
            std::hint::black_box(gt_index.closest_batch(points.positions())).ok();
        });
        row(format!("gt to {} queries", name), &|| {
            std::hint::black_box(index.closest_batch(gt_points.positions())).ok();
        });
        row(format!("{name} structure"), &|| {
            std::hint::black_box(MeshStats::of(mesh));
        });
        row(format!("{name} index"), &|| {
            std::hint::black_box(SurfaceIndex::new(mesh.positions(), mesh.triangles())).ok();
        });
        row(format!("{name} samples"), &|| {
            std::hint::black_box(sample_uniform(mesh, samples, 0));
        });
        total += row(format!("{name} measure_with"), &|| {
            std::hint::black_box(measure_with(mesh, gt, samples, tau)).ok();
        });
    }
    println!("{f:<10} {:<28} {total:>10.4}", "scoring (1 thread)");
    Ok(())
}

/// `--from DIR`: scores the meshes of an earlier `--dump`, frame by frame.
fn run_from(
    args: &ScoreArgs,
    dir: &std::path::Path,
    one: &rayon::ThreadPool,
) -> anyhow::Result<()> {
    let options = ExtractOptions::default();
    let samples = options.metrics.samples;
    let tau = options.metrics.threshold();
    let mut frames: Vec<String> = std::fs::read_dir(dir)?
        .filter_map(|e| {
            let name = e.ok()?.file_name().into_string().ok()?;
            name.strip_suffix("_gt.ply").map(str::to_owned)
        })
        .collect();
    frames.sort();
    if frames.is_empty() {
        anyhow::bail!("{}: no <frame>_gt.ply", dir.display());
    }
    println!(
        "{:<10} {:<28} {:>10} {:>10}",
        "frame", "stage", "1 thread", "pool"
    );
    for f in frames {
        let read =
            |name: &str| trisplat_geometry::io::read_mesh(&dir.join(format!("{f}_{name}.ply")));
        let Some(gt) = GtSamples::new(read("gt")?, samples) else {
            anyhow::bail!("frame {f}: the ground truth has no area");
        };
        let meshes = ["tsdf", "delaunay", "alpha"]
            .into_iter()
            .filter(|m| dir.join(format!("{f}_{m}.ply")).exists())
            .map(|m| Ok((m, read(m)?)))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let methods: Vec<(&str, &TriMesh)> = meshes.iter().map(|(m, mesh)| (*m, mesh)).collect();
        score_frame(args, one, &f, &gt, &methods, samples, tau)?;
    }
    Ok(())
}
