//! `tsdf`: fusing 60 depth maps of 512 x 512 into a mesh, trisplat vs Open3D 0.20's
//! `VoxelBlockGrid` (CPU) on the same `.npy` files, and an error-vs-time table over voxel sizes.
//!
//! Scene: Spot (`fixtures/data/reference/smoothing/spot.ply`, public domain) scaled by
//! [`SCENE_SIZE`] / its largest bounding-box extent (about 0.3 m tall, a head-sized object),
//! seen by `camera::sphere_rig` (60 cameras on a Fibonacci sphere, 40° field of view, 512 x 512).
//! Depth maps are rendered once by BVH ray casting (`MeshRenderer`) and written as float32 `.npy`
//! with a `cameras.json` to a temporary folder; both sides read those files and loading is not
//! timed.
//!
//! Both sides use the same voxel, truncation [`TRUNC_VOXELS`] voxels and depth truncation (2DGS
//! default: 2 x the scene radius). Timed: ours = allocation + integration + marching cubes +
//! 2DGS clean-up (`tsdf::fuse`); Open3D = `compute_unique_block_coordinates` + `integrate` per
//! frame + `extract_triangle_mesh` (its default weight threshold 3 and block resolution 16).
//! Open3D's VoxelBlockGrid differs from the legacy rules we follow (docs/conventions.md §6): z-difference sdf,
//! floored pixel lookup, integer voxel positions.
//!
//! Chamfer: docs/conventions.md §8 surface mode (exact point-to-triangle distances both ways, as `trisplat
//! eval --surface`) with [`SAMPLES`] area-uniform samples per mesh, both meshes measured by the
//! same Rust code against the scaled Spot.

use std::path::Path;

use anyhow::Context as _;
use glam::Vec3;
use trisplat_extract::tsdf::{DepthImage, TsdfOptions, fuse, read_depth_dir, scene_radius};
use trisplat_geometry::TriMesh;
use trisplat_geometry::camera::{sphere_rig, write_cameras_json};
use trisplat_geometry::io::{read_mesh, write_npy};
use trisplat_geometry::mesh_render::{MeshRenderOptions, MeshRenderer};
use trisplat_geometry::metrics::{MetricsOptions, Shape, evaluate};
use trisplat_geometry::sampling::sample_uniform;

use crate::harness::{python_script, report, run_python, time_best};

/// Largest bounding-box extent of the scaled Spot, in metres.
const SCENE_SIZE: f64 = 0.3;
/// Number of cameras.
const VIEWS: usize = 60;
/// Image size.
const SIZE: u32 = 512;
/// Vertical field of view of the rig.
const FOV_Y_DEG: f64 = 40.0;
/// Truncation in voxels on both sides (2DGS's default).
const TRUNC_VOXELS: f64 = 5.0;
/// Headline voxel (the target: ≥ 2x faster than Open3D at 2 mm).
const VOXEL: f64 = 0.002;
/// Voxels of the error-vs-time table.
const TABLE_VOXELS: [f64; 4] = [0.004, 0.002, 0.0015, 0.001];
/// Samples per mesh for the Chamfer distance.
const SAMPLES: usize = 200_000;
/// Repeats of our side (best time).
const REPEATS: usize = 3;

/// Arguments of the `tsdf` benchmark.
#[derive(Debug, clap::Args)]
pub struct TsdfBenchArgs {
    /// Skip the error-vs-time table (only the 2 mm comparison).
    #[arg(long)]
    no_table: bool,
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
fn scene() -> anyhow::Result<TriMesh> {
    let spot = read_mesh(&trisplat_fixtures::path("reference/smoothing/spot.ply"))?;
    let b = spot.bounds().context("empty mesh")?;
    let extent = (b.max - b.min).max_element();
    let scale = (SCENE_SIZE / f64::from(extent)) as f32;
    let c = b.center();
    let positions: Vec<Vec3> = spot.positions().iter().map(|&p| (p - c) * scale).collect();
    Ok(TriMesh::try_new(positions, spot.triangles().to_vec())?)
}

/// One row of Open3D's results.
struct Theirs {
    seconds: f64,
    chamfer: f64,
    triangles: u64,
}

fn open3d(
    python: &str,
    dir: &Path,
    voxel: f64,
    depth_trunc: f64,
    gt: &TriMesh,
) -> anyhow::Result<Theirs> {
    let out = dir.join(format!("open3d_{voxel}.ply"));
    let args = [
        dir.to_str()
            .context("temporary path is not UTF-8")?
            .to_owned(),
        voxel.to_string(),
        TRUNC_VOXELS.to_string(),
        depth_trunc.to_string(),
        out.to_str()
            .context("temporary path is not UTF-8")?
            .to_owned(),
    ];
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let result = run_python(python, &python_script("tsdf_open3d.py"), &refs)?;
    let seconds = result["seconds"].as_f64().context("no seconds")?;
    let mesh = read_mesh(&out)?;
    Ok(Theirs {
        seconds,
        chamfer: chamfer(&mesh, gt)?,
        triangles: mesh.triangle_count() as u64,
    })
}

/// Runs the benchmark; `python` runs the Open3D side (None: ours only).
///
/// # Errors
/// When the fixture cannot be read, the files cannot be written, or the Python side fails.
pub fn run(args: &TsdfBenchArgs, python: Option<&str>) -> anyhow::Result<()> {
    let gt = scene()?;
    let b = gt.bounds().context("empty mesh")?;
    let radius = gt
        .positions()
        .iter()
        .map(|p| f64::from((*p - b.center()).length()))
        .fold(0.0, f64::max);
    let cameras = sphere_rig(
        b.center().as_dvec3(),
        radius,
        VIEWS,
        (SIZE, SIZE),
        FOV_Y_DEG,
    )?;
    let dir = tempfile::tempdir()?;
    let renderer = MeshRenderer::new(&gt, MeshRenderOptions::default())?;
    for cam in &cameras {
        let maps = renderer.render(cam);
        write_npy(
            &dir.path().join(format!("{}_depth.npy", cam.name)),
            &[SIZE as usize, SIZE as usize],
            &maps.depth,
        )?;
    }
    write_cameras_json(&dir.path().join("cameras.json"), &cameras)?;
    let depths: Vec<DepthImage> = read_depth_dir(dir.path(), &cameras, 1000.0)?;
    let (_, scene_r) = scene_radius(&cameras).context("cameras do not meet")?;
    let depth_trunc = 2.0 * scene_r;
    println!(
        "scene: Spot scaled to {SCENE_SIZE} m ({} triangles), {VIEWS} depth maps {SIZE}x{SIZE}, \
         depth_trunc {depth_trunc:.3} m, trunc {TRUNC_VOXELS} voxels ({} rayon threads)",
        gt.triangle_count(),
        rayon::current_num_threads()
    );

    let run_ours = |voxel: f64| {
        let options = TsdfOptions {
            voxel: Some(voxel),
            trunc: Some(TRUNC_VOXELS * voxel),
            depth_trunc: Some(depth_trunc),
            ..TsdfOptions::default()
        };
        time_best(REPEATS, || fuse(&cameras, &depths, None, &options))
    };

    let (ours_s, fused) = run_ours(VOXEL);
    let fused = fused?;
    let ours_chamfer = chamfer(&fused.mesh, &gt)?;
    println!(
        "trisplat {:.1} mm: {} blocks, allocate {:.3} s, integrate {:.3} s, marching cubes {:.3} \
         s, clean-up {:.3} s, {} triangles, chamfer_l1 {:.4} mm",
        VOXEL * 1e3,
        fused.blocks,
        fused.allocate_seconds,
        fused.integrate_seconds,
        fused.marching_cubes_seconds,
        fused.extract_seconds - fused.marching_cubes_seconds,
        fused.mesh.triangle_count(),
        ours_chamfer * 1e3
    );
    let theirs = match python {
        Some(py) => Some(open3d(py, dir.path(), VOXEL, depth_trunc, &gt)?),
        None => None,
    };
    let label = format!("tsdf {VIEWS} x {SIZE}^2 at {:.0} mm", VOXEL * 1e3);
    report(
        &label,
        ours_s,
        theirs.as_ref().map(|t| ("Open3D VBG", t.seconds)),
    );
    if let Some(t) = &theirs {
        println!(
            "{:<40} chamfer_l1 trisplat {:.4} mm   Open3D {:.4} mm ({} triangles)   ratio {:.3}",
            "",
            ours_chamfer * 1e3,
            t.chamfer * 1e3,
            t.triangles,
            ours_chamfer / t.chamfer
        );
    }

    if args.no_table {
        return Ok(());
    }
    println!("\nerror vs run time (Chamfer L1 to Spot, surface mode, {SAMPLES} samples):");
    println!(
        "| voxel (mm) | trisplat ms | trisplat chamfer (mm) | Open3D VBG ms | Open3D chamfer (mm) |"
    );
    println!("|---|---|---|---|---|");
    for voxel in TABLE_VOXELS {
        let (s, fused) = run_ours(voxel);
        let c = chamfer(&fused?.mesh, &gt)?;
        let theirs = match python {
            Some(py) => {
                let t = open3d(py, dir.path(), voxel, depth_trunc, &gt)?;
                format!("{:.0} | {:.4}", t.seconds * 1e3, t.chamfer * 1e3)
            }
            None => "- | -".to_owned(),
        };
        println!(
            "| {:.1} | {:.0} | {:.4} | {theirs} |",
            voxel * 1e3,
            s * 1e3,
            c * 1e3
        );
    }
    Ok(())
}
