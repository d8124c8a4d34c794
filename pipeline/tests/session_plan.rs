//! `--explain` and the run cannot disagree: a session runs exactly the stages its plan says
//! run (write and report are the caller's), for every combination of methods, ground truth
//! and Gaussian source; and skipped stages cost nothing (no mesher, no rendering).

use std::path::PathBuf;
use trisplat_pipeline::config::{MetricOptions, TsdfOptions};

use trisplat_pipeline::input::bind_here;
use trisplat_pipeline::{
    ExtractConfig, ExtractOptions, GroundTruth, Method, Mode, Plan, Session, Stage,
};
use trisplat_splat::ply::{PlyWriteOptions, write_gaussians};

/// RiggedFigure (370 vertices, a skinned clip): small enough to mesh by every method.
fn template() -> PathBuf {
    trisplat_fixtures::path("anim/RiggedFigure.glb")
}

fn config(
    methods: &[Method],
    gt: Option<GroundTruth>,
    gaussians: Option<PathBuf>,
) -> ExtractConfig {
    ExtractConfig {
        template: template(),
        animation: None,
        gaussians,
        methods: methods.to_vec(),
        output: PathBuf::from("unused"),
        frames: Some("0..2".to_owned()),
        gt,
        options: ExtractOptions {
            tsdf: TsdfOptions {
                views: 4,
                resolution: 48,
                ..Default::default()
            },
            metrics: MetricOptions {
                samples: 500,
                ..Default::default()
            },
            ..ExtractOptions::default()
        },
    }
}

/// The stages a plan runs, less those the caller runs (writing files, the report).
fn session_stages(plan: &Plan) -> Vec<Stage> {
    let mut stages: Vec<Stage> = plan
        .stages
        .iter()
        .filter(|s| s.runs && !matches!(s.stage, Stage::Write | Stage::Report))
        .map(|s| s.stage)
        .collect();
    stages.sort_by_key(|s| format!("{s}"));
    stages
}

#[test]
fn a_session_runs_exactly_the_stages_its_plan_runs() {
    let dir = tempfile::tempdir().expect("temp dir");
    // A bound Gaussian file for the configurations that read one.
    let stored = trisplat_pipeline::input::read_template(&template()).expect("template");
    let welded = trisplat_pipeline::input::WeldedTemplate::new(&stored);
    let bound = bind_here(&welded.mesh, &template(), Mode::Binding, 1).expect("bind");
    let bound_path = dir.path().join("bound.ply");
    write_gaussians(&bound_path, &bound, &PlyWriteOptions::default()).expect("write");

    let subsets: [&[Method]; 5] = [
        &[Method::Delaunay],
        &[Method::Alpha],
        &[Method::Tsdf],
        &[Method::Delaunay, Method::Alpha],
        &[],
    ];
    let mut checked = 0;
    for methods in subsets {
        for gt in [None, Some(GroundTruth::Template)] {
            for gaussians in [None, Some(bound_path.clone())] {
                let config = config(methods, gt.clone(), gaussians.clone());
                let mut session = Session::open(&config).expect("open");
                assert_eq!(
                    session.plan(),
                    &Plan::new(&config),
                    "the session follows the plan --explain prints"
                );
                for f in session.frames() {
                    let result = session.frame(f).expect("frame");
                    assert_eq!(result.methods.len(), methods.len());
                    for m in &result.methods {
                        assert_eq!(
                            m.metrics.is_some(),
                            gt.is_some() && m.output.mesh.triangle_count() > 0,
                            "{:?}: metrics only with a ground truth",
                            m.method
                        );
                        // The tsdf renders where it meshes: every frame of a per-frame
                        // run, the keys of a carried one (the default, adaptive).
                        let meshed = m.topology.is_none_or(|t| t.key == f);
                        assert_eq!(
                            m.output.render_ms.is_some(),
                            m.method == Method::Tsdf && meshed
                        );
                    }
                }
                let mut executed = session.executed().to_vec();
                executed.sort_by_key(|s| format!("{s}"));
                assert_eq!(
                    executed,
                    session_stages(session.plan()),
                    "methods {methods:?}, gt {gt:?}, gaussians {gaussians:?}"
                );
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 20);
}

#[test]
fn deform_only_sessions_return_world_space_gaussians() {
    let config = config(&[], None, None);
    let mut session = Session::open(&config).expect("open");
    let world = session.world(1).expect("world");
    assert_eq!(world.len(), session.gaussians().len());
    assert!(world.binding().is_none());
    let vertices = session.template().vertex_count();
    let (positions, means) = session.deform(1).expect("deform");
    assert_eq!(positions.len(), vertices);
    assert_eq!(means, world.means());
    assert_eq!(
        session.executed(),
        &[Stage::Animate, Stage::Bind, Stage::Deform]
    );
}

#[test]
fn options_nothing_takes_are_refused_before_anything_runs() {
    // `--clip` with an OBJ template and no animation: there is no clip to pick.
    let mut config = config(&[Method::Delaunay], None, None);
    config.template = trisplat_fixtures::path("spot_triangulated.obj");
    config.options.animation.clip = Some("walk".to_owned());
    let err = Session::open(&config).expect_err("clip without a glTF");
    assert!(err.to_string().contains("--clip walk"), "{err}");
    // `--targets` without a weights animation.
    config.options.animation.clip = None;
    let options = trisplat_pipeline::SessionOptions {
        targets: Some(PathBuf::from("targets")),
        ..trisplat_pipeline::SessionOptions::default()
    };
    let err = Session::open_with(&config, &options).expect_err("targets without weights");
    assert!(err.to_string().contains("--targets"), "{err}");
    // `--adaptive-scale` in jacobian mode (J already carries the area change).
    let mut config = config_for_jacobian();
    let options = trisplat_pipeline::SessionOptions {
        adaptive_scale: true,
        ..trisplat_pipeline::SessionOptions::default()
    };
    let err = Session::open_with(&config, &options).expect_err("adaptive scale in jacobian");
    assert!(err.to_string().contains("--adaptive-scale"), "{err}");
    config.options.animation.mode = Mode::Binding;
    assert!(Session::open_with(&config, &options).is_ok());
}

fn config_for_jacobian() -> ExtractConfig {
    let mut c = config(&[Method::Delaunay], None, None);
    c.options.animation.mode = Mode::Jacobian;
    c
}

#[test]
fn rest_means_come_from_the_rest_template_in_every_mode() {
    // The canonical means the Delaunay mesher takes are the Gaussians on the rest template,
    // whatever frame the run starts at (lbs included: its engine poses frames, not the rest).
    for mode in [Mode::Binding, Mode::Jacobian, Mode::Lbs] {
        let mut config = config(&[Method::Delaunay], None, None);
        config.options.animation.mode = mode;
        config.frames = Some("5..6".to_owned());
        let session = Session::open(&config).expect("open");
        let deform_mode = trisplat_pipeline::input::deform_mode(mode);
        let expected = trisplat_splat::Deformer::new(session.template(), deform_mode)
            .means(session.gaussians(), session.template().positions())
            .expect("rest means");
        assert_eq!(session.rest_means(), expected.as_slice(), "{mode:?}");
        let mut moved = Session::open(&config).expect("open");
        let (_, frame_means) = moved.deform(5).expect("frame 5");
        assert_ne!(frame_means, expected.as_slice(), "{mode:?}: frame 5 moves");
    }
}
