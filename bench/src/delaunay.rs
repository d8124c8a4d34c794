//! `delaunay`: incremental Delaunay meshing of ~100k bound Gaussians on an avatar template,
//! frame update against full rebuild, and the "error against run time" table (hop threshold,
//! rebuild period vs Chamfer vs ms).
//!
//! Template: the FLAME template (5,023 vertices, 9,976 triangles) from the shared data folder
//! when present, else Spot subdivided once (23,424 triangles). Gaussians: GaussianAvatars
//! binding, `--per-triangle` per triangle spread over the triangle, with a normal offset and an
//! in-plane jitter (in units of the triangle scale `k`) so some lie beside their triangle and
//! hop when the surface bends. Animation (made here, deterministic): the lower part of the head
//! bends about a horizontal axis ("jaw"), with a smooth blend zone, plus a small twist, over
//! `--frames` frames. Deformation of the Gaussians is timed separately; the update and rebuild
//! times are those of `IncrementalDelaunay::update` plus collecting the triangle list.
//!
//! Chamfer: L1 Chamfer (surface mode, 20k area-uniform samples per side) of the extracted mesh
//! against the deformed template, averaged over every 5th frame. "flipped" is the fraction of
//! output triangles whose normal points against their chart's deformed template triangle.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use glam::{DVec3, Vec3};
use trisplat_extract::incremental_delaunay::{DelaunayOptions, IncrementalDelaunay};
use trisplat_geometry::TriMesh;
use trisplat_geometry::metrics::{MetricsOptions, Shape, evaluate};
use trisplat_geometry::rng::Rng;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_splat::GaussianSet;
use trisplat_splat::{BindOptions, init_bound};
use trisplat_splat::{DeformMode, Deformer, WorldGeometry};

/// The FLAME template in the shared data folder (not redistributable: never a fixture).
const FLAME: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/faces/flame/flame_template.ply"
);

/// Samples per side for the Chamfer distance.
const CHAMFER_SAMPLES: usize = 20_000;

/// Options of the delaunay benchmark.
#[derive(Debug, clap::Args)]
pub struct DelaunayBenchArgs {
    /// Frames of the animation.
    #[arg(long, default_value_t = 60)]
    pub frames: usize,
    /// Gaussians per template triangle.
    #[arg(long, default_value_t = 10)]
    pub per_triangle: usize,
    /// Bend amplitude in radians.
    #[arg(long, default_value_t = 0.35)]
    pub amplitude: f64,
    /// Normal offset of the Gaussians (uniform in ±this, in units of the triangle scale).
    #[arg(long, default_value_t = 0.15)]
    pub normal_offset: f32,
    /// In-plane jitter of the Gaussians (uniform in ±this, in units of the triangle scale).
    #[arg(long, default_value_t = 0.3)]
    pub jitter: f32,
    /// Skip the error/run-time table.
    #[arg(long)]
    pub no_table: bool,
    /// Write the scene instead of timing it: `DIR/template.ply`, the bound Gaussians
    /// `DIR/gaussians.ply` and the animation `DIR/frames/frame_NNNN.ply` (binary, vertices as
    /// doubles), so `trisplat extract` can be timed on it as a whole process.
    #[arg(long, value_name = "DIR")]
    pub write: Option<std::path::PathBuf>,
}

fn load_template() -> anyhow::Result<(String, TriMesh)> {
    if Path::new(FLAME).exists() {
        let mesh = trisplat_geometry::io::read_mesh(Path::new(FLAME))
            .with_context(|| format!("reading {FLAME}"))?;
        return Ok(("FLAME template".into(), mesh));
    }
    let spot = trisplat_fixtures::spot()?;
    Ok((
        "Spot subdivided once".into(),
        trisplat_geometry::subdivide::midpoint(&spot, 1)?,
    ))
}

fn make_gaussians(mesh: &TriMesh, args: &DelaunayBenchArgs) -> anyhow::Result<GaussianSet> {
    let set = init_bound(
        mesh,
        &BindOptions {
            per_triangle: args.per_triangle,
            ..BindOptions::default()
        },
    )?;
    let mut parts = set.into_parts();
    let mut rng = Rng::new(7);
    for m in &mut parts.means {
        let mut u = || 2.0 * rng.uniform_f32() - 1.0;
        // GaussianAvatars local frame: y is the normal.
        *m += Vec3::new(
            args.jitter * u(),
            args.normal_offset * u(),
            args.jitter * u(),
        );
    }
    Ok(GaussianSet::try_new(parts)?)
}

/// The animation: vertices below the pivot bend about the x axis through it by up to
/// `amplitude · sin`, blended smoothly over a band, plus a twist about y.
struct Animation {
    rest: Vec<DVec3>,
    pivot: DVec3,
    height: f64,
    amplitude: f64,
    frames: usize,
}

impl Animation {
    fn new(mesh: &TriMesh, amplitude: f64, frames: usize) -> Self {
        let b = mesh
            .bounds()
            .map_or((DVec3::ZERO, DVec3::ONE), |b| (b.min, b.max));
        let (lo, hi) = b;
        Self {
            rest: mesh.positions().to_vec(),
            pivot: DVec3::new(0.5 * (lo.x + hi.x), lo.y + 0.45 * (hi.y - lo.y), lo.z),
            height: (hi.y - lo.y).max(f64::MIN_POSITIVE),
            amplitude,
            frames: frames.max(1),
        }
    }

    fn frame(&self, f: usize) -> Vec<DVec3> {
        let phase = std::f64::consts::TAU * f as f64 / self.frames as f64;
        let bend = self.amplitude * (0.5 - 0.5 * phase.cos());
        let twist = 0.3 * self.amplitude * phase.sin();
        self.rest
            .iter()
            .map(|&p| {
                let s = (self.pivot.y - p.y) / (0.25 * self.height);
                let w = s.clamp(0.0, 1.0);
                let w = w * w * (3.0 - 2.0 * w);
                let (sin, cos) = (bend * w).sin_cos();
                let d = p - self.pivot;
                let q = DVec3::new(d.x, cos * d.y - sin * d.z, sin * d.y + cos * d.z);
                let t = twist * (p.y - self.pivot.y) / self.height;
                let (st, ct) = t.sin_cos();
                let q = DVec3::new(ct * q.x + st * q.z, q.y, -st * q.x + ct * q.z);
                q + self.pivot
            })
            .collect()
    }
}

/// CPU time of all threads of the process in nanoseconds (Linux: the sum of
/// `/proc/self/task/*/schedstat`), to see through a loaded machine.
fn process_cpu_ns() -> Option<u64> {
    let mut total = 0u64;
    for entry in std::fs::read_dir("/proc/self/task").ok()? {
        let path = entry.ok()?.path().join("schedstat");
        let text = std::fs::read_to_string(path).ok()?;
        total += text.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total)
}

/// Per-run results.
struct Run {
    update_ms: Vec<f64>,
    /// Process CPU milliseconds of each update (all threads), when available.
    update_cpu_ms: Vec<f64>,
    hop_fraction: Vec<f64>,
    search_fraction: Vec<f64>,
    charts_fraction: Vec<f64>,
    chamfer: Vec<f64>,
    flipped: Vec<f64>,
    /// Per frame, a fingerprint of the output triangles as a set (see [`fingerprint`]).
    fingerprints: Vec<u64>,
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn flipped_fraction(d: &IncrementalDelaunay, positions: &[DVec3], template: &TriMesh) -> f64 {
    let verts = d.vertices();
    let (mut flipped, mut total) = (0usize, 0usize);
    for (t, tri) in template.triangles().iter().enumerate() {
        let c = tri.map(|k| positions[k as usize]);
        let n = (c[1] - c[0]).cross(c[2] - c[0]);
        for out in d.chart_triangles(t) {
            let v = out.map(|k| verts[k as usize]);
            total += 1;
            if (v[1] - v[0]).cross(v[2] - v[0]).dot(n) < 0.0 {
                flipped += 1;
            }
        }
    }
    flipped as f64 / total.max(1) as f64
}

#[expect(
    clippy::too_many_arguments,
    reason = "one benchmark driver, all inputs named"
)]
fn run_once(
    template: &TriMesh,
    set: &GaussianSet,
    anim: &Animation,
    options: DelaunayOptions,
    frames: usize,
    measure_error: bool,
    keep_triangles: bool,
    deform_ms: &mut Vec<f64>,
) -> anyhow::Result<Run> {
    let deformer = Deformer::new(template, DeformMode::Binding);
    let mut d = IncrementalDelaunay::new(
        template,
        &deformer.means(set, template.positions())?,
        options,
    )?;
    let mut geometry = WorldGeometry::default();
    let n = set.len() as f64;
    let charts = template.triangle_count() as f64;
    let mut run = Run {
        update_ms: Vec::new(),
        update_cpu_ms: Vec::new(),
        hop_fraction: Vec::new(),
        search_fraction: Vec::new(),
        charts_fraction: Vec::new(),
        chamfer: Vec::new(),
        flipped: Vec::new(),
        fingerprints: Vec::new(),
    };
    for f in 0..frames {
        let positions = anim.frame(f);
        let start = Instant::now();
        deformer.deform_geometry(set, &positions, &mut geometry)?;
        deform_ms.push(start.elapsed().as_secs_f64() * 1e3);
        let cpu_start = process_cpu_ns();
        let start = Instant::now();
        let stats = d.update(&positions, &geometry.means)?;
        let triangles = d.triangles();
        let ms = start.elapsed().as_secs_f64() * 1e3;
        let cpu = cpu_start
            .zip(process_cpu_ns())
            .map(|(a, b)| b.saturating_sub(a) as f64 * 1e-6);
        // Frame 0 is the initial build of every run.
        if f > 0 {
            run.update_ms.push(ms);
            run.update_cpu_ms.extend(cpu);
            run.hop_fraction.push(stats.hopped as f64 / n);
            run.search_fraction.push(stats.searches as f64 / n);
            run.charts_fraction
                .push(stats.charts_redone as f64 / charts);
        }
        if measure_error && f % 5 == 0 {
            let deformed = TriMesh::new_unchecked(positions.clone(), template.triangles().to_vec());
            let mesh = d.mesh();
            let (ps, gs) = (
                sample_uniform(&mesh, CHAMFER_SAMPLES, 1),
                sample_uniform(&deformed, CHAMFER_SAMPLES, 2),
            );
            let m = evaluate(
                Shape::mesh(&mesh, &ps),
                Shape::mesh(&deformed, &gs),
                &MetricsOptions {
                    taus: vec![1e-3],
                    surface: true,
                },
            )?;
            run.chamfer.push(m.chamfer_l1);
            run.flipped.push(flipped_fraction(&d, &positions, template));
        }
        if keep_triangles {
            run.fingerprints.push(fingerprint(&triangles));
        }
    }
    Ok(run)
}

/// splitmix64's finaliser.
fn mix(mut x: u64) -> u64 {
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// An order-independent 64-bit fingerprint of the triangles as a set (each rotated to start
/// at its smallest vertex id, hashed, and the hashes summed): equal sets give equal
/// fingerprints. One streaming pass and no allocation, so that checking a frame between
/// updates neither keeps every frame's list (fresh pages to fault in) nor evicts the mesher's
/// state from the caches the way sorting the list would.
fn fingerprint(t: &[[u32; 3]]) -> u64 {
    t.iter().fold(0u64, |acc, tri| {
        let k = (0..3).min_by_key(|&k| tri[k]).unwrap_or(0);
        let mut r = *tri;
        r.rotate_left(k);
        let h = mix(u64::from(r[0]) ^ mix(u64::from(r[1]) ^ mix(u64::from(r[2]))));
        acc.wrapping_add(h)
    })
}

/// Writes the template, the bound Gaussians and the animation's frames to `dir` and prints the
/// `trisplat extract` commands that time the incremental mesher and the rebuild on them.
fn write_scene(
    dir: &Path,
    template: &TriMesh,
    set: &GaussianSet,
    anim: &Animation,
    frames: usize,
) -> anyhow::Result<()> {
    use trisplat_geometry::io::{WriteOptions, write_mesh};
    let frames_dir = dir.join("frames");
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("creating {}", frames_dir.display()))?;
    write_mesh(&dir.join("template.ply"), template, WriteOptions::default())?;
    trisplat_splat::ply::write_gaussians(
        &dir.join("gaussians.ply"),
        set,
        &trisplat_splat::ply::PlyWriteOptions::default(),
    )?;
    for f in 0..frames {
        let mesh = TriMesh::try_new(anim.frame(f), template.triangles().to_vec())?;
        write_mesh(
            &frames_dir.join(format!("frame_{f:04}.ply")),
            &mesh,
            WriteOptions::default(),
        )?;
    }
    let d = dir.display();
    println!(
        "wrote {d}/template.ply, {d}/gaussians.ply ({} Gaussians) and {frames} frames in \
         {d}/frames; time the whole process with\n  trisplat extract --template {d}/template.ply \
         --gaussians {d}/gaussians.ply --animation {d}/frames --method delaunay --targets report \
         -q -o OUT [--rebuild-every 1]",
        set.len()
    );
    Ok(())
}

/// Runs the benchmark.
///
/// # Errors
/// When the template cannot be read or meshing fails.
pub fn run(args: &DelaunayBenchArgs) -> anyhow::Result<()> {
    let (name, template) = load_template()?;
    let set = make_gaussians(&template, args)?;
    let anim = Animation::new(&template, args.amplitude, args.frames);
    if let Some(dir) = &args.write {
        return write_scene(dir, &template, &set, &anim, args.frames);
    }
    println!(
        "delaunay: {name} ({} vertices, {} triangles), {} Gaussians, {} frames, {} threads",
        template.vertex_count(),
        template.triangle_count(),
        set.len(),
        args.frames,
        rayon::current_num_threads()
    );
    let mut deform_ms = Vec::new();
    let incremental = run_once(
        &template,
        &set,
        &anim,
        DelaunayOptions::default(),
        args.frames,
        false,
        true,
        &mut deform_ms,
    )?;
    let rebuild = run_once(
        &template,
        &set,
        &anim,
        DelaunayOptions {
            rebuild_every: 1,
            ..DelaunayOptions::default()
        },
        args.frames,
        false,
        true,
        &mut deform_ms,
    )?;
    let same = incremental
        .fingerprints
        .iter()
        .zip(&rebuild.fingerprints)
        .filter(|(a, b)| a == b)
        .count();
    let (inc, reb) = (median(&incremental.update_ms), median(&rebuild.update_ms));
    println!(
        "Gaussians hopped per frame: mean {:.2}%, max {:.2}%; charts redone per frame: mean {:.2}%",
        100.0 * mean(&incremental.hop_fraction),
        100.0 * incremental.hop_fraction.iter().copied().fold(0.0, f64::max),
        100.0 * mean(&incremental.charts_fraction)
    );
    println!(
        "Gaussians checked in full per frame (the others settled by motion certificates): \
         mean {:.2}%",
        100.0 * mean(&incremental.search_fraction)
    );
    println!(
        "deforming the Gaussians (not included below): median {:.2} ms/frame",
        median(&deform_ms)
    );
    println!(
        "incremental update (hop threshold 0): median {inc:.2} ms/frame   full rebuild: median \
         {reb:.2} ms/frame   speed-up x{:.2} (target >= 5)",
        reb / inc
    );
    if !incremental.update_cpu_ms.is_empty() && !rebuild.update_cpu_ms.is_empty() {
        let (inc, reb) = (
            median(&incremental.update_cpu_ms),
            median(&rebuild.update_cpu_ms),
        );
        println!(
            "process CPU time (all threads): incremental median {inc:.2} ms/frame   rebuild \
             median {reb:.2} ms/frame   ratio x{:.2}",
            reb / inc
        );
    }
    println!(
        "frames whose incremental mesh equals the rebuilt one: {same} of {}",
        incremental.fingerprints.len()
    );
    if args.no_table {
        return Ok(());
    }
    println!();
    println!(
        "| hop threshold (x mean edge) | rebuild every | ms/frame (mean, rebuilds included) \
         | ms/frame (median) | hopped/frame | Chamfer L1 vs deformed template | flipped triangles |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    for &tau in &[0.0, 0.05, 0.1, 0.25, 0.5] {
        for &period in &[0usize, 10] {
            let r = run_once(
                &template,
                &set,
                &anim,
                DelaunayOptions {
                    hop_threshold: tau,
                    rebuild_every: period,
                    ..DelaunayOptions::default()
                },
                args.frames,
                true,
                false,
                &mut Vec::new(),
            )?;
            println!(
                "| {tau} | {} | {:.2} | {:.2} | {:.2}% | {:.3e} | {:.3}% |",
                if period == 0 {
                    "never".to_string()
                } else {
                    period.to_string()
                },
                mean(&r.update_ms),
                median(&r.update_ms),
                100.0 * mean(&r.hop_fraction),
                mean(&r.chamfer),
                100.0 * mean(&r.flipped)
            );
        }
    }
    Ok(())
}
