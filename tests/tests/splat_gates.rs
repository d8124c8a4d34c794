//! The seed's (GSDHuman's) gate beside the stable form (issue 14 item 2): the squared
//! 2-Wasserstein distance to a split's children against its closed form, and the two forms
//! agreeing wherever both are defined (docs/conventions.md §4).

use trisplat_geometry::rng::Rng;
use trisplat_splat::glam::{DVec3, Vec3};
use trisplat_splat::{
    DensifyError, SEED_NORMAL, SEED_OUTLIER, SEED_W2_SQ, SplitOptions, normal_deviation_mask,
    normal_inconsistency_mask, outlier_mask, seed_w2_gate, split_selected, w2_gate,
    w2_sq_to_children, w2_sq_to_nearest,
};
use trisplat_splat::{GaussianParts, GaussianSet};

/// `n` world-space Gaussians with random centres in a unit cube, rotations and log-scales in
/// `[-4, -2]` (scales 0.02..0.14: W² around the seed's 0.012).
fn random_set(n: usize, seed: u64) -> GaussianSet {
    let mut rng = Rng::new(seed);
    let mut u = || rng.uniform_f32();
    let mut means = Vec::new();
    let mut log_scales = Vec::new();
    let mut rotations = Vec::new();
    for _ in 0..n {
        means.push(Vec3::new(u(), u(), u()));
        log_scales.push(Vec3::new(
            -4.0 + 2.0 * u(),
            -4.0 + 2.0 * u(),
            -4.0 + 2.0 * u(),
        ));
        rotations.push([u() + 0.5, u() - 0.5, u() - 0.5, u() - 0.5]);
    }
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

/// A threshold at the `q`-quantile of `values`, halfway to the next value (no value on it).
fn quantile_threshold(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * q) as usize;
    0.5 * (v[i] + v[i + 1])
}

/// Children of a split keep the parent's rotation and take scales `c s`, `c = 1 / (shrink N)`:
/// same axes, so `W² = |Δμ|² + (1 - c)² |s|²` exactly, per child; the gate's value is the mean.
#[test]
fn children_w2_matches_the_closed_form() {
    let parents = random_set(300, 1);
    let options = SplitOptions {
        children: 3,
        shrink: 0.8,
        seed: 5,
    };
    let split = split_selected(&parents, &vec![true; 300], &options, None).unwrap();
    let got = w2_sq_to_children(&parents, &split.set, &split.sources).unwrap();
    let c = 1.0 / (options.shrink * options.children as f64);
    let mut worst = 0.0f64;
    for (p, &g) in got.iter().enumerate() {
        let s = parents.scale(p).as_dvec3();
        let mu = parents.means()[p].as_dvec3();
        // The children's stored (f32) scales: c s up to rounding.
        let (mut sum, mut count) = (0.0, 0);
        for (j, _) in split.sources.iter().enumerate().filter(|(_, q)| **q == p) {
            let d = split.set.means()[j].as_dvec3() - mu;
            let sc = split.set.scale(j).as_dvec3();
            sum += d.length_squared() + (s - sc).length_squared();
            count += 1;
        }
        assert_eq!(count, 3);
        let want = sum / 3.0;
        // And the scales are c s.
        assert!(((split.set.scale(3 * p).as_dvec3() - s * c).length()) < 1e-6 * s.length());
        worst = worst.max((g - want).abs() / want);
    }
    assert!(worst < 1e-6, "worst relative error {worst:.2e}");
}

/// The mean over many children approaches `E W² = (1 + (1 - c)²) |s|²`.
#[test]
fn children_w2_expectation() {
    let parent = random_set(1, 7);
    let options = SplitOptions {
        children: 40_000,
        shrink: 0.8,
        seed: 11,
    };
    let split = split_selected(&parent, &[true], &options, None).unwrap();
    let got = w2_sq_to_children(&parent, &split.set, &split.sources).unwrap()[0];
    let c = 1.0 / (0.8 * 40_000.0);
    let want = (1.0 + (1.0 - c) * (1.0 - c)) * parent.scale(0).as_dvec3().length_squared();
    assert!((got - want).abs() < 0.02 * want, "{got} vs {want}");
}

/// Seed `W² > ε` and stable `√W² > W k` select the same Gaussians for `W = √ε / k` (every `k`
/// equal; `k = 1` is an unbound set), on both pairings, at thresholds that split the set.
#[test]
fn seed_and_stable_w2_gates_agree() {
    let set = random_set(400, 3);
    let split = split_selected(
        &set,
        &vec![true; 400],
        &SplitOptions {
            seed: 2,
            ..SplitOptions::default()
        },
        None,
    )
    .unwrap();
    let pairings = [
        ("nearest", w2_sq_to_nearest(&set).unwrap()),
        (
            "children",
            w2_sq_to_children(&set, &split.set, &split.sources).unwrap(),
        ),
    ];
    for (name, w2_sq) in &pairings {
        assert!(w2_sq.iter().all(|d| *d >= 0.0), "{name}: negative W²");
        let root: Vec<f64> = w2_sq.iter().map(|d| d.sqrt()).collect();
        let mut thresholds: Vec<f64> = [0.1, 0.5, 0.9]
            .iter()
            .map(|&q| quantile_threshold(w2_sq, q))
            .collect();
        thresholds.push(SEED_W2_SQ);
        for eps in thresholds {
            let seed = seed_w2_gate(w2_sq, eps);
            let passed = seed.iter().filter(|&&b| b).count();
            for k in [1.0, 0.37, 2.5] {
                let stable = w2_gate(&root, &vec![k; root.len()], eps.sqrt() / k).unwrap();
                let differ = seed.iter().zip(&stable).filter(|(a, b)| a != b).count();
                assert_eq!(differ, 0, "{name}: ε {eps}, k {k}: {differ} differ");
            }
            if eps != SEED_W2_SQ {
                assert!(
                    passed > 0 && passed < w2_sq.len(),
                    "{name}: ε {eps}: {passed}"
                );
            }
        }
    }
}

/// The seed's normal criterion (mean `1 - |cos|` above ε_n) is the stable one (mean `|cos|`
/// below `1 - ε_n`); outliers are the same criterion in both.
#[test]
fn seed_and_stable_pruning_agree() {
    let set = random_set(500, 9);
    // Random normals: mean |cos| over 5 neighbours is about 1/2.
    for eps in [0.45, SEED_NORMAL, 0.5, 0.55] {
        let seed = normal_deviation_mask(&set, 5, eps).unwrap();
        let stable = normal_inconsistency_mask(&set, 5, 1.0 - eps).unwrap();
        assert_eq!(seed, stable, "ε_n {eps}");
        let flagged = seed.iter().filter(|&&b| b).count();
        if eps != SEED_NORMAL {
            assert!(flagged > 0 && flagged < 500, "ε_n {eps}: {flagged}");
        }
    }
    // Outliers: the mean distance to the 5 nearest, against a brute-force reference.
    let means: Vec<DVec3> = set.means().iter().map(|m| m.as_dvec3()).collect();
    let mean_knn: Vec<f64> = means
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let mut d: Vec<f64> = means
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, o)| (*o - *m).length())
                .collect();
            d.sort_by(f64::total_cmp);
            d[..5].iter().sum::<f64>() / 5.0
        })
        .collect();
    for eps in [SEED_OUTLIER, quantile_threshold(&mean_knn, 0.7)] {
        let got = outlier_mask(&set, 5, eps).unwrap();
        let want: Vec<bool> = mean_knn.iter().map(|&m| m > eps).collect();
        assert_eq!(got, want, "ε_o {eps}");
    }
}

#[test]
fn children_w2_refuses_bad_sources() {
    let set = random_set(4, 1);
    assert!(matches!(
        w2_sq_to_children(&set, &set, &[0, 1]),
        Err(DensifyError::MaskLength {
            len: 2,
            expected: 4
        })
    ));
    assert_eq!(
        w2_sq_to_children(&set, &set, &[0, 1, 2, 9]).unwrap_err(),
        DensifyError::ParentOutOfRange {
            child: 3,
            parent: 9,
            parents: 4
        }
    );
    // A parent without children gets 0 (it never passes the gate).
    let got = w2_sq_to_children(&set, &set, &[0, 0, 1, 1]).unwrap();
    assert_eq!(got[2], 0.0);
    assert_eq!(got[3], 0.0);
}
