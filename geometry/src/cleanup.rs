//! Mesh clean-up: degenerate and duplicate triangles, unreferenced vertices, small clusters.
//!
//! Each function returns a new mesh and keeps per-vertex attributes aligned with positions.

use std::collections::HashSet;

use glam::DVec3;

use crate::TriMesh;
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

/// A mesh with new positions/triangles carrying over `mesh`'s attributes, re-indexed through
/// `vertex_map` (new vertex i = old vertex `vertex_map[i]`) when given.
fn rebuild(
    mesh: &TriMesh,
    positions: Vec<glam::Vec3>,
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
}
