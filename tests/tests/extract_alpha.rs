//! Alpha shapes against Open3D 0.20 (`tests/reference/ref_alpha.py`): the same boundary
//! triangles on generic inputs, success where Open3D fails, outward orientation.
//!
//! Tolerance: triangles of tetrahedra whose circumradius is within [`ALPHA_TIE_REL`] (relative)
//! of α are left out of the comparison on both sides (Open3D computes circumradii with 4x4
//! determinants of absolute coordinates, we relative to a vertex; the two can round to opposite
//! sides of α). Everything else must match exactly, as sets of sorted index triples.

use std::collections::{BTreeSet, HashMap};

use glam::Vec3;
use serde::Deserialize;
use trisplat_extract::alpha_shape::{
    AlphaError, AlphaShape, alpha_shape, alpha_shape_from_delaunay, circumradius,
};
use trisplat_extract::delaunay3d::{Delaunay3d, DelaunayError, FACE_VERTICES};
use trisplat_geometry::io::read_points;

/// Relative band around α inside which a tetrahedron counts as a tie.
const ALPHA_TIE_REL: f64 = 1e-9;

#[derive(Deserialize)]
struct Reference {
    cases: Vec<Case>,
    degenerate: Vec<Degenerate>,
}

#[derive(Deserialize)]
struct Case {
    input: String,
    alpha: f64,
    triangles: Vec<u32>,
}

#[derive(Deserialize)]
struct Degenerate {
    name: String,
    error: Option<String>,
    watertight: bool,
}

fn reference() -> Reference {
    let path = trisplat_fixtures::path("reference/alpha/alpha.json");
    let text = std::fs::read_to_string(&path).expect("reference JSON");
    serde_json::from_str(&text).expect("valid reference JSON")
}

fn load(name: &str) -> Vec<Vec3> {
    let path = trisplat_fixtures::path(&format!("reference/alpha/{name}"));
    read_points(&path)
        .expect("fixture points")
        .positions()
        .to_vec()
}

fn sorted(t: [u32; 3]) -> [u32; 3] {
    let mut t = t;
    t.sort_unstable();
    t
}

/// Our boundary as sorted input-index triples.
fn boundary_set(shape: &AlphaShape) -> BTreeSet<[u32; 3]> {
    shape
        .mesh
        .triangles()
        .iter()
        .map(|t| sorted(t.map(|v| shape.vertex_ids[v as usize])))
        .collect()
}

/// Volume of a tetrahedron positive in Shewchuk's `orient3d` convention
/// (`det[a - d, b - d, c - d] / 6`).
fn tet_volume(p: [[f64; 3]; 4]) -> f64 {
    let [a, b, c, d] = p;
    let u = [a[0] - d[0], a[1] - d[1], a[2] - d[2]];
    let v = [b[0] - d[0], b[1] - d[1], b[2] - d[2]];
    let w = [c[0] - d[0], c[1] - d[1], c[2] - d[2]];
    (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0]))
        / 6.0
}

/// The boundary is a closed 2-cycle oriented outward: every directed edge is matched by its
/// reverse, and the signed volume equals the kept tetrahedra's total volume.
fn assert_outward_cycle(d: &Delaunay3d, shape: &AlphaShape, alpha: f64) {
    let mut edges: HashMap<(u32, u32), i64> = HashMap::new();
    for t in shape.mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
        }
    }
    assert!(edges.values().all(|&c| c == 0), "boundary is not a cycle");
    let kept: f64 = d
        .tetrahedra()
        .iter()
        .map(|t| t.map(|v| d.points()[v as usize]))
        .filter(|p| circumradius(*p) <= alpha)
        .map(tet_volume)
        .sum();
    let vol = shape.mesh.signed_volume();
    // f32 output positions vs f64 volumes: same coordinates (the inputs are f32).
    assert!(
        (vol - kept).abs() <= 1e-9 * kept.abs().max(1e-12),
        "signed volume {vol} vs kept volume {kept}"
    );
    if shape.kept_tetrahedra > 0 {
        assert!(vol > 0.0);
    }
}

#[test]
fn boundary_triangles_match_open3d() {
    let reference = reference();
    let mut cache: HashMap<String, Delaunay3d> = HashMap::new();
    for case in &reference.cases {
        let d = cache.entry(case.input.clone()).or_insert_with(|| {
            let d = Delaunay3d::new(&load(&case.input)).expect("finite points");
            assert!(d.sanity_check(false).is_empty());
            d
        });
        let shape = alpha_shape_from_delaunay(d, case.alpha).expect("valid alpha");
        // Faces of tie tetrahedra are excluded from the comparison.
        let mut ties = BTreeSet::new();
        for t in d.tetrahedra() {
            let r = circumradius(t.map(|v| d.points()[v as usize]));
            if (r - case.alpha).abs() <= ALPHA_TIE_REL * case.alpha {
                for f in FACE_VERTICES {
                    ties.insert(sorted(f.map(|k| t[k])));
                }
            }
        }
        let ours: BTreeSet<[u32; 3]> = boundary_set(&shape).difference(&ties).copied().collect();
        let theirs: BTreeSet<[u32; 3]> = case
            .triangles
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .filter(|t| !ties.contains(t))
            .collect();
        let only_ours = ours.difference(&theirs).count();
        let only_theirs = theirs.difference(&ours).count();
        assert_eq!(
            (only_ours, only_theirs),
            (0, 0),
            "{} alpha {}: {} triangles here, {} in Open3D, {} tie faces",
            case.input,
            case.alpha,
            ours.len(),
            theirs.len(),
            ties.len()
        );
        assert!(!ours.is_empty());
        assert_outward_cycle(d, &shape, case.alpha);
    }
}

fn cube_corners() -> Vec<Vec3> {
    (0..8)
        .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
        .collect()
}

#[test]
fn succeeds_where_open3d_fails() {
    let reference = reference();
    let outcome = |name: &str| {
        reference
            .degenerate
            .iter()
            .find(|d| d.name == name)
            .expect("degenerate case recorded")
    };
    // Open3D: Qhull QH6239 on cube corners and on a plane; a non-watertight mesh on a grid.
    assert!(
        outcome("cube_corners")
            .error
            .as_deref()
            .is_some_and(|e| e.contains("QH6239"))
    );
    assert!(
        outcome("plane_10x10")
            .error
            .as_deref()
            .is_some_and(|e| e.contains("QH6239"))
    );
    assert!(!outcome("grid_10x10x10").watertight);

    // Ours: the closed cube (12 triangles, volume 1).
    let cube = cube_corners();
    let shape = alpha_shape(&cube, 2.0).expect("finite points");
    assert_eq!(shape.mesh.triangle_count(), 12);
    assert!((shape.mesh.signed_volume() - 1.0).abs() < 1e-6);
    assert!(shape.mesh.report().is_clean(), "{:?}", shape.mesh.report());
    // The grid: every tetrahedron has circumradius sqrt(3)/2 < 2: the box surface.
    let mut grid = Vec::new();
    for x in 0..10 {
        for y in 0..10 {
            for z in 0..10 {
                grid.push(Vec3::new(x as f32, y as f32, z as f32));
            }
        }
    }
    let d = Delaunay3d::new(&grid).expect("finite points");
    let shape = alpha_shape_from_delaunay(&d, 2.0).expect("valid alpha");
    assert_eq!(shape.mesh.triangle_count(), 6 * 81 * 2);
    assert!((shape.mesh.signed_volume() - 729.0).abs() < 1e-6);
    assert_outward_cycle(&d, &shape, 2.0);
    // Below the cell circumradius nothing is kept.
    let none = alpha_shape_from_delaunay(&d, 0.8).expect("valid alpha");
    assert_eq!(none.mesh.triangle_count(), 0);
    assert_eq!(none.mesh.vertex_count(), 0);
    // A plane: no tetrahedra, an empty mesh by design.
    let plane: Vec<Vec3> = grid.iter().copied().filter(|p| p.z == 0.0).collect();
    let shape = alpha_shape(&plane, 2.0).expect("finite points");
    assert_eq!(shape.mesh.triangle_count(), 0);
}

#[test]
fn degenerate_inputs_never_panic() {
    // Fewer than four points, duplicates, coplanar: empty or valid meshes.
    assert_eq!(alpha_shape(&[], 1.0).expect("ok").mesh.triangle_count(), 0);
    let three = [Vec3::X, Vec3::Y, Vec3::Z];
    assert_eq!(
        alpha_shape(&three, 1.0).expect("ok").mesh.triangle_count(),
        0
    );
    let mut dup = cube_corners();
    dup.extend(cube_corners());
    let shape = alpha_shape(&dup, 2.0).expect("ok");
    assert_eq!(shape.duplicates.len(), 8);
    assert_eq!(shape.mesh.triangle_count(), 12);
    // Output vertices are the first copies, in input order.
    assert_eq!(shape.vertex_ids, (0..8).collect::<Vec<u32>>());
    // Convex hull at infinite alpha, nothing at negative alpha.
    let hull = alpha_shape(&cube_corners(), f64::INFINITY).expect("ok");
    assert_eq!(hull.mesh.triangle_count(), 12);
    assert_eq!(
        alpha_shape(&cube_corners(), -1.0)
            .expect("ok")
            .mesh
            .triangle_count(),
        0
    );
    // Bad inputs: clear errors.
    assert!(matches!(
        alpha_shape(&cube_corners(), f64::NAN),
        Err(AlphaError::InvalidAlpha(_))
    ));
    let mut bad = cube_corners();
    bad[5].z = f32::NAN;
    let err = alpha_shape(&bad, 1.0).expect_err("NaN point");
    assert!(matches!(
        err,
        AlphaError::Delaunay(DelaunayError::NonFinite { index: 5, .. })
    ));
    assert!(err.to_string().contains("point 5"), "{err}");
}
