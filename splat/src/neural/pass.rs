//! The model's forward and backward passes over many Gaussians: rayon over chunks of
//! [`CHUNK`] Gaussians, each chunk in batches of [`ROWS`] rows through per-thread scratch (no
//! allocation per Gaussian). The backward recomputes the forward per batch rather than keeping
//! every activation; the MLP gradients are summed per chunk in `T` and the chunks in `f64`, in
//! chunk order, so they do not depend on the thread count; the hash-table gradients are
//! scattered level by level (levels in parallel, Gaussians in order) into the rows touched.

use std::sync::Mutex;

use glam::DVec3;
use rayon::prelude::*;

use super::config::ATTR_INPUTS;
use super::dense;
use super::model::{Appearance, NeuralAppearance, NeuralInputs, view_dir};
use super::real::{Real, axpy};

/// Gaussians per parallel task.
pub const CHUNK: usize = 1024;
/// Rows of one batch through the layers.
pub const ROWS: usize = 32;

/// Activations and their gradients for one batch: `a[0]` the geometry MLP's input, `a[1..=2]`
/// its hidden layers, `a[3]` its output (opacity logit, feature), `a[4]` the colour MLP's input
/// (feature, view direction), `a[5..=6]` its hidden layers, `a[7]` the RGB.
struct Scratch<T> {
    a: [Vec<T>; 8],
    d: [Vec<T>; 8],
}

impl<T: Real> Scratch<T> {
    fn new(widths: [usize; 8]) -> Self {
        Self {
            a: widths.map(|w| vec![T::ZERO; ROWS * w]),
            d: widths.map(|w| vec![T::ZERO; ROWS * w]),
        }
    }
}

/// Reusable buffers of the passes (per-thread scratch, per-chunk gradient sums, the encoding's
/// gradient per Gaussian).
#[derive(Default)]
pub struct Workspace<T: Real = f32> {
    widths: [usize; 8],
    scratch: Vec<Mutex<Scratch<T>>>,
    slots: Vec<Vec<T>>,
    d_enc: Vec<T>,
}

impl<T: Real> Workspace<T> {
    fn prepare(&mut self, model: &NeuralAppearance<T>) {
        let s = model.slots();
        let widths = [
            s[0].inputs,
            s[0].outputs,
            s[1].outputs,
            s[2].outputs,
            s[3].inputs,
            s[3].outputs,
            s[4].outputs,
            s[5].outputs,
        ];
        let threads = rayon::current_num_threads().max(1);
        if self.widths != widths || self.scratch.len() != threads {
            self.widths = widths;
            self.scratch = (0..threads)
                .map(|_| Mutex::new(Scratch::new(widths)))
                .collect();
            self.slots.clear();
        }
    }
}

/// Runs `f` on the calling thread's scratch (any other's if called from outside the pool).
fn with_scratch<T, R>(scratch: &[Mutex<Scratch<T>>], f: impl FnOnce(&mut Scratch<T>) -> R) -> R {
    let k = rayon::current_thread_index().unwrap_or(0) % scratch.len();
    let mut guard = scratch[k]
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    f(&mut guard)
}

/// Gradients of a loss with respect to the model's parameters.
#[derive(Clone, Debug, Default)]
pub struct NeuralGrads<T: Real = f32> {
    /// d loss / d MLP parameter, laid out as [`NeuralAppearance::mlp`].
    pub mlp: Vec<f64>,
    /// d loss / d table value, laid out as [`NeuralAppearance::tables`] (zero outside
    /// `touched`).
    pub tables: Vec<T>,
    /// The table rows with a gradient, per level, in the order first touched.
    pub touched: Vec<Vec<u32>>,
    marks: Vec<bool>,
}

impl<T: Real> NeuralGrads<T> {
    /// Zero gradients for `model`.
    #[must_use]
    pub fn new(model: &NeuralAppearance<T>) -> Self {
        let rows = model.grid().total_rows();
        Self {
            mlp: vec![0.0; model.mlp().len()],
            tables: vec![T::ZERO; model.tables().len()],
            touched: vec![Vec::new(); model.grid().levels().len()],
            marks: vec![false; rows],
        }
    }

    /// Zeroes the gradients (only the touched table rows are visited).
    pub fn clear(&mut self, features_per_level: usize) {
        self.mlp.fill(0.0);
        for list in &mut self.touched {
            for &r in list.iter() {
                let r = r as usize;
                self.tables[r * features_per_level..(r + 1) * features_per_level].fill(T::ZERO);
                self.marks[r] = false;
            }
            list.clear();
        }
    }
}

/// Runs one batch forward: fills `s.a` for `len` Gaussians starting at `first`.
fn forward_batch<T: Real>(
    model: &NeuralAppearance<T>,
    inputs: &NeuralInputs,
    camera: DVec3,
    first: usize,
    len: usize,
    s: &mut Scratch<T>,
) {
    let cfg = model.config();
    let (f, lf) = (cfg.features_per_level, cfg.encoding_width());
    let slots = model.slots();
    let tables = model.tables();
    let w0 = slots[0].inputs;
    for r in 0..len {
        let g = first + r;
        let x = &mut s.a[0][r * w0..(r + 1) * w0];
        x[..lf].fill(T::ZERO);
        for l in 0..cfg.levels {
            let (rows, weights) = model.grid().corners(l, inputs.unit[g]);
            let out = &mut x[l * f..(l + 1) * f];
            for c in 0..8 {
                let row = rows[c] as usize;
                axpy(
                    T::from_f64(weights[c]),
                    &tables[row * f..(row + 1) * f],
                    out,
                );
            }
        }
        for k in 0..ATTR_INPUTS {
            x[lf + k] = T::from_f64(inputs.attrs[g][k]);
        }
    }
    let p = model.mlp();
    let (a0, rest) = s.a.split_at_mut(1);
    let (a1, rest) = rest.split_at_mut(1);
    let (a2, rest) = rest.split_at_mut(1);
    let (a3, rest) = rest.split_at_mut(1);
    let (a4, rest) = rest.split_at_mut(1);
    let (a5, rest) = rest.split_at_mut(1);
    let (a6, a7) = rest.split_at_mut(1);
    dense::forward(p, &slots[0], &a0[0], len, true, &mut a1[0]);
    dense::forward(p, &slots[1], &a1[0], len, true, &mut a2[0]);
    dense::forward(p, &slots[2], &a2[0], len, false, &mut a3[0]);
    let (w3, w4) = (slots[2].outputs, slots[3].inputs);
    let fw = w3 - 1;
    for r in 0..len {
        let y = &mut a4[0][r * w4..(r + 1) * w4];
        y[..fw].copy_from_slice(&a3[0][r * w3 + 1..(r + 1) * w3]);
        let dir = view_dir(camera, inputs.centres[first + r]);
        for k in 0..3 {
            y[fw + k] = T::from_f64(dir[k]);
        }
    }
    dense::forward(p, &slots[3], &a4[0], len, true, &mut a5[0]);
    dense::forward(p, &slots[4], &a5[0], len, true, &mut a6[0]);
    dense::forward(p, &slots[5], &a6[0], len, false, &mut a7[0]);
}

/// The model's opacity logits and RGB for every Gaussian of `inputs` seen from `camera`
/// (the view direction is `centre − camera`, normalised).
pub fn forward<T: Real>(
    model: &NeuralAppearance<T>,
    inputs: &NeuralInputs,
    camera: DVec3,
    out: &mut Appearance<T>,
    ws: &mut Workspace<T>,
) {
    let n = inputs.len();
    ws.prepare(model);
    out.opacity_logits.clear();
    out.opacity_logits.resize(n, T::ZERO);
    out.rgb.clear();
    out.rgb.resize(n, [T::ZERO; 3]);
    let w3 = model.slots()[2].outputs;
    let scratch = &ws.scratch[..];
    out.opacity_logits
        .par_chunks_mut(CHUNK)
        .zip(out.rgb.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (logits, rgb))| {
            with_scratch(scratch, |s| {
                for b in (0..logits.len()).step_by(ROWS) {
                    let len = ROWS.min(logits.len() - b);
                    forward_batch(model, inputs, camera, c * CHUNK + b, len, s);
                    for r in 0..len {
                        logits[b + r] = s.a[3][r * w3];
                        rgb[b + r] = [s.a[7][3 * r], s.a[7][3 * r + 1], s.a[7][3 * r + 2]];
                    }
                }
            });
        });
}

/// Adds into `grads` the gradients of a loss whose gradients with respect to the outputs of
/// [`forward`] (same `inputs` and `camera`) are `d_logits` and `d_rgb`.
///
/// # Panics
/// If the gradient slices are not one per Gaussian or `grads` was made for another model.
pub fn backward<T: Real>(
    model: &NeuralAppearance<T>,
    inputs: &NeuralInputs,
    camera: DVec3,
    d_logits: &[f64],
    d_rgb: &[[f64; 3]],
    grads: &mut NeuralGrads<T>,
    ws: &mut Workspace<T>,
) {
    let n = inputs.len();
    assert!(
        d_logits.len() == n && d_rgb.len() == n,
        "one gradient per Gaussian"
    );
    assert_eq!(
        grads.mlp.len(),
        model.mlp().len(),
        "gradients of another model"
    );
    ws.prepare(model);
    let total = model.mlp().len();
    let chunks = n.div_ceil(CHUNK);
    ws.slots.resize_with(chunks, Vec::new);
    for s in &mut ws.slots {
        s.clear();
        s.resize(total, T::ZERO);
    }
    let lf = model.config().encoding_width();
    ws.d_enc.clear();
    ws.d_enc.resize(n * lf, T::ZERO);
    let Workspace {
        scratch,
        slots,
        d_enc,
        ..
    } = ws;
    let scratch = &scratch[..];
    slots
        .par_iter_mut()
        .zip(d_enc.par_chunks_mut(CHUNK * lf))
        .enumerate()
        .for_each(|(c, (slot, d_enc))| {
            with_scratch(scratch, |s| {
                let count = d_enc.len() / lf.max(1);
                for b in (0..count).step_by(ROWS) {
                    let len = ROWS.min(count - b);
                    let first = c * CHUNK + b;
                    forward_batch(model, inputs, camera, first, len, s);
                    backward_batch(model, first, len, d_logits, d_rgb, s, slot);
                    for r in 0..len {
                        let w0 = model.slots()[0].inputs;
                        d_enc[(b + r) * lf..(b + r + 1) * lf]
                            .copy_from_slice(&s.d[0][r * w0..r * w0 + lf]);
                    }
                }
            });
        });
    for slot in slots.iter() {
        for (g, v) in grads.mlp.iter_mut().zip(slot) {
            *g += v.to_f64();
        }
    }
    scatter_tables(model, inputs, d_enc, grads);
}

/// The backward of one batch whose forward is in `s.a`; adds the MLP gradients into `slot`
/// and leaves d loss / d input of the geometry MLP in `s.d[0]`.
fn backward_batch<T: Real>(
    model: &NeuralAppearance<T>,
    first: usize,
    len: usize,
    d_logits: &[f64],
    d_rgb: &[[f64; 3]],
    s: &mut Scratch<T>,
    slot: &mut [T],
) {
    let p = model.mlp();
    let sl = model.slots();
    let (w3, w4) = (sl[2].outputs, sl[3].inputs);
    let fw = w3 - 1;
    for r in 0..len {
        for (k, &g) in d_rgb[first + r].iter().enumerate() {
            s.d[7][3 * r + k] = T::from_f64(g);
        }
    }
    let (a, d) = (&s.a, &mut s.d);
    let (d_lo, d_hi) = d.split_at_mut(7);
    dense::backward(
        p,
        &sl[5],
        &a[6],
        &d_hi[0],
        len,
        slot,
        Some(&mut d_lo[6]),
        true,
    );
    let (d_lo, d_hi) = d.split_at_mut(6);
    dense::backward(
        p,
        &sl[4],
        &a[5],
        &d_hi[0],
        len,
        slot,
        Some(&mut d_lo[5]),
        true,
    );
    let (d_lo, d_hi) = d.split_at_mut(5);
    dense::backward(
        p,
        &sl[3],
        &a[4],
        &d_hi[0],
        len,
        slot,
        Some(&mut d_lo[4]),
        false,
    );
    let (d_lo, d_hi) = d.split_at_mut(4);
    for r in 0..len {
        let o = &mut d_lo[3][r * w3..(r + 1) * w3];
        o[0] = T::from_f64(d_logits[first + r]);
        o[1..].copy_from_slice(&d_hi[0][r * w4..r * w4 + fw]);
    }
    let (d_lo, d_hi) = d.split_at_mut(3);
    dense::backward(
        p,
        &sl[2],
        &a[2],
        &d_hi[0],
        len,
        slot,
        Some(&mut d_lo[2]),
        true,
    );
    let (d_lo, d_hi) = d.split_at_mut(2);
    dense::backward(
        p,
        &sl[1],
        &a[1],
        &d_hi[0],
        len,
        slot,
        Some(&mut d_lo[1]),
        true,
    );
    let (d_lo, d_hi) = d.split_at_mut(1);
    dense::backward(
        p,
        &sl[0],
        &a[0],
        &d_hi[0],
        len,
        slot,
        Some(&mut d_lo[0]),
        false,
    );
}

/// Scatters d loss / d encoding into the touched table rows, one level per task.
fn scatter_tables<T: Real>(
    model: &NeuralAppearance<T>,
    inputs: &NeuralInputs,
    d_enc: &[T],
    grads: &mut NeuralGrads<T>,
) {
    let cfg = model.config();
    let (f, lf) = (cfg.features_per_level, cfg.encoding_width());
    let grid = model.grid();
    let mut tasks = Vec::with_capacity(cfg.levels);
    let (mut tables, mut marks) = (&mut grads.tables[..], &mut grads.marks[..]);
    for (l, touched) in grads.touched.iter_mut().enumerate() {
        let rows = grid.levels()[l].rows as usize;
        let (t, t_rest) = tables.split_at_mut(rows * f);
        let (m, m_rest) = marks.split_at_mut(rows);
        tables = t_rest;
        marks = m_rest;
        tasks.push((l, t, m, touched));
    }
    tasks
        .into_par_iter()
        .for_each(|(l, table, marks, touched)| {
            let offset = grid.levels()[l].offset;
            for (i, &unit) in inputs.unit.iter().enumerate() {
                let de = &d_enc[i * lf + l * f..i * lf + (l + 1) * f];
                let (rows, weights) = grid.corners(l, unit);
                for c in 0..8 {
                    if weights[c] == 0.0 {
                        continue;
                    }
                    let row = (rows[c] - offset) as usize;
                    axpy(
                        T::from_f64(weights[c]),
                        de,
                        &mut table[row * f..(row + 1) * f],
                    );
                    if !marks[row] {
                        marks[row] = true;
                        touched.push(rows[c]);
                    }
                }
            }
        });
}
