//! Metrics against the scipy/trimesh references of `tests/reference/ref_metrics.py`.
//!
//! Tolerances:
//! - point mode (k-d tree both ways): every metric equal to scipy's cKDTree result to
//!   [`POINT_REL`] relative (the distances are the same f64 computations on the same float32
//!   inputs; only summation order differs);
//! - surface mode: exact point-to-triangle distances equal to the brute-force minimum over all
//!   triangles of trimesh's `triangles.closest_point` to [`SURFACE_ABS`] times Spot's
//!   bounding-box diagonal, absolute, per point and for the means. (trimesh's
//!   `proximity.closest_point` is stored too but is not exact: it is printed for information.)
//!   The closest triangle may differ from the reference only where both are equally close
//!   (closest point on a shared edge or vertex; none on this data). The normal metrics are
//!   compared to [`SURFACE_NORMAL_REL`]: the face normals are stored as f32.

use serde_json::Value;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{read_mesh, read_points};
use trisplat_geometry::metrics::{Metrics, MetricsOptions, Shape, evaluate, point_metrics};
use trisplat_geometry::spatial::{TriangleBvh, closest_point_on_triangle};

/// Relative tolerance of point-mode metrics against scipy.
const POINT_REL: f64 = 1e-9;
/// Absolute tolerance of surface distances against trimesh, in bounding-box diagonals.
const SURFACE_ABS: f64 = 1e-6;
/// Precision/recall are counts over n: numpy's mean of booleans and our count / n may differ
/// in the last bit.
const FRACTION_REL: f64 = 1e-15;
/// Relative tolerance of surface-mode normal metrics (f32 face normals vs trimesh's f64).
const SURFACE_NORMAL_REL: f64 = 1e-6;
/// Two triangles count as equally close when their distances differ by less than this many
/// bounding-box diagonals.
const TIE: f64 = 1e-12;

fn reference() -> Value {
    let path = trisplat_fixtures::path("reference/metrics/metrics.json");
    let text = std::fs::read_to_string(&path).expect("reference json");
    serde_json::from_str(&text).expect("valid json")
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} missing in reference"))
}

fn rel_err(got: f64, want: f64) -> f64 {
    if want == 0.0 {
        got.abs()
    } else {
        ((got - want) / want).abs()
    }
}

/// Largest relative error over every metric of `m` against `r`.
fn compare(m: &Metrics, r: &Value, skip_accuracy: bool) -> f64 {
    let mut worst = 0.0f64;
    let mut check = |name: &str, got: f64| {
        let e = rel_err(got, num(r, name));
        eprintln!("  {name:<20} {got:.15e}  rel err {e:.2e}");
        worst = worst.max(e);
    };
    if !skip_accuracy {
        check("accuracy", m.accuracy);
        check("chamfer_l1", m.chamfer_l1);
        check("chamfer_l2", m.chamfer_l2);
    }
    check("completeness", m.completeness);
    check(
        "normal_consistency",
        m.normal_consistency.expect("both sides have normals"),
    );
    check(
        "normal_angle_deg",
        m.normal_angle_deg.expect("both sides have normals"),
    );
    assert_eq!(m.n_pred as u64, r["n_pred"].as_u64().expect("n_pred"));
    assert_eq!(m.n_gt as u64, r["n_gt"].as_u64().expect("n_gt"));
    let thresholds = r["thresholds"].as_array().expect("thresholds");
    assert_eq!(m.thresholds.len(), thresholds.len());
    for (t, w) in m.thresholds.iter().zip(thresholds) {
        assert_eq!(t.tau, num(w, "tau"));
        if !skip_accuracy {
            assert!(
                rel_err(t.precision, num(w, "precision")) <= FRACTION_REL,
                "precision at {}",
                t.tau
            );
            assert!(rel_err(t.fscore, num(w, "fscore")) <= FRACTION_REL);
        }
        assert!(
            rel_err(t.recall, num(w, "recall")) <= FRACTION_REL,
            "recall at {}",
            t.tau
        );
    }
    worst
}

fn taus(r: &Value) -> Vec<f64> {
    r["taus"]
        .as_array()
        .expect("taus")
        .iter()
        .filter_map(Value::as_f64)
        .collect()
}

#[test]
fn point_mode_matches_scipy() {
    let r = reference();
    let pred = read_points(&trisplat_fixtures::path("reference/metrics/pred.ply")).expect("pred");
    let gt = read_points(&trisplat_fixtures::path("reference/metrics/gt.ply")).expect("gt");
    let m = point_metrics(&pred, &gt, &taus(&r)).expect("metrics");
    eprintln!("point mode vs scipy cKDTree:");
    let worst = compare(&m, &r["point"], false);
    eprintln!("point mode: max relative error {worst:.2e} (tolerance {POINT_REL:e})");
    assert!(worst <= POINT_REL);
}

#[test]
fn surface_mode_matches_trimesh() {
    let r = reference();
    let surface = &r["surface"];
    let diag = num(&r, "bbox_diagonal");
    let pred = read_points(&trisplat_fixtures::path("reference/metrics/pred.ply")).expect("pred");
    let gt = read_points(&trisplat_fixtures::path("reference/metrics/gt.ply")).expect("gt");
    // The reference was computed on Spot's f32 values (tests/reference/ref_metrics.py).
    let decimal = read_mesh(&trisplat_fixtures::path("spot_triangulated.obj")).expect("spot");
    let spot = TriMesh::new(decimal.positions_f32(), decimal.triangles().to_vec());

    // Per-point exact distances.
    let bvh = TriangleBvh::new(&spot).expect("bvh");
    let found = bvh.closest_points(pred.positions()).expect("queries");
    let want = surface["per_point_distance"].as_array().expect("distances");
    assert_eq!(found.len(), want.len());
    let worst_point = found
        .iter()
        .zip(want)
        .map(|(f, w)| (f.distance - w.as_f64().expect("number")).abs() / diag)
        .fold(0.0f64, f64::max);
    let proximity = surface["per_point_distance_trimesh_proximity"]
        .as_array()
        .expect("trimesh distances");
    let worst_proximity = found
        .iter()
        .zip(proximity)
        .map(|(f, w)| (f.distance - w.as_f64().expect("number")).abs() / diag)
        .fold(0.0f64, f64::max);
    let triangles = surface["per_point_triangle"].as_array().expect("triangles");
    let mut differing = 0;
    for ((f, t), q) in found.iter().zip(triangles).zip(pred.positions()) {
        let t = t.as_u64().expect("id") as u32;
        if f.triangle != t {
            differing += 1;
            let [a, b, c] = spot.corners(t as usize).map(|p| p);
            let (p, _) = closest_point_on_triangle(q.as_dvec3(), a, b, c);
            let d = (p - q.as_dvec3()).length();
            assert!(
                (d - f.distance).abs() <= TIE * diag,
                "triangle {} vs reference {t}: not a tie",
                f.triangle
            );
        }
    }

    let m = evaluate(
        Shape::points(&pred),
        Shape::mesh(&spot, &gt),
        &MetricsOptions {
            taus: taus(&r),
            surface: true,
        },
    )
    .expect("metrics");
    eprintln!("surface mode vs trimesh:");
    let worst_other = compare(&m, surface, true);
    eprintln!(
        "surface mode: {differing} of {} closest triangles differ from the reference, all ties; \
         trimesh.proximity.closest_point differs from the exact distances by up to \
         {worst_proximity:.2e} diagonals",
        found.len()
    );
    let mean_err = |got: f64, key: &str| (got - num(surface, key)).abs() / diag;
    let worst_mean = mean_err(m.accuracy, "accuracy")
        .max(mean_err(m.chamfer_l1, "chamfer_l1"))
        .max(mean_err(m.chamfer_l2, "chamfer_l2"));
    eprintln!(
        "surface mode: max per-point distance error {worst_point:.2e} diagonals, means \
         {worst_mean:.2e} diagonals (tolerance {SURFACE_ABS:e}); other metrics max relative \
         error {worst_other:.2e}"
    );
    assert!(worst_point <= SURFACE_ABS);
    assert!(worst_mean <= SURFACE_ABS);
    assert!(worst_other <= SURFACE_NORMAL_REL);
    for (t, w) in m
        .thresholds
        .iter()
        .zip(surface["thresholds"].as_array().expect("list"))
    {
        assert!(
            rel_err(t.precision, num(w, "precision")) <= FRACTION_REL,
            "precision at {}",
            t.tau
        );
    }
}
