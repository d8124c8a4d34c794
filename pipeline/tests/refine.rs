//! `pipeline::refine` (issue 14 item 1): the re-initialisation keeps the binding invariants,
//! the new Gaussians carry their nearest old Gaussian's attributes and triangle, the reported
//! Chamfer distance is the one measured independently, runs are seeded, and bad inputs are
//! errors naming the round and stage.

use trisplat_geometry::TriMesh;
use trisplat_geometry::spatial::{PointIndex, TriangleBvh};
use trisplat_pipeline::refine::{PruneCriteria, Rebind, RefineError, RefineOptions, refine};
use trisplat_splat::GaussianSet;
use trisplat_splat::TriangleCounts;
use trisplat_splat::{BindOptions, init_bound};
use trisplat_splat::{DeformMode, Deformer};

fn spot() -> TriMesh {
    trisplat_fixtures::spot().expect("spot fixture")
}

/// Three Gaussians per triangle, each with its own colour (its index in the DC coefficients)
/// and opacity, so that every output Gaussian names its source.
fn bound(mesh: &TriMesh) -> GaussianSet {
    let set = init_bound(
        mesh,
        &BindOptions {
            per_triangle: 3,
            ..BindOptions::default()
        },
    )
    .unwrap();
    let mut parts = set.into_parts();
    for (i, o) in parts.opacity_logits.iter_mut().enumerate() {
        *o = (i % 17) as f32 * 0.1 - 0.8;
    }
    for (i, dc) in parts.sh.chunks_mut(3).enumerate() {
        dc[0] = i as f32;
        dc[1] = -(i as f32);
        dc[2] = 0.5;
    }
    GaussianSet::try_new(parts).unwrap()
}

fn bake(set: &GaussianSet, mesh: &TriMesh) -> GaussianSet {
    Deformer::new(mesh, DeformMode::Binding)
        .deform(set, mesh.positions())
        .unwrap()
}

fn source_of(set: &GaussianSet, i: usize) -> usize {
    set.sh_coeffs(i)[0] as usize
}

#[test]
fn a_round_keeps_every_triangle_and_inherits_from_the_nearest_old_gaussian() {
    let mesh = spot();
    let input = bound(&mesh);
    let before_counts = TriangleCounts::from_set(&input, mesh.triangle_count()).unwrap();
    let mut seen = Vec::new();
    let mut areas = Vec::new();
    let out = refine(&input, &mesh, &RefineOptions::default(), |r, surfaces| {
        seen.push(r.clone());
        areas.push((surfaces.alpha.area(), surfaces.smoothed.area()));
        assert_eq!(surfaces.alpha.triangle_count(), r.alpha_triangles);
        assert_eq!(surfaces.smoothed.triangle_count(), r.alpha_triangles);
    })
    .unwrap();
    assert_eq!(seen.len(), 1);
    let r = &out.rounds[0];
    assert_eq!(&seen[0], r);
    // Laplacian smoothing shrinks the surface.
    assert!(areas[0].1 < areas[0].0 && areas[0].1 > 0.0, "{areas:?}");
    assert_eq!(r.before, input.len());
    assert_eq!(r.after, out.set.len());
    assert_eq!(r.after, r.samples + r.refilled - r.pruned);
    assert!(r.samples > 0 && r.alpha_triangles > 0);
    println!("{r:?}");

    // Binding: valid against the template; no triangle that had Gaussians is left empty.
    assert!(out.set.report(Some(mesh.triangle_count())).is_valid());
    let after_counts = TriangleCounts::from_set(&out.set, mesh.triangle_count()).unwrap();
    for (t, (&b, &a)) in before_counts
        .counts()
        .iter()
        .zip(after_counts.counts())
        .enumerate()
    {
        assert!(b == 0 || a > 0, "triangle {t} emptied");
    }
    assert_eq!(
        r.covered_triangles,
        after_counts.counts().iter().filter(|&&c| c > 0).count()
    );

    // Inheritance, in world space: each output Gaussian carries the colour, opacity, world
    // scales and triangle of its source, which is the old Gaussian nearest to its centre
    // (new ones) or itself (refilled ones).
    let old = bake(&input, &mesh);
    let new = bake(&out.set, &mesh);
    let index = PointIndex::new(old.means()).unwrap();
    let old_tris = &input.binding().unwrap().triangles;
    let new_tris = &out.set.binding().unwrap().triangles;
    let mut refilled = 0;
    for (j, new_tri) in new_tris.iter().enumerate() {
        let s = source_of(&out.set, j);
        assert_eq!(out.set.sh_coeffs(j)[1], -(s as f32));
        assert_eq!(out.set.opacity_logits()[j], input.opacity_logits()[s]);
        assert_eq!(
            *new_tri, old_tris[s],
            "Gaussian {j}: triangle not inherited"
        );
        let (ws, os) = (new.scale(j), old.scale(s));
        assert!(
            (ws - os).length() <= 1e-4 * os.length(),
            "{j}: {ws} vs {os}"
        );
        let c = new.means()[j];
        if (c - old.means()[s]).length() < 1e-6 {
            refilled += 1;
            continue;
        }
        let nearest = index.nearest(c).unwrap();
        let d_source = (c - old.means()[s]).length();
        assert!(
            nearest.index as usize == s || d_source <= nearest.distance as f32 * (1.0 + 1e-4),
            "Gaussian {j}: source {s} at {d_source}, nearest {} at {}",
            nearest.index,
            nearest.distance
        );
    }
    assert!(refilled >= r.refilled - r.pruned.min(r.refilled));

    // The reported Chamfer after the round, measured again: centres to the exact surface.
    let bvh = TriangleBvh::new(&mesh).unwrap();
    let d = bvh.closest_points(new.means()).unwrap();
    let accuracy = d.iter().map(|c| c.distance).sum::<f64>() / d.len() as f64;
    assert!(
        (accuracy - r.chamfer_after.accuracy).abs() <= 1e-5 * accuracy.max(1e-9),
        "{accuracy} vs {}",
        r.chamfer_after.accuracy
    );
    assert!(r.chamfer_after.chamfer_l1.is_finite() && r.chamfer_before.chamfer_l1 >= 0.0);
    for ms in [
        r.ms.bake,
        r.ms.alpha,
        r.ms.smooth,
        r.ms.sample,
        r.ms.chamfer,
    ] {
        assert!(ms.is_finite() && ms >= 0.0);
    }
}

#[test]
fn runs_are_seeded_and_do_not_depend_on_the_thread_count() {
    let mesh = spot();
    let input = bound(&mesh);
    let options = RefineOptions {
        rounds: 2,
        ..RefineOptions::default()
    };
    let a = refine(&input, &mesh, &options, |_, _| {}).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let b = pool.install(|| refine(&input, &mesh, &options, |_, _| {}).unwrap());
    assert_eq!(a.set, b.set);
    assert_eq!(a.rounds.len(), 2);
    assert_eq!(a.rounds[1].chamfer_before, a.rounds[0].chamfer_after);
    let other = RefineOptions {
        sample: trisplat_geometry::sampling::SampleOptions {
            seed: 7,
            ..Default::default()
        },
        ..options
    };
    let c = refine(&input, &mesh, &other, |_, _| {}).unwrap();
    assert_ne!(a.set, c.set);
}

#[test]
fn nearest_rebinding_and_explicit_counts() {
    let mesh = spot();
    let input = bound(&mesh);
    let options = RefineOptions {
        rebind: Rebind::Nearest,
        samples: Some(5000),
        prune: PruneCriteria::none(),
        ..RefineOptions::default()
    };
    let out = refine(&input, &mesh, &options, |_, _| {}).unwrap();
    let r = &out.rounds[0];
    assert_eq!(r.samples, 5000);
    assert_eq!(out.set.len(), 5000 + r.refilled);
    assert_eq!((r.flagged, r.pruned), (0, 0));
    // The first 5000 are new: each on the triangle nearest its centre.
    let world = bake(&out.set, &mesh);
    let bvh = TriangleBvh::new(&mesh).unwrap();
    let nearest = bvh.closest_points(&world.means()[..5000]).unwrap();
    let tris = &out.set.binding().unwrap().triangles;
    let mismatched = nearest
        .iter()
        .zip(tris)
        .filter(|(c, t)| c.triangle != t.0)
        .count();
    // Centres on a shared edge may round to the neighbour triangle.
    assert!(
        mismatched <= 5,
        "{mismatched} of 5000 not on their nearest triangle"
    );
}

#[test]
fn bad_inputs_are_errors_naming_what_failed() {
    let mesh = spot();
    let input = bound(&mesh);
    let err = |options: RefineOptions| refine(&input, &mesh, &options, |_, _| {}).unwrap_err();
    assert!(matches!(
        err(RefineOptions {
            alpha: Some(1e-9),
            ..RefineOptions::default()
        }),
        RefineError::Stage {
            round: 1,
            stage: "alpha",
            ..
        }
    ));
    for options in [
        RefineOptions {
            alpha: Some(f64::NAN),
            ..RefineOptions::default()
        },
        RefineOptions {
            alpha_spacings: -1.0,
            ..RefineOptions::default()
        },
        RefineOptions {
            samples: Some(0),
            ..RefineOptions::default()
        },
        RefineOptions {
            prune: PruneCriteria {
                k: 0,
                ..PruneCriteria::seed()
            },
            ..RefineOptions::default()
        },
        RefineOptions {
            prune: PruneCriteria {
                outlier: Some(f64::INFINITY),
                ..PruneCriteria::seed()
            },
            ..RefineOptions::default()
        },
    ] {
        let e = err(options);
        assert!(matches!(e, RefineError::BadOption { .. }), "{e}");
    }
    // Unbound, empty, and bound past the template.
    let world = bake(&input, &mesh);
    assert!(matches!(
        refine(&world, &mesh, &RefineOptions::default(), |_, _| {}),
        Err(RefineError::Input(_))
    ));
    assert!(matches!(
        refine(
            &input.select(&[]),
            &mesh,
            &RefineOptions::default(),
            |_, _| {}
        ),
        Err(RefineError::Input(_))
    ));
    let small = TriMesh::try_new(mesh.positions_f32(), mesh.triangles()[..10].to_vec()).unwrap();
    let e = refine(&input, &small, &RefineOptions::default(), |_, _| {}).unwrap_err();
    assert!(e.to_string().contains("triangle"), "{e}");
}
