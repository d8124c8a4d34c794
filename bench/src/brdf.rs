//! `brdf-avatar`: the synthetic-materials avatar of docs/benchmarks.md ("Relightable fit on the
//! LAM avatar", issue #33) made from any bound set, and the fitted sets scored against it.
//!
//! - `make`: a bound set (e.g. `trisplat bind LAM/skin.glb`) becomes the truth (flat Gaussians
//!   with known, smoothly varying albedo, roughness and F0: `pipeline::fit::synthetic_materials`)
//!   and the start of its fit (rotations turned, no materials), both bound PLYs. The truth is
//!   then deformed to world space and relit by `trisplat render --env` for the target images,
//!   and the start fitted back by `trisplat fit --appearance brdf` (bench/fit_brdf_lam.sh).
//! - `score`: each given bound set against the truth on held-out cameras, as HRAvatar's Table 3
//!   (albedo LMSE, normal cosine) plus the per-Gaussian shortest-axis `|cos|`; one JSON line
//!   per set.

use std::path::PathBuf;

use anyhow::Context as _;
use glam::Vec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::read_cameras_json;
use trisplat_pipeline::fit::{rest_world, synthetic_materials, synthetic_scores};
use trisplat_pipeline::input::{read_bound, read_template};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};
use trisplat_splat::render::RenderOptions;
use trisplat_splat::{GaussianParts, GaussianSet};

/// Options of the synthetic-materials benchmark.
#[derive(Debug, clap::Args)]
pub struct BrdfAvatarArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: Action,
}

/// The two steps around `trisplat render --env` and `trisplat fit --appearance brdf`.
#[derive(Debug, clap::Subcommand)]
pub enum Action {
    /// Writes OUT/truth.ply and OUT/init.ply from a bound set.
    Make {
        /// The template the set is bound to.
        #[arg(long)]
        template: PathBuf,
        /// A bound Gaussian PLY (`trisplat bind`).
        bound: PathBuf,
        /// Output folder.
        #[arg(short = 'o', long)]
        output: PathBuf,
        /// Seed of the rotations' perturbation.
        #[arg(long, default_value_t = 7)]
        seed: u64,
    },
    /// Scores bound sets against the truth on held-out cameras.
    Score {
        /// The template.
        #[arg(long)]
        template: PathBuf,
        /// The truth (`make`'s truth.ply).
        #[arg(long)]
        truth: PathBuf,
        /// Held-out cameras (a 3DGS cameras.json).
        #[arg(long)]
        cameras: PathBuf,
        /// Bound sets to score (the start, fitted sets).
        sets: Vec<PathBuf>,
    },
}

/// The truth at the template's rest pose in world space, with its material (what `trisplat
/// render --env` relights for the targets; the same placement as the fit's).
fn world_set(truth: &GaussianSet, mesh: &TriMesh) -> anyhow::Result<GaussianSet> {
    let (w, material) = rest_world(truth, mesh)?;
    let v = |a: &[f64; 3]| Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32);
    let parts = GaussianParts {
        means: w.means.iter().map(v).collect(),
        log_scales: w.log_scales.iter().map(v).collect(),
        scale_dims: truth.scale_dims(),
        rotations: w.rotations.iter().map(|q| q.map(|x| x as f32)).collect(),
        opacity_logits: w.opacity_logits.iter().map(|&x| x as f32).collect(),
        sh_degree: w.sh_degree,
        sh: w.sh.iter().map(|&x| x as f32).collect(),
        material: Some(material),
        ..GaussianParts::default()
    };
    Ok(GaussianSet::try_new(parts)?)
}

/// Runs one step.
///
/// # Errors
/// Unreadable inputs, sets not bound to the template, a failed render or write.
pub fn run(args: &BrdfAvatarArgs) -> anyhow::Result<()> {
    match &args.action {
        Action::Make {
            template,
            bound,
            output,
            seed,
        } => {
            let mesh = read_template(template)?;
            let set = read_bound(bound, &mesh, template)?;
            let (truth, init) = synthetic_materials(&set, &mesh, *seed)
                .with_context(|| bound.display().to_string())?;
            std::fs::create_dir_all(output)?;
            write_gaussians(
                &output.join("truth.ply"),
                &truth,
                &PlyWriteOptions::default(),
            )?;
            write_gaussians(&output.join("init.ply"), &init, &PlyWriteOptions::default())?;
            write_gaussians(
                &output.join("truth_world.ply"),
                &world_set(&truth, &mesh)?,
                &PlyWriteOptions::default(),
            )?;
            println!(
                "{} Gaussians: wrote {}/truth.ply, truth_world.ply, init.ply",
                truth.len(),
                output.display()
            );
            Ok(())
        }
        Action::Score {
            template,
            truth,
            cameras,
            sets,
        } => {
            let mesh = read_template(template)?;
            let truth_set = read_bound(truth, &mesh, template)?;
            let cams = read_cameras_json(cameras)?;
            for path in sets {
                let set = read_bound(path, &mesh, template)?;
                let (s, cos) =
                    synthetic_scores(&truth_set, &set, &mesh, &cams, &RenderOptions::default())
                        .with_context(|| path.display().to_string())?;
                println!(
                    "{}",
                    serde_json::json!({
                        "set": path,
                        "albedo_lmse": s.albedo_lmse,
                        "normal_cosine": s.normal_cosine,
                        "gaussian_normal_cos": cos,
                        "views": s.views,
                    })
                );
            }
            Ok(())
        }
    }
}
