//! Mesh clean-up: degenerate and duplicate triangles, unreferenced vertices, small clusters,
//! welding of duplicated vertices.
//!
//! Each function returns a new mesh and keeps per-vertex attributes aligned with positions.

use std::collections::{HashMap, HashSet};

use glam::DVec3;

use crate::mesh::TriMesh;
use crate::topology::TriangleClusters;

/// Keeps only the triangles for which `keep(t)` is true (vertices are untouched).
#[must_use]
pub fn filter_triangles(mesh: &TriMesh, mut keep: impl FnMut(usize) -> bool) -> TriMesh {
    let triangles: Vec<[u32; 3]> = (0..mesh.triangle_count())
        .filter(|&t| keep(t))
        .map(|t| mesh.triangles()[t])
        .collect();
    rebuild(mesh, mesh.positions().to_vec(), triangles, None)
}

/// Removes triangles with a repeated vertex index or exactly zero area (f64 cross product).
#[must_use]
pub fn remove_degenerate_triangles(mesh: &TriMesh) -> TriMesh {
    filter_triangles(mesh, |t| {
        let [a, b, c] = mesh.triangles()[t];
        a != b && b != c && a != c && mesh.triangle_cross(t) != DVec3::ZERO
    })
}

/// Removes triangles that use the same three vertices as an earlier triangle, in any order or
/// orientation (as Open3D's `remove_duplicated_triangles`). The first occurrence is kept.
#[must_use]
pub fn remove_duplicate_triangles(mesh: &TriMesh) -> TriMesh {
    let mut seen = HashSet::with_capacity(mesh.triangle_count());
    filter_triangles(mesh, |t| {
        let mut key = mesh.triangles()[t];
        key.sort_unstable();
        seen.insert(key)
    })
}

/// Removes vertices that no triangle uses, renumbering triangles and attributes.
#[must_use]
pub fn remove_unreferenced_vertices(mesh: &TriMesh) -> TriMesh {
    let mut new_index = vec![u32::MAX; mesh.vertex_count()];
    let mut order = Vec::new();
    for tri in mesh.triangles() {
        for &v in tri {
            if new_index[v as usize] == u32::MAX {
                new_index[v as usize] = 0;
                order.push(v);
            }
        }
    }
    // Keep the original vertex order among the survivors.
    order.sort_unstable();
    for (i, &v) in order.iter().enumerate() {
        new_index[v as usize] = i as u32;
    }
    let positions = order
        .iter()
        .map(|&v| mesh.positions()[v as usize])
        .collect();
    let triangles = mesh
        .triangles()
        .iter()
        .map(|t| t.map(|v| new_index[v as usize]))
        .collect();
    rebuild(mesh, positions, triangles, Some(&order))
}

/// Keeps the edge-connected clusters that are at least as large (in triangles) as the
/// `k`-th largest, as 2DGS's `post_process_mesh` does, then drops unreferenced vertices.
/// `k = 0` or `k >= cluster count` keeps everything.
#[must_use]
pub fn keep_largest_clusters(mesh: &TriMesh, k: usize) -> TriMesh {
    let clusters = TriangleClusters::of(mesh);
    if k == 0 || k >= clusters.count() {
        return mesh.clone();
    }
    let mut sizes = clusters.sizes.clone();
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    let min_size = sizes[k - 1];
    let kept = filter_triangles(mesh, |t| {
        clusters.sizes[clusters.cluster_of[t] as usize] >= min_size
    });
    remove_unreferenced_vertices(&kept)
}

/// The full clean-up: degenerate and duplicate triangles, then unreferenced vertices.
#[must_use]
pub fn clean(mesh: &TriMesh) -> TriMesh {
    remove_unreferenced_vertices(&remove_duplicate_triangles(&remove_degenerate_triangles(
        mesh,
    )))
}

/// Merges duplicated vertices (glTF and OBJ split vertices at UV and normal seams) and returns
/// the welded mesh with the old-to-new vertex map (`map[old] = new`).
///
/// # Rule
/// - `tolerance == 0` (also a negative or NaN tolerance): vertices are merged when their
///   positions compare equal component-wise as `f32` (so `-0.0` equals `0.0`; a vertex with a
///   NaN coordinate is never merged). This is trimesh's
///   `merge_vertices(merge_tex=True, merge_norm=True)` for positions that agree to its 8
///   rounded decimals, and Open3D's `merge_close_vertices(0)`.
/// - `tolerance > 0`: greedy in vertex order. The first vertex not yet merged starts a new
///   vertex and absorbs every later vertex not yet merged whose position is equal to it or
///   within `tolerance` of it (Euclidean distance, f64). The rule is not transitive: two
///   vertices within `tolerance` of each other may stay apart when an earlier vertex absorbed
///   only one of them (a chain is never merged beyond `tolerance` from its first vertex).
///
/// # Output
/// New vertices are numbered in the order of their first occurrence (as trimesh and Open3D
/// do), so `map` is non-decreasing over first occurrences and an input without duplicates
/// comes back unchanged with the identity map. A welded vertex keeps the position, normal,
/// UV and colour of its first (lowest-index) original vertex (so per-vertex UVs are wrong
/// across a UV seam; the per-corner UVs of an attached base colour, which is kept, are not).
/// Vertices are merged whether or not a triangle uses them.
///
/// Every triangle is kept, in order, with its indices remapped: triangle `t` of the output is
/// triangle `t` of the input, so per-triangle data (e.g. Gaussian bindings) stays valid.
/// A triangle whose corners merge (it had zero area already, or, with a tolerance, at most
/// `2 × tolerance` across) comes back with a repeated index;
/// [`remove_degenerate_triangles`] drops such triangles when wanted. Exact seams (equal
/// positions) never merge corners of a triangle with non-zero area.
#[must_use]
pub fn weld_vertices(mesh: &TriMesh, tolerance: f32) -> (TriMesh, Vec<u32>) {
    let positions = mesh.positions();
    let map = if tolerance > 0.0 {
        weld_map_within(positions, f64::from(tolerance))
    } else {
        weld_map_exact(positions)
    };
    let mut first = Vec::new();
    for (old, &new) in map.iter().enumerate() {
        if new as usize == first.len() {
            first.push(old as u32);
        }
    }
    let welded_positions = first.iter().map(|&v| positions[v as usize]).collect();
    let triangles = mesh
        .triangles()
        .iter()
        .map(|t| t.map(|v| map.get(v as usize).copied().unwrap_or(v)))
        .collect();
    let mut welded = rebuild(mesh, welded_positions, triangles, Some(&first));
    // Same triangles in the same order: the per-corner base colour still fits.
    if let Some(b) = mesh.base_color() {
        welded = welded
            .with_base_color(b.clone())
            .unwrap_or_else(|_| unreachable!());
    }
    (welded, map)
}

/// Bit pattern of a position for exact comparison (`-0.0` as `0.0`); `None` with a NaN.
fn exact_key(p: DVec3) -> Option<[u64; 3]> {
    if p.is_nan() {
        return None;
    }
    // Adding 0.0 turns -0.0 into +0.0 and leaves every other value as it is.
    Some(p.to_array().map(|c| (c + 0.0).to_bits()))
}

/// Old-to-new map merging positions that compare equal.
fn weld_map_exact(positions: &[DVec3]) -> Vec<u32> {
    let mut seen: HashMap<[u64; 3], u32> = HashMap::with_capacity(positions.len());
    let mut next = 0u32;
    positions
        .iter()
        .map(|&p| {
            let fresh = |next: &mut u32| {
                let id = *next;
                *next += 1;
                id
            };
            match exact_key(p) {
                Some(key) => *seen.entry(key).or_insert_with(|| fresh(&mut next)),
                None => fresh(&mut next),
            }
        })
        .collect()
}

/// Old-to-new map of the greedy rule of [`weld_vertices`] for `tolerance > 0`: a uniform grid
/// of cells `tolerance` wide finds the candidates (the 27 cells around a vertex); positions
/// with a non-finite coordinate merge only with equal positions.
fn weld_map_within(positions: &[DVec3], tolerance: f64) -> Vec<u32> {
    const UNSET: u32 = u32::MAX;
    // Float-to-int casts saturate: far-out cells share a key, which costs time, not accuracy.
    let cell = |p: DVec3| (p / tolerance).floor().to_array().map(|c| c as i64);
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let mut non_finite: HashMap<[u64; 3], Vec<u32>> = HashMap::new();
    for (i, &p) in positions.iter().enumerate() {
        if p.is_finite() {
            grid.entry(cell(p)).or_default().push(i as u32);
        } else if let Some(key) = exact_key(p) {
            non_finite.entry(key).or_default().push(i as u32);
        }
    }
    let mut map = vec![UNSET; positions.len()];
    let mut next = 0u32;
    for i in 0..positions.len() {
        if map[i] != UNSET {
            continue;
        }
        let id = next;
        next += 1;
        map[i] = id;
        let p = positions[i];
        if !p.is_finite() {
            if let Some(same) = exact_key(p).and_then(|key| non_finite.get(&key)) {
                for &j in same {
                    if map[j as usize] == UNSET {
                        map[j as usize] = id;
                    }
                }
            }
            continue;
        }
        let c = cell(p);
        let mut visited: Vec<[i64; 3]> = Vec::with_capacity(27);
        for dx in -1i64..=1 {
            for dy in -1i64..=1 {
                for dz in -1i64..=1 {
                    let key = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    // Saturated neighbours may repeat a cell.
                    if visited.contains(&key) {
                        continue;
                    }
                    visited.push(key);
                    let Some(members) = grid.get(&key) else {
                        continue;
                    };
                    for &j in members {
                        let q = positions[j as usize];
                        if map[j as usize] == UNSET && (q == p || (q - p).length() <= tolerance) {
                            map[j as usize] = id;
                        }
                    }
                }
            }
        }
    }
    map
}

/// A mesh with new positions/triangles carrying over `mesh`'s attributes, re-indexed through
/// `vertex_map` (new vertex i = old vertex `vertex_map[i]`) when given.
fn rebuild(
    mesh: &TriMesh,
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    vertex_map: Option<&[u32]>,
) -> TriMesh {
    fn pick<T: Copy>(values: &[T], map: Option<&[u32]>) -> Vec<T> {
        match map {
            Some(map) => map.iter().map(|&v| values[v as usize]).collect(),
            None => values.to_vec(),
        }
    }
    let mut out = TriMesh::new_unchecked(positions, triangles);
    // Lengths match by construction, so attaching cannot fail.
    if let Some(n) = mesh.normals() {
        out = out
            .with_normals(pick(n, vertex_map))
            .unwrap_or_else(|_| unreachable!());
    }
    if let Some(uv) = mesh.uvs() {
        out = out
            .with_uvs(pick(uv, vertex_map))
            .unwrap_or_else(|_| unreachable!());
    }
    if let Some(c) = mesh.colors() {
        out = out
            .with_colors(pick(c, vertex_map))
            .unwrap_or_else(|_| unreachable!());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Vec2, Vec3};

    #[test]
    fn removes_degenerate_duplicate_and_unreferenced() {
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::Z,
        ];
        let uvs: Vec<Vec2> = (0..5).map(|i| Vec2::splat(i as f32)).collect();
        let tris = vec![[0, 1, 2], [2, 1, 0], [1, 2, 0], [0, 1, 3], [0, 0, 2]];
        let m = TriMesh::new(p, tris).with_uvs(uvs).unwrap();
        let c = clean(&m);
        assert_eq!(c.triangles(), &[[0, 1, 2]]);
        assert_eq!(c.vertex_count(), 3);
        assert_eq!(c.uvs().unwrap()[2], Vec2::splat(2.0));
    }

    #[test]
    fn keeps_k_largest_clusters() {
        // A 2-triangle square and a lone triangle far away.
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::Y,
            Vec3::splat(5.0),
            Vec3::new(6.0, 5.0, 5.0),
            Vec3::new(5.0, 6.0, 5.0),
        ];
        let m = TriMesh::new(p, vec![[0, 1, 2], [0, 2, 3], [4, 5, 6]]);
        let one = keep_largest_clusters(&m, 1);
        assert_eq!(one.triangle_count(), 2);
        assert_eq!(one.vertex_count(), 4);
        assert_eq!(keep_largest_clusters(&m, 2), m);
        assert_eq!(keep_largest_clusters(&m, 0), m);
    }

    /// Two triangles of a unit square split along its diagonal, with the diagonal's two
    /// vertices duplicated (as a UV seam does).
    fn split_square() -> TriMesh {
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-0.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::Y,
        ];
        let uvs: Vec<Vec2> = (0..6).map(|i| Vec2::splat(i as f32)).collect();
        TriMesh::new(p, vec![[0, 1, 2], [3, 4, 5]])
            .with_uvs(uvs)
            .unwrap()
    }

    #[test]
    fn weld_exact_merges_seams_in_first_occurrence_order() {
        let m = split_square();
        let (w, map) = weld_vertices(&m, 0.0);
        assert_eq!(map, vec![0, 1, 2, 0, 2, 3]);
        assert_eq!(w.vertex_count(), 4);
        assert_eq!(
            w.positions_f32(),
            [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]
        );
        assert_eq!(w.triangles(), &[[0, 1, 2], [0, 2, 3]]);
        // Attributes of the first copy.
        assert_eq!(
            w.uvs().unwrap(),
            &[
                Vec2::splat(0.0),
                Vec2::splat(1.0),
                Vec2::splat(2.0),
                Vec2::splat(5.0)
            ]
        );
        // The welded square has one shared interior edge and four boundary edges.
        assert_eq!(crate::topology::boundary_edges(w.triangles()).len(), 4);
        // Negative, NaN and zero tolerances are the exact rule.
        assert_eq!(weld_vertices(&m, -1.0).1, map);
        assert_eq!(weld_vertices(&m, f32::NAN).1, map);
    }

    #[test]
    fn weld_without_duplicates_is_the_identity() {
        let m = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        );
        let (w, map) = weld_vertices(&m, 0.0);
        assert_eq!(w, m);
        assert_eq!(map, vec![0, 1, 2, 3]);
        let (w, map) = weld_vertices(&m, 0.5);
        assert_eq!(w, m);
        assert_eq!(map, vec![0, 1, 2, 3]);
        let empty = weld_vertices(&TriMesh::default(), 0.0);
        assert_eq!(empty.0.vertex_count(), 0);
        assert!(empty.1.is_empty());
    }

    #[test]
    fn weld_with_tolerance_is_greedy_from_the_first_vertex() {
        // A chain 0 - 1 - 2 spaced 0.6 apart at tolerance 1: 1 joins 0, 2 is 1.2 from 0 and
        // stays apart (not transitive); 3 is within 1 of 2 only.
        let p = vec![
            Vec3::ZERO,
            Vec3::new(0.6, 0.0, 0.0),
            Vec3::new(1.2, 0.0, 0.0),
            Vec3::new(1.9, 0.0, 0.0),
            Vec3::new(5.0, 0.0, 0.0),
        ];
        let m = TriMesh::new(p, vec![[0, 1, 4], [2, 3, 4]]);
        let (w, map) = weld_vertices(&m, 1.0);
        assert_eq!(map, vec![0, 0, 1, 1, 2]);
        assert_eq!(
            w.positions_f32(),
            [
                Vec3::ZERO,
                Vec3::new(1.2, 0.0, 0.0),
                Vec3::new(5.0, 0.0, 0.0)
            ]
        );
        // Triangles are kept, in order, even when their corners merge.
        assert_eq!(w.triangles(), &[[0, 0, 2], [1, 1, 2]]);
        assert_eq!(remove_degenerate_triangles(&w).triangle_count(), 0);
        // The boundary of the tolerance is inclusive; the exact rule merges nothing here.
        let (_, exact) = weld_vertices(&m, 0.0);
        assert_eq!(exact, vec![0, 1, 2, 3, 4]);
        let (_, edge) = weld_vertices(&m, 0.6);
        assert_eq!(edge[1], 0);
    }

    #[test]
    fn weld_never_panics_on_odd_coordinates() {
        let p = vec![
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::new(f32::INFINITY, 0.0, 0.0),
            Vec3::new(f32::INFINITY, 0.0, 0.0),
            Vec3::splat(f32::MAX),
            Vec3::splat(-f32::MAX),
            Vec3::splat(f32::MAX),
        ];
        let m = TriMesh::new_unchecked(p, vec![[0, 1, 2], [3, 4, 5], [6, 0, 1]]);
        for tol in [0.0, 1e-30, 1.0, f32::MAX, f32::INFINITY] {
            let (w, map) = weld_vertices(&m, tol);
            assert_eq!(map.len(), 7);
            // NaN never merges; equal infinities and equal huge values do.
            assert_ne!(map[0], map[1], "{tol}");
            assert_eq!(map[2], map[3], "{tol}");
            assert_eq!(map[4], map[6], "{tol}");
            assert_eq!(w.triangle_count(), 3);
        }
    }
}
