//! Times reading and writing a 1M-Gaussian SH-degree-3 INRIA PLY (62 floats per Gaussian,
//! 248 MB) with trisplat's reader/writer; report only.
//!
//! `cargo run --release -p trisplat-splat --example ply_bench [-- COUNT]`

use std::time::Instant;

use glam::Vec3;
use trisplat_geometry::rng::Rng;
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};
use trisplat_splat::{ExtraProperty, GaussianParts, GaussianSet, PropertyValues};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::args()
        .nth(1)
        .map_or(Ok(1_000_000), |s| s.parse())?;
    let mut rng = Rng::new(1);
    let mut u = || rng.uniform_f32() - 0.5;
    let zeros = PropertyValues::F32(vec![0.0; n]);
    let set = GaussianSet::try_new(GaussianParts {
        means: (0..n).map(|_| Vec3::new(u(), u(), u())).collect(),
        log_scales: (0..n).map(|_| Vec3::new(u(), u(), u())).collect(),
        rotations: (0..n).map(|_| [u() + 1.0, u(), u(), u()]).collect(),
        opacity_logits: (0..n).map(|_| u()).collect(),
        sh_degree: 3,
        sh: (0..48 * n).map(|_| u()).collect(),
        extras: ["nx", "ny", "nz"]
            .map(|name| ExtraProperty {
                name: name.into(),
                values: zeros.clone(),
            })
            .to_vec(),
        property_order: Some(
            ["x", "y", "z", "nx", "ny", "nz"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
        ),
        ..GaussianParts::default()
    })?;
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("g.ply");
    let mut best_w = f64::INFINITY;
    let mut best_r = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        write_gaussians(&path, &set, &PlyWriteOptions::default())?;
        best_w = best_w.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let back = read_gaussians(&path)?;
        best_r = best_r.min(t.elapsed().as_secs_f64());
        assert_eq!(back.len(), n);
    }
    let mb = std::fs::metadata(&path)?.len() as f64 / 1e6;
    println!(
        "{n} Gaussians, degree 3, {mb:.0} MB: write {best_w:.3} s, read {best_r:.3} s (best of 3)"
    );
    Ok(())
}
