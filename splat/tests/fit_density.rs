//! `splat::fit::density` and `splat::fit::sh_schedule`: the clone / split / prune decisions on a
//! hand-made bound set (children keep the binding, a triangle's last Gaussian is spared), Adam's
//! state across a densification step, the opacity reset, and the SH schedule's zero gradients
//! for inactive bands through the renderer's backward pass.

use glam::DVec3;
use trisplat_geometry::{Camera, TriMesh};
use trisplat_splat::fit::adam::{Adam, LearningRates};
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames};
use trisplat_splat::fit::density::{
    DensifyOptions, DensityStats, RESET_OPACITY, camera_extent, densify_and_prune, reset_opacity,
    world_max_scale,
};
use trisplat_splat::fit::sh_schedule::{expand_sh_grads, truncate_sh};
use trisplat_splat::render::{
    GaussianGrads, GaussianParams, ImageGrads, RenderOptions, backward_into, render_with_grad,
};

/// Two triangles of a unit square at z = 0.
fn template() -> TriMesh {
    TriMesh::try_new(
        vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap()
}

fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

/// Four Gaussians: 0 (triangle 0, hot, small, opaque), 1 (triangle 0, hot, large, opaque),
/// 2 (triangle 0, cold, nearly transparent), 3 (triangle 1, cold, nearly transparent: its
/// triangle's only one). World sizes at rest: 0.005 and 0.05 against a limit of
/// 0.01 × extent 1 = 0.01. SH degree 1, each coefficient distinct.
fn scene() -> (BoundParams, TriangleFrames, DensityStats) {
    let mesh = template();
    let rest = TriangleFrames::binding(&mesh, mesh.positions());
    let k = rest.scale[0];
    let small = (0.005 / k).ln();
    let large = (0.05 / k).ln();
    let local = GaussianParams {
        means: vec![
            [0.1, 0.0, 0.0],
            [0.0, 0.2, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
        ],
        log_scales: vec![
            [small, small - 1.0, small - 2.0],
            [large, large - 1.0, large - 0.5],
            [small; 3],
            [small; 3],
        ],
        rotations: vec![
            [1.0, 0.0, 0.0, 0.0],
            [0.9, 0.1, 0.2, 0.3],
            [1.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
        ],
        opacity_logits: vec![logit(0.5), logit(0.8), logit(0.001), logit(0.002)],
        sh_degree: 1,
        sh: (0..4 * 12).map(|x| x as f64 * 0.01).collect(),
    };
    let bound = BoundParams {
        local,
        triangles: vec![0, 0, 0, 1],
    };
    let mut stats = DensityStats::new(4);
    // 100 x 100 pixels: d loss / d ndc = 50 × d loss / d pixel. Gaussians 0 and 1: |(1e-5,
    // 0)| × 50 = 5e-4 over two views, above 2e-4; 2 and 3 get nothing.
    let grads = [[1e-5, 0.0], [0.0, -1e-5], [0.0, 0.0], [0.0, 0.0]];
    stats.add_view(&grads, &[0, 1, 2, 3], 100, 100);
    stats.add_view(&grads, &[0, 1], 100, 100);
    (bound, rest, stats)
}

fn warmed_adam(bound: &mut BoundParams) -> Adam {
    let mut adam = Adam::new(
        LearningRates::BOUND,
        bound.len(),
        bound.local.sh_per_gaussian(),
    );
    let mut g = GaussianGrads::zeros(bound.len(), bound.local.sh_degree);
    for (i, m) in g.means.iter_mut().enumerate() {
        *m = [1.0 + i as f64, -2.0, 0.5];
    }
    g.opacity_logits = vec![0.3, -0.2, 0.1, 0.4];
    // Steps with zero learning rates: the moments move, the parameters do not.
    adam.lr = LearningRates {
        means: 0.0,
        log_scales: 0.0,
        rotations: 0.0,
        opacities: 0.0,
        sh_dc: 0.0,
        sh_rest: 0.0,
    };
    adam.step(&mut bound.local, &g);
    adam.step(&mut bound.local, &g);
    adam
}

#[test]
fn statistics_are_mean_ndc_norms_over_visible_views() {
    let (_, _, stats) = scene();
    assert_eq!(stats.views(), &[2, 2, 1, 1]);
    assert!((stats.mean_grad(0) - 5e-4).abs() < 1e-15);
    assert!((stats.mean_grad(1) - 5e-4).abs() < 1e-15);
    assert_eq!(stats.mean_grad(2), 0.0);
    assert_eq!(stats.mean_grad(3), 0.0);
    // Non-square images: x scales with W/2, y with H/2.
    let mut s = DensityStats::new(1);
    s.add_view(&[[1e-4, 1e-4]], &[0], 40, 10);
    assert!((s.mean_grad(0) - (2e-3f64).hypot(5e-4)).abs() < 1e-15);
    assert!((camera_extent(&[DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0)]) - 1.1).abs() < 1e-12);
}

#[test]
fn clone_small_split_large_prune_transparent_spare_the_last() {
    let (mut bound, rest, stats) = scene();
    let before = bound.clone();
    let mut adam = warmed_adam(&mut bound);
    let old_adam = adam.clone();
    let options = DensifyOptions::default();
    let step = densify_and_prune(
        &mut bound, &mut adam, &stats, &rest, 1.0, &options, false, 7,
    )
    .unwrap();
    let c = step.counts;
    assert_eq!(
        (c.cloned, c.split, c.pruned, c.spared),
        (1, 1, 1, 1),
        "{c:?}"
    );
    // 4 + 1 clone + 2 children − 1 parent − 1 pruned.
    assert_eq!(c.count, 5);
    assert_eq!(bound.len(), 5);
    // Order (3DGS): survivors [0, 3], the clone of 0, then the two children of 1.
    assert_eq!(step.origins, vec![0, 3, 0, 1, 1]);
    assert_eq!(
        bound.triangles,
        vec![0, 1, 0, 0, 0],
        "children keep the binding"
    );
    let p = &bound.local;
    let b = &before.local;
    // Survivors and the clone are exact f64 copies.
    for (new, old) in [(0, 0), (1, 3), (2, 0)] {
        assert_eq!(p.means[new], b.means[old]);
        assert_eq!(p.log_scales[new], b.log_scales[old]);
        assert_eq!(p.rotations[new], b.rotations[old]);
        assert_eq!(p.opacity_logits[new], b.opacity_logits[old]);
        assert_eq!(p.sh[new * 12..new * 12 + 12], b.sh[old * 12..old * 12 + 12]);
    }
    // Children: scales / 1.6 (up to the f32 round trip), the parent's rotation, opacity and
    // colour, means drawn around the parent's (within 6 σ, not on it).
    let parent = 1;
    for child in [3, 4] {
        for a in 0..3 {
            let want = b.log_scales[parent][a] - 1.6f64.ln();
            assert!((p.log_scales[child][a] - want).abs() < 1e-5);
        }
        assert_eq!(p.rotations[child], b.rotations[parent]);
        assert_eq!(p.opacity_logits[child], b.opacity_logits[parent]);
        assert_eq!(
            p.sh[child * 12..child * 12 + 12],
            b.sh[parent * 12..parent * 12 + 12]
        );
        let d = DVec3::from_array(p.means[child]) - DVec3::from_array(b.means[parent]);
        let s_max = b.log_scales[parent][0].exp();
        assert!(d.length() > 0.0 && d.length() < 6.0 * s_max * 3f64.sqrt());
    }
    assert_ne!(p.means[3], p.means[4]);
    // The world size rule: the children of the large one are still above the clone limit.
    assert!(world_max_scale(&bound, &rest, 3) > 0.01);

    // Adam: survivors keep their moments and steps, new Gaussians start at zero.
    assert_eq!(adam.len(), 5);
    assert_eq!(adam.mean_moments(0), old_adam.mean_moments(0));
    assert_eq!(adam.mean_moments(1), old_adam.mean_moments(3));
    assert_eq!(adam.opacity_state(1), old_adam.opacity_state(3));
    assert_eq!(adam.opacity_state(0).2, 2);
    for new in [2, 3, 4] {
        assert_eq!(
            adam.mean_moments(new),
            ([0.0; 3], [0.0; 3]),
            "Gaussian {new}"
        );
        assert_eq!(adam.opacity_state(new), (0.0, 0.0, 0));
    }
    // The next step runs on the new count.
    let g = GaussianGrads::zeros(5, 1);
    adam.step(&mut bound.local, &g);
}

#[test]
fn sampling_is_seeded() {
    let run = |seed| {
        let (mut bound, rest, stats) = scene();
        let mut adam = Adam::new(LearningRates::BOUND, 4, 12);
        let options = DensifyOptions::default();
        densify_and_prune(
            &mut bound, &mut adam, &stats, &rest, 1.0, &options, false, seed,
        )
        .unwrap();
        bound
    };
    assert_eq!(run(3), run(3));
    assert_ne!(run(3).local.means, run(4).local.means);
}

#[test]
fn threshold_and_size_limits_decide() {
    // Nothing is hot above a higher threshold: only the prune happens.
    let (mut bound, rest, stats) = scene();
    let mut adam = Adam::new(LearningRates::BOUND, 4, 12);
    let options = DensifyOptions {
        grad_threshold: 6e-4,
        ..DensifyOptions::default()
    };
    let c = densify_and_prune(
        &mut bound, &mut adam, &stats, &rest, 1.0, &options, false, 0,
    )
    .unwrap()
    .counts;
    assert_eq!(
        (c.cloned, c.split, c.pruned, c.spared, c.count),
        (0, 0, 1, 1, 3)
    );
    // A ten times larger extent makes both hot Gaussians small: two clones.
    let (mut bound, rest, stats) = scene();
    let mut adam = Adam::new(LearningRates::BOUND, 4, 12);
    let c = densify_and_prune(
        &mut bound,
        &mut adam,
        &stats,
        &rest,
        10.0,
        &DensifyOptions::default(),
        false,
        0,
    )
    .unwrap()
    .counts;
    assert_eq!((c.cloned, c.split), (2, 0));
    // World-size pruning (after an opacity reset): the large one (0.05 > 0.04 × 1) goes, and
    // nothing else of its triangle is spared for it.
    let (mut bound, rest, stats) = scene();
    let mut adam = Adam::new(LearningRates::BOUND, 4, 12);
    let options = DensifyOptions {
        grad_threshold: 1.0,
        max_world_size: Some(0.04),
        ..DensifyOptions::default()
    };
    let step =
        densify_and_prune(&mut bound, &mut adam, &stats, &rest, 1.0, &options, true, 0).unwrap();
    assert_eq!(step.origins, vec![0, 3]);
    // Without `prune_large` the size rule is off.
    let (mut bound, rest, stats) = scene();
    let mut adam = Adam::new(LearningRates::BOUND, 4, 12);
    let step = densify_and_prune(
        &mut bound, &mut adam, &stats, &rest, 1.0, &options, false, 0,
    )
    .unwrap();
    assert_eq!(step.origins, vec![0, 1, 3]);
}

#[test]
fn every_gaussian_of_a_triangle_flagged_keeps_them_all() {
    let (mut bound, rest, stats) = scene();
    // Everything nearly transparent: triangle 0's three are all flagged, so all stay.
    bound.local.opacity_logits = vec![logit(0.001); 4];
    let mut adam = Adam::new(LearningRates::BOUND, 4, 12);
    let options = DensifyOptions {
        grad_threshold: 1.0,
        ..DensifyOptions::default()
    };
    let c = densify_and_prune(
        &mut bound, &mut adam, &stats, &rest, 1.0, &options, false, 0,
    )
    .unwrap()
    .counts;
    assert_eq!((c.pruned, c.spared, c.count), (0, 4, 4));
}

#[test]
fn opacity_reset_caps_through_the_logit_and_zeroes_moments() {
    let (mut bound, _, _) = scene();
    let mut adam = warmed_adam(&mut bound);
    assert_ne!(adam.opacity_state(0).0, 0.0);
    reset_opacity(&mut bound, &mut adam, RESET_OPACITY);
    let sig = |l: f64| 1.0 / (1.0 + (-l).exp());
    let o: Vec<f64> = bound.local.opacity_logits.iter().map(|&l| sig(l)).collect();
    assert!((o[0] - 0.01).abs() < 1e-12 && (o[1] - 0.01).abs() < 1e-12);
    assert!((o[2] - 0.001).abs() < 1e-12 && (o[3] - 0.002).abs() < 1e-12);
    for i in 0..4 {
        let (m, v, steps) = adam.opacity_state(i);
        assert_eq!((m, v, steps), (0.0, 0.0, 2));
    }
}

#[test]
fn options_are_checked() {
    assert!(DensifyOptions::default().check().is_ok());
    let bad = [
        DensifyOptions {
            every: 0,
            ..DensifyOptions::default()
        },
        DensifyOptions {
            from: 20_000,
            ..DensifyOptions::default()
        },
        DensifyOptions {
            grad_threshold: -1.0,
            ..DensifyOptions::default()
        },
        DensifyOptions {
            percent_dense: f64::NAN,
            ..DensifyOptions::default()
        },
        DensifyOptions {
            prune_opacity: 1.0,
            ..DensifyOptions::default()
        },
        DensifyOptions {
            opacity_reset_every: Some(0),
            ..DensifyOptions::default()
        },
    ];
    for b in bad {
        assert!(b.check().is_err(), "{b:?}");
    }
    // The schedule: 3DGS's iteration tests, and nothing after the last iteration.
    let d = DensifyOptions::default();
    assert!(!d.densifies_at(500, 3000) && d.densifies_at(600, 3000));
    assert!(!d.densifies_at(3000, 3000) && d.densifies_at(3000, 3001));
    assert!(!d.densifies_at(15_000, 20_000) && !d.densifies_at(650, 3000));
    assert!(d.resets_opacity_at(3000, 3001) && !d.resets_opacity_at(3000, 3000));
    assert!(!d.resets_opacity_at(15_000, 20_000));
    assert!(d.gathers(14_999) && !d.gathers(15_000));
}

/// A camera looking down −z at the square from z = 2 (OpenCV axes: +z forward).
fn camera() -> Camera {
    Camera::look_at(
        "top",
        DVec3::new(0.5, 0.5, 2.0),
        DVec3::new(0.5, 0.5, 0.0),
        DVec3::Y,
        (24, 24),
        40.0,
    )
    .unwrap()
}

#[test]
fn inactive_sh_bands_get_zero_gradient_and_stay_unchanged() {
    // World-space Gaussians of degree 3 with every band non-zero, rendered at active degree 1.
    let n = 6;
    let full = GaussianParams {
        means: (0..n)
            .map(|i| {
                [
                    0.2 + 0.12 * i as f64,
                    0.3 + 0.07 * i as f64,
                    0.05 * i as f64,
                ]
            })
            .collect(),
        log_scales: vec![[-2.5, -2.8, -3.0]; n],
        rotations: (0..n)
            .map(|i| [1.0, 0.1 * i as f64, -0.05, 0.02 * i as f64])
            .collect(),
        opacity_logits: vec![0.5; n],
        sh_degree: 3,
        sh: (0..n * 48)
            .map(|x| 0.3 * ((x as f64 * 0.37).sin()))
            .collect(),
    };
    let options = RenderOptions::default();
    let cam = camera();
    let loss_grads = |params: &GaussianParams| {
        let fwd = render_with_grad::<f64, _>(params, &cam, &options).unwrap();
        // Loss: Σ rgb · w with fixed weights.
        let w: Vec<f64> = (0..fwd.rgb.len())
            .map(|x| ((x * 7919) % 13) as f64 / 13.0 - 0.4)
            .collect();
        let mut g = GaussianGrads::zeros(params.means.len(), params.sh_degree);
        let grads = ImageGrads {
            rgb: Some(&w[..]),
            ..ImageGrads::default()
        };
        backward_into(params, &cam, &options, &fwd, &grads, &mut g).unwrap();
        (fwd.rgb, g)
    };
    let mut cut = full.clone();
    truncate_sh(&mut cut, 1);
    let (rgb_cut, g_cut) = loss_grads(&cut);
    assert!(g_cut.sh.iter().any(|&v| v != 0.0));
    // The same render as the full set with bands 2 and 3 set to zero, and the same gradient
    // on bands 0 and 1.
    let mut zeroed = full.clone();
    let mut sh = cut.sh.clone();
    expand_sh_grads(&mut sh, n, 1, 3);
    zeroed.sh = sh;
    let (rgb_zeroed, g_zeroed) = loss_grads(&zeroed);
    for (a, b) in rgb_cut.iter().zip(&rgb_zeroed) {
        assert!((a - b).abs() < 1e-12);
    }
    let mut g = g_cut.sh.clone();
    expand_sh_grads(&mut g, n, 1, 3);
    assert_eq!(g.len(), n * 48);
    let active = |j: usize| j < 3 || (j - 3) % 15 < 3;
    for i in 0..n {
        for j in 0..48 {
            let v = g[i * 48 + j];
            if active(j) {
                assert!((v - g_zeroed.sh[i * 48 + j]).abs() < 1e-12, "{i} {j}");
            } else {
                assert_eq!(v, 0.0, "inactive band, Gaussian {i}, coefficient {j}");
                // ... where the full render's gradient is not zero.
            }
        }
    }
    assert!(
        (0..n * 48).any(|x| !active(x % 48) && g_zeroed.sh[x] != 0.0),
        "the test needs inactive bands that would get a gradient"
    );
    // An Adam step with the widened gradient leaves the inactive bands as they were.
    let mut params = full.clone();
    let mut adam = Adam::new(LearningRates::BOUND, n, 48);
    let mut grads = GaussianGrads::zeros(n, 3);
    grads.sh = g;
    for _ in 0..3 {
        adam.step(&mut params, &grads);
    }
    for x in 0..n * 48 {
        if active(x % 48) {
            if grads.sh[x] != 0.0 {
                assert_ne!(params.sh[x], full.sh[x]);
            }
        } else {
            assert_eq!(params.sh[x], full.sh[x]);
        }
    }
}
