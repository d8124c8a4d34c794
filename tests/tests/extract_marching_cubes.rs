//! Marching cubes on analytic fields and random fields that span many 8³ blocks: closed,
//! manifold, outward, the right topology (Euler characteristic), vertices on the surface.
//!
//! Tolerances: a vertex of a linearly interpolated signed distance lies within
//! [`SURFACE_TOL`] grid spacings of the true surface for these smooth fields; enclosed volumes
//! are within [`VOLUME_REL`] of the analytic ones at these resolutions.

use glam::DVec3;
use trisplat_extract::marching_cubes_dense;
use trisplat_geometry::TriMesh;
use trisplat_geometry::topology::{boundary_edges, non_manifold_edges, unique_edges};

/// Largest vertex distance from the analytic surface, in grid spacings.
const SURFACE_TOL: f64 = 0.1;
/// Relative volume error allowed.
const VOLUME_REL: f64 = 0.02;

fn field(n: usize, spacing: f64, origin: DVec3, f: impl Fn(DVec3) -> f64) -> Vec<f32> {
    let mut v = Vec::with_capacity(n * n * n);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = origin + DVec3::new(x as f64, y as f64, z as f64) * spacing;
                v.push(f(p) as f32);
            }
        }
    }
    v
}

fn euler(mesh: &TriMesh) -> i64 {
    mesh.vertex_count() as i64 - unique_edges(mesh.triangles()).len() as i64
        + mesh.triangle_count() as i64
}

fn assert_closed(mesh: &TriMesh) {
    assert!(mesh.triangle_count() > 0);
    assert!(boundary_edges(mesh.triangles()).is_empty());
    assert!(non_manifold_edges(mesh.triangles()).is_empty());
    assert!(mesh.report().is_clean(), "{:?}", mesh.report());
}

#[test]
fn torus_has_genus_one() {
    let (big, small) = (0.6, 0.25);
    let torus = |p: DVec3| {
        let q = (p.x * p.x + p.z * p.z).sqrt() - big;
        (q * q + p.y * p.y).sqrt() - small
    };
    let (n, h) = (64, 0.03);
    // Negative coordinates: blocks with negative keys.
    let origin = DVec3::splat(-0.5 * (n - 1) as f64 * h);
    let mesh = marching_cubes_dense(&field(n, h, origin, torus), [n; 3], origin, h).unwrap();
    assert_closed(&mesh);
    assert_eq!(euler(&mesh), 0);
    let exact = 2.0 * std::f64::consts::PI.powi(2) * big * small * small;
    let volume = mesh.signed_volume();
    assert!(
        (volume - exact).abs() < VOLUME_REL * exact,
        "{volume} vs {exact}"
    );
    for p in mesh.positions() {
        assert!(torus(*p).abs() < SURFACE_TOL * h, "{p}");
    }
}

#[test]
fn two_separate_spheres_are_two_shells() {
    let sdf = |p: DVec3| {
        let a = (p - DVec3::new(-0.4, 0.0, 0.0)).length() - 0.3;
        let b = (p - DVec3::new(0.45, 0.1, 0.0)).length() - 0.25;
        a.min(b)
    };
    let (n, h) = (50, 0.04);
    let origin = DVec3::splat(-1.0);
    let mesh = marching_cubes_dense(&field(n, h, origin, sdf), [n; 3], origin, h).unwrap();
    assert_closed(&mesh);
    assert_eq!(euler(&mesh), 4);
    let exact = 4.0 / 3.0 * std::f64::consts::PI * (0.3f64.powi(3) + 0.25f64.powi(3));
    assert!((mesh.signed_volume() - exact).abs() < VOLUME_REL * exact);
}

#[test]
fn inverted_field_faces_inward() {
    // A hollow: outside is negative. Faces point to the positive side, so the volume is
    // negative.
    let (n, h) = (24, 0.1);
    let origin = DVec3::splat(-1.15);
    let hollow = field(n, h, origin, |p| 0.7 - p.length());
    let mesh = marching_cubes_dense(&hollow, [n; 3], origin, h).unwrap();
    assert!(boundary_edges(mesh.triangles()).is_empty());
    assert!(mesh.signed_volume() < 0.0);
}

#[test]
fn random_fields_across_many_blocks_stay_closed() {
    // Random values inside a 30³ box (4 x 4 x 4 blocks) whose border is positive, with some
    // unobserved samples: the surface of the observed cells may have holes only where a cell
    // is skipped, so check closure without unobserved samples and manifoldness with them.
    let n = 30;
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut v = vec![1.0f32; n * n * n];
    for z in 1..n - 1 {
        for y in 1..n - 1 {
            for x in 1..n - 1 {
                v[x + n * (y + n * z)] = next() - 0.55;
            }
        }
    }
    let mesh = marching_cubes_dense(&v, [n; 3], DVec3::new(-3.0, 2.0, -7.0), 0.5).unwrap();
    assert_closed(&mesh);
    assert!(mesh.signed_volume() > 0.0);
    for (i, value) in v.iter_mut().enumerate() {
        if i % 17 == 3 {
            *value = f32::NAN;
        }
    }
    let holed = marching_cubes_dense(&v, [n; 3], DVec3::ZERO, 0.5).unwrap();
    assert!(holed.triangle_count() > 0);
    assert!(non_manifold_edges(holed.triangles()).is_empty());
}
