//! The renderer on extreme and degenerate inputs (finite images, no panic), hand-checkable single
//! Gaussians, the original-3DGS switch, geometry-only renders and thread-count independence.

use trisplat_geometry::Camera;
use trisplat_geometry::TriId;
use trisplat_geometry::mesh_render::NormalFrame;
use trisplat_splat::glam::{DVec3, Vec3};
use trisplat_splat::render::DEFAULT_NEAR;
use trisplat_splat::render::{Outputs, RenderError, RenderMode, RenderOptions, render};
use trisplat_splat::{Binding, GaussianParts, GaussianSet, ParameterSpace};

/// Agreement of the renderer's f32 pipeline with an f64 hand evaluation of one Gaussian.
const HAND_TOL: f32 = 1e-5;

/// A camera at the origin looking down +z (OpenCV axes: world = camera frame).
fn camera(size: (u32, u32), focal: f64) -> Camera {
    Camera::try_new(
        0,
        "cam",
        size.0,
        size.1,
        (focal, focal),
        (0.5 * f64::from(size.0), 0.5 * f64::from(size.1)),
        trisplat_splat::glam::DMat3::IDENTITY,
        DVec3::ZERO,
    )
    .unwrap()
}

/// A Gaussian: mean, log-scales, opacity logit.
type Item = (Vec3, Vec3, f32);

fn gaussians(items: &[Item]) -> GaussianSet {
    GaussianSet::try_new(GaussianParts {
        means: items.iter().map(|g| g.0).collect(),
        log_scales: items.iter().map(|g| g.1).collect(),
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; items.len()],
        opacity_logits: items.iter().map(|g| g.2).collect(),
        sh: items.iter().flat_map(|_| [0.5f32, -0.2, 0.1]).collect(),
        ..GaussianParts::default()
    })
    .unwrap()
}

fn all_modes() -> Vec<RenderOptions> {
    let base = RenderOptions {
        outputs: Outputs::ALL,
        ..RenderOptions::default()
    };
    vec![
        base,
        RenderOptions {
            antialiased: true,
            ..base
        },
        RenderOptions {
            outputs: Outputs::ALL,
            ..RenderOptions::original_3dgs()
        },
        RenderOptions {
            mode: RenderMode::Surfel2d,
            ..base
        },
        RenderOptions {
            mode: RenderMode::Perspective,
            ..base
        },
    ]
}

fn assert_sane(set: &GaussianSet, cam: &Camera, what: &str) {
    for options in all_modes() {
        let out = render(set, cam, &options).unwrap();
        let img = &out.images;
        assert!(
            img.is_finite(),
            "{what} {:?}: non-finite image",
            options.mode
        );
        for &a in img.alpha.as_ref().unwrap() {
            assert!((0.0..=1.0).contains(&a), "{what}: alpha {a}");
        }
        for &d in img.depth.as_ref().unwrap() {
            assert!(d >= 0.0, "{what}: depth {d}");
        }
    }
}

#[test]
fn extreme_gaussians_give_finite_images() {
    let cam = camera((40, 30), 30.0);
    let log = |s: f32| Vec3::splat(s);
    let cases: Vec<(&str, Vec<Item>)> = vec![
        ("empty", vec![]),
        ("behind", vec![(Vec3::new(0.0, 0.0, -1.0), log(-1.0), 2.0)]),
        (
            "on the near plane",
            vec![
                (Vec3::new(0.0, 0.0, DEFAULT_NEAR), log(-3.0), 2.0),
                (
                    Vec3::new(0.0, 0.0, 1.000_001 * DEFAULT_NEAR),
                    log(-3.0),
                    2.0,
                ),
                (Vec3::new(0.0, 0.0, 0.0), log(-3.0), 2.0),
            ],
        ),
        (
            "log-scale -29",
            vec![(
                Vec3::new(0.0, 0.0, 1.0),
                Vec3::new(-29.0, -29.6, -29.0),
                5.0,
            )],
        ),
        (
            "scale 1e3",
            vec![
                (Vec3::new(0.0, 0.0, 2.0), log(1000f32.ln()), 1.0),
                (
                    Vec3::new(0.1, 0.0, 1.0),
                    Vec3::new(1000f32.ln(), -29.0, -5.0),
                    1.0,
                ),
            ],
        ),
        (
            "zero opacity",
            vec![(Vec3::new(0.0, 0.0, 1.0), log(-2.0), -1000.0)],
        ),
        (
            "huge coordinates",
            vec![
                (Vec3::new(1e30, 0.0, 1.0), log(-2.0), 1.0),
                (Vec3::new(0.0, 0.0, 1e30), log(-2.0), 1.0),
                (Vec3::new(1e6, 1e6, 1e-3), log(-2.0), 1.0),
            ],
        ),
    ];
    for (what, items) in &cases {
        assert_sane(&gaussians(items), &cam, what);
    }
    // Nothing visible: the background and zeros.
    let set = gaussians(&cases[1].1);
    let options = RenderOptions {
        outputs: Outputs::ALL,
        background: [0.25, 0.5, 1.0],
        ..RenderOptions::default()
    };
    let img = render(&set, &cam, &options).unwrap().images;
    assert!(img.alpha.unwrap().iter().all(|&a| a == 0.0));
    assert!(img.depth.unwrap().iter().all(|&d| d == 0.0));
    assert!(img.rgb.unwrap().chunks(3).all(|c| c == [0.25, 0.5, 1.0]));
}

#[test]
fn tiny_and_huge_images() {
    let set = gaussians(&[
        (Vec3::new(0.0, 0.0, 1.0), Vec3::splat(-2.0), 2.0),
        (Vec3::new(0.05, -0.02, 1.5), Vec3::splat(-4.0), 1.0),
        (Vec3::new(-0.3, 0.2, 3.0), Vec3::new(-1.0, -3.0, -6.0), 0.0),
    ]);
    assert_sane(&set, &camera((1, 1), 1.0), "1x1");
    let one = render(&set, &camera((1, 1), 1.0), &RenderOptions::default())
        .unwrap()
        .images;
    assert!(one.alpha.unwrap()[0] > 0.5);
    // 4096 x 4096, alpha only (64 MiB): finite, and the covered area is where the Gaussians are.
    let big = camera((4096, 4096), 4096.0);
    let options = RenderOptions {
        outputs: Outputs {
            alpha: true,
            ..Outputs::NONE
        },
        ..RenderOptions::default()
    };
    let img = render(&set, &big, &options).unwrap().images;
    let alpha = img.alpha.unwrap();
    assert_eq!(alpha.len(), 4096 * 4096);
    assert!(
        alpha
            .iter()
            .all(|a| a.is_finite() && (0.0..=1.0).contains(a))
    );
    assert!(alpha[2048 * 4096 + 2048] > 0.5);
    assert_eq!(alpha[0], 0.0);
}

#[test]
fn one_gaussian_by_hand() {
    // Isotropic Gaussian of scale s at depth z on the optical axis: Sigma2D = (f s / z)^2 I
    // + 0.3 I; at the centre pixel (its mean projects to a pixel centre) sigma = 0.
    let (f, z, s) = (50.0f64, 2.0f64, 0.02f64);
    let cam = Camera::try_new(
        0,
        "c",
        32,
        32,
        (f, f),
        (16.5, 16.5),
        trisplat_splat::glam::DMat3::IDENTITY,
        DVec3::ZERO,
    )
    .unwrap();
    let opacity = 0.8f32;
    let logit = trisplat_splat::logit(opacity);
    let mut parts = GaussianParts {
        means: vec![Vec3::new(0.0, 0.0, z as f32)],
        log_scales: vec![Vec3::new((s as f32).ln(), (s as f32).ln(), -29.0)],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]],
        opacity_logits: vec![logit],
        sh: vec![0.0; 3],
        ..GaussianParts::default()
    };
    let set = GaussianSet::try_new(parts.clone()).unwrap();
    let options = RenderOptions {
        outputs: Outputs::ALL,
        normal_frame: NormalFrame::Camera,
        ..RenderOptions::default()
    };
    let img = render(&set, &cam, &options).unwrap().images;
    let var = (f * s / z).powi(2) + 0.3;
    let alpha_at = |dx: f64, dy: f64| f64::from(opacity) * (-0.5 * (dx * dx + dy * dy) / var).exp();
    let w = 32usize;
    let a = img.alpha.as_ref().unwrap();
    // Pixel (16, 16) has centre (16.5, 16.5) = the projected mean; (16, 17) is one pixel right.
    assert!((a[16 * w + 16] - alpha_at(0.0, 0.0) as f32).abs() < HAND_TOL);
    assert!((a[16 * w + 17] - alpha_at(1.0, 0.0) as f32).abs() < HAND_TOL);
    assert!((a[18 * w + 15] - alpha_at(-1.0, 2.0) as f32).abs() < HAND_TOL);
    // Depth is the Gaussian's z wherever it is seen; the median only where alpha > 0.5.
    let d = img.depth.as_ref().unwrap();
    let m = img.median_depth.as_ref().unwrap();
    assert!((d[16 * w + 16] - z as f32).abs() < HAND_TOL);
    assert!((m[16 * w + 16] - z as f32).abs() < HAND_TOL);
    assert_eq!(m[16 * w + 20], 0.0);
    // Colour: SH DC 0 gives 0.5 grey, times alpha.
    let rgb = img.rgb.as_ref().unwrap();
    assert!((rgb[3 * (16 * w + 16)] - 0.5 * a[16 * w + 16]).abs() < HAND_TOL);
    // The flat axis (local z = camera z) faces the camera: (0, 0, -1) times alpha.
    let n = img.normal.as_ref().unwrap();
    let p = 3 * (16 * w + 16);
    assert!(n[p].abs() < HAND_TOL && n[p + 1].abs() < HAND_TOL);
    assert!((n[p + 2] + a[16 * w + 16]).abs() < HAND_TOL);
    // Original 3DGS rules: opacity 1 saturates at 0.99 instead of 0.999.
    parts.opacity_logits = vec![30.0];
    let opaque = GaussianSet::try_new(parts).unwrap();
    let gs = render(&opaque, &cam, &RenderOptions::default())
        .unwrap()
        .images;
    let orig = render(&opaque, &cam, &RenderOptions::original_3dgs())
        .unwrap()
        .images;
    assert!((gs.alpha.unwrap()[16 * w + 16] - 0.999).abs() < HAND_TOL);
    assert!((orig.alpha.unwrap()[16 * w + 16] - 0.99).abs() < HAND_TOL);
}

#[test]
fn geometry_only_renders_skip_colour() {
    // NaN SH coefficients (only possible through new_unchecked) never reach a geometry render.
    let mut parts = GaussianParts {
        means: vec![Vec3::new(0.0, 0.0, 1.0)],
        log_scales: vec![Vec3::splat(-2.0)],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]],
        opacity_logits: vec![2.0],
        sh_degree: 1,
        sh: vec![f32::NAN; 12],
        ..GaussianParts::default()
    };
    let set = GaussianSet::new_unchecked(parts.clone());
    let options = RenderOptions {
        outputs: Outputs {
            alpha: true,
            depth: true,
            median_depth: true,
            normal: true,
            rgb: false,
        },
        ..RenderOptions::default()
    };
    let img = render(&set, &camera((24, 24), 20.0), &options)
        .unwrap()
        .images;
    assert!(img.rgb.is_none());
    assert!(img.is_finite());
    // Bound Gaussians in local frames are refused with a clear error.
    parts.space = ParameterSpace::Local;
    parts.sh = vec![0.0; 12];
    parts.binding = Some(Binding {
        triangles: vec![TriId(0)],
        ..Binding::default()
    });
    let bound = GaussianSet::try_new(parts).unwrap();
    let err = render(&bound, &camera((8, 8), 8.0), &options).unwrap_err();
    assert_eq!(err, RenderError::LocalParameters);
    assert!(err.to_string().contains("deform"));
    // Bad clip planes are refused.
    let bad = RenderOptions {
        near: 0.0,
        ..options
    };
    assert!(matches!(
        render(&set, &camera((8, 8), 8.0), &bad),
        Err(RenderError::BadClipPlanes { .. })
    ));
}

#[test]
fn images_do_not_depend_on_the_thread_count() {
    let set =
        trisplat_splat::ply::read_gaussians(&trisplat_fixtures::path("render/random_deg3.ply"))
            .unwrap();
    let cams = trisplat_geometry::read_cameras_json(&trisplat_fixtures::path(
        "render/random_cameras.json",
    ))
    .unwrap();
    let options = RenderOptions {
        outputs: Outputs::ALL,
        ..RenderOptions::default()
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| render(&set, &cams[2], &options).unwrap().images)
    };
    assert_eq!(run(1), run(3));
}
