//! The multiresolution hash grid's addressing (instant-ngp, Müller et al. 2022): per level a
//! resolution, a table of feature rows, and for a point in the unit cube the 8 rows of its
//! cell's corners with their trilinear weights.
//!
//! Level `l` has `N_l` cells per axis (`N_l + 1` vertices). Its table has
//! `min(T, (N_l + 1)³)` rows: where the whole grid fits it is indexed densely,
//! `x + (N + 1)(y + (N + 1) z)`, as instant-ngp does; otherwise by the spatial hash
//! `(x·1 ⊕ y·2654435761 ⊕ z·805459861) mod T` in wrapping `u32` arithmetic (`T` a power of 2).

use super::config::{HASH_PRIMES, NeuralConfig};

/// One level's addressing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Level {
    /// Cells per axis.
    pub resolution: u32,
    /// Rows of the table.
    pub rows: u32,
    /// First row of this level in the concatenated tables.
    pub offset: u32,
    /// Whether the grid is indexed densely (else hashed).
    pub dense: bool,
}

/// The levels of a hash grid and their rows in one concatenated table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HashGrid {
    levels: Vec<Level>,
    total_rows: usize,
}

impl HashGrid {
    /// The grid of `config` (assumed checked).
    #[must_use]
    pub fn new(config: &NeuralConfig) -> Self {
        let t = 1u64 << config.log2_table_size;
        let mut offset = 0u64;
        let levels = (0..config.levels)
            .map(|l| {
                let resolution = config.resolution(l);
                let vertices = u64::from(resolution) + 1;
                let full = vertices * vertices * vertices;
                let rows = full.min(t);
                let level = Level {
                    resolution,
                    rows: rows as u32,
                    offset: offset as u32,
                    dense: full <= t,
                };
                offset += rows;
                level
            })
            .collect();
        Self {
            levels,
            total_rows: offset as usize,
        }
    }

    /// The levels, coarsest first.
    #[must_use]
    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// Rows of all levels together.
    #[must_use]
    pub fn total_rows(&self) -> usize {
        self.total_rows
    }

    /// The 8 corner rows (global, i.e. with the level's offset) of the cell holding `unit`
    /// (each coordinate clamped to 0..1) at `level`, and their trilinear weights (summing to 1).
    /// Corner `c` is the vertex offset by `(c & 1, c >> 1 & 1, c >> 2 & 1)`.
    #[must_use]
    pub fn corners(&self, level: usize, unit: [f64; 3]) -> ([u32; 8], [f64; 8]) {
        let lv = self.levels[level];
        let n = lv.resolution;
        let mut cell = [0u32; 3];
        let mut frac = [0.0f64; 3];
        for a in 0..3 {
            let x = unit[a].clamp(0.0, 1.0) * f64::from(n);
            let i = (x.floor() as u32).min(n - 1);
            cell[a] = i;
            frac[a] = x - f64::from(i);
        }
        let mut rows = [0u32; 8];
        let mut weights = [0.0f64; 8];
        for c in 0..8 {
            let mut v = [0u32; 3];
            let mut w = 1.0;
            for a in 0..3 {
                let bit = (c >> a) & 1 == 1;
                v[a] = cell[a] + u32::from(bit);
                w *= if bit { frac[a] } else { 1.0 - frac[a] };
            }
            rows[c] = lv.offset + index(lv, v);
            weights[c] = w;
        }
        (rows, weights)
    }
}

/// The row of vertex `v` inside its level's table.
fn index(level: Level, v: [u32; 3]) -> u32 {
    if level.dense {
        let s = level.resolution + 1;
        v[0] + s * (v[1] + s * v[2])
    } else {
        let h = v[0].wrapping_mul(HASH_PRIMES[0])
            ^ v[1].wrapping_mul(HASH_PRIMES[1])
            ^ v[2].wrapping_mul(HASH_PRIMES[2]);
        h & (level.rows - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_follow_instant_ngp() {
        let grid = HashGrid::new(&NeuralConfig::default());
        let l = grid.levels();
        // 17³, 33³, 65³ fit in 2^19 rows; 129³ does not.
        assert_eq!(
            l.iter().map(|l| l.dense).collect::<Vec<_>>(),
            [true, true, true, false]
        );
        assert_eq!(l[0].rows, 17 * 17 * 17);
        assert_eq!(l[3].rows, 1 << 19);
        assert_eq!(l[1].offset, 17 * 17 * 17);
        assert_eq!(grid.total_rows(), 4913 + 35937 + 274_625 + 524_288);
        // The hash of instant-ngp's tcnn `grid_index`: coordinate times prime, xor, mod T.
        let h = (3u32 ^ 5u32.wrapping_mul(2_654_435_761) ^ 7u32.wrapping_mul(805_459_861))
            & ((1 << 19) - 1);
        assert_eq!(index(l[3], [3, 5, 7]), h);
    }

    #[test]
    fn corners_interpolate_trilinearly() {
        let grid = HashGrid::new(&NeuralConfig::default());
        let (rows, w) = grid.corners(0, [0.5 / 16.0, 0.25, 1.0]);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // x sits in the middle of cell 0, y on vertex 4, z on the last vertex (16).
        let base = 4 * 17 + 16 * 17 * 17;
        assert_eq!(rows[0], base as u32 - 17 * 17);
        assert!((w[0b100] - 0.5).abs() < 1e-12 && (w[0b101] - 0.5).abs() < 1e-12);
        assert_eq!(rows[0b101], base as u32 + 1);
    }
}
