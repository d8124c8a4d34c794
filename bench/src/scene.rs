//! `gaussian-scene`: a static Gaussian scene bound densely to a scanned mesh, for timing
//! `trisplat opacity-mesh` at scale (issue #34, "Scale") and scoring its mesh against the scan.
//!
//! `-n` area-uniform samples on the mesh (the same sampler as `trisplat sample`), each a flat
//! Gaussian tangent to its triangle: tangent standard deviation = the mean distance to its
//! `--neighbours` nearest samples (the local spacing, clamped to [1/2, 2] x the mean spacing
//! `sqrt(area / n)`), normal standard deviation = `--flatness` x that, opacity `--opacity`, a
//! colour from the normal (`0.5 + 0.5 n`, as SH degree 0). Written as a standard world-space 3DGS
//! PLY (INRIA layout, binary). Deterministic for a given mesh, `-n` and `--seed`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, bail};
use glam::{Mat3, Quat, Vec3};
use rayon::prelude::*;
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::spatial::PointIndex;
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};
use trisplat_splat::{GaussianParts, GaussianSet, ParameterSpace, rgb_to_dc};

/// Options of the scene generator.
#[derive(Debug, clap::Args)]
pub struct SceneArgs {
    /// The scanned mesh the Gaussians are bound to (e.g. the FLAME registered scan).
    #[arg(long)]
    pub mesh: PathBuf,
    /// Number of Gaussians.
    #[arg(short = 'n', long = "number", value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    pub n: u64,
    /// Seed of the surface sampling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Opacity of every Gaussian, in (0, 1).
    #[arg(long, default_value_t = 0.9)]
    pub opacity: f32,
    /// Normal standard deviation over the tangent one (flat Gaussians, as GOF trains them).
    #[arg(long, default_value_t = 0.1)]
    pub flatness: f32,
    /// Nearest samples whose mean distance is a Gaussian's tangent standard deviation.
    #[arg(long, default_value_t = 6)]
    pub neighbours: usize,
    /// Output 3DGS PLY (refused if it exists).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
}

/// Writes the scene and prints what it made.
///
/// # Errors
/// Unreadable mesh, zero area, bad options, an existing output, a failed write.
pub fn run(args: &SceneArgs) -> anyhow::Result<()> {
    if args.opacity.is_nan() || args.opacity <= 0.0 || args.opacity >= 1.0 {
        bail!("--opacity {}: expected a value in (0, 1)", args.opacity);
    }
    if !args.flatness.is_finite() || args.flatness <= 0.0 {
        bail!("--flatness {}: expected a finite value > 0", args.flatness);
    }
    if args.neighbours == 0 {
        bail!("--neighbours 0: expected at least 1");
    }
    if args.output.exists() {
        bail!("{}: exists; not overwritten", args.output.display());
    }
    let clock = Instant::now();
    let mesh = read_mesh(&args.mesh).with_context(|| format!("{}", args.mesh.display()))?;
    let area = mesh.area();
    if area.is_nan() || area <= 0.0 {
        bail!("{}: zero surface area", args.mesh.display());
    }
    let n = usize::try_from(args.n)?;
    let samples = sample_uniform(&mesh, n, args.seed);
    let positions = samples.positions();
    let normals = samples
        .normals()
        .context("the sampler gives normals")?
        .to_vec();
    let spacing = (area / n as f64).sqrt() as f32;
    let index = PointIndex::new(positions)?;
    // The query itself comes first (distance 0): ask for one more.
    let k = args.neighbours + 1;
    let local: Vec<f32> = positions
        .par_iter()
        .with_min_len(1024)
        .map(|&q| {
            let near = index.k_nearest(q, k);
            let d: f64 = near.iter().skip(1).map(|x| x.distance).sum::<f64>()
                / (near.len().max(2) - 1) as f64;
            (d as f32).clamp(0.5 * spacing, 2.0 * spacing)
        })
        .collect();
    drop(index);
    let rotations: Vec<[f32; 4]> = normals
        .iter()
        .map(|&nrm| {
            let (t1, t2) = nrm.any_orthonormal_pair();
            let q = Quat::from_mat3(&Mat3::from_cols(t1, t2, nrm)).normalize();
            [q.w, q.x, q.y, q.z]
        })
        .collect();
    let log_scales: Vec<Vec3> = local
        .iter()
        .map(|&s| Vec3::new(s.ln(), s.ln(), (s * args.flatness).ln()))
        .collect();
    let sh: Vec<f32> = normals
        .iter()
        .flat_map(|nrm| (0.5 + 0.5 * *nrm).to_array().map(rgb_to_dc))
        .collect();
    let logit = (args.opacity / (1.0 - args.opacity)).ln();
    let set = GaussianSet::try_new(GaussianParts {
        means: positions.to_vec(),
        log_scales,
        rotations,
        opacity_logits: vec![logit; n],
        sh_degree: 0,
        sh,
        space: ParameterSpace::World,
        ..GaussianParts::default()
    })?;
    write_gaussians(&args.output, &set, &PlyWriteOptions::default())
        .with_context(|| format!("{}", args.output.display()))?;
    let mut sorted = local.clone();
    sorted.sort_unstable_by(f32::total_cmp);
    println!(
        "{}: {n} Gaussians on {} (area {area:.6}, mean spacing {spacing:.6}; tangent sigma median {:.6}, \
         normal sigma x{}; opacity {}), {:.1} s",
        args.output.display(),
        args.mesh.display(),
        sorted[n / 2],
        args.flatness,
        args.opacity,
        clock.elapsed().as_secs_f64()
    );
    Ok(())
}
