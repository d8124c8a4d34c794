//! Micro benchmark: deforming 100k bound Gaussians per frame in `binding` and `jacobian` modes
//! on the Spot template (5856 triangles, 17 Gaussians each = 99,552), template evaluation (an
//! analytic warp of the 2930 vertices) included, file writing excluded. Report only.
//!
//! `cargo run --release -p trisplat-splat --example deform_bench [-- FRAMES]`

use std::time::Instant;

use glam::Vec3;
use trisplat_geometry::TriId;
use trisplat_geometry::rng::Rng;
use trisplat_splat::deform::{DeformMode, Deformer, WorldGeometry};
use trisplat_splat::{Binding, BindingEncoding, GaussianParts, GaussianSet, ParameterSpace};

const PER_TRIANGLE: usize = 17;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let frames: usize = std::env::args().nth(1).map_or(Ok(50), |s| s.parse())?;
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
        "{} Gaussians on {} triangles, {} threads, {frames} frames",
        n,
        mesh.triangle_count(),
        rayon::current_num_threads()
    );
    for mode in [DeformMode::Binding, DeformMode::Jacobian] {
        let deformer = Deformer::new(&mesh, mode);
        let mut out = WorldGeometry::default();
        let mut frame = rest.clone();
        let mut times = Vec::with_capacity(frames);
        for f in 0..frames + 3 {
            let t = f as f32 * 0.05;
            let start = Instant::now();
            // Template evaluation: a smooth non-rigid warp of every vertex.
            for (p, r) in frame.iter_mut().zip(&rest) {
                *p = *r
                    + 0.05 * Vec3::new((3.0 * r.y + t).sin(), (2.0 * r.z).cos() * t, 0.2 * r.x * t);
            }
            deformer.deform_geometry(&set, &frame, &mut out)?;
            if f >= 3 {
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
        times.sort_by(f64::total_cmp);
        println!(
            "{mode:?}: median {:.2} ms, best {:.2} ms per frame",
            times[times.len() / 2],
            times[0]
        );
    }
    Ok(())
}
