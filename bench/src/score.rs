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

use trisplat_geometry::mesh_stats::MeshStats;
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
}

/// Runs the benchmark.
///
/// # Errors
/// When the avatar cannot be read or a frame fails.
pub fn run(args: &ScoreArgs) -> anyhow::Result<()> {
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
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
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
                for m in &result.methods {
                    let mesh = &m.output.mesh;
                    let mut local = mesh.clone();
                    local.translate(-centre);
                    let points = sample_uniform(&local, samples, 0);
                    let index = SurfaceIndex::new(local.positions(), local.triangles())?;
                    row(format!("{} to gt queries", m.method.name()), &|| {
                        std::hint::black_box(gt_index.closest_batch(points.positions())).ok();
                    });
                    row(format!("gt to {} queries", m.method.name()), &|| {
                        std::hint::black_box(index.closest_batch(gt_points.positions())).ok();
                    });
                    let name = m.method.name();
                    row(format!("{name} structure"), &|| {
                        std::hint::black_box(MeshStats::of(mesh));
                    });
                    row(format!("{name} index"), &|| {
                        std::hint::black_box(SurfaceIndex::new(mesh.positions(), mesh.triangles()))
                            .ok();
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
            })?
            .1?;
    }
    Ok(())
}
