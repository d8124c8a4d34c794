//! `sweep`: error against run time of the main job's three methods on real animated templates,
//! through the pipeline crate's public pieces (`trisplat extract`'s own inputs, meshers,
//! metrics and summaries).
//!
//! Templates: CesiumMan (the committed Khronos fixture, its skinned walk clip sampled at the
//! pipeline's default 30 fps) and, when the shared data folder is present (`TRISPLAT_SHARED_DATA`,
//! else `../shared/data` beside the workspace), the LAM head `skin.glb` driven by
//! `test_expression_1s.json` (ARKit weights on its morph targets, 30 fps). Gaussians are bound
//! by the pipeline (4 per triangle, flat opaque discs), deformed in binding mode.
//!
//! Per template and setting, every method meshes a run of consecutive frames in order, as
//! `trisplat extract` does; incremental Delaunay meshes every frame (its cost depends on the
//! motion between frames) and is measured on every `--measure-every`-th, the stateless alpha
//! shape meshes every `--alpha-every`-th and TSDF every `--tsdf-every`-th of them. Milliseconds are the method's own work, timed as the pipeline
//! times it ([`Mesher::mesh`]: render + fuse for tsdf, the tetrahedralisation + boundary for
//! alpha; for delaunay `IncrementalDelaunay::update` + `mesh()`, the pipeline's Delaunay arm).
//! Metrics are the pipeline's (`report::measure`, surface mode) against each frame's deformed
//! template.
//!
//! The pipeline's options have no hop threshold, so the Delaunay rows call the extract crate
//! directly with the same timing; the (τ = 0, never) setting is also run through the
//! pipeline's own [`Mesher`] and its meshes are checked equal, frame by frame.

use std::path::{Path, PathBuf};
use std::time::Instant;
use trisplat_pipeline::config::{self as extract_config, MetricOptions};

use anyhow::bail;
use glam::{DVec3, Vec3};
use trisplat_extract::incremental_delaunay::{DelaunayOptions, IncrementalDelaunay};
use trisplat_geometry::TriMesh;
use trisplat_pipeline::config::DEFAULT_SAMPLES;
use trisplat_pipeline::input::deform_mode;
use trisplat_pipeline::methods::{FrameInput, Mesher};
use trisplat_pipeline::metrics::{GtSamples, is_watertight, measure};
use trisplat_pipeline::records::{FrameRecord, Resolved};
use trisplat_pipeline::report::Summary;
use trisplat_pipeline::{ExtractConfig, ExtractOptions, Method, Session};
use trisplat_splat::GaussianSet;
use trisplat_splat::{DeformMode, Deformer};

/// TSDF voxels as fractions of the bounding radius: radius / this.
const VOXELS_PER_RADIUS: [f64; 3] = [64.0, 128.0, 256.0];
/// Delaunay hop thresholds (× mean template edge).
const HOP_THRESHOLDS: [f64; 3] = [0.0, 0.1, 0.5];
/// Delaunay rebuild periods (0: never; 1: from scratch every frame).
const REBUILD_PERIODS: [usize; 3] = [0, 10, 1];
/// Alpha radii in multiples of the mean nearest-neighbour spacing of the Gaussian means.
const ALPHA_SPACINGS: [f64; 3] = [1.5, 3.0, 6.0];

/// Options of the sweep benchmark.
#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// Frames of CesiumMan to mesh (consecutive from 0, at 30 fps) [default: the whole clip].
    #[arg(long)]
    pub cesium_frames: Option<usize>,
    /// Frames of the LAM expression track to mesh (consecutive from 0, 30 fps).
    #[arg(long, default_value_t = 30)]
    pub lam_frames: usize,
    /// The alpha shape meshes every N-th frame.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    pub alpha_every: u64,
    /// TSDF meshes every N-th frame.
    #[arg(long, default_value_t = 15, value_parser = clap::value_parser!(u64).range(1..))]
    pub tsdf_every: u64,
    /// Delaunay meshes every frame but is measured on every N-th (the metrics of its large
    /// meshes cost more than the meshing).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    pub measure_every: u64,
    /// Points sampled on each mesh for the metrics.
    #[arg(long, default_value_t = DEFAULT_SAMPLES)]
    pub samples: usize,
    /// Skip the LAM head even when the shared data is present.
    #[arg(long)]
    pub no_lam: bool,
}

/// The shared data folder: `TRISPLAT_SHARED_DATA`, else `../shared/data` beside the workspace.
fn shared_data() -> PathBuf {
    std::env::var_os("TRISPLAT_SHARED_DATA").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
        PathBuf::from,
    )
}

/// One template and its animation.
struct Case {
    name: &'static str,
    template: PathBuf,
    animation: Option<PathBuf>,
    /// Frames to mesh, `None`: all.
    frames: Option<usize>,
}

/// One frame of the animation: deformed template, Gaussian means, ground-truth samples.
struct Frame {
    index: usize,
    positions: Vec<DVec3>,
    means: Vec<Vec3>,
    gt: GtSamples,
}

/// A template ready for the methods.
struct Prepared {
    template: TriMesh,
    set: GaussianSet,
    /// The Gaussians' means on the rest template.
    rest_means: Vec<Vec3>,
    mode: DeformMode,
    options: ExtractOptions,
    /// Working scale: radius and mean spacing (the pipeline's, unless the animation's scale
    /// differs from the template file's).
    resolved: Resolved,
    frames: Vec<Frame>,
}

impl Prepared {
    fn new(case: &Case, options: ExtractOptions) -> anyhow::Result<Self> {
        let config = ExtractConfig {
            template: case.template.clone(),
            animation: case.animation.as_ref().map(|p| p.display().to_string()),
            gaussians: None,
            methods: Vec::new(),
            output: std::env::temp_dir(),
            frames: None,
            gt: None,
            options,
        };
        // The pipeline's own session: the template welded and in world space, its frames
        // checked against its scale, the Gaussians bound and the rest pose deformed as
        // `trisplat extract` does; no mesher is built (no method), the sweep builds its own.
        let mut session = Session::open(&config)?;
        let count = case
            .frames
            .unwrap_or(usize::MAX)
            .min(session.frames().len());
        let mut frames = Vec::with_capacity(count);
        for f in 0..count {
            let (positions, means) = session.deform(f)?;
            let means = means.to_vec();
            let mesh =
                TriMesh::new_unchecked(positions.clone(), session.template().triangles().to_vec());
            let Some(gt) = GtSamples::new(mesh, config.options.metrics.samples) else {
                bail!("{}: frame {f} has no area", case.name);
            };
            frames.push(Frame {
                index: f,
                positions,
                means,
                gt,
            });
        }
        if frames.is_empty() {
            bail!("{}: no frames", case.name);
        }
        Ok(Self {
            template: session.template().clone(),
            set: session.gaussians().clone(),
            rest_means: session.rest_means().to_vec(),
            mode: deform_mode(config.options.animation.mode),
            resolved: *session.resolved(),
            options: config.options,
            frames,
        })
    }

    /// The frames meshed by a method meshing every `every`-th.
    fn every(&self, every: u64) -> impl Iterator<Item = &Frame> {
        let every = usize::try_from(every).unwrap_or(usize::MAX).max(1);
        self.frames.iter().step_by(every)
    }

    /// The pipeline's record of one frame; metrics only when `measured`.
    fn record(
        &self,
        frame: &Frame,
        mesh: &TriMesh,
        ms: f64,
        measured: bool,
    ) -> anyhow::Result<FrameRecord> {
        let metrics = if measured {
            measure(
                mesh,
                &frame.gt,
                self.options.metrics.samples,
                self.options.metrics.tau,
            )?
        } else {
            None
        };
        Ok(FrameRecord {
            frame: frame.index,
            time: frame.index as f64 / self.options.animation.fps,
            ms,
            render_ms: None,
            vertices: mesh.vertex_count(),
            faces: mesh.triangle_count(),
            watertight: is_watertight(mesh),
            metrics,
            consistency: None,
            topology: None,
            simplify: None,
        })
    }

    fn frame_range(&self, every: u64) -> String {
        let idx: Vec<usize> = self.every(every).map(|f| f.index).collect();
        match (idx.first(), idx.last()) {
            (Some(a), Some(b)) if every > 1 => format!("{} ({a}..={b} step {every})", idx.len()),
            (Some(a), Some(b)) => format!("{} ({a}..={b})", idx.len()),
            _ => "0".to_owned(),
        }
    }
}

/// One line of the table.
struct Row {
    method: Method,
    parameter: String,
    summary: Summary,
    note: String,
}

fn run_stateless(
    p: &Prepared,
    method: Method,
    resolved: &Resolved,
    every: u64,
) -> anyhow::Result<(Summary, f64)> {
    let mut mesher = Mesher::new(method, &p.options, resolved, &p.template, &p.rest_means, 0)?;
    let deformer = Deformer::new(&p.template, p.mode);
    let mut records = Vec::new();
    let mut render_ms = Vec::new();
    for frame in p.every(every) {
        let world = if method == Method::Tsdf {
            Some(deformer.deform(&p.set, &frame.positions)?)
        } else {
            None
        };
        let input = FrameInput {
            frame: frame.index,
            positions: &frame.positions,
            means: &frame.means,
            world: world.as_ref(),
        };
        let out = mesher.mesh(&input)?;
        render_ms.extend(out.render_ms);
        records.push(p.record(frame, &out.mesh, out.ms, true)?);
    }
    Ok((Summary::of(&records), mean(&render_ms)))
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Result of one Delaunay setting.
struct DelaunayRun {
    summary: Summary,
    hopped: f64,
    charts: f64,
    /// (frames equal, pipeline Mesher's mean ms) when checked against the pipeline.
    check: Option<(usize, f64)>,
}

fn run_delaunay(
    p: &Prepared,
    hop_threshold: f64,
    rebuild_every: usize,
    measure_every: u64,
) -> anyhow::Result<DelaunayRun> {
    let measure_every = usize::try_from(measure_every).unwrap_or(usize::MAX).max(1);
    let first = p.frames.first().map_or(0, |f| f.index);
    let options = DelaunayOptions {
        hop_threshold,
        rebuild_every,
        ..DelaunayOptions::default()
    };
    let mut d = IncrementalDelaunay::new(&p.template, &p.rest_means, options)?;
    // The pipeline's own mesher for the setting it can express.
    let mut pipeline = if hop_threshold == 0.0 && rebuild_every == 0 {
        let o = ExtractOptions {
            delaunay: extract_config::DelaunayOptions {
                rebuild_every,
                ..p.options.clone().delaunay
            },
            ..p.options.clone()
        };
        Some(Mesher::new(
            Method::Delaunay,
            &o,
            &p.resolved,
            &p.template,
            &p.rest_means,
            0,
        )?)
    } else {
        None
    };
    let (mut equal, mut pipeline_ms) = (0usize, Vec::new());
    let mut records = Vec::with_capacity(p.frames.len());
    let (mut hopped, mut charts) = (Vec::new(), Vec::new());
    let (n, c) = (
        p.set.len().max(1) as f64,
        p.template.triangle_count().max(1) as f64,
    );
    for frame in &p.frames {
        let start = Instant::now();
        let stats = d.update(&frame.positions, &frame.means)?;
        let mesh = d.mesh();
        let ms = start.elapsed().as_secs_f64() * 1e3;
        if stats.frame > 0 {
            hopped.push(stats.hopped as f64 / n);
            charts.push(stats.charts_redone as f64 / c);
        }
        if let Some(m) = pipeline.as_mut() {
            let out = m.mesh(&FrameInput {
                frame: frame.index,
                positions: &frame.positions,
                means: &frame.means,
                world: None,
            })?;
            pipeline_ms.push(out.ms);
            if out.mesh.triangles() == mesh.triangles() && out.mesh.positions() == mesh.positions()
            {
                equal += 1;
            }
        }
        let measured = frame.index.saturating_sub(first) % measure_every == 0;
        records.push(p.record(frame, &mesh, ms, measured)?);
    }
    Ok(DelaunayRun {
        summary: Summary::of(&records),
        hopped: mean(&hopped),
        charts: mean(&charts),
        check: pipeline.map(|_| (equal, mean(&pipeline_ms))),
    })
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".to_owned())
}

fn sweep(case: &Case, args: &SweepArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let options = ExtractOptions {
        metrics: MetricOptions {
            samples: args.samples,
            ..Default::default()
        },
        ..ExtractOptions::default()
    };
    println!();
    println!("### {}", case.name);
    println!();
    let t = Instant::now();
    let p = Prepared::new(case, options)?;
    eprintln!("  prepared in {:.1} s", t.elapsed().as_secs_f64());
    let (radius, spacing) = (p.resolved.template_radius, p.resolved.mean_spacing);
    println!(
        "{} vertices after welding seams, {} triangles; {} Gaussians bound by the pipeline ({} per triangle), \
         binding mode; bounding radius R = {radius:.4e}, mean spacing s = {spacing:.4e}; \
         frames at {} fps: delaunay {} (measured on {}), alpha {}, tsdf {} ({} views of {}², 40°); metrics: {} \
         samples per mesh, F-score at τ = {}; load average at start {}.",
        p.template.vertex_count(),
        p.template.triangle_count(),
        p.set.len(),
        p.options.bind.per_triangle,
        p.options.animation.fps,
        p.frame_range(1),
        p.frame_range(args.measure_every),
        p.frame_range(args.alpha_every),
        p.frame_range(args.tsdf_every),
        p.options.tsdf.views,
        p.options.tsdf.resolution,
        p.options.metrics.samples,
        p.options.metrics.tau,
        load()
    );
    let mut rows = Vec::new();
    for &k in &VOXELS_PER_RADIUS {
        let voxel = radius / k;
        let resolved = Resolved {
            voxel,
            ..p.resolved
        };
        let t = Instant::now();
        let (summary, render) = run_stateless(&p, Method::Tsdf, &resolved, args.tsdf_every)?;
        eprintln!(
            "  tsdf R/{k}: {:.0} ms/frame ({:.0} s)",
            summary.ms,
            t.elapsed().as_secs_f64()
        );
        rows.push(Row {
            method: Method::Tsdf,
            parameter: format!("voxel R/{k} = {voxel:.3e}"),
            summary,
            note: format!("render {render:.0} ms of it"),
        });
    }
    let mut check = None;
    for &tau in &HOP_THRESHOLDS {
        for &period in &REBUILD_PERIODS {
            let t = Instant::now();
            let r = run_delaunay(&p, tau, period, args.measure_every)?;
            eprintln!(
                "  delaunay τ {tau} every {period}: {:.1} ms/frame ({:.0} s)",
                r.summary.ms,
                t.elapsed().as_secs_f64()
            );
            check = check.or(r.check);
            let period = match period {
                0 => "never".to_owned(),
                1 => "every frame".to_owned(),
                n => format!("every {n}"),
            };
            rows.push(Row {
                method: Method::Delaunay,
                parameter: format!("τ {tau}, rebuild {period}"),
                summary: r.summary,
                note: format!(
                    "hopped {:.3}%, charts redone {:.2}% per frame",
                    100.0 * r.hopped,
                    100.0 * r.charts
                ),
            });
        }
    }
    for &a in &ALPHA_SPACINGS {
        let alpha = a * spacing;
        let resolved = Resolved {
            alpha,
            ..p.resolved
        };
        let t = Instant::now();
        let (summary, _) = run_stateless(&p, Method::Alpha, &resolved, args.alpha_every)?;
        eprintln!(
            "  alpha {a} s: {:.0} ms/frame ({:.0} s)",
            summary.ms,
            t.elapsed().as_secs_f64()
        );
        rows.push(Row {
            method: Method::Alpha,
            parameter: format!("α {a} s = {alpha:.3e}"),
            summary,
            note: String::new(),
        });
    }
    println!();
    println!(
        "| method | parameter | frames | ms/frame mean | ms/frame median | Chamfer L1 | \
         F-score | normal consistency | vertices | faces | watertight | notes |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for r in &rows {
        let s = &r.summary;
        let opt = |v: Option<f64>, f: fn(f64) -> String| v.map_or_else(|| "-".to_owned(), f);
        println!(
            "| {} | {} | {} | {:.1} | {:.1} | {} | {} | {} | {:.0} | {:.0} | {}/{} | {} |",
            r.method,
            r.parameter,
            s.frames,
            s.ms,
            s.median_ms,
            opt(s.chamfer_l1, |v| format!("{v:.3e}")),
            opt(s.fscore, |v| format!("{v:.3}")),
            opt(s.normal_consistency, |v| format!("{v:.4}")),
            s.vertices,
            s.faces,
            s.watertight_frames,
            s.frames,
            r.note
        );
    }
    println!();
    if let Some((equal, ms)) = check {
        println!(
            "The pipeline's own Delaunay mesher (τ 0, rebuild never) gave the same mesh on \
             {equal} of {} frames ({ms:.1} ms/frame).",
            p.frames.len()
        );
    }
    println!(
        "Template watertight: {}. {} done in {:.0} s; load average at end {}.",
        if is_watertight(&p.template) {
            "yes"
        } else {
            "no"
        },
        case.name,
        started.elapsed().as_secs_f64(),
        load()
    );
    Ok(())
}

/// Runs the benchmark.
///
/// # Errors
/// When an input cannot be read or a method fails.
pub fn run(args: &SweepArgs) -> anyhow::Result<()> {
    println!(
        "sweep: {} threads; ms = the method's own work per frame as the pipeline times it; \
         Chamfer L1 and F-score against each frame's deformed template (surface mode)",
        rayon::current_num_threads()
    );
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/data/anim");
    let mut cases = vec![Case {
        name: "CesiumMan (skinned walk cycle)",
        template: fixtures.join("CesiumMan.glb"),
        animation: None,
        frames: args.cesium_frames,
    }];
    let lam = shared_data().join("avatars/lam_p2-1");
    if args.no_lam {
        println!("LAM head skipped (--no-lam)");
    } else if lam.join("skin.glb").exists() && lam.join("test_expression_1s.json").exists() {
        cases.push(Case {
            name: "LAM head (skin.glb + test_expression_1s.json)",
            template: lam.join("skin.glb"),
            animation: Some(lam.join("test_expression_1s.json")),
            frames: Some(args.lam_frames),
        });
    } else {
        println!(
            "note: {} not found (set TRISPLAT_SHARED_DATA): LAM head skipped",
            lam.display()
        );
    }
    for case in &cases {
        sweep(case, args)?;
    }
    Ok(())
}
