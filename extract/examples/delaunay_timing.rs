//! Times the 3D Delaunay on random points in a cube and on a sphere:
//! `cargo run --release -p trisplat-extract --example delaunay_timing -- [N] [POINTS.ply]`.

use std::time::Instant;

use glam::Vec3;
use trisplat_extract::delaunay3d::Delaunay3d;
use trisplat_geometry::rng::Rng;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(100_000);
    let mut rng = Rng::new(1);
    let cube: Vec<Vec3> = (0..n)
        .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()))
        .collect();
    let sphere: Vec<Vec3> = (0..n)
        .map(|_| {
            let z = 2.0 * rng.uniform_f64() - 1.0;
            let phi = std::f64::consts::TAU * rng.uniform_f64();
            let r = (1.0 - z * z).sqrt();
            Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
        })
        .collect();
    let file: Vec<Vec3> = std::env::args()
        .nth(2)
        .map(|p| {
            trisplat_geometry::io::read_points(p.as_ref())
                .expect("readable points")
                .positions()
                .to_vec()
        })
        .unwrap_or_default();
    for (name, pts) in [("cube", &cube), ("sphere", &sphere), ("file", &file)] {
        if pts.is_empty() {
            continue;
        }
        let n = pts.len();
        let t = Instant::now();
        let d = Delaunay3d::new(pts).expect("finite points");
        let t_delaunay = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let shape = trisplat_extract::alpha_shape::alpha_shape_from_delaunay(&d, 0.01)
            .expect("valid alpha");
        println!(
            "{name:<8} alpha 0.01: {:.3} s, {} triangles",
            t.elapsed().as_secs_f64(),
            shape.mesh.triangle_count()
        );
        println!(
            "{name:<8} {n} points: {:.3} s, {} tetrahedra, {} hull faces",
            t_delaunay,
            d.tetrahedra().len(),
            d.hull_face_count()
        );
    }
}
