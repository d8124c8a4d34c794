//! Issue #15, item 4, for the main job's report: a method's mesh and its ground truth moved by
//! up to 1e6 in every axis score the same within 1e-6 relative (`GtSamples` moves both sides
//! to the ground truth's centre in f64 before sampling them in f32). The vertex-sharing test
//! (self-consistency) looks at the meshes where they are.

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::metrics::Tau;
use trisplat_pipeline::report::{FrameMetrics, GtSamples, measure_with};

const SAMPLES: usize = 4000;

fn spot() -> TriMesh {
    trisplat_fixtures::spot().expect("Spot fixture")
}

fn moved(mesh: &TriMesh, offset: DVec3) -> TriMesh {
    let mut m = mesh.clone();
    m.translate(offset);
    m
}

fn scores(pred: &TriMesh, gt: &TriMesh, offset: DVec3) -> FrameMetrics {
    let gt = GtSamples::new(moved(gt, offset), SAMPLES).expect("area");
    measure_with(&moved(pred, offset), &gt, SAMPLES, Tau::Fraction(0.005))
        .expect("measurable")
        .expect("area")
}

fn values(m: &FrameMetrics) -> Vec<(&'static str, f64)> {
    vec![
        ("chamfer_l1", m.chamfer_l1),
        ("chamfer_l2", m.chamfer_l2),
        (
            "normal_consistency",
            m.normal_consistency.unwrap_or(f64::NAN),
        ),
        ("accuracy", m.accuracy),
        ("completeness", m.completeness),
        ("precision", m.precision),
        ("recall", m.recall),
        ("fscore", m.fscore),
        ("tau", m.tau),
        ("gt_diagonal", m.gt_diagonal),
        ("gt_area", m.gt_area),
        ("area_ratio", m.area_ratio.unwrap_or(f64::NAN)),
    ]
}

#[test]
fn report_scores_do_not_depend_on_the_origin() {
    let gt = spot();
    let bent: Vec<DVec3> = gt
        .positions()
        .iter()
        .map(|p| DVec3::new(1.03 * p.x, p.y + 0.02 * (5.0 * p.z).sin(), p.z))
        .collect();
    let pred = TriMesh::new(bent, gt.triangles().to_vec());
    let here = scores(&pred, &gt, DVec3::ZERO);
    assert!(here.chamfer_l1 > 1e-3 && here.fscore < 1.0, "{here:?}");
    for offset in [
        DVec3::splat(1e6),
        DVec3::new(1e6, -1e6, 3e5),
        DVec3::new(-7e5, 2.5e5, 1e6),
    ] {
        let there = scores(&pred, &gt, offset);
        for ((key, a), (_, b)) in values(&here).iter().zip(values(&there)) {
            // The normal of the closest triangle jumps at edges: where the closest point is
            // on an edge both triangles are at the same distance up to rounding, and the
            // rounding of the moved coordinates picks one or the other (4e-5 measured).
            let rel = if *key == "normal_consistency" {
                1e-4
            } else {
                1e-6
            };
            assert!(
                (a - b).abs() <= rel * a.abs().max(1e-9),
                "{key} at {offset}: {a} here, {b} there"
            );
        }
    }
    // The template against itself far away: every vertex shared, a perfect score.
    let far = moved(&gt, DVec3::splat(1e6));
    let m = scores(&far, &far, DVec3::ZERO);
    assert_eq!(m.shared_vertex_fraction, Some(1.0));
    assert_eq!(m.fscore, 1.0, "{m:?}");
}
