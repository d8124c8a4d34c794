//! Marching tetrahedra over the sign of the field: one vertex per crossing edge (welded: an
//! edge is shared by every tetrahedron around it), one or two triangles per crossing
//! tetrahedron, each facing from the inside (field at or above the level) to the outside.
//! The result does not depend on the order of the tetrahedra or of their vertices (a
//! tetrahedralisation carried from the last frame lists them in another order than a
//! rebuild): each tetrahedron is read with its vertices sorted, and the triangles are sorted.

use glam::DVec3;
use rayon::prelude::*;

/// The crossing edges and the triangles over them.
#[derive(Debug, Default)]
pub(crate) struct Crossings {
    /// Each crossing edge as (inside point, outside point), sorted.
    pub edges: Vec<[u32; 2]>,
    /// Triangles, as indices into `edges`, facing the outside.
    pub triangles: Vec<[u32; 3]>,
}

/// Tetrahedra marched per parallel task: fixed, so the output order (concatenated chunk by
/// chunk) does not depend on the thread count.
const MARCH_CHUNK: usize = 1 << 16;

/// Marching tetrahedra on `tets` over `points` whose side is `inside[i]`. Only the crossing
/// tetrahedra's triangles are held (memory grows with the surface, not the volume: at 1M
/// Gaussians, ~60M tetrahedra, of which a few percent cross).
pub(crate) fn march(points: &[DVec3], tets: &[[u32; 4]], inside: &[bool]) -> Crossings {
    // Per chunk of tetrahedra: the triangles of its crossing ones as point pairs, oriented.
    let chunks: Vec<Vec<[[u32; 2]; 3]>> = tets
        .par_chunks(MARCH_CHUNK)
        .map(|chunk| {
            let mut out = Vec::new();
            for tet in chunk {
                let (tris, n) = tet_triangles(points, tet, inside);
                out.extend_from_slice(&tris[..usize::from(n)]);
            }
            out
        })
        .collect();
    let local: Vec<[[u32; 2]; 3]> = chunks.concat();
    drop(chunks);
    let mut edges: Vec<[u32; 2]> = local.iter().flatten().copied().collect();
    edges.par_sort_unstable();
    edges.dedup();
    edges.shrink_to_fit();
    let find = |e: [u32; 2]| edges.binary_search(&e).map_or(0, |i| i as u32);
    let mut triangles: Vec<[u32; 3]> = local
        .par_iter()
        .map(|t| {
            // Smallest edge first, the orientation kept.
            let [a, b, c] = [find(t[0]), find(t[1]), find(t[2])];
            if a <= b && a <= c {
                [a, b, c]
            } else if b <= c {
                [b, c, a]
            } else {
                [c, a, b]
            }
        })
        .collect();
    drop(local);
    triangles.par_sort_unstable();
    Crossings { edges, triangles }
}

/// The triangles of one tetrahedron (0, 1 or 2), each as three (inside, outside) edges, facing
/// the outside points.
fn tet_triangles(points: &[DVec3], tet: &[u32; 4], inside: &[bool]) -> ([[[u32; 2]; 3]; 2], u8) {
    let mut tet = *tet;
    tet.sort_unstable();
    let mut ins = [0u32; 4];
    let mut outs = [0u32; 4];
    let (mut ni, mut no) = (0, 0);
    for v in tet {
        if inside[v as usize] {
            ins[ni] = v;
            ni += 1;
        } else {
            outs[no] = v;
            no += 1;
        }
    }
    let mut tris = [[[0u32; 2]; 3]; 2];
    if ni == 0 || ni == 4 {
        return (tris, 0);
    }
    let n = match ni {
        1 => {
            tris[0] = [[ins[0], outs[0]], [ins[0], outs[1]], [ins[0], outs[2]]];
            1
        }
        3 => {
            tris[0] = [[ins[0], outs[0]], [ins[1], outs[0]], [ins[2], outs[0]]];
            1
        }
        2 => {
            // The quad ac, ad, bd, bc (a, b inside; c, d outside), split along ac-bd.
            let (a, b, c, d) = (ins[0], ins[1], outs[0], outs[1]);
            tris[0] = [[a, c], [a, d], [b, d]];
            tris[1] = [[a, c], [b, d], [b, c]];
            2
        }
        _ => 0,
    };
    let centroid =
        |vs: &[u32]| vs.iter().map(|&v| points[v as usize]).sum::<DVec3>() / vs.len() as f64;
    let outward = centroid(&outs[..no]) - centroid(&ins[..ni]);
    let mid = |e: [u32; 2]| (points[e[0] as usize] + points[e[1] as usize]) * 0.5;
    for tri in &mut tris[..n] {
        let [p0, p1, p2] = tri.map(mid);
        if (p1 - p0).cross(p2 - p0).dot(outward) < 0.0 {
            tri.swap(1, 2);
        }
    }
    (tris, n as u8)
}
