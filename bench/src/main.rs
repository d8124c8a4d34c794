//! `cargo run --release -p trisplat-bench -- <benchmark>`: times trisplat and, side by side on
//! the same input files, the Python tool a user would otherwise pick (scipy, Open3D, trimesh),
//! and prints the ratio. Timing never decides a test; these numbers go in the docs.
//!
//! The Python side needs a virtualenv with the pinned packages of
//! `tests/reference/requirements.txt`; pass its interpreter with `--python` (default: the
//! `TRISPLAT_PYTHON` environment variable, else `python3`). Without one, only trisplat's
//! timings are printed.

mod alpha;
mod brdf;
mod deform;
mod delaunay;
mod eval;
mod floor;
mod harness;
mod render;
mod scene;
mod score;
mod smooth;
mod sweep;
mod tsdf;

use clap::{Parser, Subcommand};

/// Benchmarks against the reference tools.
#[derive(Debug, Parser)]
struct Args {
    /// Python interpreter with numpy/scipy/open3d/trimesh installed.
    #[arg(
        long,
        env = "TRISPLAT_PYTHON",
        default_value = "python3",
        global = true
    )]
    python: String,
    /// Skip the Python side.
    #[arg(long, global = true)]
    no_python: bool,
    /// Which benchmark.
    #[command(subcommand)]
    bench: Bench,
}

#[derive(Debug, Subcommand)]
enum Bench {
    /// A synthetic-materials avatar for the relightable fit, and its scores (HRAvatar Table 3).
    BrdfAvatar(brdf::BrdfAvatarArgs),
    /// Deforming 100k bound Gaussians per frame (binding and jacobian modes); trisplat only.
    Deform(deform::DeformBenchArgs),
    /// Incremental Delaunay of ~100k bound Gaussians: frame update vs rebuild, error vs time.
    Delaunay(delaunay::DelaunayBenchArgs),
    /// 3D Delaunay + alpha shape of 100k scan samples vs Open3D (Qhull).
    Alpha(alpha::AlphaBenchArgs),
    /// Chamfer/F-score metrics 1M <-> 1M vs scipy cKDTree, surface distances vs trimesh.
    Eval(eval::EvalBenchArgs),
    /// How well any single surface can score under render consistency: the held-out views'
    /// mutual consistency and oracle surfaces built from them (issue #34).
    OpacityFloor(floor::FloorArgs),
    /// 3DGS CPU rendering of a 75k-Gaussian avatar at 512x512 (1 and 2 threads, stage split).
    Render(render::RenderBenchArgs),
    /// A static scene of flat Gaussians bound densely to a scanned mesh (opacity-mesh at scale).
    GaussianScene(scene::SceneArgs),
    /// What scoring one frame of `extract --gt gaussians` costs, stage by stage (LAM).
    Score(score::ScoreArgs),
    /// Laplacian/Taubin x10 on a 1.5M-face mesh and 1M/100k sampling vs Open3D.
    Smooth,
    /// The main job's three methods on real animated templates: Chamfer against ms per frame.
    Sweep(sweep::SweepArgs),
    /// TSDF fusion of 60 depth maps 512x512 of Spot vs Open3D VoxelBlockGrid, error vs time.
    Tsdf(tsdf::TsdfBenchArgs),
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let python = (!args.no_python).then_some(args.python.as_str());
    match args.bench {
        Bench::BrdfAvatar(a) => brdf::run(&a),
        Bench::Deform(a) => deform::run(&a),
        Bench::Delaunay(a) => delaunay::run(&a),
        Bench::Alpha(a) => alpha::run(&a, python),
        Bench::Eval(a) => eval::run(&a, python),
        Bench::OpacityFloor(a) => floor::run(&a),
        Bench::Render(a) => render::run(&a),
        Bench::GaussianScene(a) => scene::run(&a),
        Bench::Score(a) => score::run(&a),
        Bench::Smooth => smooth::run(python),
        Bench::Sweep(a) => sweep::run(&a),
        Bench::Tsdf(a) => tsdf::run(&a, python),
    }
}
