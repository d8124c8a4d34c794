//! The model's parameters ([`NeuralAppearance`]), the box positions are normalised into
//! ([`Aabb`]), and the per-Gaussian inputs ([`NeuralInputs`]) and outputs ([`Appearance`]).

use glam::DVec3;
use trisplat_geometry::rng::Rng;

use super::config::{
    ATTR_INPUTS, INITIAL_OPACITY_LOGIT, LOG_SCALE_CLAMP, LOG_SCALE_UNIT, LayerSlot, NeuralConfig,
    mlp_layout,
};
use super::error::NeuralError;
use super::grid::HashGrid;
use super::real::Real;

/// Half-width of the uniform initialisation of the hash tables (instant-ngp's 1e-4).
pub const TABLE_INIT: f64 = 1e-4;

/// The axis-aligned box the Gaussians' positions are normalised into. Positions map into the
/// unit cube through the **cube** around the box (centred on it, side the box's longest
/// extent, so cells stay cubic): `u = (p − (c − s/2)) / s`, clamped to 0..1 per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub lo: [f64; 3],
    /// Largest corner.
    pub hi: [f64; 3],
}

impl Aabb {
    /// The box of `points`.
    ///
    /// # Errors
    /// [`NeuralError::Inputs`] for no points or a non-finite one.
    pub fn of_points(points: impl IntoIterator<Item = [f64; 3]>) -> Result<Self, NeuralError> {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (i, p) in points.into_iter().enumerate() {
            if !p.iter().all(|v| v.is_finite()) {
                return Err(NeuralError::Inputs(format!(
                    "Gaussian {i}: non-finite mean"
                )));
            }
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if lo[0] > hi[0] {
            return Err(NeuralError::Inputs("no Gaussians".into()));
        }
        Ok(Self { lo, hi })
    }

    /// The side of the cube around the box (1 for a single point).
    #[must_use]
    pub fn side(&self) -> f64 {
        let mut side = 0.0f64;
        for a in 0..3 {
            side = side.max(self.hi[a] - self.lo[a]);
        }
        if side > 0.0 { side } else { 1.0 }
    }

    /// `p` in the unit cube around the box (clamped).
    #[must_use]
    pub fn unit(&self, p: [f64; 3]) -> [f64; 3] {
        let side = self.side();
        std::array::from_fn(|a| {
            let c = 0.5 * (self.lo[a] + self.hi[a]);
            ((p[a] - (c - 0.5 * side)) / side).clamp(0.0, 1.0)
        })
    }
}

/// The hash-grid MLP appearance model: hash tables and the two MLPs' parameters in `T`.
#[derive(Clone, Debug, PartialEq)]
pub struct NeuralAppearance<T: Real = f32> {
    config: NeuralConfig,
    grid: HashGrid,
    slots: [LayerSlot; 6],
    aabb: Aabb,
    mlp: Vec<T>,
    tables: Vec<T>,
}

impl<T: Real> NeuralAppearance<T> {
    /// A fresh model: tables uniform in ±[`TABLE_INIT`], hidden layers He-uniform
    /// (`±√(6 / inputs)`), output layers `±0.1 √(3 / inputs)`, biases 0 except the colour's,
    /// 0.5 (grey), and the opacity's, [`INITIAL_OPACITY_LOGIT`] (`bind`'s opacity 0.1), all
    /// drawn from `seed`.
    ///
    /// # Errors
    /// [`NeuralError::Config`] for a configuration out of range.
    pub fn new(config: NeuralConfig, aabb: Aabb, seed: u64) -> Result<Self, NeuralError> {
        config.check()?;
        let grid = HashGrid::new(&config);
        let (slots, total) = mlp_layout(&config);
        let mut rng = Rng::new(seed);
        let mut uniform = |half: f64| T::from_f64((2.0 * rng.uniform_f64() - 1.0) * half);
        let tables = (0..grid.total_rows() * config.features_per_level)
            .map(|_| uniform(TABLE_INIT))
            .collect();
        let mut mlp = vec![T::ZERO; total];
        for (k, s) in slots.iter().enumerate() {
            let fan_in = s.inputs as f64;
            let half = if k == 2 || k == 5 {
                0.1 * (3.0 / fan_in).sqrt()
            } else {
                (6.0 / fan_in).sqrt()
            };
            for w in &mut mlp[s.weights..s.biases] {
                *w = uniform(half);
            }
        }
        for b in &mut mlp[slots[5].biases..slots[5].biases + 3] {
            *b = T::from_f64(0.5);
        }
        mlp[slots[2].biases] = T::from_f64(INITIAL_OPACITY_LOGIT);
        Ok(Self {
            config,
            grid,
            slots,
            aabb,
            mlp,
            tables,
        })
    }

    /// A model from its parts (a weights file's), checking their sizes and finiteness.
    ///
    /// # Errors
    /// [`NeuralError::Config`] for a bad configuration, [`NeuralError::Inputs`] for sizes that
    /// do not fit it or a non-finite value.
    pub fn from_parts(
        config: NeuralConfig,
        aabb: Aabb,
        mlp: Vec<T>,
        tables: Vec<T>,
    ) -> Result<Self, NeuralError> {
        config.check()?;
        let grid = HashGrid::new(&config);
        let (slots, total) = mlp_layout(&config);
        let rows = grid.total_rows() * config.features_per_level;
        if mlp.len() != total || tables.len() != rows {
            return Err(NeuralError::Inputs(format!(
                "{} MLP parameters and {} table values, the configuration wants {total} and {rows}",
                mlp.len(),
                tables.len()
            )));
        }
        if !mlp.iter().chain(&tables).all(|v| v.to_f64().is_finite())
            || !aabb.lo.iter().chain(&aabb.hi).all(|v| v.is_finite())
        {
            return Err(NeuralError::Inputs("a non-finite parameter".into()));
        }
        Ok(Self {
            config,
            grid,
            slots,
            aabb,
            mlp,
            tables,
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &NeuralConfig {
        &self.config
    }
    /// The grid's addressing.
    #[must_use]
    pub fn grid(&self) -> &HashGrid {
        &self.grid
    }
    /// The six dense layers' slots in [`NeuralAppearance::mlp`].
    #[must_use]
    pub fn slots(&self) -> &[LayerSlot; 6] {
        &self.slots
    }
    /// The normalisation box.
    #[must_use]
    pub fn aabb(&self) -> &Aabb {
        &self.aabb
    }
    /// The MLP parameters, layer by layer (weights input-major, then biases).
    #[must_use]
    pub fn mlp(&self) -> &[T] {
        &self.mlp
    }
    /// The MLP parameters, mutable (an optimiser's step).
    pub fn mlp_mut(&mut self) -> &mut [T] {
        &mut self.mlp
    }
    /// The hash tables: `rows × features_per_level`, levels one after the other.
    #[must_use]
    pub fn tables(&self) -> &[T] {
        &self.tables
    }
    /// The hash tables, mutable.
    pub fn tables_mut(&mut self) -> &mut [T] {
        &mut self.tables
    }
}

/// What the model reads of each Gaussian: its position in the unit cube, its unit rotation
/// (sign chosen with `w ≥ 0`), its log-scales relative to the cube's side in units of
/// [`LOG_SCALE_UNIT`] (clamped to ±[`LOG_SCALE_CLAMP`]), and its centre (for the view
/// direction).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NeuralInputs {
    /// Positions in the unit cube ([`Aabb::unit`]).
    pub unit: Vec<[f64; 3]>,
    /// `[w, x, y, z, l0, l1, l2]`, `l = (log s − ln side) / LOG_SCALE_UNIT`.
    pub attrs: Vec<[f64; ATTR_INPUTS]>,
    /// World centres.
    pub centres: Vec<[f64; 3]>,
}

impl NeuralInputs {
    /// Fills the inputs from world-space means, raw quaternions `[w, x, y, z]` and log-scales
    /// (the buffers are reused).
    ///
    /// # Errors
    /// [`NeuralError::Inputs`] naming the first Gaussian with a non-finite value or a zero
    /// quaternion.
    pub fn fill(
        &mut self,
        aabb: &Aabb,
        means: &[[f64; 3]],
        rotations: &[[f64; 4]],
        log_scales: &[[f64; 3]],
    ) -> Result<(), NeuralError> {
        self.unit.clear();
        self.attrs.clear();
        self.centres.clear();
        let ln_side = aabb.side().ln();
        for (i, ((m, q), s)) in means.iter().zip(rotations).zip(log_scales).enumerate() {
            let bad = |what: &str| NeuralError::Inputs(format!("Gaussian {i}: {what}"));
            if !m.iter().all(|v| v.is_finite()) {
                return Err(bad("non-finite mean"));
            }
            let len = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !(len.is_finite() && len > 0.0) {
                return Err(bad("zero or non-finite quaternion"));
            }
            let sign = if q[0] < 0.0 { -1.0 } else { 1.0 } / len;
            let ls = s.map(|v| {
                if v.is_nan() {
                    0.0
                } else {
                    ((v - ln_side) / LOG_SCALE_UNIT).clamp(-LOG_SCALE_CLAMP, LOG_SCALE_CLAMP)
                }
            });
            self.unit.push(aabb.unit(*m));
            self.attrs.push([
                q[0] * sign,
                q[1] * sign,
                q[2] * sign,
                q[3] * sign,
                ls[0],
                ls[1],
                ls[2],
            ]);
            self.centres.push(*m);
        }
        Ok(())
    }

    /// Number of Gaussians.
    #[must_use]
    pub fn len(&self) -> usize {
        self.unit.len()
    }

    /// Whether there are none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.unit.is_empty()
    }
}

/// The unit direction from the camera centre to `centre` (zero where they coincide).
#[must_use]
pub fn view_dir(camera: DVec3, centre: [f64; 3]) -> [f64; 3] {
    (DVec3::from_array(centre) - camera)
        .normalize_or_zero()
        .to_array()
}

/// The model's outputs per Gaussian.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Appearance<T: Real = f32> {
    /// Opacity logits (opacity = sigmoid).
    pub opacity_logits: Vec<T>,
    /// Linear RGB.
    pub rgb: Vec<[T; 3]>,
}
