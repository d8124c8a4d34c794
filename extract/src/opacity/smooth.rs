//! The median field's settled surface made smooth: Taubin smoothing (Open3D's rule: λ = 1/2
//! then μ = -0.53 per iteration, inverse-distance weights over the 1-ring, Jacobi steps) of the
//! vertices that settling moved, the others held. Settling moves each vertex on its own, onto
//! the median depth, so neighbouring vertices land up to a tetrahedron's resolution apart
//! along the normal: a saw-tooth that adds area and turns normals. Vertices that did not
//! settle (thin layers and rims that keep the margin) are held, so thin parts are not shrunk.

use glam::DVec3;
use rayon::prelude::*;

/// Taubin's first step (Open3D's default).
const LAMBDA: f64 = 0.5;
/// Taubin's second, inflating step (Open3D's default).
const MU: f64 = -0.53;
/// Open3D's offset in the inverse-distance weight.
const OFFSET: f64 = 1e-12;

/// `vertices` after `iterations` Taubin iterations over the 1-rings of `triangles`, moving only
/// the vertices whose `free` is true (the rest are held, and still pull their neighbours).
/// Deterministic: every step reads only the previous iterate.
pub(crate) fn taubin_free(
    vertices: Vec<DVec3>,
    triangles: &[[u32; 3]],
    free: &[bool],
    iterations: u32,
) -> Vec<DVec3> {
    if iterations == 0 || !free.iter().any(|&f| f) {
        return vertices;
    }
    let ring = rings(vertices.len(), triangles);
    let mut cur = vertices;
    let mut next = cur.clone();
    for _ in 0..iterations {
        for step in [LAMBDA, MU] {
            next.par_iter_mut()
                .enumerate()
                .with_min_len(1024)
                .for_each(|(v, out)| {
                    let x = cur[v];
                    *out = x;
                    if !free[v] {
                        return;
                    }
                    let (mut sum, mut weight) = (DVec3::ZERO, 0.0);
                    for &j in &ring.1[ring.0[v] as usize..ring.0[v + 1] as usize] {
                        let y = cur[j as usize];
                        let w = 1.0 / ((y - x).length() + OFFSET);
                        sum += y * w;
                        weight += w;
                    }
                    if weight > 0.0 {
                        let moved = x + (sum / weight - x) * step;
                        if moved.is_finite() {
                            *out = moved;
                        }
                    }
                });
            std::mem::swap(&mut cur, &mut next);
        }
    }
    cur
}

/// The 1-ring of every vertex (distinct neighbours, ascending), as offsets and a flat list.
fn rings(n: usize, triangles: &[[u32; 3]]) -> (Vec<u32>, Vec<u32>) {
    let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(triangles.len() * 6);
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a != b {
                pairs.push((a, b));
                pairs.push((b, a));
            }
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    let mut start = vec![0u32; n + 1];
    for &(a, _) in &pairs {
        start[a as usize + 1] += 1;
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    (start, pairs.into_iter().map(|(_, b)| b).collect())
}
