//! Connected pieces of a triangle soup over shared vertices, measured by area.

use glam::DVec3;

/// The pieces of `triangles` (connected through shared vertices): each triangle's piece,
/// pieces numbered by decreasing area (ties: by first triangle), and each piece's area.
pub(crate) fn pieces(positions: &[DVec3], triangles: &[[u32; 3]]) -> (Vec<u32>, Vec<f64>) {
    let mut parent: Vec<u32> = (0..positions.len() as u32).collect();
    fn root(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            let up = parent[parent[v as usize] as usize];
            parent[v as usize] = up;
            v = up;
        }
        v
    }
    for t in triangles {
        for k in 1..3 {
            let (a, b) = (root(&mut parent, t[0]), root(&mut parent, t[k]));
            if a != b {
                let (lo, hi) = (a.min(b), a.max(b));
                parent[hi as usize] = lo;
            }
        }
    }
    // Number roots in order of first triangle.
    let mut label = vec![u32::MAX; positions.len()];
    let mut first_area: Vec<f64> = Vec::new();
    let mut raw = Vec::with_capacity(triangles.len());
    for t in triangles {
        let r = root(&mut parent, t[0]) as usize;
        if label[r] == u32::MAX {
            label[r] = first_area.len() as u32;
            first_area.push(0.0);
        }
        let [a, b, c] = t.map(|v| positions[v as usize]);
        first_area[label[r] as usize] += 0.5 * (b - a).cross(c - a).length();
        raw.push(label[r]);
    }
    let mut order: Vec<u32> = (0..first_area.len() as u32).collect();
    order.sort_by(|&a, &b| {
        first_area[b as usize]
            .total_cmp(&first_area[a as usize])
            .then(a.cmp(&b))
    });
    let mut rank = vec![0u32; order.len()];
    for (i, &o) in order.iter().enumerate() {
        rank[o as usize] = i as u32;
    }
    let areas = order.iter().map(|&o| first_area[o as usize]).collect();
    (raw.into_iter().map(|l| rank[l as usize]).collect(), areas)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_pieces_by_area() {
        let p = [
            DVec3::ZERO,
            DVec3::X,
            DVec3::Y,
            DVec3::new(5.0, 0.0, 0.0),
            DVec3::new(8.0, 0.0, 0.0),
            DVec3::new(5.0, 3.0, 0.0),
        ];
        let (piece, areas) = pieces(&p, &[[0, 1, 2], [3, 4, 5]]);
        assert_eq!(piece, vec![1, 0]);
        assert!((areas[0] - 4.5).abs() < 1e-12 && (areas[1] - 0.5).abs() < 1e-12);
    }
}
