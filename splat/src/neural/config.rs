//! The neural appearance model's shape (docs/conventions.md §5 "Neural appearance") and where
//! each layer's parameters sit in the flat MLP parameter vector.

use super::error::NeuralError;

/// Instant-ngp's spatial-hash primes, one per axis.
pub const HASH_PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

/// Inputs besides the hash encoding: the unit quaternion (4) and the log-scales (3).
pub const ATTR_INPUTS: usize = 7;

/// Log-scales enter the MLP relative to the normalisation cube's side and in units of
/// `LOG_SCALE_UNIT`, `(log s − ln side) / 5` (a Gaussian 1/150 of the cube enters as −1), so the
/// inputs are of order 1 whatever the scene's units.
pub const LOG_SCALE_UNIT: f64 = 5.0;

/// The normalised log-scales are clamped to `±LOG_SCALE_CLAMP` (a surfel's flat axis, `−∞`,
/// enters as −4).
pub const LOG_SCALE_CLAMP: f64 = 4.0;

/// The opacity output's initial bias: `logit(0.1)`, `bind`'s initial opacity.
pub const INITIAL_OPACITY_LOGIT: f64 = -2.197_224_577_336_219_6;

/// The model's shape. [`NeuralConfig::default`] is the static-head seed's: 4 levels of 8
/// features, tables of 2^19 entries, base resolution 16, growth 2 (resolutions 16, 32, 64,
/// 128), two hidden layers of 64 in each MLP, a 64-wide feature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeuralConfig {
    /// Hash-grid levels.
    pub levels: usize,
    /// Features per level.
    pub features_per_level: usize,
    /// log2 of the most entries a level's table has.
    pub log2_table_size: u32,
    /// Cells per axis of the coarsest level.
    pub base_resolution: u32,
    /// Factor between the resolutions of consecutive levels: `N_l = ⌊N_0 b^l⌋`.
    pub growth: f64,
    /// Width of the hidden layers (two per MLP).
    pub hidden: usize,
    /// Width of the feature the first MLP hands the second.
    pub feature_width: usize,
}

impl Default for NeuralConfig {
    fn default() -> Self {
        Self {
            levels: 4,
            features_per_level: 8,
            log2_table_size: 19,
            base_resolution: 16,
            growth: 2.0,
            hidden: 64,
            feature_width: 64,
        }
    }
}

impl NeuralConfig {
    /// Checks the ranges (levels 1..=16, features 1..=64, log2 table 4..=24, base resolution
    /// 1..=4096, growth 1..=16, widths 1..=1024, finest resolution at most 2^20).
    ///
    /// # Errors
    /// [`NeuralError::Config`] naming the first field out of range.
    pub fn check(&self) -> Result<(), NeuralError> {
        let bad = |field: &str, v: String| Err(NeuralError::Config(format!("{field} = {v}")));
        if !(1..=16).contains(&self.levels) {
            return bad("levels", self.levels.to_string());
        }
        if !(1..=64).contains(&self.features_per_level) {
            return bad("features_per_level", self.features_per_level.to_string());
        }
        if !(4..=24).contains(&self.log2_table_size) {
            return bad("log2_table_size", self.log2_table_size.to_string());
        }
        if !(1..=4096).contains(&self.base_resolution) {
            return bad("base_resolution", self.base_resolution.to_string());
        }
        if !(self.growth.is_finite() && (1.0..=16.0).contains(&self.growth)) {
            return bad("growth", self.growth.to_string());
        }
        if !(1..=1024).contains(&self.hidden) {
            return bad("hidden", self.hidden.to_string());
        }
        if !(1..=1024).contains(&self.feature_width) {
            return bad("feature_width", self.feature_width.to_string());
        }
        if self.resolution(self.levels - 1) > 1 << 20 {
            return bad(
                "growth",
                format!("{} (finest resolution over 2^20)", self.growth),
            );
        }
        Ok(())
    }

    /// Cells per axis of level `l`: `⌊N_0 b^l⌋`.
    #[must_use]
    pub fn resolution(&self, level: usize) -> u32 {
        let n = f64::from(self.base_resolution) * self.growth.powi(level as i32);
        (n.floor() as u32).max(1)
    }

    /// Width of the hash encoding (levels × features).
    #[must_use]
    pub fn encoding_width(&self) -> usize {
        self.levels * self.features_per_level
    }

    /// `(inputs, outputs)` of the six dense layers: the geometry MLP (encoding + 7 → hidden →
    /// hidden → 1 + feature) then the colour MLP (feature + 3 → hidden → hidden → 3).
    #[must_use]
    pub fn layer_shapes(&self) -> [(usize, usize); 6] {
        let h = self.hidden;
        [
            (self.encoding_width() + ATTR_INPUTS, h),
            (h, h),
            (h, 1 + self.feature_width),
            (self.feature_width + 3, h),
            (h, h),
            (h, 3),
        ]
    }
}

/// Where a dense layer's parameters sit in the flat MLP vector: the weights stored transposed
/// (`w[i * outputs + o]` from input `i` to output `o`), then the biases.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayerSlot {
    /// Inputs.
    pub inputs: usize,
    /// Outputs.
    pub outputs: usize,
    /// Offset of the weights.
    pub weights: usize,
    /// Offset of the biases.
    pub biases: usize,
}

/// The six layers' slots and the total number of MLP parameters.
#[must_use]
pub fn mlp_layout(config: &NeuralConfig) -> ([LayerSlot; 6], usize) {
    let mut at = 0;
    let slots = config.layer_shapes().map(|(inputs, outputs)| {
        let s = LayerSlot {
            inputs,
            outputs,
            weights: at,
            biases: at + inputs * outputs,
        };
        at += inputs * outputs + outputs;
        s
    });
    (slots, at)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_the_issues_shape() {
        let c = NeuralConfig::default();
        c.check().unwrap();
        assert_eq!(
            (0..4).map(|l| c.resolution(l)).collect::<Vec<_>>(),
            [16, 32, 64, 128]
        );
        let (slots, total) = mlp_layout(&c);
        assert_eq!(slots[0].inputs, 39);
        assert_eq!(slots[2].outputs, 65);
        assert_eq!(slots[3].inputs, 67);
        assert_eq!(
            total,
            39 * 64 + 64 + 64 * 64 + 64 + 64 * 65 + 65 + 67 * 64 + 64 + 64 * 64 + 64 + 64 * 3 + 3
        );
        let bad = NeuralConfig {
            growth: f64::NAN,
            ..c
        };
        assert!(bad.check().unwrap_err().to_string().contains("growth"));
    }
}
