//! Statistical tests of surface sampling: per-triangle counts against area (and against
//! curvature weights), the distribution of points inside a triangle, the Poisson-disk spacing,
//! seeded reproducibility and independence from the thread count.
//!
//! Every test uses fixed seeds, so it is deterministic; the significance levels say how
//! unlikely a failure would be for a correct sampler on a fresh seed. Each statistical check
//! is paired with a deliberately wrong sampler that the same check rejects, so the checks can
//! fail.

use glam::Vec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::sampling::{
    SampleMethod, SampleOptions, SurfaceSamples, sample, sample_curvature, sample_poisson_disk,
    sample_uniform_with_triangles, vertex_mean_curvature,
};

/// Significance level of the chi-square and Kolmogorov-Smirnov tests.
const ALPHA: f64 = 1e-3;
/// Standard normal quantile for [`ALPHA`] (upper tail).
const Z_ALPHA: f64 = 3.090_232;
/// Kolmogorov-Smirnov critical value `c(α)` for α = 1e-3: reject when `sqrt(n) D > c`.
const KS_CRITICAL: f64 = 1.949_5;
/// Chi-square bins are pooled (consecutive triangles) until each expects this many points.
const MIN_EXPECTED_PER_BIN: f64 = 10.0;

fn spot() -> TriMesh {
    read_mesh(&trisplat_fixtures::path("reference/smoothing/spot.ply")).expect("spot.ply")
}

/// Upper-α critical value of chi-square with `df` degrees of freedom (Wilson-Hilferty; within
/// 0.1% of the exact quantile for df > 30).
fn chi_square_critical(df: f64) -> f64 {
    let a = 2.0 / (9.0 * df);
    df * (1.0 - a + Z_ALPHA * a.sqrt()).powi(3)
}

/// Pearson's chi-square of `counts` against probabilities `p` (bins pooled in index order until
/// each expects [`MIN_EXPECTED_PER_BIN`]); returns (statistic, degrees of freedom).
fn chi_square(counts: &[u64], p: &[f64]) -> (f64, f64) {
    let n: u64 = counts.iter().sum();
    let total_p: f64 = p.iter().sum();
    let mut stat = 0.0;
    let mut bins = 0usize;
    let (mut obs, mut exp) = (0.0, 0.0);
    for (&c, &pi) in counts.iter().zip(p) {
        obs += c as f64;
        exp += n as f64 * pi / total_p;
        if exp >= MIN_EXPECTED_PER_BIN {
            stat += (obs - exp) * (obs - exp) / exp;
            bins += 1;
            obs = 0.0;
            exp = 0.0;
        }
    }
    if exp > 0.0 {
        stat += (obs - exp) * (obs - exp) / exp;
        bins += 1;
    }
    (stat, (bins - 1) as f64)
}

fn triangle_counts(s: &SurfaceSamples, triangles: usize) -> Vec<u64> {
    let mut counts = vec![0u64; triangles];
    for t in &s.triangles {
        counts[t.index()] += 1;
    }
    counts
}

#[test]
fn uniform_counts_follow_area_chi_square() {
    let mesh = spot();
    let areas = mesh.triangle_areas();
    let n = 200_000;
    let s = sample_uniform_with_triangles(&mesh, n, 42);
    assert_eq!(s.len(), n);
    let (stat, df) = chi_square(&triangle_counts(&s, mesh.triangle_count()), &areas);
    let crit = chi_square_critical(df);
    println!("uniform: chi2 {stat:.1}, df {df}, critical (alpha {ALPHA}) {crit:.1}");
    assert!(stat < crit, "chi2 {stat} >= {crit}");

    // The same check rejects a sampler that picks triangles uniformly by index.
    let equal = vec![1.0; mesh.triangle_count()];
    let (wrong, wrong_df) = chi_square(&triangle_counts(&s, mesh.triangle_count()), &equal);
    println!("uniform vs equal-triangle hypothesis: chi2 {wrong:.1}, df {wrong_df}");
    assert!(wrong > chi_square_critical(wrong_df));
}

#[test]
fn points_are_uniform_inside_a_triangle() {
    // Right triangle (0,0) (1,0) (0,1): a point (x, y) has barycentrics (1 - x - y, x, y).
    let mesh = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
    let n = 100_000;
    let s = sample_uniform_with_triangles(&mesh, n, 7);
    let pts: Vec<(f64, f64)> = s
        .points
        .positions()
        .iter()
        .map(|p| (f64::from(p.x), f64::from(p.y)))
        .collect();
    assert!(
        pts.iter()
            .all(|&(x, y)| x >= 0.0 && y >= 0.0 && x + y <= 1.0 + 1e-6)
    );

    // 1. Kolmogorov-Smirnov on each barycentric marginal: Beta(1, 2), CDF 1 - (1 - t)^2.
    for (name, coord) in [
        ("b1 = x", pts.iter().map(|p| p.0).collect::<Vec<_>>()),
        ("b2 = y", pts.iter().map(|p| p.1).collect()),
        ("b0 = 1-x-y", pts.iter().map(|p| 1.0 - p.0 - p.1).collect()),
    ] {
        let d = ks_statistic(coord, |t| 1.0 - (1.0 - t) * (1.0 - t));
        println!(
            "KS {name}: sqrt(n) D = {:.3} (critical {KS_CRITICAL})",
            d * (n as f64).sqrt()
        );
        assert!(d * (n as f64).sqrt() < KS_CRITICAL, "{name}");
    }
    // The KS check rejects the classic mistake (u, v) -> (u (1 - v), u v)-style non-uniform
    // barycentrics, whose b1 marginal is not Beta(1, 2).
    let wrong: Vec<f64> = pts.iter().map(|p| p.0 + p.1).collect();
    assert!(ks_statistic(wrong, |t| 1.0 - (1.0 - t) * (1.0 - t)) * (n as f64).sqrt() > KS_CRITICAL);

    // 2. Chi-square over a k x k grid clipped to the triangle (diagonal cells are half cells).
    let k = 20usize;
    let mut counts = vec![0u64; k * k];
    let mut p = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..k {
            p[i * k + j] = match i + j {
                s if s + 1 < k => 1.0,
                s if s + 1 == k => 0.5,
                _ => 0.0,
            };
        }
    }
    for &(x, y) in &pts {
        let (i, j) = (
            ((x * k as f64) as usize).min(k - 1),
            ((y * k as f64) as usize).min(k - 1),
        );
        // Points on the diagonal belong to the half cell.
        let (i, j) = if i + j >= k {
            (i.min(k - 1 - j), j)
        } else {
            (i, j)
        };
        counts[i * k + j] += 1;
    }
    let (stat, df) = chi_square(&counts, &p);
    let crit = chi_square_critical(df);
    println!("in-triangle grid: chi2 {stat:.1}, df {df}, critical {crit:.1}");
    assert!(stat < crit);
}

fn ks_statistic(mut xs: Vec<f64>, cdf: impl Fn(f64) -> f64) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len() as f64;
    xs.iter()
        .enumerate()
        .map(|(i, &x)| {
            let f = cdf(x.clamp(0.0, 1.0));
            (f - i as f64 / n).abs().max(((i + 1) as f64 / n - f).abs())
        })
        .fold(0.0, f64::max)
}

/// Nearest-neighbour distances by brute force (small sets only).
fn nn_distances(points: &[Vec3]) -> Vec<f64> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (p.as_dvec3() - q.as_dvec3()).length())
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

#[test]
fn poisson_disk_spacing() {
    // d_max = 2 sqrt(A / (2 sqrt 3 N)) is the largest possible minimum distance (hexagonal
    // packing). Yuksel's elimination gets close to it; uniform sampling does not. Open3D's own
    // elimination on this mesh (tests/reference/ref_smoothing.py, poisson_open3d.json) reaches
    // min NN / d_max = 0.689 at N = 1000 and 4000; we require at least 0.6 (and at least 90% of
    // Open3D's value), and a mean NN distance of at least 0.7 d_max.
    const MIN_NN_OVER_D_MAX: f64 = 0.6;
    const MEAN_NN_OVER_D_MAX: f64 = 0.7;
    let reference = trisplat_tests::reference_json(&trisplat_fixtures::path(
        "reference/smoothing/poisson_open3d.json",
    ));
    let mesh = spot();
    let area = mesh.area();
    for run in reference["runs"].as_array().unwrap() {
        let n = run["n"].as_u64().unwrap() as usize;
        let open3d_min = run["min_nn_over_d_max"].as_f64().unwrap();
        let d_max = 2.0 * (area / (2.0 * 3f64.sqrt() * n as f64)).sqrt();
        let s = sample_poisson_disk(&mesh, n, 5).unwrap();
        assert_eq!(s.len(), n);
        let nn = nn_distances(s.points.positions());
        let min = nn.iter().copied().fold(f64::INFINITY, f64::min) / d_max;
        let mean = nn.iter().sum::<f64>() / nn.len() as f64 / d_max;
        let u = sample_uniform_with_triangles(&mesh, n, 5);
        let unn = nn_distances(u.points.positions());
        let umin = unn.iter().copied().fold(f64::INFINITY, f64::min) / d_max;
        println!(
            "poisson n={n}: min NN / d_max {min:.3} (Open3D {open3d_min:.3}), mean {mean:.3}; uniform min {umin:.3}"
        );
        assert!(min >= MIN_NN_OVER_D_MAX && min >= 0.9 * open3d_min, "{min}");
        assert!(mean >= MEAN_NN_OVER_D_MAX, "{mean}");
        // The spacing check fails for uniform sampling.
        assert!(umin < MIN_NN_OVER_D_MAX);
        // Every point lies on its triangle's plane.
        for (p, t) in s.points.positions().iter().zip(&s.triangles) {
            let [a, b, c] = mesh.corners(t.index());
            let nrm = (b - a).cross(c - a).normalize();
            assert!((p.as_dvec3() - a).dot(nrm).abs() < 1e-6);
        }
    }
}

#[test]
fn curvature_counts_follow_weights_chi_square() {
    let mesh = spot();
    let strength = 2.0;
    let h = vertex_mean_curvature(&mesh);
    let areas = mesh.triangle_areas();
    let ht: Vec<f64> = mesh
        .triangles()
        .iter()
        .map(|t| t.iter().map(|&v| h[v as usize]).sum::<f64>() / 3.0)
        .collect();
    let mean = areas.iter().zip(&ht).map(|(a, h)| a * h).sum::<f64>() / areas.iter().sum::<f64>();
    let weights: Vec<f64> = areas
        .iter()
        .zip(&ht)
        .map(|(a, h)| a * (1.0 + strength * h / mean))
        .collect();
    let n = 200_000;
    let s = sample_curvature(&mesh, n, 11, strength).unwrap();
    let counts = triangle_counts(&s, mesh.triangle_count());
    let (stat, df) = chi_square(&counts, &weights);
    let crit = chi_square_critical(df);
    println!("curvature: chi2 {stat:.1}, df {df}, critical {crit:.1}");
    assert!(stat < crit);
    // Area-uniform would be rejected: the weighting really changes the density.
    let (vs_area, df_area) = chi_square(&counts, &areas);
    println!("curvature vs area hypothesis: chi2 {vs_area:.1}, df {df_area}");
    assert!(vs_area > chi_square_critical(df_area));
}

fn all_methods() -> [SampleMethod; 3] {
    [
        SampleMethod::Uniform,
        SampleMethod::Poisson,
        SampleMethod::Curvature,
    ]
}

#[test]
fn seeded_runs_are_reproducible() {
    let mesh = spot();
    for method in all_methods() {
        let opts = |seed| SampleOptions {
            method,
            seed,
            ..SampleOptions::default()
        };
        let a = sample(&mesh, 3000, &opts(1)).unwrap();
        let b = sample(&mesh, 3000, &opts(1)).unwrap();
        let c = sample(&mesh, 3000, &opts(2)).unwrap();
        assert_eq!(a, b, "{method:?}");
        assert_ne!(a.points.positions(), c.points.positions(), "{method:?}");
    }
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let mesh = spot();
    // More than one SAMPLE_CHUNK so the work really splits across threads.
    let n = 20_000;
    for method in all_methods() {
        let opts = SampleOptions {
            method,
            seed: 99,
            ..SampleOptions::default()
        };
        let runs: Vec<SurfaceSamples> = [1, 2, 4]
            .iter()
            .map(|&threads| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap()
                    .install(|| sample(&mesh, n, &opts).unwrap())
            })
            .collect();
        for r in &runs[1..] {
            // Bit-exact: compare the raw bits so -0.0 / 0.0 or NaN could not hide a difference.
            let bits = |s: &SurfaceSamples| -> Vec<u32> {
                s.points
                    .positions()
                    .iter()
                    .chain(s.points.normals().unwrap())
                    .flat_map(|p| p.to_array().map(f32::to_bits))
                    .collect()
            };
            assert_eq!(bits(r), bits(&runs[0]), "{method:?}");
            assert_eq!(r.triangles, runs[0].triangles, "{method:?}");
        }
    }
}
