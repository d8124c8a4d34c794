//! `trisplat alpha-shape` through the real binary: a closed, outward result on real samples,
//! degenerate inputs that Open3D (Qhull) refuses, and the error contract.

mod common;
use common::{fresh_dir, run, s};

use trisplat_geometry::io::read_mesh;
use trisplat_geometry::topology::boundary_edges;

#[test]
fn ball_samples_give_a_closed_outward_mesh() {
    let dir = fresh_dir("ball");
    let out = dir.join("ball_alpha.ply");
    let input = trisplat_fixtures::path("reference/alpha/ball.ply");
    // A large alpha keeps every tetrahedron: the convex hull, closed and outward.
    let res = run(&["alpha-shape", s(&input), "--alpha", "1e6", "-o", s(&out)]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let mesh = read_mesh(&out).expect("read output");
    assert!(mesh.triangle_count() > 0);
    assert!(
        boundary_edges(mesh.triangles()).is_empty(),
        "hull is closed"
    );
    assert!(mesh.signed_volume() > 0.0, "faces point outward");
}

#[test]
fn cube_corners_work_where_qhull_fails() {
    let dir = fresh_dir("cube");
    let input = dir.join("cube.ply");
    let mut text = String::from(
        "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\n\
         property float z\nend_header\n",
    );
    for i in 0..8 {
        text.push_str(&format!("{} {} {}\n", i & 1, (i >> 1) & 1, (i >> 2) & 1));
    }
    std::fs::write(&input, text).expect("write cube");
    let out = dir.join("cube_alpha.obj");
    let res = run(&["alpha-shape", s(&input), "--alpha", "10", "-o", s(&out)]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let mesh = read_mesh(&out).expect("read output");
    assert_eq!(mesh.triangle_count(), 12);
    assert!((mesh.signed_volume() - 1.0).abs() < 1e-6);
}

#[test]
fn pieces_are_counted_and_the_largest_kept_on_request() {
    let dir = fresh_dir("pieces");
    let input = dir.join("two_cubes.ply");
    // The corners of a unit cube (12 triangles) and a tetrahedron far from it (4).
    let mut text = String::from(
        "ply\nformat ascii 1.0\nelement vertex 12\nproperty float x\nproperty float y\n\
         property float z\nend_header\n",
    );
    for i in 0..8 {
        text.push_str(&format!("{} {} {}\n", i & 1, (i >> 1) & 1, (i >> 2) & 1));
    }
    text.push_str("10 10 10\n11 10 10\n10 11 10\n10 10 11\n");
    std::fs::write(&input, text).expect("write cubes");
    let all = dir.join("all.ply");
    let res = run(&["alpha-shape", s(&input), "--alpha", "2", "-o", s(&all)]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let stderr = String::from_utf8_lossy(&res.stderr);
    assert!(stderr.contains("2 edge-connected pieces"), "{stderr}");
    assert_eq!(read_mesh(&all).expect("read").triangle_count(), 16);

    let one = dir.join("one.ply");
    let res = run(&[
        "alpha-shape",
        s(&input),
        "--alpha",
        "2",
        "--keep-clusters",
        "1",
        "-o",
        s(&one),
    ]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let mesh = read_mesh(&one).expect("read");
    assert_eq!(mesh.triangle_count(), 12);
    assert!(
        (mesh.signed_volume() - 1.0).abs() < 1e-6,
        "the cube is kept"
    );

    // --quiet drops the note.
    let res = run(&[
        "-q",
        "alpha-shape",
        s(&input),
        "--alpha",
        "2",
        "-o",
        s(&all),
    ]);
    assert!(res.status.success());
    assert!(
        res.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
}

#[test]
fn bad_alpha_and_missing_file_fail_cleanly() {
    let dir = fresh_dir("bad");
    let out = dir.join("never.ply");
    let input = trisplat_fixtures::path("reference/alpha/ball.ply");
    for args in [
        vec!["alpha-shape", s(&input), "--alpha", "nan", "-o", s(&out)],
        vec![
            "alpha-shape",
            "/nonexistent/points.ply",
            "--alpha",
            "1",
            "-o",
            s(&out),
        ],
    ] {
        let res = run(&args);
        let stderr = String::from_utf8_lossy(&res.stderr);
        assert_eq!(res.status.code(), Some(1), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr:?}");
        assert!(!out.exists());
    }
    assert_eq!(
        run(&["alpha-shape", s(&input), "-o", s(&out)])
            .status
            .code(),
        Some(2)
    );
}

#[test]
fn degenerate_point_sets_end_at_once_with_an_empty_shape_and_a_warning() {
    use trisplat_geometry::PointCloud;
    use trisplat_geometry::io::{WriteOptions, write_points};
    use trisplat_splat::glam::Vec3;
    let dir = fresh_dir("degenerate");
    let n = 50_000;
    let sets: [(&str, Vec<Vec3>); 3] = [
        ("coincident", vec![Vec3::new(1.0, 2.0, 3.0); n]),
        (
            "collinear",
            (0..n).map(|i| Vec3::splat(i as f32 / n as f32)).collect(),
        ),
        (
            "coplanar",
            (0..n)
                .map(|i| Vec3::new((i % 250) as f32, (i / 250) as f32 * 0.7, 0.0))
                .collect(),
        ),
    ];
    for (name, points) in sets {
        let input = dir.join(format!("{name}.ply"));
        write_points(
            &input,
            &PointCloud::new_unchecked(points),
            WriteOptions::default(),
        )
        .expect("write");
        let out = dir.join(format!("{name}_shape.ply"));
        let res = run(&["alpha-shape", s(&input), "--alpha", "10", "-o", s(&out)]);
        let stderr = String::from_utf8_lossy(&res.stderr);
        assert_eq!(res.status.code(), Some(0), "{name}: {stderr}");
        assert!(
            stderr.contains("alpha shape is empty") && stderr.contains(&format!("{name}.ply")),
            "{name}: {stderr}"
        );
        assert_eq!(read_mesh(&out).expect("written").triangle_count(), 0);
    }
}
