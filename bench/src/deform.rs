//! `deform`: deforming ~100k bound Gaussians per frame in `binding` and `jacobian` modes on the
//! Spot template (5,856 triangles, 17 Gaussians each = 99,552), template evaluation (a smooth
//! non-rigid analytic warp of the 2,930 vertices) included, file writing excluded.
//!
//! The targets on the 2-core machine: ≤ 2 ms/frame (`binding`), ≤ 4 ms/frame
//! (`jacobian`). There is no CPU tool to compare with (GaussianAvatars and SurFhead deform on
//! the GPU inside their PyTorch training code), so only trisplat's timings are printed.
//!
//! On a shared, loaded machine wall times inflate; `perf stat -e task-clock` around runs with
//! `--frames 0` and `--frames N --mode M` gives the CPU time per frame (all threads summed).

use std::time::Instant;

use glam::{DMat3, DQuat, DVec3, Vec3};
use trisplat_geometry::rng::Rng;
use trisplat_geometry::{TriId, TriMesh};
use trisplat_splat::{Binding, BindingEncoding, GaussianParts, GaussianSet, ParameterSpace};
use trisplat_splat::{CanonicalTriangle, FrameOptions, corners_of};
use trisplat_splat::{DeformMode, Deformer, FrameHold, WorldGeometry};

/// Gaussians per Spot triangle: 5,856 × 17 = 99,552.
const PER_TRIANGLE: usize = 17;
/// Frames not timed (warm-up).
const WARM_UP: usize = 3;

/// Options of the deform benchmark.
#[derive(Debug, clap::Args)]
pub struct DeformBenchArgs {
    /// Timed frames per mode.
    #[arg(long, default_value_t = 100)]
    pub frames: usize,
    /// Only this mode (`binding` or `jacobian`); default both.
    #[arg(long)]
    pub mode: Option<String>,
    /// After timing `jacobian`, compare the last frame's covariances with a `f64` evaluation
    /// of `Σ' = M Σ_local Mᵀ` (`M = J k_c R_c` from the canonical and deformed triangles).
    #[arg(long)]
    pub check: bool,
}

/// Runs the benchmark.
///
/// # Errors
/// When the fixture cannot be read or a deformation fails.
pub fn run(args: &DeformBenchArgs) -> anyhow::Result<()> {
    let mesh = trisplat_fixtures::spot()?;
    let n = mesh.triangle_count() * PER_TRIANGLE;
    let mut rng = Rng::new(1);
    let mut u = || rng.uniform_f32() - 0.5;
    let set = GaussianSet::try_new(GaussianParts {
        means: (0..n).map(|_| Vec3::new(u(), u(), u())).collect(),
        log_scales: (0..n)
            .map(|_| Vec3::new(u(), u(), u()) * 4.0 - 3.0)
            .collect(),
        rotations: (0..n).map(|_| [u() + 1.0, u(), u(), u()]).collect(),
        opacity_logits: vec![0.0; n],
        sh: vec![0.0; 3 * n],
        binding: Some(Binding {
            triangles: (0..n).map(|i| TriId((i / PER_TRIANGLE) as u32)).collect(),
            encoding: BindingEncoding::Float,
        }),
        space: ParameterSpace::Local,
        ..GaussianParts::default()
    })?;
    let rest = mesh.positions().to_vec();
    println!(
        "deform: {n} Gaussians on {} triangles, {} threads, {} frames per mode",
        mesh.triangle_count(),
        rayon::current_num_threads(),
        args.frames
    );
    for mode in [DeformMode::Binding, DeformMode::Jacobian] {
        if args
            .mode
            .as_deref()
            .is_some_and(|m| !format!("{mode:?}").eq_ignore_ascii_case(m))
        {
            continue;
        }
        let deformer = Deformer::new(&mesh, mode);
        let mut out = WorldGeometry::default();
        let mut frame = rest.clone();
        let mut times = Vec::with_capacity(args.frames);
        // The same frames through the path the main job takes (`deform_geometry_held`: a
        // triangle that collapses keeps its last valid frame), timed alternately with the
        // plain one so that both see the same machine.
        let mut hold = FrameHold::new();
        let mut held_times = Vec::with_capacity(args.frames);
        for f in 0..args.frames + WARM_UP {
            let t = f as f64 * 0.05;
            let start = Instant::now();
            // Template evaluation: a smooth non-rigid warp of every vertex.
            for (p, r) in frame.iter_mut().zip(&rest) {
                *p = *r
                    + 0.05
                        * DVec3::new((3.0 * r.y + t).sin(), (2.0 * r.z).cos() * t, 0.2 * r.x * t);
            }
            let warp = start.elapsed().as_secs_f64() * 1e3;
            let mut time = |held: bool| -> anyhow::Result<f64> {
                let start = Instant::now();
                if held {
                    deformer.deform_geometry_held(&set, &frame, &mut hold, &mut out)?;
                } else {
                    deformer.deform_geometry(&set, &frame, &mut out)?;
                }
                Ok(warp + start.elapsed().as_secs_f64() * 1e3)
            };
            let (plain, held) = if f % 2 == 0 {
                let p = time(false)?;
                (p, time(true)?)
            } else {
                let h = time(true)?;
                (time(false)?, h)
            };
            if f >= WARM_UP {
                times.push(plain);
                held_times.push(held);
            }
        }
        times.sort_by(f64::total_cmp);
        held_times.sort_by(f64::total_cmp);
        let target = match mode {
            DeformMode::Binding => 2.0,
            DeformMode::Jacobian => 4.0,
        };
        println!(
            "{:<10} median {:>6.2} ms/frame   best {:>6.2} ms/frame   (target {target} ms)",
            format!("{mode:?}"),
            times[times.len() / 2],
            times[0]
        );
        println!(
            "{:<10} median {:>6.2} ms/frame   best {:>6.2} ms/frame   (the main job's path: \
             keeping the last valid frame of collapsed triangles; {:+.1}% on the median)",
            "  held",
            held_times[held_times.len() / 2],
            held_times[0],
            100.0 * (held_times[held_times.len() / 2] / times[times.len() / 2] - 1.0)
        );
        if args.check && mode == DeformMode::Jacobian {
            let (max_entry, frob) = jacobian_errors(&mesh, &set, &frame, &out);
            println!(
                "jacobian vs f64 Σ' = M Σ Mᵀ over {n} Gaussians: max |ΔΣ_ij| / max |Σ_ij| {max_entry:.2e}, |ΔΣ|_F / |Σ|_F {frob:.2e}"
            );
        }
    }
    Ok(())
}

/// Worst errors of the deformed covariances against `f64`: the largest entry error relative to
/// the largest entry, and the Frobenius-relative error.
fn jacobian_errors(
    mesh: &TriMesh,
    set: &GaussianSet,
    frame: &[DVec3],
    out: &WorldGeometry,
) -> (f64, f64) {
    let opts = FrameOptions::for_positions(mesh.positions());
    let binding = set.binding().map_or(&[][..], |b| b.triangles.as_slice());
    let (mut worst_entry, mut worst_frob) = (0.0f64, 0.0f64);
    for (i, tri) in binding.iter().enumerate() {
        let t = mesh.triangles()[tri.index()];
        let canonical = CanonicalTriangle::new(corners_of(mesh.positions(), t), &opts);
        let j = canonical.gradient(corners_of(frame, t), &opts);
        let m = j * canonical.frame.rotation * canonical.frame.scale;
        let want = m * set.covariance(i) * m.transpose();
        let [w, x, y, z] = out.rotations[i].map(f64::from);
        let r = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w));
        let s = out.log_scales[i].as_dvec3().exp();
        let got = r * DMat3::from_diagonal(s * s) * r.transpose();
        let max = |m: DMat3| m.to_cols_array().iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let f = |m: DMat3| m.to_cols_array().iter().map(|v| v * v).sum::<f64>().sqrt();
        worst_entry = worst_entry.max(max(got - want) / max(want));
        worst_frob = worst_frob.max(f(got - want) / f(want));
    }
    (worst_entry, worst_frob)
}
