//! A sparse grid of voxel blocks: the storage of [`crate::tsdf::TsdfVolume`] and the input of
//! [`crate::marching_cubes()`].
//!
//! Voxel `g` (an integer index) sits at `origin + g * voxel`. Voxels are stored in blocks of
//! [`BLOCK`]³; block `k` holds voxels `8k .. 8k + 7` on each axis. Each voxel has a value (the
//! truncated signed distance, negative inside), a weight (0 = never observed) and, when the grid
//! has colours, an RGB colour. Blocks are kept in creation order; a hash map finds them by key.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use glam::{DVec3, IVec3};
use rayon::iter::ParallelExtend as _;

/// Voxels along each edge of a block.
pub const BLOCK: i32 = 8;
/// Voxels in a block.
pub const BLOCK_VOXELS: usize = (BLOCK * BLOCK * BLOCK) as usize;

/// A small multiplicative hasher for block keys (three `i32`s): std's SipHash costs more than
/// the work done per block lookup. Keys are not attacker-chosen in a way that matters here
/// (a pathological input only slows the map down).
#[derive(Clone, Copy, Debug, Default)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }

    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    #[inline]
    fn write_i32(&mut self, i: i32) {
        self.write_u64(u64::from(i as u32));
    }

    #[inline]
    fn write_u64(&mut self, i: u64) {
        // FxHash's step.
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Hash map from block keys.
pub type KeyMap<V> = HashMap<IVec3, V, BuildHasherDefault<KeyHasher>>;

/// Index of a voxel inside its block: `x + 8y + 64z` for local coordinates in `0..8`.
#[inline]
#[must_use]
pub fn local_index(local: IVec3) -> usize {
    (local.x + BLOCK * (local.y + BLOCK * local.z)) as usize
}

/// Local coordinates of a voxel index inside a block (inverse of [`local_index`]).
#[inline]
#[must_use]
pub fn local_coords(index: usize) -> IVec3 {
    let i = index as i32;
    IVec3::new(i % BLOCK, (i / BLOCK) % BLOCK, i / (BLOCK * BLOCK))
}

/// The block holding voxel `g` and the voxel's local coordinates in it.
#[inline]
#[must_use]
pub fn split(g: IVec3) -> (IVec3, IVec3) {
    (
        g.div_euclid(IVec3::splat(BLOCK)),
        g.rem_euclid(IVec3::splat(BLOCK)),
    )
}

/// Sparse block storage (see the module docs).
#[derive(Clone, Debug)]
pub struct BlockGrid {
    /// Edge length of a voxel.
    pub(crate) voxel: f64,
    /// Position of voxel index (0, 0, 0).
    pub(crate) origin: DVec3,
    /// Block keys in creation order.
    pub(crate) keys: Vec<IVec3>,
    /// Key -> position in `keys`.
    pub(crate) lookup: KeyMap<u32>,
    /// `BLOCK_VOXELS` values per block.
    pub(crate) value: Vec<f32>,
    /// `BLOCK_VOXELS` weights per block (0 = unobserved).
    pub(crate) weight: Vec<f32>,
    /// `BLOCK_VOXELS` colours per block, when the grid carries colour.
    pub(crate) color: Option<Vec<[f32; 3]>>,
}

impl BlockGrid {
    /// An empty grid.
    #[must_use]
    pub(crate) fn new(voxel: f64, origin: DVec3, with_color: bool) -> Self {
        Self {
            voxel,
            origin,
            keys: Vec::new(),
            lookup: KeyMap::default(),
            value: Vec::new(),
            weight: Vec::new(),
            color: with_color.then(Vec::new),
        }
    }

    /// A grid over a dense array of samples: sample `(i, j, k)` of a `dims[0] x dims[1] x
    /// dims[2]` array in x-fastest order sits at `origin + (i, j, k) * spacing`. Non-finite
    /// samples are unobserved (weight 0). Blocks without any finite sample are not stored.
    ///
    /// Returns `None` when a dimension exceeds `i32::MAX / 2` or `values` has the wrong length.
    #[must_use]
    pub fn from_dense(
        values: &[f32],
        dims: [usize; 3],
        origin: DVec3,
        spacing: f64,
    ) -> Option<Self> {
        let limit = (i32::MAX / 2) as usize;
        if dims.iter().any(|&d| d > limit) {
            return None;
        }
        let count = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d))?;
        if count != values.len() {
            return None;
        }
        let mut grid = Self::new(spacing, origin, false);
        let blocks = dims.map(|d| d.div_ceil(BLOCK as usize) as i32);
        for bz in 0..blocks[2] {
            for by in 0..blocks[1] {
                for bx in 0..blocks[0] {
                    let key = IVec3::new(bx, by, bz);
                    let mut value = [0.0f32; BLOCK_VOXELS];
                    let mut weight = [0.0f32; BLOCK_VOXELS];
                    let mut any = false;
                    for l in 0..BLOCK_VOXELS {
                        let g = key * BLOCK + local_coords(l);
                        let [x, y, z] = g.to_array().map(|c| c as usize);
                        if x >= dims[0] || y >= dims[1] || z >= dims[2] {
                            continue;
                        }
                        let v = values[x + dims[0] * (y + dims[1] * z)];
                        if v.is_finite() {
                            value[l] = v;
                            weight[l] = 1.0;
                            any = true;
                        }
                    }
                    if any {
                        let b = grid.push_block(key);
                        grid.value[b * BLOCK_VOXELS..(b + 1) * BLOCK_VOXELS]
                            .copy_from_slice(&value);
                        grid.weight[b * BLOCK_VOXELS..(b + 1) * BLOCK_VOXELS]
                            .copy_from_slice(&weight);
                    }
                }
            }
        }
        Some(grid)
    }

    /// Appends an empty block (all weights 0) and returns its position. The caller makes sure
    /// the key is new.
    pub(crate) fn push_block(&mut self, key: IVec3) -> usize {
        let b = self.keys.len();
        self.keys.push(key);
        self.lookup.insert(key, b as u32);
        self.value.resize(self.value.len() + BLOCK_VOXELS, 0.0);
        self.weight.resize(self.weight.len() + BLOCK_VOXELS, 0.0);
        if let Some(color) = &mut self.color {
            color.resize(color.len() + BLOCK_VOXELS, [0.0; 3]);
        }
        b
    }

    /// Appends empty blocks for `keys` (all new, as for [`BlockGrid::push_block`]). The
    /// storage grows once, and its new pages are written (zeros) by all threads: memory
    /// that is read before it is first written costs a second page fault and a TLB
    /// shoot-down per page (20% of the time of a 185k-block fusion).
    pub(crate) fn push_blocks(&mut self, keys: &[IVec3]) {
        let voxels = (self.keys.len() + keys.len()) * BLOCK_VOXELS;
        let grow = |column: &mut Vec<f32>| {
            let old = column.len();
            column.reserve_exact(voxels - old);
            column.par_extend(rayon::iter::repeat_n(0.0, voxels - old));
        };
        grow(&mut self.value);
        grow(&mut self.weight);
        if let Some(color) = &mut self.color {
            color.resize(voxels, [0.0; 3]);
        }
        self.keys.reserve(keys.len());
        self.lookup.reserve(keys.len());
        for &key in keys {
            self.lookup.insert(key, self.keys.len() as u32);
            self.keys.push(key);
        }
    }

    /// Number of blocks.
    #[must_use]
    pub fn block_count(&self) -> usize {
        self.keys.len()
    }

    /// Block keys in creation order.
    #[must_use]
    pub fn keys(&self) -> &[IVec3] {
        &self.keys
    }

    /// Voxel edge length.
    #[must_use]
    pub fn voxel(&self) -> f64 {
        self.voxel
    }

    /// Position of voxel index (0, 0, 0).
    #[must_use]
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Whether voxels carry colours.
    #[must_use]
    pub fn has_color(&self) -> bool {
        self.color.is_some()
    }

    /// Position of voxel `g`.
    #[inline]
    #[must_use]
    pub fn position(&self, g: IVec3) -> DVec3 {
        self.origin + g.as_dvec3() * self.voxel
    }

    /// Storage slot of voxel `g` (block * BLOCK_VOXELS + local), `None` when its block is not
    /// allocated.
    #[inline]
    #[must_use]
    pub fn slot(&self, g: IVec3) -> Option<usize> {
        let (key, local) = split(g);
        let b = *self.lookup.get(&key)? as usize;
        Some(b * BLOCK_VOXELS + local_index(local))
    }

    /// `(value, weight)` of voxel `g`; `None` when its block is not allocated (the voxel is
    /// unobserved).
    #[must_use]
    pub fn voxel_value(&self, g: IVec3) -> Option<(f32, f32)> {
        self.slot(g).map(|s| (self.value[s], self.weight[s]))
    }

    /// Number of voxels with a non-zero weight.
    #[must_use]
    pub fn observed_voxels(&self) -> usize {
        self.weight.iter().filter(|&&w| w > 0.0).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_index_round_trips() {
        for l in 0..BLOCK_VOXELS {
            assert_eq!(local_index(local_coords(l)), l);
        }
        let (key, local) = split(IVec3::new(-1, 8, 17));
        assert_eq!(key, IVec3::new(-1, 1, 2));
        assert_eq!(local, IVec3::new(7, 0, 1));
    }

    #[test]
    fn dense_grid_keeps_finite_samples() {
        let dims = [10, 3, 2];
        let mut values: Vec<f32> = (0..60).map(|i| i as f32).collect();
        values[5] = f32::NAN;
        let grid = BlockGrid::from_dense(&values, dims, DVec3::ZERO, 0.5).unwrap();
        assert_eq!(grid.block_count(), 2);
        assert_eq!(grid.voxel_value(IVec3::new(9, 2, 1)), Some((59.0, 1.0)));
        assert_eq!(
            grid.voxel_value(IVec3::new(5, 0, 0)).map(|v| v.1),
            Some(0.0)
        );
        assert_eq!(
            grid.voxel_value(IVec3::new(0, 7, 0)).map(|v| v.1),
            Some(0.0)
        );
        assert_eq!(grid.voxel_value(IVec3::new(0, 0, 9)), None);
        assert_eq!(grid.observed_voxels(), 59);
        assert!(BlockGrid::from_dense(&values, [10, 3, 3], DVec3::ZERO, 0.5).is_none());
    }
}
