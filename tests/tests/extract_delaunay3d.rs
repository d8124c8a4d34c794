//! 3D Delaunay tetrahedralisation: validity (orientation, neighbour symmetry, empty spheres by
//! brute force) on generic and degenerate inputs, degenerate inputs by design, bad input errors.

use glam::Vec3;
use trisplat_extract::delaunay3d::{Delaunay3d, DelaunayError, Duplicate};
use trisplat_geometry::rng::Rng;

fn random_cube(n: usize, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()))
        .collect()
}

fn grid(n: usize) -> Vec<Vec3> {
    let mut pts = Vec::new();
    for x in 0..n {
        for y in 0..n {
            for z in 0..n {
                pts.push(Vec3::new(x as f32, y as f32, z as f32));
            }
        }
    }
    pts
}

/// Sum of the finite tetrahedra's volumes (f64).
fn volume(d: &Delaunay3d) -> f64 {
    let p = d.points();
    d.tetrahedra()
        .iter()
        .map(|t| {
            let [a, b, c, e] = t.map(|v| p[v as usize]);
            let u = [a[0] - e[0], a[1] - e[1], a[2] - e[2]];
            let v = [b[0] - e[0], b[1] - e[1], b[2] - e[2]];
            let w = [c[0] - e[0], c[1] - e[1], c[2] - e[2]];
            (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
                + u[2] * (v[0] * w[1] - v[1] * w[0]))
                / 6.0
        })
        .sum()
}

fn assert_valid(d: &Delaunay3d, brute_force: bool) {
    let v = d.sanity_check(brute_force);
    assert!(
        v.is_empty(),
        "{} violations, first: {}",
        v.len(),
        v.iter()
            .take(5)
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join("; ")
    );
}

#[test]
fn random_points_are_valid_delaunay() {
    for (n, seed) in [(5, 1), (50, 2), (500, 3), (2000, 4)] {
        let pts = random_cube(n, seed);
        let d = Delaunay3d::new(&pts).expect("finite input");
        assert_eq!(d.dimension(), 3);
        assert!(d.duplicates().is_empty());
        assert_valid(&d, true);
        // Euler for a 3-ball: V - E + F - T = 1; with the infinite vertex the closed
        // 3-sphere gives T_total = sum over vertices ... simpler: hull faces = 2 * hull
        // vertices - 4 and the volume sum is positive and below the unit cube's.
        let vol = volume(&d);
        assert!(vol > 0.0 && vol <= 1.0, "volume {vol}");
    }
}

#[test]
fn larger_random_set_is_valid_without_brute_force() {
    let pts = random_cube(50_000, 7);
    let d = Delaunay3d::new(&pts).expect("finite input");
    assert_valid(&d, false);
    // About 6.5 tetrahedra per point for uniform random points.
    let ratio = d.tetrahedra().len() as f64 / pts.len() as f64;
    assert!((6.0..7.0).contains(&ratio), "tets per point {ratio}");
}

#[test]
fn cube_corners_are_tetrahedralised() {
    let pts: Vec<Vec3> = (0..8)
        .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
        .collect();
    let d = Delaunay3d::new(&pts).expect("finite input");
    assert_eq!(d.dimension(), 3);
    assert_valid(&d, true);
    // A cube splits into 5 or 6 tetrahedra; the volume is exactly 1; hull = 12 triangles.
    assert!(
        (5..=6).contains(&d.tetrahedra().len()),
        "{}",
        d.tetrahedra().len()
    );
    assert!((volume(&d) - 1.0).abs() < 1e-12);
    assert_eq!(d.hull_face_count(), 12);
}

#[test]
fn regular_grid_is_tetrahedralised() {
    let pts = grid(10);
    let d = Delaunay3d::new(&pts).expect("finite input");
    assert_valid(&d, true);
    // Every grid cell is filled: the volume is exactly 9^3; the hull is the cube's 6 faces
    // of 9 x 9 squares, two triangles each.
    assert!((volume(&d) - 729.0).abs() < 1e-9, "volume {}", volume(&d));
    assert_eq!(d.hull_face_count(), 6 * 81 * 2);
}

#[test]
fn points_on_a_sphere_and_jittered_grid() {
    // Points on a sphere in f32 are not exactly co-spherical, but nearly: the exact stages of
    // the predicates run often.
    let mut rng = Rng::new(11);
    let sphere: Vec<Vec3> = (0..3000)
        .map(|_| {
            let z = 2.0 * rng.uniform_f64() - 1.0;
            let phi = std::f64::consts::TAU * rng.uniform_f64();
            let r = (1.0 - z * z).sqrt();
            Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
        })
        .collect();
    let d = Delaunay3d::new(&sphere).expect("finite input");
    assert_valid(&d, false);
    assert_valid(&Delaunay3d::new(&sphere[..400]).expect("finite"), true);
    // Exactly co-spherical: the 26 neighbours-at-distance-sqrt(2)-ish points of integer
    // coordinates on the sphere of radius 5 (3-4-5 triples and axis points).
    let mut exact = Vec::new();
    for x in -5i32..=5 {
        for y in -5i32..=5 {
            for z in -5i32..=5 {
                if x * x + y * y + z * z == 25 {
                    exact.push(Vec3::new(x as f32, y as f32, z as f32));
                }
            }
        }
    }
    let d = Delaunay3d::new(&exact).expect("finite input");
    assert_valid(&d, true);
}

#[test]
fn planar_and_collinear_inputs_give_empty_results() {
    let plane: Vec<Vec3> = random_cube(100, 5)
        .into_iter()
        .map(|p| Vec3::new(p.x, p.y, 0.25))
        .collect();
    let d = Delaunay3d::new(&plane).expect("finite input");
    assert_eq!(d.dimension(), 2);
    assert!(d.tetrahedra().is_empty());
    // A tilted exact plane x + y + z = 1 on a grid.
    let mut tilted = Vec::new();
    for x in 0..6 {
        for y in 0..6 {
            tilted.push(Vec3::new(x as f32, y as f32, (1 - x - y) as f32));
        }
    }
    assert_eq!(Delaunay3d::new(&tilted).expect("finite").dimension(), 2);
    let line: Vec<Vec3> = (0..10).map(|i| Vec3::splat(i as f32)).collect();
    assert_eq!(Delaunay3d::new(&line).expect("finite").dimension(), 1);
    let one = [Vec3::ONE; 3];
    let d = Delaunay3d::new(&one).expect("finite");
    assert_eq!(d.dimension(), 0);
    assert_eq!(d.duplicates().len(), 2);
    let d = Delaunay3d::new(&[]).expect("empty input is fine");
    assert!(d.tetrahedra().is_empty());
    // Three points: fewer than four can never span a tetrahedron.
    let d = Delaunay3d::new(&[Vec3::X, Vec3::Y, Vec3::Z]).expect("finite");
    assert!(d.tetrahedra().is_empty());
    assert_eq!(d.dimension(), 2);
}

#[test]
fn a_plane_plus_one_point_is_a_valid_cone() {
    let mut pts: Vec<Vec3> = grid(6).into_iter().filter(|p| p.z == 0.0).collect();
    pts.push(Vec3::new(2.5, 2.5, 3.0));
    let d = Delaunay3d::new(&pts).expect("finite");
    assert_valid(&d, true);
    assert!((volume(&d) - 25.0).abs() < 1e-9, "volume {}", volume(&d));
}

#[test]
fn duplicates_are_skipped_and_reported() {
    let mut pts = random_cube(200, 9);
    pts.push(pts[3]);
    pts.push(pts[150]);
    pts.push(pts[3]);
    // -0.0 and 0.0 are the same point.
    pts.push(Vec3::new(0.0, 2.0, 2.0));
    pts.push(Vec3::new(-0.0, 2.0, 2.0));
    let d = Delaunay3d::new(&pts).expect("finite");
    assert_valid(&d, true);
    assert_eq!(
        d.duplicates(),
        &[
            Duplicate {
                skipped: 200,
                kept: 3
            },
            Duplicate {
                skipped: 201,
                kept: 150
            },
            Duplicate {
                skipped: 202,
                kept: 3
            },
            Duplicate {
                skipped: 204,
                kept: 203
            },
        ]
    );
    // All copies of the grid: the same tetrahedra count as one copy.
    let mut twice = grid(4);
    twice.extend(grid(4));
    let one = Delaunay3d::new(&grid(4)).expect("finite");
    let two = Delaunay3d::new(&twice).expect("finite");
    assert_eq!(one.tetrahedra().len(), two.tetrahedra().len());
    assert_eq!(two.duplicates().len(), 64);
    assert_valid(&two, true);
}

#[test]
fn bad_coordinates_name_the_point() {
    let mut pts = random_cube(10, 1);
    pts[7].y = f32::NAN;
    let err = Delaunay3d::new(&pts).expect_err("NaN");
    assert!(
        matches!(err, DelaunayError::NonFinite { index: 7, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("point 7"));
    pts[7].y = f32::INFINITY;
    assert!(matches!(
        Delaunay3d::new(&pts),
        Err(DelaunayError::NonFinite { index: 7, .. })
    ));
    pts[7].y = 1e35;
    assert!(matches!(
        Delaunay3d::new(&pts),
        Err(DelaunayError::TooLarge { index: 7, .. })
    ));
}

#[test]
fn tiny_and_offset_coordinates_stay_exact() {
    // Far from the origin and at a tiny scale: exact predicates keep the result valid.
    let base = random_cube(300, 21);
    for (scale, offset) in [(1e-20f32, 0.0f32), (1.0, 1e6), (1e-3, 1e4)] {
        let pts: Vec<Vec3> = base
            .iter()
            .map(|&p| p * scale + Vec3::splat(offset))
            .collect();
        let d = Delaunay3d::new(&pts).expect("finite");
        assert_valid(&d, true);
    }
    // Grid far from the origin: f32 spacing is exact at 1024 + k.
    let pts: Vec<Vec3> = grid(5)
        .into_iter()
        .map(|p| p + Vec3::splat(1024.0))
        .collect();
    assert_valid(&Delaunay3d::new(&pts).expect("finite"), true);
}

/// Heavily degenerate random sets: points drawn (with repetition) from small integer grids and
/// planes, so co-spherical, coplanar, collinear and duplicated points are everywhere. Every
/// result must be a valid Delaunay tetrahedralisation (brute-force empty spheres) or empty by
/// design, and never panic.
#[test]
fn random_degenerate_sets_are_always_valid() {
    let mut rng = Rng::new(2024);
    for trial in 0..300 {
        let side = 2 + rng.below(3);
        let n = 4 + rng.below(40) as usize;
        let flat = trial % 5 == 0;
        let pts: Vec<Vec3> = (0..n)
            .map(|_| {
                let z = if flat { 0 } else { rng.below(side) };
                Vec3::new(rng.below(side) as f32, rng.below(side) as f32, z as f32)
            })
            .collect();
        let d = Delaunay3d::new(&pts).expect("finite input");
        let v = d.sanity_check(true);
        assert!(
            v.is_empty(),
            "trial {trial}: {:?} -> {}",
            pts,
            v.iter()
                .take(3)
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join("; ")
        );
        if d.dimension() == 3 {
            // Every distinct point is a vertex and the tetrahedra tile the hull: compare the
            // volume with the box spanned when all eight corners are present.
            assert!(volume(&d) > 0.0);
        } else {
            assert!(d.tetrahedra().is_empty());
        }
    }
}

/// The tetrahedra-only build (large inputs) gives the full build's finite tetrahedra in the
/// same order, and its dimension, on generic, co-spherical, duplicated and flat inputs; bad
/// coordinates are the same errors.
#[test]
fn finite_tetrahedra_equal_the_full_build() {
    let to64 = |pts: &[Vec3]| -> Vec<[f64; 3]> {
        pts.iter()
            .map(|p| [f64::from(p.x), f64::from(p.y), f64::from(p.z)])
            .collect()
    };
    let mut dup = random_cube(300, 9);
    let head = dup[..40].to_vec();
    dup.extend(head);
    let flat: Vec<Vec3> = (0..50)
        .map(|i| Vec3::new((i % 7) as f32, (i / 7) as f32, 0.0))
        .collect();
    for pts in [random_cube(3000, 5), grid(7), dup, flat] {
        let coords = to64(&pts);
        let full = Delaunay3d::from_f64(coords.clone()).expect("full");
        let (tets, dimension) = Delaunay3d::finite_tetrahedra(&coords).expect("tets only");
        assert_eq!(dimension, full.dimension());
        assert_eq!(tets, full.tetrahedra());
    }
    let mut bad = to64(&random_cube(10, 1));
    bad[3][2] = f64::NAN;
    assert!(matches!(
        Delaunay3d::finite_tetrahedra(&bad),
        Err(DelaunayError::NonFinite { index: 3, .. })
    ));
}
