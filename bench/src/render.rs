//! `render`: the CPU 3DGS renderer on an avatar-sized scene — 75,000 Gaussians (HRAvatar's
//! size) sampled on the FLAME registered head scan, flat along the surface (in-plane scale the
//! mean sample spacing, normal scale a tenth of it), degree-3 SH, opacities 0.5..0.98 — at
//! 512×512, rgb + alpha + expected depth, for 1 and 2 threads, with the per-stage split.
//!
//! The target on the 2-core machine: ≥ 20 frames per second on 2 threads. There is no
//! CPU tool to compare with (gsplat's rasterizer needs CUDA), so only trisplat's timings print.
//!
//! Unless `--no-backward`, the backward-pass rows follow per thread count: 3DGS (rgb + alpha +
//! depth loss) and 2DGS surfels (rgb + alpha + depth + normal + depth distortion), each beside
//! the plain render of the same mode (the goal: backward ≤ 2× the plain render).

use std::path::Path;

use glam::{DQuat, DVec3, Vec3};
use trisplat_geometry::Camera;
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::rng::Rng;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_splat::render::SURFEL_NEAR;
use trisplat_splat::render::{
    BackwardStats, GaussianGrads, ImageGrads, Outputs, RenderMode, RenderOptions, RenderStats,
    backward_into, render, render_with_grad,
};
use trisplat_splat::{GaussianParts, GaussianSet};
use trisplat_splat::{logit, to_wxyz};

/// The FLAME registered scan (not redistributable: read from the shared data folder).
const SCAN: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/faces/flame/flame_registered_scan.ply"
);
/// Frames not timed (warm-up).
const WARM_UP: usize = 3;

/// Options of the render benchmark.
#[derive(Debug, clap::Args)]
pub struct RenderBenchArgs {
    /// Number of Gaussians.
    #[arg(long, default_value_t = 75_000)]
    pub gaussians: usize,
    /// Image width and height.
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Timed frames per thread count.
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Thread counts to time.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    pub threads: Vec<usize>,
    /// Also render normals and median depth (the geometry outputs).
    #[arg(long)]
    pub all_outputs: bool,
    /// Skip the backward-pass rows (3DGS: differentiable forward and backward of an rgb +
    /// alpha + depth loss; 2DGS surfels: rgb + alpha + depth + normal + depth distortion; each
    /// timed against the plain render of the same images in the same mode).
    #[arg(long)]
    pub no_backward: bool,
}

/// The benchmark scene: Gaussians on the scan and a camera framing it from the front.
fn scene(n: usize, size: u32) -> anyhow::Result<(GaussianSet, Camera)> {
    let mesh = read_mesh(Path::new(SCAN))?;
    let points = sample_uniform(&mesh, n, 7);
    let normals = points
        .normals()
        .ok_or_else(|| anyhow::anyhow!("sampling gave no normals"))?;
    let bounds = mesh
        .bounds()
        .ok_or_else(|| anyhow::anyhow!("the scan has no vertices"))?;
    let area: f64 = mesh.triangle_areas().iter().sum();
    let spacing = (area / n as f64).sqrt();
    let mut rng = Rng::new(11);
    let mut sh = Vec::with_capacity(n * 48);
    let mut rotations = Vec::with_capacity(n);
    let mut log_scales = Vec::with_capacity(n);
    let mut opacity_logits = Vec::with_capacity(n);
    for nrm in normals {
        let q = DQuat::from_rotation_arc(DVec3::Z, nrm.as_dvec3().normalize_or(DVec3::Z));
        let spin = DQuat::from_rotation_z(rng.uniform_f64() * std::f64::consts::TAU);
        rotations.push(to_wxyz(q * spin));
        let s = spacing * (0.8 + 0.6 * rng.uniform_f64());
        log_scales.push(Vec3::new(
            s.ln() as f32,
            (0.7 * s).ln() as f32,
            (0.1 * s).ln() as f32,
        ));
        opacity_logits.push(logit(0.5 + 0.48 * rng.uniform_f32()));
        for k in 0..48 {
            let amp = if k < 3 { 0.8 } else { 0.1 };
            sh.push(amp * (rng.uniform_f32() - 0.5));
        }
    }
    let set = GaussianSet::try_new(GaussianParts {
        means: points.positions().to_vec(),
        log_scales,
        rotations,
        opacity_logits,
        sh_degree: 3,
        sh,
        ..GaussianParts::default()
    })?;
    let center = (bounds.min + bounds.max) * 0.5;
    let radius = (bounds.max - bounds.min).length() * 0.5;
    let fov = 30.0f64;
    let distance = radius / (0.5 * fov.to_radians()).sin();
    let camera = Camera::look_at(
        "front",
        center + DVec3::new(0.15, 0.1, 1.0).normalize() * distance,
        center,
        DVec3::Y,
        (size, size),
        fov,
    )?;
    Ok((set, camera))
}

/// CPU time of the calling thread in seconds (Linux `/proc/thread-self/schedstat`), to see
/// through a loaded machine: with one worker thread all rendering runs on it.
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

/// CPU time of the whole process (all threads, user + system) in seconds, from
/// `/proc/self/stat` (in `USER_HZ` ticks, 100 per second on Linux).
fn process_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may contain spaces) start at field 3 (state);
    // utime and stime are fields 14 and 15.
    let rest = text.get(text.rfind(')')? + 1..)?;
    let mut fields = rest.split_whitespace().skip(11);
    let utime: f64 = fields.next()?.parse().ok()?;
    let stime: f64 = fields.next()?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// Runs the benchmark.
///
/// # Errors
/// When the scan cannot be read (it lives outside the repository, in the shared data folder)
/// or a thread pool cannot be built.
pub fn run(args: &RenderBenchArgs) -> anyhow::Result<()> {
    let (set, camera) = scene(args.gaussians, args.size)?;
    let options = RenderOptions {
        outputs: if args.all_outputs {
            Outputs::ALL
        } else {
            Outputs::RGB_ALPHA_DEPTH
        },
        ..RenderOptions::default()
    };
    println!(
        "render: {} Gaussians (degree 3) on the FLAME scan, {}x{}, outputs {:?}",
        set.len(),
        args.size,
        args.size,
        options.outputs
    );
    for &threads in &args.threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()?;
        let (frames, best, sum, coverage, opaque, (cpu, process_cpu)) =
            pool.install(|| -> anyhow::Result<_> {
                for _ in 0..WARM_UP {
                    render(&set, &camera, &options)?;
                }
                let mut best = f64::INFINITY;
                let cpu_start = thread_cpu_s();
                let process_start = process_cpu_s();
                let mut sum = RenderStats::default();
                let mut coverage = 0.0;
                let mut opaque = 0.0;
                for _ in 0..args.frames.max(1) {
                    let start = std::time::Instant::now();
                    let out = render(&set, &camera, &options)?;
                    best = best.min(start.elapsed().as_secs_f64());
                    let s = out.stats;
                    sum.project_s += s.project_s;
                    sum.sort_s += s.sort_s;
                    sum.composite_s += s.composite_s;
                    sum.visible = s.visible;
                    sum.intersections = s.intersections;
                    if let Some(alpha) = &out.images.alpha {
                        let count = |min: f32| alpha.iter().filter(|a| **a > min).count() as f64;
                        coverage = count(0.5) / alpha.len() as f64;
                        opaque = count(0.9999) / alpha.len() as f64;
                    }
                }
                let cpu = match (cpu_start, thread_cpu_s()) {
                    (Some(a), Some(b)) if threads == 1 => Some((b - a) / args.frames.max(1) as f64),
                    _ => None,
                };
                let process_cpu = match (process_start, process_cpu_s()) {
                    (Some(a), Some(b)) => Some((b - a) / args.frames.max(1) as f64),
                    _ => None,
                };
                Ok((
                    args.frames.max(1),
                    best,
                    sum,
                    coverage,
                    opaque,
                    (cpu, process_cpu),
                ))
            })?;
        let f = frames as f64;
        if let Some(cpu) = cpu {
            println!(
                "1 thread: {:.2} ms CPU time per frame ({:.1} fps if unloaded)",
                cpu * 1e3,
                1.0 / cpu
            );
        }
        if let Some(cpu) = process_cpu {
            println!(
                "{threads} thread(s): {:.2} ms process CPU time per frame, all threads \
                 (10 ms ticks, summed over all frames)",
                cpu * 1e3
            );
        }
        let mean = (sum.project_s + sum.sort_s + sum.composite_s) / f;
        println!(
            "{threads} thread(s): best {:.2} ms ({:.1} fps), mean {:.2} ms ({:.1} fps); \
             project {:.2} ms, sort {:.2} ms, composite {:.2} ms; {} visible, {} tile pairs, \
             {:.0}% of pixels alpha > 0.5, {:.0}% stopped (alpha > 0.9999)",
            best * 1e3,
            1.0 / best,
            mean * 1e3,
            1.0 / mean,
            sum.project_s / f * 1e3,
            sum.sort_s / f * 1e3,
            sum.composite_s / f * 1e3,
            sum.visible,
            sum.intersections,
            coverage * 100.0,
            opaque * 100.0
        );
        if args.no_backward {
            continue;
        }
        for mode in [RenderMode::Gaussian3d, RenderMode::Surfel2d] {
            let t = pool.install(|| time_backward(&set, &camera, args.frames.max(1), mode))?;
            let label = match mode {
                RenderMode::Surfel2d => "2DGS surfels",
                _ => "3DGS",
            };
            println!(
                "{threads} thread(s), {label} backward pass: plain render {:.2} ms, \
                 render_with_grad (f32) {:.2} ms, backward {:.2} ms (best of {}); backward / \
                 plain render {:.2}, backward / render_with_grad {:.2}; backward stages: tiles \
                 {:.2} ms, reduce {:.2} ms, projection {:.2} ms",
                t.plain * 1e3,
                t.forward * 1e3,
                t.backward * 1e3,
                args.frames.max(1),
                t.backward / t.plain,
                t.backward / t.forward,
                t.stages.composite_s * 1e3,
                t.stages.reduce_s * 1e3,
                t.stages.project_s * 1e3
            );
            if threads == 1 && t.cpu[0] > 0.0 {
                let f = args.frames.max(1) as f64;
                println!(
                    "1 thread, {label} backward pass, CPU time per frame: plain render {:.2} ms, \
                     render_with_grad {:.2} ms, backward {:.2} ms; backward / plain render {:.2}",
                    t.cpu[0] / f * 1e3,
                    t.cpu[1] / f * 1e3,
                    t.cpu[2] / f * 1e3,
                    t.cpu[2] / t.cpu[0]
                );
            }
        }
    }
    Ok(())
}

/// Best times of one frame, in seconds.
struct BackwardTimes {
    plain: f64,
    forward: f64,
    backward: f64,
    /// The stages of the best backward pass.
    stages: BackwardStats,
    /// CPU time of the calling thread summed over the timed frames (plain render,
    /// differentiable forward, backward): with one thread all the work runs on it, so this sees
    /// through a loaded machine.
    cpu: [f64; 3],
}

/// Times the plain render, the differentiable forward and the backward pass of a loss on all
/// the images the differentiable forward makes (seeded random image gradients), best of
/// `frames`: in 3DGS mode rgb + alpha + depth; in 2DGS mode also the normal image (the plain
/// render makes it too) and the depth distortion (weight 1; the plain render has none), with
/// hbb1's near plane.
fn time_backward(
    set: &GaussianSet,
    camera: &Camera,
    frames: usize,
    mode: RenderMode,
) -> anyhow::Result<BackwardTimes> {
    let surfels = mode == RenderMode::Surfel2d;
    let options = if surfels {
        RenderOptions {
            mode,
            near: SURFEL_NEAR,
            outputs: Outputs {
                normal: true,
                ..Outputs::RGB_ALPHA_DEPTH
            },
            ..RenderOptions::default()
        }
    } else {
        RenderOptions::default()
    };
    let pixels = camera.width as usize * camera.height as usize;
    let mut rng = Rng::new(5);
    let mut draw = |n: usize| {
        (0..n)
            .map(|_| rng.uniform_f32() - 0.5)
            .collect::<Vec<f32>>()
    };
    let (g_rgb, g_alpha, g_depth) = (draw(3 * pixels), draw(pixels), draw(pixels));
    let g_normal = draw(3 * pixels);
    let grads = ImageGrads {
        rgb: Some(&g_rgb),
        alpha: Some(&g_alpha),
        depth: Some(&g_depth),
        normal: surfels.then_some(g_normal.as_slice()),
        distortion: if surfels { 1.0 } else { 0.0 },
    };
    let mut t = BackwardTimes {
        plain: f64::INFINITY,
        forward: f64::INFINITY,
        backward: f64::INFINITY,
        stages: BackwardStats::default(),
        cpu: [0.0; 3],
    };
    let mut g = GaussianGrads::zeros(set.len(), set.sh_degree());
    for frame in 0..WARM_UP + frames {
        let cpu0 = thread_cpu_s();
        let start = std::time::Instant::now();
        render(set, camera, &options)?;
        let plain = start.elapsed().as_secs_f64();
        let cpu1 = thread_cpu_s();
        let start = std::time::Instant::now();
        let fwd = render_with_grad::<f32, _>(set, camera, &options)?;
        let forward = start.elapsed().as_secs_f64();
        let cpu2 = thread_cpu_s();
        let start = std::time::Instant::now();
        // A fitter's step: the gradient buffers cleared and filled again.
        g.clear();
        let stages = backward_into(set, camera, &options, &fwd, &grads, &mut g)?;
        let back = start.elapsed().as_secs_f64();
        let cpu3 = thread_cpu_s();
        std::hint::black_box(&g);
        if let (Some(c0), Some(c1), Some(c2), Some(c3)) = (cpu0, cpu1, cpu2, cpu3)
            && frame >= WARM_UP
        {
            t.cpu[0] += c1 - c0;
            t.cpu[1] += c2 - c1;
            t.cpu[2] += c3 - c2;
        }
        if frame >= WARM_UP && back < t.backward {
            t.backward = back;
            t.stages = stages;
        }
        if frame >= WARM_UP {
            t.plain = t.plain.min(plain);
            t.forward = t.forward.min(forward);
        }
    }
    Ok(t)
}
