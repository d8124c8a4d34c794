//! Which Gaussians the meshers use (`--min-contribution`, `--floater-std-ratio`,
//! `--tsdf-alpha-cut`): on the LAM fixture, the Gaussians that render nothing from outside
//! (inside the mouth and eyes) are left out of delaunay and alpha, tsdf renders them all, and
//! the options are checked.

use std::path::PathBuf;
use trisplat_pipeline::config::{BindOptions, TsdfOptions, VisibilityRule};

use glam::Vec3;
use trisplat_pipeline::PipelineError;
use trisplat_pipeline::avatar::AvatarFolder;
use trisplat_pipeline::config::GaussianLayout;
use trisplat_pipeline::{ExtractConfig, ExtractOptions, Method, Session};

fn config(methods: Vec<Method>, options: ExtractOptions) -> ExtractConfig {
    let avatar = AvatarFolder::open(&trisplat_fixtures::path("lam_mini")).expect("fixture");
    ExtractConfig {
        template: avatar.template,
        animation: Some(
            trisplat_fixtures::path("lam_mini/expression.json")
                .display()
                .to_string(),
        ),
        gaussians: Some(avatar.gaussians),
        methods,
        output: PathBuf::from("unused"),
        frames: Some("0..2".to_owned()),
        gt: None,
        options: ExtractOptions {
            bind: BindOptions {
                layout: GaussianLayout::Lam,
                ..options.bind
            },
            ..options
        },
    }
}

#[test]
fn hidden_gaussians_are_left_out_of_the_point_methods() {
    let mut session = Session::open(&config(
        vec![Method::Alpha, Method::Delaunay],
        ExtractOptions::default(),
    ))
    .expect("open");
    let used = session.visibility().used;
    assert!(used.hidden > 0, "{used:?}");
    assert_eq!(used.floaters, 0, "the floater rule is off by default");
    assert_eq!(used.kept + used.hidden, used.total);
    let kept = session.visibility().kept().expect("some left out").to_vec();
    let hidden: Vec<usize> = (0..used.total).filter(|i| !kept.contains(i)).collect();
    let origin = session.origin();
    let (_, means) = session.deform(1).expect("deforms");
    let hidden_means: Vec<Vec3> = hidden.iter().map(|&i| means[i]).collect();
    let kept_means: Vec<Vec3> = kept.iter().map(|&i| means[i]).collect();
    let result = session.frame(1).expect("frame 1");
    for m in &result.methods {
        // The alpha shape's vertices are Gaussian means: none is a hidden one.
        if m.method == Method::Alpha {
            for v in m.output.mesh.positions() {
                let local = (*v - origin).as_vec3();
                let near = |p: &Vec3| p.distance(local) < 1e-6;
                assert!(
                    !hidden_means.iter().any(near) || kept_means.iter().any(near),
                    "{:?}: a vertex at a hidden Gaussian's mean",
                    m.method
                );
            }
        }
        assert!(m.output.mesh.triangle_count() > 0, "{:?}", m.method);
    }
}

#[test]
fn zero_keeps_every_gaussian_and_the_floater_rule_is_opt_in() {
    let session = Session::open(&config(
        vec![Method::Alpha],
        ExtractOptions {
            visibility: VisibilityRule {
                min_contribution: 0.0,
                ..Default::default()
            },
            ..ExtractOptions::default()
        },
    ))
    .expect("open");
    let used = session.visibility().used;
    assert_eq!((used.kept, used.hidden), (used.total, 0));
    assert!(session.visibility().kept().is_none());

    let session = Session::open(&config(
        vec![Method::Alpha],
        ExtractOptions {
            visibility: VisibilityRule {
                floater_std_ratio: Some(1.0),
                ..Default::default()
            },
            ..ExtractOptions::default()
        },
    ))
    .expect("open");
    let used = session.visibility().used;
    assert!(used.floaters > 0, "{used:?}");
    assert_eq!(used.kept + used.hidden + used.floaters, used.total);
}

#[test]
fn the_tsdf_renders_every_gaussian() {
    let mesh = |min_contribution: f32, floater_std_ratio: Option<f64>| {
        let mut session = Session::open(&config(
            vec![Method::Tsdf, Method::Alpha],
            ExtractOptions {
                tsdf: TsdfOptions {
                    views: 8,
                    resolution: 96,
                    ..Default::default()
                },
                visibility: VisibilityRule {
                    min_contribution,
                    floater_std_ratio,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ))
        .expect("open");
        let hidden = session.visibility().used.hidden;
        let result = session.frame(1).expect("frame 1");
        (hidden, result.methods[0].output.mesh.clone())
    };
    let ((hidden, with_rule), (_, without)) = (mesh(1.0 / 255.0, None), mesh(0.0, None));
    assert!(hidden > 0);
    assert_eq!(with_rule.positions(), without.positions());
    assert_eq!(with_rule.triangles(), without.triangles());
    // Floaters lie outside the others: leaving them out of the points moves no camera.
    let (_, floaters_out) = mesh(1.0 / 255.0, Some(1.0));
    assert_eq!(floaters_out.positions(), without.positions());
}

#[test]
fn the_alpha_cut_decides_which_pixels_carry_depth() {
    let faces = |cut: f32| {
        let mut session = Session::open(&config(
            vec![Method::Tsdf],
            ExtractOptions {
                tsdf: TsdfOptions {
                    alpha_cut: cut,
                    views: 8,
                    resolution: 96,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ))
        .expect("open");
        let result = session.frame(0).expect("frame 0");
        result.methods[0].output.mesh.triangle_count()
    };
    let (loose, strict) = (faces(0.05), faces(0.95));
    assert!(
        loose > 0 && strict > 0 && loose != strict,
        "{loose} {strict}"
    );
}

#[test]
fn bad_values_are_refused_naming_the_option() {
    let cases: Vec<(&str, ExtractOptions)> = vec![
        (
            "tsdf-alpha-cut",
            ExtractOptions {
                tsdf: TsdfOptions {
                    alpha_cut: 0.0,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ),
        (
            "tsdf-alpha-cut",
            ExtractOptions {
                tsdf: TsdfOptions {
                    alpha_cut: 1.5,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ),
        (
            "tsdf-alpha-cut",
            ExtractOptions {
                tsdf: TsdfOptions {
                    alpha_cut: f32::NAN,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ),
        (
            "min-contribution",
            ExtractOptions {
                visibility: VisibilityRule {
                    min_contribution: 1.0,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ),
        (
            "min-contribution",
            ExtractOptions {
                visibility: VisibilityRule {
                    min_contribution: -0.1,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ),
        (
            "floater-std-ratio",
            ExtractOptions {
                visibility: VisibilityRule {
                    floater_std_ratio: Some(f64::INFINITY),
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ),
        (
            "floater-neighbors",
            ExtractOptions {
                visibility: VisibilityRule {
                    floater_std_ratio: Some(2.0),
                    floater_neighbors: 0,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        ),
    ];
    for (name, options) in cases {
        let e = Session::open(&config(vec![Method::Alpha], options)).expect_err(name);
        assert!(
            matches!(&e, PipelineError::BadOption { name: n, .. } if *n == name),
            "{name}: {e}"
        );
        assert!(e.to_string().contains(name), "{e}");
    }
}
