//! `extract --method opacity`: the opacity field of every deformed Gaussian meshed per frame
//! (docs/conventions.md §6), on two frames of the LAM fixture's expression track, beside alpha.

mod common;

use trisplat_pipeline::{Method, Plan, RunControl, Stage, run};

#[test]
fn opacity_meshes_every_frame_closed_and_is_measured() {
    let out = common::fresh_dir("opacity_method", "lam_mini");
    let track = trisplat_fixtures::path("lam_mini/expression.json");
    let config = common::lam_mini_config(&track, &[Method::Opacity, Method::Alpha], "7..9", &out);
    let plan = Plan::new(&config);
    assert!(plan.runs(Stage::Mesh(Method::Opacity)));
    let report = run(&config, RunControl::default(), &mut |_| {}).expect("run");
    let opacity = &report.methods["opacity"];
    assert_eq!(opacity.parameters["bisection_steps"], 8.0);
    // The defaults: the median-depth field, one piece (issue #34).
    assert_eq!(opacity.parameters["median_field"], 1.0);
    assert_eq!(opacity.parameters["min_piece_share"], 1.0);
    assert_eq!(opacity.parameters["surface"], 0.0);
    assert_eq!(opacity.frames.len(), 2);
    for f in &opacity.frames {
        // Marching tetrahedra over a closed tetrahedralisation: a closed surface.
        assert!(f.faces > 100 && f.watertight, "frame {}: {f:?}", f.frame);
        let c = f.consistency.expect("render consistency");
        assert!(c.iou > 0.1 && c.depth_error_median.is_some(), "{c:?}");
        let file = out.join(format!("opacity/frame_{:06}.ply", f.frame));
        let mesh = trisplat_geometry::io::read_mesh(&file).expect("the frame's mesh");
        let stats = trisplat_geometry::mesh_stats::MeshStats::of(&mesh);
        assert_eq!(stats.components, 1, "frame {}: one piece", f.frame);
    }
    // Methods run in report order, opacity last.
    let names: Vec<&String> = report.methods.keys().collect();
    assert_eq!(names, ["alpha", "opacity"]);
}
