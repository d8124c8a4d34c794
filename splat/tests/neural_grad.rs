//! The neural appearance model's backward pass against central finite differences of its f64
//! forward (docs/conventions.md §5 "Neural appearance"), and the f32 production path against
//! the f64 one.

use trisplat_geometry::rng::Rng;
use trisplat_splat::glam::DVec3;
use trisplat_splat::neural::{
    Aabb, Appearance, NeuralAppearance, NeuralConfig, NeuralGrads, NeuralInputs, Workspace,
    backward, forward,
};

/// Two levels (the first dense, the second hashed into 64 rows), 2 features, hidden 5,
/// feature 4: every parameter can be differenced.
fn tiny() -> NeuralConfig {
    NeuralConfig {
        levels: 2,
        features_per_level: 2,
        log2_table_size: 6,
        base_resolution: 2,
        growth: 3.0,
        hidden: 5,
        feature_width: 4,
    }
}

fn inputs(n: usize, seed: u64) -> (NeuralInputs, Aabb) {
    let mut rng = Rng::new(seed);
    let mut u = |a: f64, b: f64| a + (b - a) * rng.uniform_f64();
    let means: Vec<[f64; 3]> = (0..n)
        .map(|_| [u(-1.0, 1.0), u(-0.5, 0.7), u(0.0, 0.4)])
        .collect();
    let rots: Vec<[f64; 4]> = (0..n)
        .map(|_| [u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)])
        .collect();
    let scales: Vec<[f64; 3]> = (0..n)
        .map(|_| [u(-3.0, 0.0), u(-3.0, 0.0), u(-3.0, 0.0)])
        .collect();
    let aabb = Aabb::of_points(means.iter().copied()).unwrap();
    let mut inp = NeuralInputs::default();
    inp.fill(&aabb, &means, &rots, &scales).unwrap();
    (inp, aabb)
}

/// A model whose tables are large enough (±0.5) to matter next to the other inputs.
fn model(aabb: Aabb, seed: u64) -> NeuralAppearance<f64> {
    let mut m = NeuralAppearance::<f64>::new(tiny(), aabb, seed).unwrap();
    let mut rng = Rng::new(seed ^ 7);
    for t in m.tables_mut() {
        *t = rng.uniform_f64() - 0.5;
    }
    for b in m.mlp_mut() {
        *b += 0.1 * (rng.uniform_f64() - 0.5);
    }
    m
}

/// `Σ a·logit + Σ b·rgb`, whose gradients with respect to the outputs are `a` and `b`.
fn loss(
    m: &NeuralAppearance<f64>,
    inp: &NeuralInputs,
    cam: DVec3,
    a: &[f64],
    b: &[[f64; 3]],
) -> f64 {
    let mut out = Appearance::default();
    forward(m, inp, cam, &mut out, &mut Workspace::default());
    let mut s = 0.0;
    for i in 0..inp.len() {
        s += a[i] * out.opacity_logits[i];
        for (bk, ok) in b[i].iter().zip(out.rgb[i]) {
            s += bk * ok;
        }
    }
    s
}

#[test]
fn backward_matches_central_differences() {
    let n = 70; // three batches of 32 rows, the last partial
    let (inp, aabb) = inputs(n, 3);
    let mut m = model(aabb, 11);
    let cam = DVec3::new(0.3, -0.2, -3.0);
    let mut rng = Rng::new(5);
    let a: Vec<f64> = (0..n).map(|_| rng.uniform_f64() - 0.5).collect();
    let b: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            [
                rng.uniform_f64() - 0.5,
                rng.uniform_f64() - 0.5,
                rng.uniform_f64() - 0.5,
            ]
        })
        .collect();
    let mut grads = NeuralGrads::new(&m);
    backward(&m, &inp, cam, &a, &b, &mut grads, &mut Workspace::default());

    let h = 1e-6;
    let mut worst = 0.0f64;
    let mut largest = 0.0f64;
    for k in 0..m.mlp().len() {
        let v = m.mlp()[k];
        m.mlp_mut()[k] = v + h;
        let up = loss(&m, &inp, cam, &a, &b);
        m.mlp_mut()[k] = v - h;
        let down = loss(&m, &inp, cam, &a, &b);
        m.mlp_mut()[k] = v;
        let fd = (up - down) / (2.0 * h);
        worst = worst.max((fd - grads.mlp[k]).abs());
        largest = largest.max(fd.abs());
    }
    assert!(largest > 1e-2, "the loss must depend on the MLP");
    assert!(
        worst <= 1e-6 * largest,
        "MLP: worst {worst:e}, largest {largest:e}"
    );

    let mut worst = 0.0f64;
    let mut largest = 0.0f64;
    let mut touched = 0;
    let f = m.config().features_per_level;
    for k in 0..m.tables().len() {
        let v = m.tables()[k];
        m.tables_mut()[k] = v + h;
        let up = loss(&m, &inp, cam, &a, &b);
        m.tables_mut()[k] = v - h;
        let down = loss(&m, &inp, cam, &a, &b);
        m.tables_mut()[k] = v;
        let fd = (up - down) / (2.0 * h);
        let row = (k / f) as u32;
        let listed = grads.touched.iter().any(|l| l.contains(&row));
        if fd != 0.0 {
            assert!(
                listed,
                "table row {row} has a gradient but is not listed as touched"
            );
            touched += 1;
        }
        worst = worst.max((fd - grads.tables[k]).abs());
        largest = largest.max(fd.abs());
    }
    assert!(
        touched > 20 && largest > 1e-3,
        "the loss must depend on the tables"
    );
    assert!(
        worst <= 1e-6 * largest,
        "tables: worst {worst:e}, largest {largest:e}"
    );

    // Clearing leaves nothing behind.
    grads.clear(f);
    assert!(grads.mlp.iter().all(|&g| g == 0.0));
    assert!(grads.tables.iter().all(|&g| g == 0.0));
    assert!(grads.touched.iter().all(Vec::is_empty));
}

#[test]
fn f32_follows_f64_and_ignores_the_thread_count() {
    let n = 2500; // three chunks
    let (inp, aabb) = inputs(n, 9);
    let m64 = model(aabb, 2);
    let m32 = NeuralAppearance::<f32>::from_parts(
        *m64.config(),
        *m64.aabb(),
        m64.mlp().iter().map(|&v| v as f32).collect(),
        m64.tables().iter().map(|&v| v as f32).collect(),
    )
    .unwrap();
    let cam = DVec3::new(0.0, 0.0, -2.0);
    let mut o64 = Appearance::default();
    forward(&m64, &inp, cam, &mut o64, &mut Workspace::default());
    let mut o32 = Appearance::default();
    forward(&m32, &inp, cam, &mut o32, &mut Workspace::default());
    for i in 0..n {
        assert!((f64::from(o32.opacity_logits[i]) - o64.opacity_logits[i]).abs() < 1e-4);
        for k in 0..3 {
            assert!((f64::from(o32.rgb[i][k]) - o64.rgb[i][k]).abs() < 1e-4);
        }
    }
    let a = vec![0.01; n];
    let b = vec![[0.02, -0.01, 0.005]; n];
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut g = NeuralGrads::new(&m32);
            backward(&m32, &inp, cam, &a, &b, &mut g, &mut Workspace::default());
            g
        })
    };
    let (g1, g2) = (run(1), run(3));
    assert_eq!(g1.mlp, g2.mlp);
    assert_eq!(g1.tables, g2.tables);
    let mut g64 = NeuralGrads::new(&m64);
    backward(&m64, &inp, cam, &a, &b, &mut g64, &mut Workspace::default());
    let scale = g64.mlp.iter().fold(0.0f64, |s, g| s.max(g.abs()));
    for (x, y) in g1.mlp.iter().zip(&g64.mlp) {
        assert!((x - y).abs() <= 1e-4 * scale, "{x} vs {y}");
    }
}
