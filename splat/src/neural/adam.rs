//! Adam for the neural appearance model: dense over the MLP parameters (moments in `f64`),
//! lazy over the hash tables (moments in `f32`, only the rows with a gradient this step are
//! updated, as PyTorch's `SparseAdam`; the bias correction uses the global step count).
//! Instant-ngp's constants: β = (0.9, 0.99), ε = 1e-15.

use super::model::NeuralAppearance;
use super::pass::NeuralGrads;
use super::real::Real;

/// Learning rates of the two parameter groups.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeuralLearningRates {
    /// The MLP weights and biases.
    pub mlp: f64,
    /// The hash tables.
    pub tables: f64,
}

impl Default for NeuralLearningRates {
    /// MLP 1e-3, tables 1e-2 (instant-ngp's rate for the encoding).
    fn default() -> Self {
        Self {
            mlp: 1e-3,
            tables: 1e-2,
        }
    }
}

/// First moment decay.
pub const BETA1: f64 = 0.9;
/// Second moment decay.
pub const BETA2: f64 = 0.99;
/// Denominator floor.
pub const EPS: f64 = 1e-15;

/// Adam's state for one model.
#[derive(Clone, Debug)]
pub struct NeuralAdam {
    /// Learning rates.
    pub lr: NeuralLearningRates,
    m_mlp: Vec<f64>,
    v_mlp: Vec<f64>,
    m_tab: Vec<f32>,
    v_tab: Vec<f32>,
    step: u64,
}

impl NeuralAdam {
    /// Fresh state for `model`.
    #[must_use]
    pub fn new<T: Real>(lr: NeuralLearningRates, model: &NeuralAppearance<T>) -> Self {
        Self {
            lr,
            m_mlp: vec![0.0; model.mlp().len()],
            v_mlp: vec![0.0; model.mlp().len()],
            m_tab: vec![0.0; model.tables().len()],
            v_tab: vec![0.0; model.tables().len()],
            step: 0,
        }
    }

    /// Steps taken.
    #[must_use]
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One step with `grads` (made for `model`).
    pub fn step<T: Real>(&mut self, model: &mut NeuralAppearance<T>, grads: &NeuralGrads<T>) {
        self.step += 1;
        let t = self.step as i32;
        let c1 = 1.0 - BETA1.powi(t);
        let c2 = 1.0 - BETA2.powi(t);
        let lr = self.lr.mlp;
        for (((p, &g), m), v) in model
            .mlp_mut()
            .iter_mut()
            .zip(&grads.mlp)
            .zip(&mut self.m_mlp)
            .zip(&mut self.v_mlp)
        {
            *m = BETA1 * *m + (1.0 - BETA1) * g;
            *v = BETA2 * *v + (1.0 - BETA2) * g * g;
            let upd = lr * (*m / c1) / ((*v / c2).sqrt() + EPS);
            *p = T::from_f64(p.to_f64() - upd);
        }
        let f = model.config().features_per_level;
        let lr = self.lr.tables;
        let tables = model.tables_mut();
        for list in &grads.touched {
            for &row in list {
                let r = row as usize * f..(row as usize + 1) * f;
                for k in r {
                    let g = grads.tables[k].to_f64();
                    let m = BETA1 * f64::from(self.m_tab[k]) + (1.0 - BETA1) * g;
                    let v = BETA2 * f64::from(self.v_tab[k]) + (1.0 - BETA2) * g * g;
                    self.m_tab[k] = m as f32;
                    self.v_tab[k] = v as f32;
                    let upd = lr * (m / c1) / ((v / c2).sqrt() + EPS);
                    tables[k] = T::from_f64(tables[k].to_f64() - upd);
                }
            }
        }
    }
}
