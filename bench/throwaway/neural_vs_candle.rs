//! Throwaway: the neural appearance model's forward+backward on one batch, hand-written vs
//! candle-core CPU (same shapes, same loss Σ a·logit + Σ b·rgb).
use std::time::Instant;

use candle_core::{DType, Device, Tensor, Var};
use trisplat_geometry::rng::Rng;
use trisplat_splat::glam::DVec3;
use trisplat_splat::neural::{
    Aabb, Appearance, NeuralAppearance, NeuralConfig, NeuralGrads, NeuralInputs, Workspace,
    backward, forward,
};

/// User + system CPU seconds of this process so far (/proc/self/stat, 100 ticks a second).
fn cpu() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap();
    let f: Vec<&str> = s.rsplit(')').next().unwrap().split_whitespace().collect();
    (f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap()) / 100.0
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::args().nth(1).map_or(100_000, |s| s.parse().unwrap());
    let reps: usize = std::env::args().nth(2).map_or(5, |s| s.parse().unwrap());
    let mut rng = Rng::new(1);
    let mut u = |a: f64, b: f64| a + (b - a) * rng.uniform_f64();
    let means: Vec<[f64; 3]> = (0..n).map(|_| [u(-0.1, 0.1), u(-0.15, 0.12), u(-0.1, 0.1)]).collect();
    let rots: Vec<[f64; 4]> = (0..n).map(|_| [u(-1., 1.), u(-1., 1.), u(-1., 1.), u(-1., 1.)]).collect();
    let scales: Vec<[f64; 3]> = (0..n).map(|_| [u(-6., -3.), u(-6., -3.), u(-6., -3.)]).collect();
    let aabb = Aabb::of_points(means.iter().copied())?;
    let mut inp = NeuralInputs::default();
    inp.fill(&aabb, &means, &rots, &scales)?;
    let cam = DVec3::new(0.0, 0.0, -1.0);
    let cfg = NeuralConfig::default();
    let model = NeuralAppearance::<f32>::new(cfg, aabb, 7)?;
    let a: Vec<f64> = (0..n).map(|_| u(-1., 1.) / n as f64).collect();
    let b: Vec<[f64; 3]> = (0..n).map(|_| [u(-1., 1.) / n as f64, 0.5 / n as f64, -0.2 / n as f64]).collect();

    // Hand-written.
    let mut ws = Workspace::default();
    let mut out = Appearance::default();
    let mut grads = NeuralGrads::new(&model);
    let mut hw = Vec::new();
    for _ in 0..reps {
        grads.clear(cfg.features_per_level);
        let (t0, c0) = (Instant::now(), cpu());
        forward(&model, &inp, cam, &mut out, &mut ws);
        let tf = t0.elapsed().as_secs_f64();
        backward(&model, &inp, cam, &a, &b, &mut grads, &mut ws);
        hw.push((tf, t0.elapsed().as_secs_f64(), cpu() - c0));
    }

    // candle: the same parameters.
    let dev = Device::Cpu;
    let grid = model.grid();
    let f = cfg.features_per_level;
    let mut tables = Vec::new();
    for lv in grid.levels() {
        let s = lv.offset as usize * f..(lv.offset + lv.rows) as usize * f;
        tables.push(Var::from_tensor(&Tensor::from_slice(&model.tables()[s], (lv.rows as usize, f), &dev)?)?);
    }
    let mut idx = Vec::new();
    let mut wts = Vec::new();
    for (l, lv) in grid.levels().iter().enumerate() {
        let mut rows = vec![vec![0u32; n]; 8];
        let mut ws8 = vec![vec![0f32; n]; 8];
        for i in 0..n {
            let (r, w) = grid.corners(l, inp.unit[i]);
            for c in 0..8 {
                rows[c][i] = r[c] - lv.offset;
                ws8[c][i] = w[c] as f32;
            }
        }
        idx.push(rows.into_iter().map(|r| Tensor::from_vec(r, n, &dev)).collect::<Result<Vec<_>, _>>()?);
        wts.push(ws8.into_iter().map(|w| Tensor::from_vec(w, (n, 1), &dev)).collect::<Result<Vec<_>, _>>()?);
    }
    let attrs: Vec<f32> = inp.attrs.iter().flat_map(|a| a.map(|v| v as f32)).collect();
    let attrs = Tensor::from_vec(attrs, (n, 7), &dev)?;
    let dirs: Vec<f32> = inp.centres.iter().flat_map(|c| {
        let d = (DVec3::from_array(*c) - cam).normalize_or_zero();
        [d.x as f32, d.y as f32, d.z as f32]
    }).collect();
    let dirs = Tensor::from_vec(dirs, (n, 3), &dev)?;
    let mut layers = Vec::new();
    for s in model.slots() {
        let w = &model.mlp()[s.weights..s.biases];
        let bb = &model.mlp()[s.biases..s.biases + s.outputs];
        layers.push((
            Var::from_tensor(&Tensor::from_slice(w, (s.inputs, s.outputs), &dev)?)?,
            Var::from_tensor(&Tensor::from_slice(bb, (1, s.outputs), &dev)?)?,
        ));
    }
    let ta = Tensor::from_vec(a.iter().map(|&v| v as f32).collect::<Vec<_>>(), (n, 1), &dev)?;
    let tb = Tensor::from_vec(b.iter().flat_map(|v| v.map(|x| x as f32)).collect::<Vec<_>>(), (n, 3), &dev)?;
    let lin = |x: &Tensor, k: usize| -> candle_core::Result<Tensor> {
        x.matmul(layers[k].0.as_tensor())?.broadcast_add(layers[k].1.as_tensor())
    };
    let mut cd = Vec::new();
    let mut check = 0.0f64;
    for _ in 0..reps {
        let (t0, c0) = (Instant::now(), cpu());
        let mut parts = Vec::new();
        for l in 0..grid.levels().len() {
            let mut e = Tensor::zeros((n, f), DType::F32, &dev)?;
            for c in 0..8 {
                e = (e + tables[l].as_tensor().index_select(&idx[l][c], 0)?.broadcast_mul(&wts[l][c])?)?;
            }
            parts.push(e);
        }
        parts.push(attrs.clone());
        let x = Tensor::cat(&parts, 1)?;
        let h = lin(&x, 0)?.relu()?;
        let h = lin(&h, 1)?.relu()?;
        let o = lin(&h, 2)?;
        let logit = o.narrow(1, 0, 1)?;
        let feat = o.narrow(1, 1, cfg.feature_width)?;
        let y = Tensor::cat(&[feat, dirs.clone()], 1)?;
        let h = lin(&y, 3)?.relu()?;
        let h = lin(&h, 4)?.relu()?;
        let rgb = lin(&h, 5)?;
        let loss = ((logit * &ta)?.sum_all()? + (rgb * &tb)?.sum_all()?)?;
        let tf = t0.elapsed().as_secs_f64();
        let g = loss.backward()?;
        let gw0 = g.get(layers[0].0.as_tensor()).unwrap();
        let gt3 = g.get(tables[3].as_tensor()).unwrap();
        cd.push((tf, t0.elapsed().as_secs_f64(), cpu() - c0));
        // Agreement with the hand-written gradient (first layer's weights, finest table).
        let gw0: Vec<f32> = gw0.flatten_all()?.to_vec1()?;
        let s = model.slots()[0];
        let mut worst = 0.0f64;
        let mut big = 0.0f64;
        for (k, &v) in gw0.iter().enumerate() {
            worst = worst.max((f64::from(v) - grads.mlp[s.weights + k]).abs());
            big = big.max(f64::from(v).abs());
        }
        let gt3: Vec<f32> = gt3.flatten_all()?.to_vec1()?;
        let off = grid.levels()[3].offset as usize * f;
        for (k, &v) in gt3.iter().enumerate() {
            worst = worst.max((f64::from(v) - f64::from(grads.tables[off + k])).abs());
        }
        check = check.max(worst / big.max(1e-30));
    }
    let med = |v: &mut Vec<(f64, f64, f64)>| {
        v.sort_by(|x, y| x.1.total_cmp(&y.1));
        v[v.len() / 2]
    };
    let (h, c) = (med(&mut hw), med(&mut cd));
    println!("n = {n}, threads = {}, median of {reps}", rayon::current_num_threads());
    println!("| implementation | forward wall s | forward+backward wall s | CPU s (user+sys) |");
    println!("| hand-written (trisplat_splat::neural, f32) | {:.3} | {:.3} | {:.2} |", h.0, h.1, h.2);
    println!("| candle-core 0.9 CPU (autograd) | {:.3} | {:.3} | {:.2} |", c.0, c.1, c.2);
    println!("gradient agreement (max abs diff / max |grad|): {check:.2e}");
    Ok(())
}
