//! Binding: attaching world-space Gaussians to Spot and baking them back (both conventions),
//! through a GaussianAvatars-style PLY file, and initial bound Gaussians.

use std::path::Path;

use trisplat_geometry::rng::Rng;
use trisplat_splat::Convention;
use trisplat_splat::glam::{DMat3, Vec3};
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians_from_bytes, write_gaussians_to};
use trisplat_splat::{AttachLimits, BindError, BindOptions, attach, attach_checked, init_bound};
use trisplat_splat::{DeformMode, Deformer};
use trisplat_splat::{GaussianParts, GaussianSet, ParameterSpace};

/// Attach + bake round trip, relative to the template's bounding-box diagonal (means) or the
/// covariance's own size: float32 storage of the local parameters in between.
const ROUND_TRIP_TOL: f64 = 1e-5;

fn frob(m: DMat3) -> f64 {
    m.to_cols_array().iter().map(|v| v * v).sum::<f64>().sqrt()
}

fn world_set(mesh: &trisplat_geometry::TriMesh, n: usize) -> GaussianSet {
    let mut rng = Rng::new(8);
    let mut u = || rng.uniform_f32() - 0.5;
    let p = mesh.positions_f32();
    let means = (0..n)
        .map(|i| p[(i * 7) % p.len()] + Vec3::new(u(), u(), u()) * 0.02)
        .collect();
    GaussianSet::try_new(GaussianParts {
        means,
        log_scales: (0..n)
            .map(|_| Vec3::new(u(), u(), u()) * 4.0 - 4.0)
            .collect(),
        rotations: (0..n).map(|_| [u() + 1.0, u(), u(), u()]).collect(),
        opacity_logits: vec![0.5; n],
        sh: vec![0.25; 3 * n],
        ..GaussianParts::default()
    })
    .unwrap()
}

#[test]
fn attach_then_bake_at_rest_gives_the_world_set_back() {
    let mesh = trisplat_fixtures::spot().unwrap();
    let diag = mesh.bounds().unwrap().diagonal();
    let world = world_set(&mesh, 3000);
    for (convention, mode) in [
        (Convention::GaussianAvatars, DeformMode::Binding),
        (Convention::SurfHead, DeformMode::Jacobian),
    ] {
        let bound = attach(&world, &mesh, convention).unwrap();
        assert_eq!(bound.space(), ParameterSpace::Local);
        assert!(bound.report(Some(mesh.triangle_count())).is_valid());
        // Through a GaussianAvatars-style file (binding_0), bit-exact.
        let mut bytes = Vec::new();
        write_gaussians_to(&mut bytes, &bound, &PlyWriteOptions::default()).unwrap();
        let text = String::from_utf8_lossy(&bytes[..600]).to_string();
        assert!(text.contains("property float binding_0"));
        let read = read_gaussians_from_bytes(&bytes, Path::new("bound.ply")).unwrap();
        let mut same = read.clone().into_parts();
        same.property_order = None;
        assert!(
            same == bound.clone().into_parts(),
            "the file changed the bound set"
        );
        let baked = Deformer::new(&mesh, mode)
            .deform(&read, mesh.positions())
            .unwrap();
        let (mut worst_mu, mut worst_cov) = (0.0f64, 0.0f64);
        for i in 0..world.len() {
            let d = (baked.means()[i].as_dvec3() - world.means()[i].as_dvec3()).length();
            worst_mu = worst_mu.max(d / diag);
            let (a, b) = (baked.covariance(i), world.covariance(i));
            worst_cov = worst_cov.max(frob(a - b) / frob(b));
        }
        println!("{convention:?}: means {worst_mu:.2e}, covariances {worst_cov:.2e}");
        assert!(worst_mu < ROUND_TRIP_TOL, "{worst_mu}");
        assert!(worst_cov < ROUND_TRIP_TOL, "{worst_cov}");
        assert_eq!(baked.opacity_logits(), world.opacity_logits());
        assert_eq!(baked.sh(), world.sh());
    }
}

#[test]
fn initial_gaussians_sit_on_their_triangles() {
    let mesh = trisplat_fixtures::spot().unwrap();
    for per in [1usize, 3] {
        let opts = BindOptions {
            per_triangle: per,
            ..BindOptions::default()
        };
        let set = init_bound(&mesh, &opts).unwrap();
        assert_eq!(set.len(), per * mesh.triangle_count());
        assert!((set.opacity(0) - 0.1).abs() < 1e-6);
        let baked = Deformer::new(&mesh, DeformMode::Binding)
            .deform(&set, mesh.positions())
            .unwrap();
        for (i, m) in baked.means().iter().enumerate() {
            let t = mesh.triangles()[i / per];
            let [a, b, c] = t.map(|j| mesh.positions()[j as usize]);
            let p = m.as_dvec3();
            // On the plane, inside the triangle (barycentric coordinates in [0, 1]).
            let n = (b - a).cross(c - a);
            assert!(((p - a).dot(n) / n.length()).abs() < 1e-6);
            let area = n.length();
            let w = [
                (b - p).cross(c - p),
                (c - p).cross(a - p),
                (a - p).cross(b - p),
            ]
            .map(|x| x.dot(n) / (area * area));
            assert!(w.iter().all(|&x| x > -1e-5), "{w:?}");
            if per == 1 {
                assert!((p - (a + b + c) / 3.0).length() < 1e-6);
            }
        }
    }
}

/// `attach_checked` passes Gaussians placed on the template and refuses the usual mistakes,
/// each with the number that broke its limit: another unit (9.9x), another frame (moved off
/// the template), all on one spot.
#[test]
fn implausible_attachments_are_refused_with_their_numbers() {
    let mesh = trisplat_fixtures::spot().unwrap();
    let limits = AttachLimits::default();
    let world = world_set(&mesh, 3000);
    let (_, stats) = attach_checked(&world, &mesh, Convention::GaussianAvatars, &limits)
        .expect("placed on the template");
    assert!((0.8..1.25).contains(&stats.size_ratio), "{stats:?}");
    assert!(stats.median_distance_edges < 1.0, "{stats:?}");
    assert!(stats.triangle_share.0 < 0.01, "{stats:?}");
    let with_means = |f: &dyn Fn(usize, Vec3) -> Vec3| {
        let mut parts = world.clone().into_parts();
        for (i, m) in parts.means.iter_mut().enumerate() {
            *m = f(i, *m);
        }
        GaussianSet::try_new(parts).unwrap()
    };
    let centre = mesh.bounds().unwrap().center().as_vec3();
    let diag = mesh.bounds().unwrap().diagonal() as f32;
    let refused = |set: &GaussianSet| match attach_checked(
        set,
        &mesh,
        Convention::GaussianAvatars,
        &limits,
    ) {
        Err(BindError::Implausible(message)) => message,
        other => panic!("{:?}", other.map(|(_, s)| s)),
    };
    let scaled = refused(&with_means(&|_, m| centre + (m - centre) * 9.9));
    assert!(
        scaled.contains("span 9.") && scaled.contains("limit 3x"),
        "{scaled}"
    );
    let moved = refused(&with_means(&|_, m| m + Vec3::X * 2.0 * diag));
    assert!(
        moved.contains("mean template edges") && moved.contains("limit 25"),
        "{moved}"
    );
    let triangle = mesh.corners(100);
    let spot = ((triangle[0] + triangle[1] + triangle[2]) / 3.0).as_vec3();
    let piled = refused(&with_means(&|i, m| if i % 2 == 0 { spot } else { m }));
    assert!(piled.contains("bind to triangle 100 alone"), "{piled}");
    // The unchecked primitive binds them all the same.
    assert!(
        attach(
            &with_means(&|_, m| m * 9.9),
            &mesh,
            Convention::GaussianAvatars
        )
        .is_ok()
    );
}
