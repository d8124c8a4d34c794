//! Morton (Z-order) sorting of query points, so that tree searches reuse cached nodes.

use glam::Vec3;
use rayon::prelude::*;

use crate::mesh::Aabb;

/// Spreads the low 21 bits of `v` to every third bit (for 63-bit Morton codes).
fn spread_bits(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// Indices of `points` (finite) sorted along a Morton (Z-order) curve over their bounds, ties by
/// index: nearby queries end up next to each other, so tree searches reuse cached nodes.
pub(crate) fn morton_order(points: &[Vec3]) -> Vec<u32> {
    morton_sorted(points).into_iter().map(|(_, i)| i).collect()
}

/// `(Morton code, index)` of every point (finite), sorted (see [`morton_order`]).
pub(crate) fn morton_sorted(points: &[Vec3]) -> Vec<(u64, u32)> {
    let Some(bounds) = Aabb::from_points(points) else {
        return Vec::new();
    };
    let lo = bounds.min;
    let extent = (bounds.max - lo).max_element();
    let scale = if extent > 0.0 {
        f64::from((1u32 << 21) - 1) / extent
    } else {
        0.0
    };
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = ((p.as_dvec3() - lo) * scale).max(glam::DVec3::ZERO);
            let code = spread_bits(c.x as u64)
                | (spread_bits(c.y as u64) << 1)
                | (spread_bits(c.z as u64) << 2);
            // Point counts are checked against u32 by the callers' indices.
            (code, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_order_is_a_permutation() {
        let points: Vec<Vec3> = (0..1000)
            .map(|i| Vec3::new((i % 10) as f32, (i / 10 % 10) as f32, (i / 100) as f32))
            .collect();
        let mut order = morton_order(&points);
        assert_eq!(order[0], 0);
        order.sort_unstable();
        assert!(order.iter().enumerate().all(|(i, &o)| o as usize == i));
        assert!(morton_order(&[]).is_empty());
        assert_eq!(morton_order(&[Vec3::ONE; 3]), vec![0, 1, 2]);
    }
}
