//! Marching tetrahedra over the sign of the field: one vertex per crossing edge (welded: an
//! edge is shared by every tetrahedron around it), one or two triangles per crossing
//! tetrahedron, each facing from the inside (field at or above the level) to the outside.
//! The result does not depend on the order of the tetrahedra or of their vertices (a
//! tetrahedralisation carried from the last frame lists them in another order than a
//! rebuild): each tetrahedron is read with its vertices sorted, and the triangles are sorted.

use glam::DVec3;
use rayon::prelude::*;

use crate::delaunay3d::orient3d;

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
    // The triangles as listed face the outside exactly when the tetrahedron (ins..., outs...)
    // is negatively oriented in Shewchuk's convention (`det[q1 - q0, q2 - q0, q3 - q0] > 0`;
    // for two inside points the quad's two triangles both follow, however bent the quad is).
    // The sign is exact: a sliver of four nearly coplanar points (a flat Gaussian's box face)
    // has a volume below the rounding of any midpoint normal, which turned such triangles
    // against their neighbours before.
    let mut q = [0u32; 4];
    q[..ni].copy_from_slice(&ins[..ni]);
    q[ni..].copy_from_slice(&outs[..no]);
    let at = |v: u32| points[v as usize].to_array();
    let orientation = orient3d(at(q[0]), at(q[1]), at(q[2]), at(q[3]));
    let flip = if orientation != 0.0 {
        orientation > 0.0
    } else {
        // Flat (never from an exact Delaunay): the midpoints' normal against the direction
        // from the inside to the outside points.
        let centroid =
            |vs: &[u32]| vs.iter().map(|&v| points[v as usize]).sum::<DVec3>() / vs.len() as f64;
        let outward = centroid(&outs[..no]) - centroid(&ins[..ni]);
        let mid = |e: [u32; 2]| (points[e[0] as usize] + points[e[1] as usize]) * 0.5;
        let [p0, p1, p2] = tris[0].map(mid);
        (p1 - p0).cross(p2 - p0).dot(outward) < 0.0
    };
    if flip {
        for tri in &mut tris[..n] {
            tri.swap(1, 2);
        }
    }
    (tris, n as u8)
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use glam::{DMat3, DQuat};

    use super::*;
    use crate::delaunay3d::Delaunay3d;

    /// A small deterministic generator (no dependency).
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Directed edges (in vertex indices) that two triangles run the same way.
    fn same_way_edges(triangles: &[[u32; 3]]) -> usize {
        let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
        for t in triangles {
            for k in 0..3 {
                *uses.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        uses.values().filter(|&&n| n > 1).count()
    }

    /// The rule before the exact orientation: each triangle's midpoint normal against the
    /// direction from the inside points' centroid to the outside points'.
    fn midpoint_rule_faces_out(
        points: &[DVec3],
        ins: &[u32],
        outs: &[u32],
        tri: [[u32; 2]; 3],
    ) -> bool {
        let centroid =
            |vs: &[u32]| vs.iter().map(|&v| points[v as usize]).sum::<DVec3>() / vs.len() as f64;
        let outward = centroid(outs) - centroid(ins);
        let mid = |e: [u32; 2]| (points[e[0] as usize] + points[e[1] as usize]) * 0.5;
        let [p0, p1, p2] = tri.map(mid);
        (p1 - p0).cross(p2 - p0).dot(outward) > 0.0
    }

    /// On well-shaped tetrahedra, every side pattern: the exact orientation gives the triangles
    /// the side the midpoint rule gives them (the sign convention is right).
    #[test]
    fn exact_orientation_agrees_with_the_geometry_on_fat_tetrahedra() {
        let mut state = 5u64;
        let mut checked = 0;
        for _ in 0..300 {
            let points: Vec<DVec3> = (0..4)
                .map(|_| DVec3::new(lcg(&mut state), lcg(&mut state), lcg(&mut state)))
                .collect();
            let p = |i: usize| points[i].to_array();
            let volume = orient3d(p(0), p(1), p(2), p(3)).abs();
            if volume < 1e-3 {
                continue;
            }
            for pattern in 1..15u32 {
                let inside: Vec<bool> = (0..4).map(|i| pattern >> i & 1 == 1).collect();
                let (tris, n) = tet_triangles(&points, &[0, 1, 2, 3], &inside);
                let ins: Vec<u32> = (0..4).filter(|&i| inside[i as usize]).collect();
                let outs: Vec<u32> = (0..4).filter(|&i| !inside[i as usize]).collect();
                for tri in &tris[..usize::from(n)] {
                    assert!(
                        midpoint_rule_faces_out(&points, &ins, &outs, *tri),
                        "{points:?} {pattern}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 1000, "{checked}");
    }

    /// Flat Gaussians' 3-sigma boxes, as the opacity points are made (centre + 8 corners in
    /// f64): the four corners of a box face are coplanar up to rounding, so the Delaunay has
    /// slivers whose volume is below the rounding of a midpoint normal. Over random sides every
    /// edge of the marched surface has its two triangles running opposite ways; the midpoint
    /// rule (before) turned some sliver's triangles against their neighbours (LAM frames 450
    /// and 900: 3 such edges each).
    #[test]
    fn slivers_of_flat_boxes_keep_the_surface_oriented() {
        let mut state = 11u64;
        let mut points = Vec::new();
        for _ in 0..400 {
            let mean = DVec3::new(lcg(&mut state), lcg(&mut state), lcg(&mut state)) * 0.1;
            let q = DQuat::from_xyzw(
                lcg(&mut state) - 0.5,
                lcg(&mut state) - 0.5,
                lcg(&mut state) - 0.5,
                lcg(&mut state) - 0.5,
            )
            .normalize();
            let r = DMat3::from_quat(q);
            let s = 0.004 * lcg(&mut state) + 0.001;
            let axes = [r.x_axis * s, r.y_axis * s, r.z_axis * (s * 1e-3)];
            points.push(mean);
            for corner in 0..8u32 {
                let sign = |bit: u32| if corner >> bit & 1 == 0 { -3.0 } else { 3.0 };
                points.push(mean + axes[0] * sign(0) + axes[1] * sign(1) + axes[2] * sign(2));
            }
        }
        let coords: Vec<[f64; 3]> = points.iter().map(|p| p.to_array()).collect();
        let (tets, dimension) = Delaunay3d::finite_tetrahedra(&coords).expect("delaunay");
        assert_eq!(dimension, 3);
        // The same surface with each triangle turned as the midpoint rule (before) turned it.
        let mut same_way_before = 0;
        for round in 0..6 {
            let inside: Vec<bool> = (0..points.len()).map(|_| lcg(&mut state) < 0.5).collect();
            let crossings = march(&points, &tets, &inside);
            assert!(!crossings.triangles.is_empty());
            assert_eq!(same_way_edges(&crossings.triangles), 0, "round {round}");
            let mut before = Vec::new();
            for tet in &tets {
                let (tris, n) = tet_triangles(&points, tet, &inside);
                let ins: Vec<u32> = tet
                    .iter()
                    .copied()
                    .filter(|&v| inside[v as usize])
                    .collect();
                let outs: Vec<u32> = tet
                    .iter()
                    .copied()
                    .filter(|&v| !inside[v as usize])
                    .collect();
                for mut t in tris.into_iter().take(usize::from(n)) {
                    if !midpoint_rule_faces_out(&points, &ins, &outs, t) {
                        t.swap(1, 2);
                    }
                    let id = |e: [u32; 2]| crossings.edges.binary_search(&e).expect("edge") as u32;
                    before.push(t.map(id));
                }
            }
            same_way_before += same_way_edges(&before);
        }
        // The case is one the rule before gets wrong.
        assert!(
            same_way_before > 0,
            "no sliver misoriented by the midpoint rule"
        );
    }
}
