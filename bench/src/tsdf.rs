//! `tsdf`: fusing depth maps into a mesh, trisplat vs Open3D 0.20's `VoxelBlockGrid` (CPU) on
//! the same `.npy` files, over voxel sizes from 100 to 1,000 voxels across the object: time
//! (whole process from the shell, and in-process) against Chamfer distance.
//!
//! Scene (default): Spot (`fixtures/data/reference/smoothing/spot.ply`, public domain) scaled
//! by [`SCENE_SIZE`] / its largest bounding-box extent (about 0.3 m tall, a head-sized object),
//! seen by `camera::sphere_rig` (60 cameras on a Fibonacci sphere, 40° field of view,
//! 512 x 512). Depth maps are rendered once by BVH ray casting (`MeshRenderer`) and written as
//! float32 `.npy` with a `cameras.json` to a temporary folder. With `--scene DIR --gt MESH`,
//! the depth maps and `cameras.json` of DIR are used instead (e.g. `trisplat cameras` +
//! `trisplat render --mesh`), scored against MESH.
//!
//! Both sides use the same voxel (the object's largest extent / voxels across), truncation
//! `--trunc-voxels` (default [`TRUNC_VOXELS`]) voxels and depth truncation (2DGS default: 2 x the scene radius).
//! - Whole process: `trisplat tsdf ... -q` (the release binary next to this one) and
//!   `python tsdf_open3d.py` (interpreter start, `import open3d`, reading the `.npy` files,
//!   fusion, writing the PLY), timed from outside as a user's shell would.
//! - In-process: ours = `tsdf::fuse` (allocation + integration + marching cubes + 2DGS
//!   clean-up, depth maps already in memory); Open3D = `compute_unique_block_coordinates` +
//!   `integrate` per frame + `extract_triangle_mesh` (its default weight threshold 3 and block
//!   resolution 16), as its script times it.
//!
//! Open3D's VoxelBlockGrid differs from the rules we follow (docs/conventions.md §6: the legacy
//! integrator's, with the depth interpolated between pixel centres): z-difference sdf, floored
//! pixel lookup, integer voxel positions, and blocks created by a frame miss the free-space
//! observations of earlier frames.
//!
//! Chamfer: docs/conventions.md §8 surface mode (exact point-to-triangle distances both ways,
//! as `trisplat eval --surface`) with [`SAMPLES`] area-uniform samples per mesh, both meshes
//! measured by the same Rust code against the ground truth.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context as _, bail};
use glam::DVec3;
use trisplat_extract::tsdf::{DepthImage, Fused, TsdfOptions, fuse, read_depth_dir, scene_radius};
use trisplat_geometry::io::{read_mesh, write_npy};
use trisplat_geometry::mesh_render::{MeshRenderOptions, MeshRenderer};
use trisplat_geometry::metrics::{MetricsOptions, Shape, evaluate};
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::{Camera, TriMesh};
use trisplat_geometry::{read_cameras_json, sphere_rig, write_cameras_json};

use crate::harness::python_script;

/// Largest bounding-box extent of the scaled Spot, in metres.
const SCENE_SIZE: f64 = 0.3;
/// Number of cameras.
const VIEWS: usize = 60;
/// Image size.
const SIZE: u32 = 512;
/// Vertical field of view of the rig.
const FOV_Y_DEG: f64 = 40.0;
/// Truncation in voxels on both sides by default (2DGS's default).
const TRUNC_VOXELS: f64 = 5.0;
/// Voxels across the object's largest extent, by default.
const DEFAULT_ACROSS: [u32; 5] = [100, 200, 400, 700, 1000];
/// Samples per mesh for the Chamfer distance.
const SAMPLES: usize = 200_000;

/// Arguments of the `tsdf` benchmark.
#[derive(Debug, clap::Args)]
pub struct TsdfBenchArgs {
    /// Voxels across the object's largest extent, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_ACROSS)]
    across: Vec<u32>,
    /// More voxels-across values run by trisplat alone (no Open3D run), so that the table at
    /// equal error can pick, for each Open3D row, trisplat's fastest setting at or below its
    /// Chamfer distance.
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    ours_only: Vec<u32>,
    /// A folder with cameras.json and <img_name>_depth.npy files instead of the rendered Spot.
    #[arg(long, requires = "gt")]
    scene: Option<PathBuf>,
    /// Ground-truth mesh of --scene (its largest extent sets the voxel).
    #[arg(long, requires = "scene")]
    gt: Option<PathBuf>,
    /// Truncation in voxels, both sides.
    #[arg(long, default_value_t = TRUNC_VOXELS)]
    trunc_voxels: f64,
    /// Runs of each whole process (the best is kept).
    #[arg(long, default_value_t = 2)]
    repeats: usize,
    /// Write the time-against-voxels plot here (SVG).
    #[arg(long)]
    svg: Option<PathBuf>,
}

fn chamfer(pred: &TriMesh, gt: &TriMesh) -> anyhow::Result<f64> {
    let p = sample_uniform(pred, SAMPLES, 1);
    let g = sample_uniform(gt, SAMPLES, 2);
    let options = MetricsOptions {
        surface: true,
        ..MetricsOptions::default()
    };
    Ok(evaluate(Shape::mesh(pred, &p), Shape::mesh(gt, &g), &options)?.chamfer_l1)
}

/// Spot scaled to [`SCENE_SIZE`] and centred at the origin.
fn spot() -> anyhow::Result<TriMesh> {
    let spot = read_mesh(&trisplat_fixtures::path("reference/smoothing/spot.ply"))?;
    let b = spot.bounds().context("empty mesh")?;
    let extent = (b.max - b.min).max_element();
    let scale = SCENE_SIZE / extent;
    let c = b.center();
    let positions: Vec<DVec3> = spot.positions().iter().map(|&p| (p - c) * scale).collect();
    Ok(TriMesh::try_new(positions, spot.triangles().to_vec())?)
}

/// Renders the depth maps of `gt` seen by a sphere rig into `dir`.
fn render_scene(gt: &TriMesh, dir: &Path) -> anyhow::Result<Vec<Camera>> {
    let b = gt.bounds().context("empty mesh")?;
    let radius = gt
        .positions()
        .iter()
        .map(|p| (*p - b.center()).length())
        .fold(0.0, f64::max);
    let cameras = sphere_rig(b.center(), radius, VIEWS, (SIZE, SIZE), FOV_Y_DEG)?;
    let renderer = MeshRenderer::new(gt, MeshRenderOptions::default())?;
    for cam in &cameras {
        let maps = renderer.render(cam);
        write_npy(
            &dir.join(format!("{}_depth.npy", cam.name)),
            &[SIZE as usize, SIZE as usize],
            &maps.depth,
        )?;
    }
    write_cameras_json(&dir.join("cameras.json"), &cameras)?;
    Ok(cameras)
}

/// Best wall time of `repeats` runs of `command`, which must succeed, and the standard output
/// of that run.
fn whole_process(
    repeats: usize,
    mut command: impl FnMut() -> Command,
) -> anyhow::Result<(f64, String)> {
    let mut best = (f64::INFINITY, String::new());
    for _ in 0..repeats.max(1) {
        let mut c = command();
        let start = Instant::now();
        let output = c.output().with_context(|| format!("cannot start {c:?}"))?;
        let seconds = start.elapsed().as_secs_f64();
        if !output.status.success() {
            bail!(
                "{c:?} failed: {}",
                String::from_utf8_lossy(&output.stderr).trim()
            );
        }
        if seconds < best.0 {
            best = (
                seconds,
                String::from_utf8_lossy(&output.stdout).into_owned(),
            );
        }
    }
    Ok(best)
}

/// The `trisplat` release binary beside this benchmark's.
fn trisplat_binary() -> anyhow::Result<PathBuf> {
    let path = std::env::current_exe()?.with_file_name("trisplat");
    if !path.exists() {
        bail!(
            "{}: not built; run `cargo build --release` first",
            path.display()
        );
    }
    Ok(path)
}

/// One voxel size: both sides' times and Chamfer distances.
struct Row {
    across: u32,
    voxel: f64,
    ours_whole: f64,
    ours: Fused,
    ours_in_process: f64,
    ours_chamfer: f64,
    theirs: Option<Theirs>,
}

/// Open3D's side of a row.
struct Theirs {
    whole: f64,
    in_process: f64,
    chamfer: f64,
    triangles: u64,
}

fn path_str(p: &Path) -> anyhow::Result<&str> {
    p.to_str().context("temporary path is not UTF-8")
}

/// Runs the benchmark; `python` runs the Open3D side (None: ours only).
///
/// # Errors
/// When the fixture cannot be read, the files cannot be written, a process fails.
pub fn run(args: &TsdfBenchArgs, python: Option<&str>) -> anyhow::Result<()> {
    let binary = trisplat_binary()?;
    let tmp = tempfile::tempdir()?;
    let (gt, dir, cameras, label) = match (&args.scene, &args.gt) {
        (Some(scene), Some(gt)) => {
            let cameras = read_cameras_json(&scene.join("cameras.json"))?;
            let label = format!("{} ({} views)", scene.display(), cameras.len());
            (read_mesh(gt)?, scene.clone(), cameras, label)
        }
        _ => {
            let gt = spot()?;
            let cameras = render_scene(&gt, tmp.path())?;
            let label = format!(
                "Spot scaled to {SCENE_SIZE} m ({} triangles), {VIEWS} depth maps {SIZE}x{SIZE}",
                gt.triangle_count()
            );
            (gt, tmp.path().to_path_buf(), cameras, label)
        }
    };
    let b = gt.bounds().context("empty ground truth")?;
    let extent = (b.max - b.min).max_element();
    let depths: Vec<DepthImage> = read_depth_dir(&dir, &cameras, 1000.0)?;
    let (_, scene_r) = scene_radius(&cameras).context("cameras do not meet")?;
    let depth_trunc = 2.0 * scene_r;
    println!(
        "scene: {label}, extent {extent:.4}, depth_trunc {depth_trunc:.3}, trunc {} voxels ({} \
         rayon threads)",
        args.trunc_voxels,
        rayon::current_num_threads()
    );
    let cameras_file = dir.join("cameras.json");
    let mut sizes: Vec<(u32, bool)> = args.across.iter().map(|&a| (a, true)).collect();
    sizes.extend(args.ours_only.iter().map(|&a| (a, false)));
    sizes.sort_unstable();
    sizes.dedup_by_key(|(a, _)| *a);
    let mut rows = Vec::new();
    for (across, with_open3d) in sizes {
        let voxel = extent / f64::from(across.max(1));
        let trunc = args.trunc_voxels * voxel;
        let out = tmp.path().join("ours.ply");
        let (ours_whole, _) = whole_process(args.repeats, || {
            let mut c = Command::new(&binary);
            c.args(["tsdf", "-q", "--cameras"])
                .arg(&cameras_file)
                .arg("--depth")
                .arg(&dir)
                .args(["--voxel", &voxel.to_string(), "--trunc", &trunc.to_string()])
                .args(["--depth-trunc", &depth_trunc.to_string(), "-o"])
                .arg(&out);
            c
        })?;
        let options = TsdfOptions {
            voxel: Some(voxel),
            trunc: Some(trunc),
            depth_trunc: Some(depth_trunc),
            ..TsdfOptions::default()
        };
        let start = Instant::now();
        let fused = fuse(&cameras, &depths, None, &options)?;
        let ours_in_process = start.elapsed().as_secs_f64();
        let ours_chamfer = chamfer(&fused.mesh, &gt)?;
        let theirs = match python.filter(|_| with_open3d) {
            Some(py) => Some(open3d(py, args, &dir, voxel, depth_trunc, &gt, tmp.path())?),
            None => None,
        };
        let row = Row {
            across,
            voxel,
            ours_whole,
            ours: fused,
            ours_in_process,
            ours_chamfer,
            theirs,
        };
        print_row(&row);
        rows.push(row);
    }
    println!("\n{}", table(&rows));
    if rows.iter().any(|r| r.theirs.is_some()) {
        println!(
            "At equal or lower Chamfer distance:\n\n{}",
            equal_error_table(&rows)
        );
    }
    if let Some(svg) = &args.svg {
        std::fs::write(svg, plot(&rows, &label))
            .with_context(|| format!("{}: cannot write", svg.display()))?;
        println!("plot: {}", svg.display());
    }
    Ok(())
}

fn open3d(
    python: &str,
    args: &TsdfBenchArgs,
    dir: &Path,
    voxel: f64,
    depth_trunc: f64,
    gt: &TriMesh,
    tmp: &Path,
) -> anyhow::Result<Theirs> {
    let out = tmp.join("open3d.ply");
    let repeats = args.repeats;
    let args = [
        path_str(dir)?.to_owned(),
        voxel.to_string(),
        args.trunc_voxels.to_string(),
        depth_trunc.to_string(),
        path_str(&out)?.to_owned(),
    ];
    let script = python_script("tsdf_open3d.py");
    let (whole, stdout) = whole_process(repeats, || {
        let mut c = Command::new(python);
        c.arg(&script).args(&args);
        c
    })?;
    let result: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap_or_default())
        .with_context(|| format!("{}: no JSON result", script.display()))?;
    let in_process = result["seconds"].as_f64().context("no seconds")?;
    let mesh = read_mesh(&out)?;
    Ok(Theirs {
        whole,
        in_process,
        chamfer: chamfer(&mesh, gt)?,
        triangles: mesh.triangle_count() as u64,
    })
}

fn print_row(r: &Row) {
    let f = &r.ours;
    println!(
        "{} across (voxel {:.3e}): trisplat whole {:.3} s, in-process {:.3} s (allocate {:.3}, \
         integrate {:.3}, marching cubes {:.3}, clean-up {:.3}; {} blocks, {} triangles), \
         chamfer {:.4e}",
        r.across,
        r.voxel,
        r.ours_whole,
        r.ours_in_process,
        f.allocate_seconds,
        f.integrate_seconds,
        f.marching_cubes_seconds,
        f.extract_seconds - f.marching_cubes_seconds,
        f.blocks,
        f.mesh.triangle_count(),
        r.ours_chamfer
    );
    if let Some(t) = &r.theirs {
        println!(
            "{:>w$} Open3D VBG whole {:.3} s, in-process {:.3} s, {} triangles, chamfer {:.4e}: \
             whole-process speed-up x{:.2}, chamfer ratio {:.3}",
            "",
            t.whole,
            t.in_process,
            t.triangles,
            t.chamfer,
            t.whole / r.ours_whole,
            r.ours_chamfer / t.chamfer,
            w = 4
        );
    }
}

/// The Markdown table of the rows.
fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| voxels across | voxel | trisplat whole s | trisplat in-process s | Open3D whole s | \
         Open3D in-process s | speed-up (whole) | trisplat Chamfer | Open3D Chamfer |\n\
         |---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let (tw, ti, ratio, tc) = match &r.theirs {
            Some(t) => (
                format!("{:.2}", t.whole),
                format!("{:.2}", t.in_process),
                format!("{:.2}x", t.whole / r.ours_whole),
                format!("{:.4e}", t.chamfer),
            ),
            None => ("-".into(), "-".into(), "-".into(), "-".into()),
        };
        let _ = writeln!(
            s,
            "| {} | {:.3e} | {:.2} | {:.2} | {tw} | {ti} | {ratio} | {:.4e} | {tc} |",
            r.across, r.voxel, r.ours_whole, r.ours_in_process, r.ours_chamfer
        );
    }
    s
}

/// For each row with Open3D's side: trisplat's fastest row (whole process) whose Chamfer
/// distance is at most Open3D's, and the speed-up between the two, as a Markdown table.
fn equal_error_table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| Open3D voxels across | Open3D whole s | Open3D Chamfer | trisplat voxels across | \
         trisplat whole s | trisplat Chamfer | speed-up (whole) |\n\
         |---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let Some(t) = &r.theirs else { continue };
        let fastest = rows
            .iter()
            .filter(|o| o.ours_chamfer <= t.chamfer)
            .min_by(|a, b| a.ours_whole.total_cmp(&b.ours_whole));
        let (across, whole, chamfer, ratio) = match fastest {
            Some(o) => (
                o.across.to_string(),
                format!("{:.2}", o.ours_whole),
                format!("{:.4e}", o.ours_chamfer),
                format!("{:.2}x", t.whole / o.ours_whole),
            ),
            None => ("none as close".into(), "-".into(), "-".into(), "-".into()),
        };
        let _ = writeln!(
            s,
            "| {} | {:.2} | {:.4e} | {across} | {whole} | {chamfer} | {ratio} |",
            r.across, t.whole, t.chamfer
        );
    }
    s
}

/// Time against voxels across, log-log, as a small standalone SVG.
fn plot(rows: &[Row], label: &str) -> String {
    const W: f64 = 640.0;
    const H: f64 = 400.0;
    const LEFT: f64 = 70.0;
    const RIGHT: f64 = 170.0;
    const TOP: f64 = 40.0;
    const BOTTOM: f64 = 50.0;
    type Series<'a> = (
        &'a str,
        &'a str,
        bool,
        Box<dyn Fn(&Row) -> Option<f64> + 'a>,
    );
    let series: [Series<'_>; 4] = [
        (
            "trisplat whole",
            "#1f77b4",
            false,
            Box::new(|r| Some(r.ours_whole)),
        ),
        (
            "trisplat in-process",
            "#1f77b4",
            true,
            Box::new(|r| Some(r.ours_in_process)),
        ),
        (
            "Open3D whole",
            "#d62728",
            false,
            Box::new(|r| r.theirs.as_ref().map(|t| t.whole)),
        ),
        (
            "Open3D in-process",
            "#d62728",
            true,
            Box::new(|r| r.theirs.as_ref().map(|t| t.in_process)),
        ),
    ];
    let xs: Vec<f64> = rows.iter().map(|r| f64::from(r.across)).collect();
    let ys: Vec<f64> = series
        .iter()
        .flat_map(|(_, _, _, f)| rows.iter().filter_map(f))
        .filter(|&y| y > 0.0)
        .collect();
    let (x0, x1) = (
        xs.iter().copied().fold(f64::INFINITY, f64::min).max(1.0),
        xs.iter().copied().fold(0.0, f64::max).max(2.0),
    );
    let y0 = ys.iter().copied().fold(f64::INFINITY, f64::min).min(1.0) * 0.8;
    let y1 = ys.iter().copied().fold(0.0, f64::max).max(y0 * 2.0) * 1.25;
    let (x0, x1) = if x1 > x0 {
        (x0, x1)
    } else {
        (x0 * 0.5, x0 * 2.0)
    };
    let px = |x: f64| LEFT + (x.ln() - x0.ln()) / (x1.ln() - x0.ln()) * (W - LEFT - RIGHT);
    let py = |y: f64| H - BOTTOM - (y.ln() - y0.ln()) / (y1.ln() - y0.ln()) * (H - TOP - BOTTOM);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{H}\" \
         font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"{W}\" height=\"{H}\" \
         fill=\"white\"/>\n<text x=\"{LEFT}\" y=\"20\" font-size=\"13\">TSDF: time against \
         voxels across ({})</text>\n",
        escape(label)
    );
    let (bx0, by0, bx1, by1) = (LEFT, TOP, W - RIGHT, H - BOTTOM);
    let _ = writeln!(
        s,
        "<rect x=\"{bx0}\" y=\"{by0}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#444\"/>",
        bx1 - bx0,
        by1 - by0
    );
    // A grid line per size; a label only where it clears the previous one.
    let mut last_label = f64::NEG_INFINITY;
    for &x in &xs {
        let _ = write!(
            s,
            "<line x1=\"{0:.1}\" y1=\"{by1}\" x2=\"{0:.1}\" y2=\"{by0}\" stroke=\"#ddd\"/>",
            px(x)
        );
        if px(x) - last_label >= 30.0 {
            last_label = px(x);
            let _ = write!(
                s,
                "<text x=\"{0:.1}\" y=\"{1}\" text-anchor=\"middle\">{x}</text>",
                px(x),
                by1 + 16.0
            );
        }
        s.push('\n');
    }
    let mut tick = 10f64.powf(y0.log10().floor());
    while tick <= y1 {
        for m in [1.0, 2.0, 5.0] {
            let y = tick * m;
            if y >= y0 && y <= y1 {
                let _ = writeln!(
                    s,
                    "<line x1=\"{bx0}\" y1=\"{0:.1}\" x2=\"{bx1}\" y2=\"{0:.1}\" stroke=\"#ddd\"/>\
                     <text x=\"{1}\" y=\"{2:.1}\" text-anchor=\"end\">{y} s</text>",
                    py(y),
                    bx0 - 6.0,
                    py(y) + 4.0
                );
            }
        }
        tick *= 10.0;
    }
    let _ = writeln!(
        s,
        "<text x=\"{:.1}\" y=\"{}\" text-anchor=\"middle\">voxels across the object (log)</text>\
         <text x=\"16\" y=\"{:.1}\" transform=\"rotate(-90 16 {:.1})\" \
         text-anchor=\"middle\">seconds (log)</text>",
        0.5 * (bx0 + bx1),
        H - 12.0,
        0.5 * (by0 + by1),
        0.5 * (by0 + by1)
    );
    for (k, (name, colour, dashed, value)) in series.iter().enumerate() {
        let points: Vec<String> = rows
            .iter()
            .filter_map(|r| {
                value(r).map(|y| format!("{:.1},{:.1}", px(f64::from(r.across)), py(y)))
            })
            .collect();
        if points.is_empty() {
            continue;
        }
        let dash = if *dashed {
            " stroke-dasharray=\"6 4\""
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\"{dash}/>",
            points.join(" ")
        );
        let ly = TOP + 20.0 + 22.0 * k as f64;
        let _ = writeln!(
            s,
            "<line x1=\"{0}\" y1=\"{ly}\" x2=\"{1}\" y2=\"{ly}\" stroke=\"{colour}\" \
             stroke-width=\"2\"{dash}/><text x=\"{2}\" y=\"{3}\">{name}</text>",
            bx1 + 10.0,
            bx1 + 34.0,
            bx1 + 40.0,
            ly + 4.0
        );
    }
    s.push_str("</svg>\n");
    s
}

/// `text` with the XML special characters escaped.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
