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
use trisplat_pipeline::metrics::{GtSamples, ScoreCache, measure_cached, measure_with};
use trisplat_pipeline::records::FrameMetrics;
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
    /// With `--from`: score the dumped frames one after another as the session does (each
    /// method's `ScoreCache` and the ground truth's index carried from frame to frame), on one
    /// thread, and print its CPU seconds per frame; the metrics are checked against fresh
    /// ones (`measure_with`), bit for bit.
    #[arg(long, requires = "from")]
    pub track: bool,
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
    // Numerically (frame 10 after frame 9): `--track` scores them in this order.
    frames.sort_by_key(|f| (f.parse::<u64>().unwrap_or(u64::MAX), f.clone()));
    if frames.is_empty() {
        anyhow::bail!("{}: no <frame>_gt.ply", dir.display());
    }
    if args.track {
        return run_track(dir, &frames, one, samples, tau);
    }
    println!(
        "{:<10} {:<28} {:>10} {:>10}",
        "frame", "stage", "1 thread", "pool"
    );
    for f in frames {
        let (gt_mesh, meshes) = read_frame(dir, &f)?;
        let Some(gt) = GtSamples::new(gt_mesh, samples) else {
            anyhow::bail!("frame {f}: the ground truth has no area");
        };
        let methods: Vec<(&str, &TriMesh)> = meshes.iter().map(|(m, mesh)| (*m, mesh)).collect();
        score_frame(args, one, &f, &gt, &methods, samples, tau)?;
    }
    Ok(())
}

/// A dumped frame: its ground truth and its methods' meshes.
type DumpedFrame = (TriMesh, Vec<(&'static str, TriMesh)>);

/// Reads frame `f` of a `--dump` folder.
fn read_frame(dir: &std::path::Path, f: &str) -> anyhow::Result<DumpedFrame> {
    let read = |name: &str| trisplat_geometry::io::read_mesh(&dir.join(format!("{f}_{name}.ply")));
    let meshes = ["tsdf", "delaunay", "alpha"]
        .into_iter()
        .filter(|m| dir.join(format!("{f}_{m}.ply")).exists())
        .map(|m| Ok((m, read(m)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok((read("gt")?, meshes))
}

/// CPU time of the calling thread so far, in seconds (`/proc/thread-self/schedstat`).
fn thread_cpu_seconds() -> anyhow::Result<f64> {
    let stat = std::fs::read_to_string("/proc/thread-self/schedstat")?;
    let ns: f64 = stat
        .split_whitespace()
        .next()
        .ok_or_else(|| anyhow::anyhow!("empty schedstat"))?
        .parse()?;
    Ok(ns * 1e-9)
}

/// `--from DIR --track`: the frames in order, scored as the session scores them (ground truth
/// refitted from the previous frame's, each method through its [`ScoreCache`]) on one thread;
/// prints each frame's CPU seconds and the mean, then checks every metric against a fresh
/// `measure_with` of the same meshes.
fn run_track(
    dir: &std::path::Path,
    frames: &[String],
    one: &rayon::ThreadPool,
    samples: usize,
    tau: Tau,
) -> anyhow::Result<()> {
    let mut dumped: Vec<DumpedFrame> = Vec::new();
    for f in frames {
        dumped.push(read_frame(dir, f)?);
    }
    let carried: Vec<(f64, Vec<Option<FrameMetrics>>)> = one.install(|| {
        let mut previous: Option<GtSamples> = None;
        let mut caches: Vec<ScoreCache> = Vec::new();
        let mut out = Vec::new();
        for (gt_mesh, methods) in &dumped {
            let start = thread_cpu_seconds()?;
            let gt = GtSamples::reusing(gt_mesh.clone(), samples, previous.take())
                .ok_or_else(|| anyhow::anyhow!("a ground truth without area"))?;
            caches.resize_with(methods.len(), ScoreCache::default);
            let metrics = methods
                .iter()
                .zip(&mut caches)
                .map(|((_, mesh), cache)| measure_cached(mesh, &gt, samples, tau, cache))
                .collect::<Result<Vec<_>, _>>()?;
            out.push((thread_cpu_seconds()? - start, metrics));
            previous = Some(gt);
        }
        anyhow::Ok(out)
    })?;
    println!("{:<10} {:>12}", "frame", "CPU-s (1 thread)");
    for (f, (seconds, _)) in frames.iter().zip(&carried) {
        println!("{f:<10} {seconds:>12.4}");
    }
    let later: Vec<f64> = carried.iter().skip(1).map(|(s, _)| *s).collect();
    println!(
        "mean of frames after the first: {:.4} CPU-s ({} frames)",
        later.iter().sum::<f64>() / later.len().max(1) as f64,
        later.len()
    );
    for ((f, (gt_mesh, methods)), (_, metrics)) in frames.iter().zip(&dumped).zip(&carried) {
        let gt = GtSamples::new(gt_mesh.clone(), samples)
            .ok_or_else(|| anyhow::anyhow!("a ground truth without area"))?;
        for ((name, mesh), got) in methods.iter().zip(metrics) {
            let fresh = measure_with(mesh, &gt, samples, tau)?;
            anyhow::ensure!(
                &fresh == got,
                "frame {f} {name}: carried metrics differ from fresh ones"
            );
        }
    }
    println!("every metric equals a fresh measure_with's, bit for bit");
    Ok(())
}
