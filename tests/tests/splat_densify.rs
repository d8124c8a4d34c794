//! Densify/prune with binding inheritance: invariants under random operation sequences
//! (property test), and the renderer-free selection criteria.

use proptest::prelude::*;
use trisplat_geometry::TriId;
use trisplat_splat::glam::Vec3;
use trisplat_splat::{Binding, BindingEncoding, GaussianParts, GaussianSet, ParameterSpace};
use trisplat_splat::{
    DensifyError, SplitOptions, TriangleCounts, clone_selected, normal_inconsistency_mask,
    outlier_mask, prune, split_selected, w2_gate, w2_to_nearest,
};

/// One Gaussian per triangle (GaussianAvatars' initial binding) plus `extra` more on triangle
/// `extra_tri`.
fn initial(triangles: usize, extra: usize, seed: u64) -> GaussianSet {
    let n = triangles + extra;
    let mut rng = trisplat_geometry::rng::Rng::new(seed);
    let mut u = || rng.uniform_f32() - 0.5;
    GaussianSet::try_new(GaussianParts {
        means: (0..n).map(|_| Vec3::new(u(), u(), u())).collect(),
        log_scales: (0..n).map(|_| Vec3::new(u(), u(), u())).collect(),
        rotations: (0..n).map(|_| [u() + 1.0, u(), u(), u()]).collect(),
        opacity_logits: (0..n).map(|i| i as f32).collect(),
        sh: (0..3 * n).map(|i| i as f32).collect(),
        binding: Some(Binding {
            triangles: (0..n).map(|i| TriId((i % triangles) as u32)).collect(),
            encoding: BindingEncoding::Float,
        }),
        space: ParameterSpace::Local,
        ..GaussianParts::default()
    })
    .unwrap()
}

#[derive(Clone, Debug)]
enum Op {
    Clone(Vec<bool>),
    Split(Vec<bool>, usize),
    Prune(Vec<bool>),
}

fn op() -> impl Strategy<Value = Op> {
    // Masks longer than any set; cut to length when applied.
    let mask = proptest::collection::vec(any::<bool>(), 200);
    prop_oneof![
        mask.clone().prop_map(Op::Clone),
        (mask.clone(), 1usize..4).prop_map(|(m, c)| Op::Split(m, c)),
        mask.clone().prop_map(Op::Prune),
        // Aggressive prunes: flag nearly everything.
        mask.prop_map(|m| Op::Prune(m.iter().map(|_| true).collect())),
    ]
}

fn recount(set: &GaussianSet, triangles: usize) -> Vec<u32> {
    let mut c = vec![0; triangles];
    for t in &set.binding().unwrap().triangles {
        c[t.index()] += 1;
    }
    c
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn densify_prune_invariants(triangles in 1usize..12, extra in 0usize..10,
                                ops in proptest::collection::vec(op(), 1..12), seed in 0u64..1000) {
        let mut set = initial(triangles, extra, seed);
        let mut counts = TriangleCounts::from_set(&set, triangles).unwrap();
        for (step, op) in ops.into_iter().enumerate() {
            let before = set.clone();
            let n = before.len();
            let parent_tri = |j: usize| before.binding().unwrap().triangles[j];
            let out = match &op {
                Op::Clone(m) => clone_selected(&before, &m[..n.min(m.len())], Some(&mut counts)),
                Op::Split(m, c) => split_selected(
                    &before,
                    &m[..n.min(m.len())],
                    &SplitOptions { children: *c, seed: step as u64, ..SplitOptions::default() },
                    Some(&mut counts),
                ),
                Op::Prune(m) => {
                    let mask = &m[..n.min(m.len())];
                    prune(&before, mask, Some(&mut counts)).map(|p| {
                        // Only flagged Gaussians go; a flagged one stays only when its whole
                        // triangle was flagged.
                        let kept: std::collections::HashSet<usize> = p.result.sources.iter().copied().collect();
                        for i in 0..n {
                            if !mask[i] {
                                assert!(kept.contains(&i));
                            } else if kept.contains(&i) {
                                let t = parent_tri(i);
                                assert!((0..n).filter(|&j| parent_tri(j) == t).all(|j| mask[j]));
                            }
                        }
                        p.result
                    })
                }
            };
            let out = match out {
                Ok(o) => o,
                Err(DensifyError::MaskLength { .. }) if n > 200 => break,
                Err(e) => panic!("{e}"),
            };
            set = out.set;
            // Counts kept incrementally equal a recount; no triangle is ever emptied.
            let expected = recount(&set, triangles);
            prop_assert_eq!(counts.counts(), expected.as_slice());
            prop_assert!(counts.counts().iter().all(|&c| c >= 1), "{:?}", counts.counts());
            // Every Gaussian inherits its source's triangle (and colour, opacity).
            prop_assert_eq!(out.sources.len(), set.len());
            for (j, &src) in out.sources.iter().enumerate() {
                prop_assert_eq!(set.binding().unwrap().triangles[j], parent_tri(src));
                prop_assert_eq!(set.opacity_logits()[j], before.opacity_logits()[src]);
                prop_assert_eq!(set.sh_coeffs(j), before.sh_coeffs(src));
            }
            prop_assert!(set.report(Some(triangles)).is_valid());
            if let Op::Split(m, c) = &op {
                let split = m[..n.min(m.len())].iter().filter(|&&b| b).count();
                prop_assert_eq!(set.len(), n + split * (c - 1));
                let shrink = (0.8 * *c as f64).ln() as f32;
                for (j, &src) in out.sources.iter().enumerate() {
                    if m[src] {
                        let want = before.log_scales()[src] - Vec3::splat(shrink);
                        prop_assert!((set.log_scales()[j] - want).abs().max_element() < 1e-6);
                    } else {
                        prop_assert_eq!(set.means()[j], before.means()[src]);
                    }
                }
            }
        }
    }
}

#[test]
fn split_children_are_seeded_and_spread_by_the_parent_covariance() {
    let set = initial(1, 0, 3);
    let mask = vec![true];
    let opts = SplitOptions {
        children: 20_000,
        seed: 9,
        ..SplitOptions::default()
    };
    let a = split_selected(&set, &mask, &opts, None).unwrap();
    let b = split_selected(&set, &mask, &opts, None).unwrap();
    assert_eq!(a, b);
    // The children's sample covariance approaches the parent's (3 sigma of a 20k sample).
    let mean = set.means()[0].as_dvec3();
    let mut cov = trisplat_splat::glam::DMat3::ZERO;
    for m in a.set.means() {
        let d = m.as_dvec3() - mean;
        cov += trisplat_splat::glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    cov *= 1.0 / 20_000.0;
    let want = set.covariance(0);
    let scale = want
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    for (g, w) in cov.to_cols_array().iter().zip(want.to_cols_array()) {
        assert!((g - w).abs() < 0.05 * scale, "{cov} vs {want}");
    }
}

#[test]
fn errors_for_bad_masks_and_counts() {
    let set = initial(3, 0, 1);
    assert!(matches!(
        clone_selected(&set, &[true], None),
        Err(DensifyError::MaskLength {
            len: 1,
            expected: 3
        })
    ));
    assert!(matches!(
        TriangleCounts::from_set(&set, 2),
        Err(DensifyError::BindingOutOfRange { index: 2, .. })
    ));
    let opts = SplitOptions {
        children: 0,
        ..SplitOptions::default()
    };
    assert_eq!(
        split_selected(&set, &[false; 3], &opts, None).unwrap_err(),
        DensifyError::NoChildren
    );
}

fn world(means: Vec<Vec3>, log_scales: Vec<Vec3>, rotations: Vec<[f32; 4]>) -> GaussianSet {
    let n = means.len();
    GaussianSet::try_new(GaussianParts {
        means,
        log_scales,
        rotations,
        opacity_logits: vec![0.0; n],
        sh: vec![0.0; 3 * n],
        ..GaussianParts::default()
    })
    .unwrap()
}

#[test]
fn outliers_normals_and_the_w2_gate() {
    // A 10 x 10 grid of flat Gaussians in z = 0 (normal z), one far away, one tilted.
    let mut means = Vec::new();
    for y in 0..10 {
        for x in 0..10 {
            means.push(Vec3::new(x as f32, y as f32, 0.0) * 0.1);
        }
    }
    means.push(Vec3::new(5.0, 5.0, 5.0));
    let n = means.len();
    let log_scales = vec![Vec3::new(-3.0, -3.0, -8.0); n];
    let mut rotations = vec![[1.0, 0.0, 0.0, 0.0]; n];
    // Gaussian 55 tilted 90 degrees about x: its normal becomes y.
    rotations[55] = [
        std::f32::consts::FRAC_1_SQRT_2,
        std::f32::consts::FRAC_1_SQRT_2,
        0.0,
        0.0,
    ];
    let set = world(means, log_scales, rotations);
    let outliers = outlier_mask(&set, 5, 1.0).unwrap();
    assert_eq!(outliers.iter().filter(|&&b| b).count(), 1);
    assert!(outliers[100]);
    let bad_normals = normal_inconsistency_mask(&set, 5, 0.5).unwrap();
    assert!(bad_normals[55]);
    assert_eq!(bad_normals.iter().take(100).filter(|&&b| b).count(), 1);
    // W2 to the nearest: grid neighbours are 0.1 apart with equal shapes, so W2 = 0.1, except
    // the tilted one's neighbours (shape differs) and the far one.
    let w2 = w2_to_nearest(&set).unwrap();
    assert!((w2[0] - 0.1).abs() < 1e-6, "{}", w2[0]);
    assert!(w2[55] > 0.1 && w2[100] > 5.0);
    let gate = w2_gate(&w2, &vec![1.0; n], 0.11).unwrap();
    assert!(!gate[0] && gate[55] && gate[100]);
}
