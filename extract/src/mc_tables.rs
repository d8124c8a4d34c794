//! Marching-cubes case tables, generated once from the cube's faces instead of typed in.
//!
//! Cube corners are numbered `c = x + 2y + 4z` with `x, y, z ∈ {0, 1}`. Edge `e = 4 * axis + k`
//! runs along `axis` (0 = x, 1 = y, 2 = z) from the corner whose coordinate on that axis is 0;
//! `k` numbers the two other coordinates `(a, b)` as `a + 2b` (for the x axis `(y, z)`, for y
//! `(x, z)`, for z `(x, y)`). The case index sets bit `c` when corner `c` is *inside*
//! (value < 0), as in Lorensen and Cline's and Bourke's tables.
//!
//! For every case the surface polygons are built from their boundary on the six cube faces:
//! on each face, one segment cuts off each run of inside corners. A face with two diagonal
//! inside corners (the ambiguous face) always gets two segments, one around each inside corner,
//! i.e. the outside region stays connected across the face — the same choice as Bourke's table
//! (case 5 gives two separate triangles). Because this choice depends only on the face's four
//! corners, the two cells sharing a face draw the same segments on it, so the surface is closed
//! wherever every cell is polygonised (tested on random fields). Segments are directed so that
//! their loops, fanned into triangles, face the outside (value ≥ 0) region.

use std::sync::LazyLock;

/// Most triangles any case produces (checked when the table is built).
pub const MAX_TRIANGLES: usize = 5;

/// Corner offsets `(x, y, z)` of the 8 cube corners, by corner number.
pub const CORNERS: [[u8; 3]; 8] = {
    let mut out = [[0u8; 3]; 8];
    let mut c = 0;
    while c < 8 {
        out[c] = [(c & 1) as u8, ((c >> 1) & 1) as u8, ((c >> 2) & 1) as u8];
        c += 1;
    }
    out
};

/// For each edge, `(corner at the low end, corner at the high end, axis)`.
pub const EDGES: [(u8, u8, u8); 12] = {
    let mut out = [(0u8, 0u8, 0u8); 12];
    let mut e = 0;
    while e < 12 {
        let axis = e / 4;
        let k = e % 4;
        let (a, b) = (k & 1, (k >> 1) & 1);
        // Coordinates of the low corner: 0 on `axis`, (a, b) on the two others in order.
        let mut xyz = [0usize; 3];
        let (i, j) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        xyz[i] = a;
        xyz[j] = b;
        let low = xyz[0] + 2 * xyz[1] + 4 * xyz[2];
        let high = low + (1 << axis);
        out[e] = (low as u8, high as u8, axis as u8);
        e += 1;
    }
    out
};

/// One case of the table: up to [`MAX_TRIANGLES`] triangles given as three edge numbers each.
#[derive(Clone, Copy, Debug, Default)]
pub struct Case {
    /// Triangles as edge numbers (the vertex lies on that edge), facing the outside.
    pub triangles: [[u8; 3]; MAX_TRIANGLES],
    /// How many of `triangles` are used.
    pub count: u8,
}

impl Case {
    /// The used triangles.
    #[inline]
    #[must_use]
    pub fn triangles(&self) -> &[[u8; 3]] {
        &self.triangles[..usize::from(self.count)]
    }
}

/// The 256 cases, built on first use.
pub static TABLE: LazyLock<[Case; 256]> = LazyLock::new(build_table);

/// Bit mask of the edges crossed by the surface in each case (Bourke's `edgeTable`).
#[must_use]
pub fn crossed_edges(case: u8) -> u16 {
    let mut mask = 0u16;
    for (e, &(a, b, _)) in EDGES.iter().enumerate() {
        if ((case >> a) & 1) != ((case >> b) & 1) {
            mask |= 1 << e;
        }
    }
    mask
}

/// The edge joining two corners that differ in one coordinate.
fn edge_between(a: usize, b: usize) -> usize {
    let (low, high) = if a < b { (a, b) } else { (b, a) };
    EDGES
        .iter()
        .position(|&(l, h, _)| usize::from(l) == low && usize::from(h) == high)
        .unwrap_or_else(|| unreachable!("corners {a} and {b} are adjacent on a face"))
}

/// Corner position as f64 coordinates.
fn corner_point(c: usize) -> [f64; 3] {
    CORNERS[c].map(f64::from)
}

/// Midpoint of an edge (the table is combinatorial: any point inside the edge orients the
/// segments the same way).
fn edge_midpoint(e: usize) -> [f64; 3] {
    let (a, b, _) = EDGES[e];
    let (pa, pb) = (corner_point(usize::from(a)), corner_point(usize::from(b)));
    [
        0.5 * (pa[0] + pb[0]),
        0.5 * (pa[1] + pb[1]),
        0.5 * (pa[2] + pb[2]),
    ]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The six faces: four corners in cyclic order and the outward normal.
fn faces() -> [([usize; 4], [f64; 3]); 6] {
    let mut out = [([0usize; 4], [0.0f64; 3]); 6];
    for axis in 0..3 {
        let (i, j) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        for side in 0..2 {
            // Walk the square (0,0) (1,0) (1,1) (0,1) in the two other coordinates.
            let ring = [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(a, b)| {
                let mut xyz = [0usize; 3];
                xyz[axis] = side;
                xyz[i] = a;
                xyz[j] = b;
                xyz[0] + 2 * xyz[1] + 4 * xyz[2]
            });
            let mut normal = [0.0; 3];
            normal[axis] = if side == 0 { -1.0 } else { 1.0 };
            out[2 * axis + side] = (ring, normal);
        }
    }
    out
}

/// Whether two cube edges lie on a common cube face.
fn edges_share_face(a: usize, b: usize) -> bool {
    let on_face = |e: usize, axis: usize, side: u8| {
        let (low, _, edge_axis) = EDGES[e];
        usize::from(edge_axis) != axis && CORNERS[usize::from(low)][axis] == side
    };
    (0..3).any(|axis| (0..2).any(|side| on_face(a, axis, side) && on_face(b, axis, side)))
}

/// Triangulates a loop of crossed edges (in loop order, keeping its orientation) so that no
/// diagonal joins two edges of one cube face: the neighbouring cell may draw the same pair on
/// that face, and the shared mesh edge would then have more than two triangles. `None` when
/// no such triangulation exists (never for the 256 cases: tested).
fn triangulate(ring: &[usize]) -> Option<Vec<[usize; 3]>> {
    if ring.len() < 3 {
        return None;
    }
    if ring.len() == 3 {
        return Some(vec![[ring[0], ring[1], ring[2]]]);
    }
    // The triangle on the side (ring[0], ring[last]) has its apex at some m; the two sides it
    // creates must be loop sides or allowed diagonals, and the two sub-polygons must work.
    let last = ring.len() - 1;
    for m in 1..last {
        let left_ok = m == 1 || !edges_share_face(ring[0], ring[m]);
        let right_ok = m == last - 1 || !edges_share_face(ring[m], ring[last]);
        if !(left_ok && right_ok) {
            continue;
        }
        let mut out = vec![[ring[0], ring[m], ring[last]]];
        if m > 1 {
            out.extend(triangulate(&ring[..=m])?);
        }
        if m < last - 1 {
            out.extend(triangulate(&ring[m..])?);
        }
        return Some(out);
    }
    None
}

/// Builds every case (see the module docs).
fn build_table() -> [Case; 256] {
    let faces = faces();
    let mut table = [Case::default(); 256];
    for (case, entry) in table.iter_mut().enumerate() {
        let inside = |c: usize| (case >> c) & 1 == 1;
        // next[e] = the edge that follows crossing edge e along its loop.
        let mut next = [usize::MAX; 12];
        for (ring, normal) in &faces {
            // Segments: one per maximal run of inside corners around the ring.
            for start in 0..4 {
                let c = ring[start];
                let prev = ring[(start + 3) % 4];
                if !inside(c) || inside(prev) {
                    continue;
                }
                // A run of inside corners starts at `start`; find where it ends.
                let mut len = 1;
                while len < 4 && inside(ring[(start + len) % 4]) {
                    len += 1;
                }
                if len == 4 {
                    break;
                }
                let last = ring[(start + len - 1) % 4];
                let after = ring[(start + len) % 4];
                let e_in = edge_between(prev, c);
                let e_out = edge_between(last, after);
                // Inside corners of this run, for the side test.
                let run: Vec<usize> = (0..len).map(|k| ring[(start + k) % 4]).collect();
                let centroid = run.iter().fold([0.0; 3], |acc, &k| {
                    let p = corner_point(k);
                    [
                        acc[0] + p[0] / len as f64,
                        acc[1] + p[1] / len as f64,
                        acc[2] + p[2] / len as f64,
                    ]
                });
                let (a, b) = (edge_midpoint(e_in), edge_midpoint(e_out));
                // Direct a -> b so that (b - a) x n points towards the inside corners.
                let toward = dot(cross(sub(b, a), *normal), sub(centroid, a));
                let (from, to) = if toward > 0.0 {
                    (e_in, e_out)
                } else {
                    (e_out, e_in)
                };
                debug_assert_eq!(next[from], usize::MAX, "case {case}: edge {from} twice");
                next[from] = to;
            }
        }
        // Follow the loops and fan each into triangles.
        let mut used = [false; 12];
        let mut count = 0;
        for start in 0..12 {
            if next[start] == usize::MAX || used[start] {
                continue;
            }
            let mut ring = vec![start];
            used[start] = true;
            let mut e = next[start];
            while e != start {
                ring.push(e);
                used[e] = true;
                e = next[e];
            }
            let triangles = triangulate(&ring)
                .unwrap_or_else(|| unreachable!("case {case}: loop {ring:?} has no triangulation"));
            for t in triangles {
                entry.triangles[count] = t.map(|e| e as u8);
                count += 1;
            }
        }
        entry.count = count as u8;
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_join_adjacent_corners() {
        for &(a, b, axis) in &EDGES {
            let (pa, pb) = (CORNERS[usize::from(a)], CORNERS[usize::from(b)]);
            for k in 0..3 {
                let expected = u8::from(k == usize::from(axis));
                assert_eq!(pb[k] - pa[k], expected);
            }
        }
    }

    #[test]
    fn every_crossed_edge_is_used_once_per_loop() {
        for case in 0..=255u8 {
            let entry = TABLE[usize::from(case)];
            let crossed = crossed_edges(case);
            let mut used = 0u16;
            for t in entry.triangles() {
                for &e in t {
                    used |= 1 << e;
                }
            }
            assert_eq!(used, crossed, "case {case}");
            // Complementary cases use the same edges.
            assert_eq!(crossed_edges(!case), crossed);
        }
        assert_eq!(TABLE[0].count, 0);
        assert_eq!(TABLE[255].count, 0);
        assert_eq!(TABLE[1].count, 1);
        // Diagonal inside corners 0 and 3 on the z = 0 face give two separate triangles.
        assert_eq!(TABLE[0b1001].count, 2);
    }

    #[test]
    fn single_corner_triangle_faces_away_from_it() {
        // Corner 0 inside: the triangle's normal must point away from corner 0.
        let t = TABLE[1].triangles()[0];
        let [a, b, c] = t.map(|e| edge_midpoint(usize::from(e)));
        let n = cross(sub(b, a), sub(c, a));
        assert!(dot(n, [1.0, 1.0, 1.0]) > 0.0);
        // Corner 0 outside (all others inside): the normal points towards corner 0.
        let t = TABLE[254].triangles()[0];
        let [a, b, c] = t.map(|e| edge_midpoint(usize::from(e)));
        let n = cross(sub(b, a), sub(c, a));
        assert!(dot(n, [1.0, 1.0, 1.0]) < 0.0);
    }
}
