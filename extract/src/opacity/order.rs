//! Z-order of the points a field evaluation walks, so that consecutive points fall in the same
//! screen tiles of every view and share that tile's Gaussians in cache.

use glam::DVec3;
use rayon::prelude::*;

/// Spreads the low 21 bits of `v` to every third bit.
fn spread(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    (x | x << 2) & 0x1249_2492_4924_9249
}

/// Indices of `points` along a Morton curve over their finite bounds (non-finite points
/// last), ties by index: a permutation that does not depend on the thread count.
pub(crate) fn z_order(points: &[DVec3]) -> Vec<u32> {
    let (lo, hi) = points
        .iter()
        .filter(|p| p.is_finite())
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    let scale = ((1u64 << 21) - 1) as f64 / (hi - lo).max_element().max(f64::MIN_POSITIVE);
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let code = if p.is_finite() {
                let q = ((*p - lo) * scale).max(DVec3::ZERO);
                spread(q.x as u64) | spread(q.y as u64) << 1 | spread(q.z as u64) << 2
            } else {
                u64::MAX
            };
            (code, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn z_order_is_a_permutation_grouping_neighbours() {
        let mut points: Vec<DVec3> = (0..64)
            .map(|i| DVec3::new(f64::from(i % 4), f64::from(i / 4 % 4), f64::from(i / 16)))
            .collect();
        points.push(DVec3::NAN);
        let order = z_order(&points);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..65).collect::<Vec<u32>>());
        assert_eq!(order[64], 64);
        // The first 8 form the 2x2x2 corner cube.
        assert!(
            order[..8]
                .iter()
                .all(|&i| points[i as usize].max_element() <= 1.0)
        );
    }
}
