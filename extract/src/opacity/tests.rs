//! Tests of the opacity field and its mesh against closed forms.

use glam::{DVec3, Vec3};
use trisplat_geometry::{Camera, sphere_rig};

use super::*;

fn gof() -> OpacityOptions {
    OpacityOptions {
        rules: AlphaRules {
            model: RayModel::Gof,
            ..AlphaRules::default()
        },
        ..OpacityOptions::default()
    }
}

fn gaussians(means: &[Vec3], scale: Vec3, opacity: f32) -> OpacityGaussians {
    let n = means.len();
    OpacityGaussians {
        means: means.to_vec(),
        scales: vec![scale; n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![opacity; n],
        colors: vec![[0.2, 0.4, 0.6]; n],
    }
}

fn rig(center: DVec3, radius: f64, views: usize) -> Vec<Camera> {
    sphere_rig(center, radius, views, (64, 64), 40.0).expect("rig")
}

/// Every edge of a closed triangle mesh is shared by exactly two triangles, once each way.
fn is_closed(triangles: &[[u32; 3]]) -> bool {
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .collect();
    edges.sort_unstable();
    let n = edges.len();
    edges.dedup();
    edges.len() == n
        && edges
            .iter()
            .all(|&(a, b)| edges.binary_search(&(b, a)).is_ok())
}

/// GOF's model, one isotropic Gaussian: a point's smallest accumulated opacity over views that see it from
/// its own side is `exp(-ρ²/2σ²)` (the ray's peak lies beyond the point), so the field is that.
#[test]
fn single_gaussian_field_is_its_density() {
    let sigma = 0.1f32;
    let g = gaussians(&[Vec3::new(0.3, -0.2, 0.1)], Vec3::splat(sigma), 1.0);
    let cams = rig(DVec3::new(0.3, -0.2, 0.1), 0.5, 32);
    let points: Vec<DVec3> = (0..40)
        .map(|i| {
            let dir = DVec3::new((i as f64 * 1.3).sin(), (i as f64 * 0.7).cos(), 0.5).normalize();
            DVec3::new(0.3, -0.2, 0.1) + dir * (0.005 * i as f64)
        })
        .collect();
    let values = opacity_at(&g, &cams, &points, &gof()).expect("field");
    for (i, (v, x)) in values.iter().zip(&points).enumerate() {
        let rho = (*x - DVec3::new(0.3, -0.2, 0.1)).length();
        let mut expected = (-rho * rho / (2.0 * 0.01)).exp().min(0.999);
        if expected < 1.0 / 255.0 {
            expected = 0.0;
        }
        assert!(
            (f64::from(*v) - expected).abs() < 1e-5,
            "point {i}: {v} vs {expected}"
        );
    }
}

/// Seen from one camera only, a point behind the Gaussian on the optical axis gets the ray's
/// peak, the opacity itself (clamped at 0.999).
#[test]
fn behind_the_peak_the_ray_maximum_counts() {
    let g = gaussians(&[Vec3::ZERO], Vec3::splat(0.1), 0.8);
    let cam = Camera::look_at(
        "c",
        DVec3::new(0.0, 0.0, -2.0),
        DVec3::ZERO,
        DVec3::Y,
        (64, 64),
        40.0,
    )
    .expect("camera");
    let v = opacity_at(
        &g,
        &[cam],
        &[DVec3::new(0.0, 0.0, 0.15)],
        &OpacityOptions::default(),
    )
    .expect("field");
    assert!((v[0] - 0.8).abs() < 1e-6, "{}", v[0]);
}

/// GOF's model: the mesh of one isotropic Gaussian of opacity 1 is closed and lies on the sphere where
/// `exp(-ρ²/2σ²) = 1/2`, ρ = σ √(2 ln 2), within the bisection's resolution (edge 3√3 σ / 2ⁿ
/// after n steps, half of it for the midpoint: 0.011 σ after GOF's 8, the default, 0.17 σ after 4).
#[test]
fn single_gaussian_mesh_is_the_level_sphere() {
    for (steps, tolerance) in [(DEFAULT_BISECTION_STEPS, 0.011), (4, 0.17)] {
        single_gaussian_sphere_within(steps, tolerance);
    }
}

fn single_gaussian_sphere_within(steps: u32, tolerance: f64) {
    let sigma = 0.1;
    let centre = DVec3::new(1.0, 2.0, 3.0);
    let g = gaussians(&[centre.as_vec3()], Vec3::splat(sigma as f32), 1.0);
    let cams = rig(centre, 0.6, 24);
    let options = OpacityOptions {
        bisection_steps: steps,
        ..gof()
    };
    let out = opacity_mesh(&g, &cams, &options).expect("mesh");
    let rho = sigma * (2.0 * 2f64.ln()).sqrt();
    assert!(out.mesh.vertex_count() >= 6, "{:?}", out.stats);
    for p in out.mesh.positions() {
        let r = (*p - centre).length();
        assert!(
            (r - rho).abs() < tolerance * sigma,
            "{steps} steps: radius {r} vs {rho}"
        );
    }
    assert!(is_closed(out.mesh.triangles()));
    // Faces toward lower opacity: the signed volume is positive.
    assert!(out.mesh.signed_volume() > 0.0);
    assert_eq!(out.stats.pieces, 1);
    let colors = out.mesh.colors().expect("colours");
    assert!(
        colors
            .iter()
            .all(|c| (c[0] - 0.2).abs() < 1e-5 && (c[2] - 0.6).abs() < 1e-5)
    );
}

/// GOF's model: a plane of flat Gaussians gives a thin closed slab: away from the rim every vertex lies
/// within 3 thicknesses of the plane, on both sides.
#[test]
fn plane_of_flat_gaussians_gives_a_flat_sheet() {
    let (s, thin) = (0.05f32, 0.002f32);
    let means: Vec<Vec3> = (0..12)
        .flat_map(|i| (0..12).map(move |j| Vec3::new(i as f32 * 0.06, j as f32 * 0.06, 0.0)))
        .collect();
    let g = gaussians(&means, Vec3::new(s, s, thin), 1.0);
    let cams = rig(DVec3::new(0.33, 0.33, 0.0), 0.6, 24);
    let out = opacity_mesh(&g, &cams, &gof()).expect("mesh");
    let mut sides = [0, 0];
    for p in out.mesh.positions() {
        if p.x > 0.1 && p.x < 0.56 && p.y > 0.1 && p.y < 0.56 {
            assert!(p.z.abs() < 3.0 * f64::from(thin), "{p}");
            sides[usize::from(p.z > 0.0)] += 1;
        }
    }
    assert!(sides[0] > 10 && sides[1] > 10, "{sides:?}");
    assert!(is_closed(out.mesh.triangles()));
}

#[test]
fn bad_input_is_named() {
    let cams = rig(DVec3::ZERO, 1.0, 8);
    let opts = OpacityOptions::default();
    let mut g = gaussians(&[Vec3::ZERO, Vec3::X], Vec3::splat(0.1), 1.0);
    for bad in [0.0, -0.1, f32::NAN] {
        g.scales[1] = Vec3::new(0.1, bad, 0.1);
        let e = opacity_mesh(&g, &cams, &opts).expect_err("bad scale");
        assert!(matches!(e, OpacityError::BadScale { index: 1, .. }), "{e}");
    }
    let g = gaussians(&[Vec3::ZERO, Vec3::X], Vec3::splat(0.1), 0.001);
    assert!(matches!(
        opacity_mesh(&g, &cams, &opts),
        Err(OpacityError::AllBelowCut { count: 2, .. })
    ));
    // Coincident corners: scales far below the means' f64 resolution, coplanar means.
    let g = gaussians(
        &[
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(2.0, 1.0, 1.0),
            Vec3::new(1.0, 2.0, 1.0),
        ],
        Vec3::splat(1e-20),
        1.0,
    );
    let e = opacity_mesh(&g, &rig(DVec3::ONE, 2.0, 8), &opts).expect_err("coplanar");
    assert!(matches!(e, OpacityError::Degenerate { .. }), "{e}");
    // Cameras looking away.
    let g = gaussians(&[Vec3::ZERO], Vec3::splat(0.1), 1.0);
    let away = Camera::look_at(
        "a",
        DVec3::new(0.0, 0.0, -2.0),
        DVec3::new(0.0, 0.0, -5.0),
        DVec3::Y,
        (64, 64),
        40.0,
    )
    .expect("camera");
    assert!(matches!(
        opacity_mesh(&g, &[away], &opts),
        Err(OpacityError::NotSeen { points: 9 })
    ));
    assert!(matches!(
        opacity_mesh(&g, &[], &opts),
        Err(OpacityError::NoCameras)
    ));
}

/// Same vertices and triangles, bit for bit, on one thread and on three.
#[test]
fn deterministic_across_thread_counts() {
    let means: Vec<Vec3> = (0..60)
        .map(|i| {
            let a = i as f32 * 0.7;
            Vec3::new(a.sin() * 0.3, a.cos() * 0.3, (i as f32 * 0.37).sin() * 0.3)
        })
        .collect();
    let g = gaussians(&means, Vec3::splat(0.06), 0.9);
    let cams = rig(DVec3::ZERO, 0.6, 16);
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool")
            .install(|| opacity_mesh(&g, &cams, &OpacityOptions::default()).expect("mesh"))
    };
    let (a, b) = (run(1), run(3));
    assert!(a.mesh.triangle_count() > 0);
    assert_eq!(a.mesh.positions(), b.mesh.positions());
    assert_eq!(a.mesh.triangles(), b.mesh.triangles());
    assert_eq!(a.mesh.colors(), b.mesh.colors());
}

/// The field by brute force: every view whose image holds the point, every Gaussian, the
/// definition of docs/conventions.md §6 with no binning, tiles or early stop.
fn brute_field(g: &OpacityGaussians, cams: &[Camera], x: DVec3, rules: AlphaRules) -> f64 {
    let mut best = 1.0f64;
    for cam in cams {
        let o = cam.position();
        let c = cam.world_to_camera_rotation() * (x - o);
        if c.z <= 0.01 {
            continue;
        }
        let (u, v) = (cam.fx * c.x / c.z + cam.cx, cam.fy * c.y / c.z + cam.cy);
        if !(u >= 0.0 && v >= 0.0 && u < f64::from(cam.width) && v < f64::from(cam.height)) {
            continue;
        }
        let mut t_all = 1.0f64;
        for i in 0..g.means.len() {
            let op = f64::from(g.opacities[i]);
            if op < f64::from(DEFAULT_OPACITY_CUT.max(rules.min_alpha)) {
                continue;
            }
            let [w, qx, qy, qz] = g.rotations[i].map(f64::from);
            let r = glam::DMat3::from_quat(glam::DQuat::from_xyzw(qx, qy, qz, w).normalize());
            let s = g.scales[i].as_dvec3();
            let white = |y: DVec3| (r.transpose() * y) / s;
            let a = white(o - g.means[i].as_dvec3());
            let b = white(x - o);
            let peak = -a.dot(b) / b.length_squared();
            if peak > 1.0 && rules.model == RayModel::Peak {
                continue;
            }
            let t = peak.clamp(0.0, 1.0);
            let mut q = (a + b * t).length_squared();
            if peak > 1.0 {
                q += (f64::from(rules.sharpness) - 1.0) * b.length_squared() * (peak - 1.0).powi(2);
            }
            let alpha = (op * (-0.5 * q).exp()).min(f64::from(rules.max_alpha));
            if alpha >= f64::from(rules.min_alpha) {
                t_all *= 1.0 - alpha;
            }
        }
        best = best.min(1.0 - t_all);
    }
    best
}

/// A cloud of anisotropic, rotated Gaussians of mixed opacities.
fn cloud(n: usize) -> OpacityGaussians {
    let h = |i: usize, k: u32| {
        ((i as f64 * 12.9898 + f64::from(k) * 78.233).sin() * 43758.5453)
            .fract()
            .abs()
    };
    OpacityGaussians {
        means: (0..n)
            .map(|i| {
                let (a, b) = (h(i, 0) * std::f64::consts::TAU, h(i, 1) * 2.0 - 1.0);
                let r = 0.25 + 0.03 * h(i, 2);
                let s = (1.0 - b * b).sqrt();
                Vec3::new(
                    (r * s * a.cos()) as f32,
                    (r * b) as f32,
                    (r * s * a.sin()) as f32,
                )
            })
            .collect(),
        scales: (0..n)
            .map(|i| {
                Vec3::new(
                    0.01 + 0.05 * h(i, 3) as f32,
                    0.01 + 0.05 * h(i, 4) as f32,
                    // Every seventh as thin as LAM's thinnest (cancels a silhouette's terms).
                    if i % 7 == 0 {
                        1e-8
                    } else {
                        0.003 + 0.01 * h(i, 5) as f32
                    },
                )
            })
            .collect(),
        rotations: (0..n)
            .map(|i| {
                [
                    h(i, 6) as f32 + 0.1,
                    h(i, 7) as f32 - 0.5,
                    h(i, 8) as f32 - 0.5,
                    h(i, 9) as f32 - 0.5,
                ]
            })
            .collect(),
        opacities: (0..n).map(|i| (0.02 + h(i, 10)).min(1.0) as f32).collect(),
        colors: (0..n)
            .map(|i| [h(i, 11) as f32, h(i, 12) as f32, h(i, 13) as f32])
            .collect(),
    }
}

/// The binned, tiled, early-stopping field equals the brute-force definition (to 1e-9) at
/// points inside, on and outside a shell of anisotropic Gaussians, from views of two sizes.
#[test]
fn field_equals_brute_force() {
    for (model, sharpness) in [
        (RayModel::Peak, 1.0),
        (RayModel::Gof, 1.0),
        (RayModel::Gof, 9.0),
    ] {
        field_equals_brute_force_with(model, sharpness);
    }
}

fn field_equals_brute_force_with(model: RayModel, sharpness: f32) {
    let g = cloud(900);
    let mut cams = rig(DVec3::ZERO, 0.4, 12);
    cams.extend(sphere_rig(DVec3::ZERO, 0.4, 5, (37, 23), 50.0).expect("rig"));
    let mut opts = OpacityOptions::default();
    opts.rules.model = model;
    opts.rules.sharpness = sharpness;
    let points: Vec<DVec3> = (0..600)
        .map(|i| {
            let f = i as f64;
            let dir = DVec3::new((f * 1.3).sin(), (f * 0.7).cos(), (f * 2.1).sin()).normalize();
            dir * (0.15 + 0.2 * ((f * 0.37).sin() * 0.5 + 0.5))
        })
        .collect();
    let fast = opacity_at(&g, &cams, &points, &opts).expect("field");
    let mut spread = [0usize; 3];
    for (i, (x, v)) in points.iter().zip(&fast).enumerate() {
        let want = brute_field(&g, &cams, *x, opts.rules);
        spread[usize::from(want > 0.05) + usize::from(want > 0.5)] += 1;
        assert!(
            (f64::from(*v) - want).abs() < 1e-6,
            "point {i}: {v} vs {want}"
        );
    }
    // The points cover empty space, the shell's rim and its inside.
    assert!(spread.iter().all(|&n| n > 30), "{model:?} {spread:?}");
}

/// Flat opaque Gaussians tangent to a sphere: with the peak model the surface lies on the
/// sphere (where every outside view's transmittance halves), not a fraction of a Gaussian in
/// front of it as with GOF's.
#[test]
fn peak_model_meshes_a_shell_on_its_gaussians() {
    let (radius, n) = (0.25f64, 700);
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut means = Vec::new();
    let mut rotations = Vec::new();
    for i in 0..n {
        let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - y * y).sqrt();
        let dir = DVec3::new(
            r * (golden * i as f64).cos(),
            y,
            r * (golden * i as f64).sin(),
        );
        means.push((dir * radius).as_vec3());
        // Local z along the normal.
        let q = glam::DQuat::from_rotation_arc(DVec3::Z, dir);
        rotations.push([q.w as f32, q.x as f32, q.y as f32, q.z as f32]);
    }
    let mut g = gaussians(&means, Vec3::new(0.02, 0.02, 0.002), 0.95);
    g.rotations = rotations;
    let cams = rig(DVec3::ZERO, 0.35, 24);
    let error = |opts: &OpacityOptions| {
        let out = opacity_mesh(&g, &cams, opts).expect("mesh");
        let mut e: Vec<f64> = out
            .mesh
            .positions()
            .iter()
            .map(|p| p.length() - radius)
            .collect();
        e.sort_by(f64::total_cmp);
        (e[e.len() / 2], out)
    };
    let mut peak_options = OpacityOptions::default();
    peak_options.rules.model = RayModel::Peak;
    let (peak, out) = error(&peak_options);
    let (gof_error, _) = error(&gof());
    assert!(peak.abs() < 0.002, "peak model: median radial error {peak}");
    assert!(
        gof_error > 0.003 && gof_error > 2.0 * peak.abs(),
        "GOF's model lies in front: {gof_error} (peak {peak})"
    );
    assert!(is_closed(out.mesh.triangles()));
    assert_eq!(out.stats.pieces, 1);
}

/// Two separate Gaussians of different sizes and a speck: `Largest` keeps the big sphere,
/// `Major` both spheres but not the speck (under 1% of the area), `All` all three.
#[test]
fn pieces_kept_by_rule() {
    let mut g = gaussians(
        &[
            Vec3::ZERO,
            Vec3::new(0.6, 0.0, 0.0),
            Vec3::new(0.0, 0.6, 0.0),
        ],
        Vec3::splat(0.1),
        1.0,
    );
    g.scales[1] = Vec3::splat(0.05);
    g.scales[2] = Vec3::splat(0.008);
    let cams = rig(DVec3::new(0.2, 0.2, 0.0), 0.8, 24);
    let pieces = |keep| {
        let out = opacity_mesh(&g, &cams, &OpacityOptions { keep, ..gof() }).expect("mesh");
        (out.stats.pieces, out.stats.kept_area_fraction)
    };
    let (n, all) = pieces(KeepPieces::All);
    let (_, major) = pieces(KeepPieces::Major);
    let (_, largest) = pieces(KeepPieces::Largest);
    assert_eq!(n, 3);
    assert!((all - 1.0).abs() < 1e-12);
    // Areas go as σ²: 1 : 0.25 : 0.0064 of the big one.
    assert!((largest - 1.0 / 1.2564).abs() < 0.02, "{largest}");
    assert!((major - 1.25 / 1.2564).abs() < 0.02, "{major}");
}

/// Held views walked from hints give the mesh of views streamed one at a time in order: the
/// same signs, vertices and triangles bit for bit, and the same colours (no two views tie).
#[test]
fn held_views_mesh_equals_streamed() {
    let g = cloud(700);
    let cams = rig(DVec3::ZERO, 0.4, 12);
    let opts = OpacityOptions::default();
    let held = opacity_mesh_within(&g, &cams, &opts, views::HELD_BYTES, None).expect("held");
    let streamed = opacity_mesh_within(&g, &cams, &opts, 0, None).expect("streamed");
    assert!(held.mesh.triangle_count() > 100);
    assert_eq!(held.mesh.positions(), streamed.mesh.positions());
    assert_eq!(held.mesh.triangles(), streamed.mesh.triangles());
    assert_eq!(held.mesh.colors(), streamed.mesh.colors());
}

/// The tiles' certificates (a depth beyond which a view's opacity is surely at or above the
/// level) decide many points without a walk and never a wrong side: the signs of the
/// certified evaluation equal the exact field's, for GOF's ramp and a sharper one.
#[test]
fn certified_signs_equal_exact_field() {
    let g = cloud(900);
    let cams = rig(DVec3::ZERO, 0.4, 12);
    let points: Vec<DVec3> = (0..3000)
        .map(|i| {
            let f = f64::from(i);
            let dir = DVec3::new((f * 1.3).sin(), (f * 0.7).cos(), (f * 2.1).sin()).normalize();
            dir * (0.1 + 0.25 * ((f * 0.37).sin() * 0.5 + 0.5))
        })
        .collect();
    for sharpness in [1.0, 4.0] {
        let rules = AlphaRules {
            sharpness,
            ..AlphaRules::default()
        };
        let level = 0.5;
        let p = gaussians::Prepared::new(&g, DEFAULT_OPACITY_CUT, rules.min_alpha).expect("set");
        let order = z_order(&points);
        let mut exact_views = Views::new(&p, &cams, views::HELD_BYTES, None);
        let exact = evaluate(
            &p,
            &mut exact_views,
            &points,
            &order,
            None,
            Mode::Exact,
            rules,
        );
        let at = CertifyAt {
            level,
            max_alpha: rules.max_alpha,
            min_alpha: rules.min_alpha,
        };
        let mut certified = Views::new(&p, &cams, views::HELD_BYTES, Some(at));
        let held = certified.held().expect("held");
        let decided: usize = points
            .iter()
            .map(|x| {
                held.iter()
                    .filter(|v| v.locate(*x).is_some_and(|h| v.is_certain(h)))
                    .count()
            })
            .sum();
        let sign = evaluate(
            &p,
            &mut certified,
            &points,
            &order,
            None,
            Mode::Sign { level },
            rules,
        );
        let inside = exact.value.iter().filter(|&&v| v >= level).count();
        assert!(inside > 200 && inside < 2800, "{inside}");
        assert!(decided > 2000, "certified point-views: {decided}");
        for (i, (a, b)) in exact.value.iter().zip(&sign.value).enumerate() {
            assert_eq!(*a >= level, *b >= level, "point {i}: exact {a}, signed {b}");
        }
    }
}

/// Over frames of a smoothly moving cloud, carrying the tetrahedralisation gives the mesh of
/// a from-scratch run at every frame, bit for bit, and is carried (repaired) on most frames.
#[test]
fn tracked_mesh_equals_from_scratch() {
    let rest = cloud(500);
    let cams = rig(DVec3::ZERO, 0.4, 8);
    let opts = OpacityOptions {
        bisection_steps: 3,
        carry: true,
        ..OpacityOptions::default()
    };
    let mut track = OpacityTrack::default();
    let mut carried = 0;
    for frame in 0..6 {
        let t = 0.001 * f64::from(frame);
        let mut g = rest.clone();
        for m in &mut g.means {
            let (c, s) = ((t * 2.0).cos() as f32, (t * 2.0).sin() as f32);
            let bend = (t * f64::from(m.y) * 8.0) as f32;
            *m = Vec3::new(c * m.x - s * m.z, m.y + bend * m.x, s * m.x + c * m.z);
        }
        let tracked = opacity_mesh_tracked(&g, &cams, &opts, &mut track).expect("tracked");
        let fresh = opacity_mesh(&g, &cams, &opts).expect("fresh");
        assert_eq!(
            tracked.stats.tetrahedra, fresh.stats.tetrahedra,
            "frame {frame}"
        );
        assert_eq!(
            tracked.mesh.positions(),
            fresh.mesh.positions(),
            "frame {frame}"
        );
        assert_eq!(
            tracked.mesh.triangles(),
            fresh.mesh.triangles(),
            "frame {frame}"
        );
        assert_eq!(tracked.mesh.colors(), fresh.mesh.colors(), "frame {frame}");
        assert!(!fresh.stats.carried);
        if tracked.stats.carried {
            carried += 1;
            assert!(tracked.stats.replaced > 0, "frame {frame}: nothing moved?");
        }
    }
    assert!(carried >= 4, "carried on {carried} of 5 frames");
}
