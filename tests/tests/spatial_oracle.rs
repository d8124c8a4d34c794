//! Spatial indexes against brute force on real data (Spot): k-d tree nearest neighbours, exact
//! closest points on triangles, ray casting (random, axis-aligned, through vertices and edge
//! midpoints), and degenerate inputs.

use glam::{DVec3, Vec3};
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::rng::Rng;
use trisplat_geometry::spatial::{
    PointIndex, SpatialError, TriangleBvh, closest_point_on_triangle, distance_f64,
};

/// Distances from the BVH and from brute force may differ by rounding only: both evaluate the
/// same f64 closest-point function on the same triangle (or an equally close one).
const DISTANCE_REL: f64 = 1e-12;

fn spot() -> TriMesh {
    read_mesh(&trisplat_fixtures::path("spot_triangulated.obj")).expect("spot reads")
}

fn random_queries(mesh: &TriMesh, n: usize, seed: u64, spread: f32) -> Vec<Vec3> {
    let bounds = mesh.bounds().expect("not empty");
    let centre = bounds.center().as_vec3();
    let size = ((bounds.max - bounds.min) * f64::from(spread)).as_vec3();
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            centre
                + Vec3::new(
                    rng.uniform_f32() - 0.5,
                    rng.uniform_f32() - 0.5,
                    rng.uniform_f32() - 0.5,
                ) * size
        })
        .collect()
}

fn brute_closest(mesh: &TriMesh, q: Vec3) -> f64 {
    (0..mesh.triangle_count())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            let (p, _) = closest_point_on_triangle(q.as_dvec3(), a, b, c);
            (p - q.as_dvec3()).length()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Brute-force first hit: Möller-Trumbore in f64 with inclusive edges, both faces.
fn brute_ray(mesh: &TriMesh, o: Vec3, d: Vec3) -> Option<f64> {
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    let mut best: Option<f64> = None;
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.corners(t);
        let (e1, e2) = (b - a, c - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() <= 1e-7 * e1.length() * e2.length() * d.length() {
            continue;
        }
        let s = o - a;
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let tol = 1e-12;
        if u < -tol || v < -tol || u + v > 1.0 + tol {
            continue;
        }
        let hit = e2.dot(q) / det;
        if hit >= 0.0 {
            best = Some(best.map_or(hit, |b: f64| b.min(hit)));
        }
    }
    best
}

#[test]
fn kdtree_nearest_on_spot_vertices() {
    let mesh = spot();
    let vertices = mesh.positions_f32();
    let index = PointIndex::new(&vertices).expect("valid");
    let queries = random_queries(&mesh, 2000, 1, 1.5);
    let found = index.nearest_batch(&queries).expect("valid");
    for (q, f) in queries.iter().zip(&found) {
        let want = vertices
            .iter()
            .map(|&p| distance_f64(*q, p))
            .fold(f64::INFINITY, f64::min);
        assert_eq!(f.distance, want, "query {q}");
    }
    // k nearest: sorted, and the k-th distance equals the brute-force k-th.
    for q in queries.iter().take(100) {
        let mut all: Vec<f64> = vertices.iter().map(|&p| distance_f64(*q, p)).collect();
        all.sort_by(f64::total_cmp);
        let got = index.k_nearest(*q, 16);
        assert_eq!(got.len(), 16);
        for (g, w) in got.iter().zip(&all) {
            assert_eq!(g.distance, *w);
        }
    }
}

#[test]
fn bvh_closest_points_on_spot() {
    let mesh = spot();
    let bvh = TriangleBvh::new(&mesh).expect("valid");
    let mut queries = random_queries(&mesh, 600, 2, 1.4);
    queries.extend(random_queries(&mesh, 20, 3, 1e4)); // far away
    queries.extend(mesh.positions_f32().iter().step_by(97).copied()); // on vertices
    let found = bvh.closest_points(&queries).expect("valid");
    for (q, f) in queries.iter().zip(&found) {
        let want = brute_closest(&mesh, *q);
        assert!(
            (f.distance - want).abs() <= DISTANCE_REL * want.max(1e-300) || f.distance == want,
            "query {q}: {} vs {want}",
            f.distance
        );
        let [a, b, c] = mesh.corners(f.triangle as usize);
        let w = f.barycentric;
        assert!((a * w[0] + b * w[1] + c * w[2] - f.point).length() < 1e-9);
        assert!(((f.point - q.as_dvec3()).length() - f.distance).abs() < 1e-12);
    }
}

#[test]
fn bvh_rays_on_spot() {
    let mesh = spot();
    let bvh = TriangleBvh::new(&mesh).expect("valid");
    let mut rng = Rng::new(4);
    let origins = random_queries(&mesh, 1500, 5, 2.0);
    let mut rays = Vec::new();
    for (i, &o) in origins.iter().enumerate() {
        let v = mesh.positions()[(i * 31) % mesh.vertex_count()].as_vec3();
        let w = mesh.positions()[(i * 31 + 1) % mesh.vertex_count()].as_vec3();
        let d = match i % 5 {
            0 => [
                Vec3::X,
                Vec3::NEG_X,
                Vec3::Y,
                Vec3::NEG_Y,
                Vec3::Z,
                Vec3::NEG_Z,
            ][i / 5 % 6],
            1 => Vec3::new(rng.uniform_f32() - 0.5, 0.0, rng.uniform_f32() - 0.5),
            2 => v - o,             // through a vertex
            3 => (v + w) * 0.5 - o, // through a point between two vertices
            _ => Vec3::new(
                rng.uniform_f32() - 0.5,
                rng.uniform_f32() - 0.5,
                rng.uniform_f32() - 0.5,
            ),
        };
        rays.push((o, d));
    }
    // Axis-aligned rays straight at every 7th vertex.
    for v in mesh.positions_f32().iter().step_by(7) {
        rays.push((*v + Vec3::new(0.0, 0.0, 3.0), Vec3::NEG_Z));
        rays.push((*v - Vec3::new(3.0, 0.0, 0.0), Vec3::X));
    }
    let hits = bvh.cast_rays(&rays, f64::INFINITY);
    let mut n_hits = 0;
    for ((o, d), hit) in rays.iter().zip(&hits) {
        let want = brute_ray(&mesh, *o, *d);
        match (hit, want) {
            (None, None) => {}
            (Some(h), Some(w)) => {
                n_hits += 1;
                assert!(
                    (h.t - w).abs() <= 1e-9 * w.max(1.0),
                    "ray {o} {d}: {} vs {w}",
                    h.t
                );
                let [a, b, c] = mesh.corners(h.triangle as usize);
                let p = a * h.barycentric[0] + b * h.barycentric[1] + c * h.barycentric[2];
                let along = o.as_dvec3() + d.as_dvec3() * h.t;
                assert!((p - along).length() < 1e-6, "ray {o} {d}");
            }
            _ => panic!("ray {o} {d}: bvh {hit:?}, brute force {want:?}"),
        }
    }
    assert!(n_hits > 1000, "{n_hits} hits");
}

#[test]
fn degenerate_meshes_and_inputs() {
    // Empty mesh: queries answer None, batch queries are errors.
    let empty = TriMesh::default();
    let bvh = TriangleBvh::new(&empty).expect("empty builds");
    assert!(bvh.closest_point(Vec3::ZERO).is_none());
    assert_eq!(bvh.closest_points(&[Vec3::ZERO]), Err(SpatialError::Empty));
    assert!(bvh.cast_ray(Vec3::ZERO, Vec3::X, f64::INFINITY).is_none());
    // All triangles degenerate (points and segments) and many identical vertices.
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for i in 0..200u32 {
        let p = Vec3::new((i % 10) as f32, 0.0, 0.0);
        positions.extend([p, p, p + Vec3::X * (i % 3) as f32]);
        triangles.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    let mesh = TriMesh::new(positions.clone(), triangles);
    let bvh = TriangleBvh::new(&mesh).expect("valid");
    for q in [
        Vec3::new(4.5, 1.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::splat(50.0),
    ] {
        let got = bvh.closest_point(q).expect("not empty");
        assert!((got.distance - brute_closest(&mesh, q)).abs() < 1e-12);
    }
    assert!(
        bvh.cast_ray(Vec3::new(4.5, 1.0, 0.0), Vec3::NEG_Y, f64::INFINITY)
            .is_none()
    );
    // A k-d tree over 600 points with only 10 distinct positions.
    let index = PointIndex::new(&positions).expect("valid");
    let got = index.nearest(Vec3::new(3.2, 0.0, 0.0)).expect("finite");
    assert!((got.distance - 0.2).abs() < 1e-6);
    assert_eq!(
        distance_f64(positions[got.index as usize], Vec3::new(3.0, 0.0, 0.0)),
        0.0
    );
    let _ = DVec3::ZERO;
}
