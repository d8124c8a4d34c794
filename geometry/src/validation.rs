//! A validity report for raw or built triangle meshes that lists every violation.

use std::fmt;

use glam::DVec3;

use crate::mesh::TriMesh;
use crate::topology::{Edge, non_manifold_edges};

/// Everything wrong (or merely unusual) with a triangle mesh. An empty report
/// ([`MeshReport::is_clean`]) means the mesh is finite, in range, non-degenerate and
/// edge-manifold.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshReport {
    /// Vertices with a NaN or infinite coordinate.
    pub non_finite_vertices: Vec<u32>,
    /// Triangles with an index `>= vertex_count`.
    pub out_of_range_triangles: Vec<u32>,
    /// Triangles that use one vertex twice.
    pub repeated_index_triangles: Vec<u32>,
    /// Triangles with zero area (exactly, in f64) but three distinct indices.
    pub zero_area_triangles: Vec<u32>,
    /// Edges shared by more than two triangles.
    pub non_manifold_edges: Vec<Edge>,
}

impl MeshReport {
    /// Checks raw arrays, which may violate the [`TriMesh`] invariants.
    #[must_use]
    pub fn of_raw(positions: &[DVec3], triangles: &[[u32; 3]]) -> Self {
        let mut report = Self {
            non_finite_vertices: positions
                .iter()
                .enumerate()
                .filter(|(_, p)| !p.is_finite())
                .map(|(i, _)| i as u32)
                .collect(),
            ..Self::default()
        };
        let n = positions.len();
        let mut in_range = Vec::with_capacity(triangles.len());
        for (t, &[a, b, c]) in triangles.iter().enumerate() {
            let t = t as u32;
            if [a, b, c].iter().any(|&v| v as usize >= n) {
                report.out_of_range_triangles.push(t);
                continue;
            }
            in_range.push([a, b, c]);
            if a == b || b == c || a == c {
                report.repeated_index_triangles.push(t);
                continue;
            }
            let [pa, pb, pc] = [a, b, c].map(|v| positions[v as usize]);
            if (pb - pa).cross(pc - pa) == DVec3::ZERO {
                report.zero_area_triangles.push(t);
            }
        }
        report.non_manifold_edges = non_manifold_edges(&in_range);
        report
    }

    /// True when nothing was found.
    #[must_use]
    pub fn is_clean(&self) -> bool {
        self == &Self::default()
    }
}

impl TriMesh {
    /// Full validation: non-finite positions, out-of-range or repeated indices, zero-area
    /// triangles, non-manifold edges. See [`MeshReport`].
    #[must_use]
    pub fn report(&self) -> MeshReport {
        MeshReport::of_raw(self.positions(), self.triangles())
    }
}

impl fmt::Display for MeshReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_clean() {
            return write!(f, "mesh is valid");
        }
        let parts = [
            (self.non_finite_vertices.len(), "non-finite vertices"),
            (
                self.out_of_range_triangles.len(),
                "triangles with out-of-range indices",
            ),
            (
                self.repeated_index_triangles.len(),
                "triangles with a repeated index",
            ),
            (self.zero_area_triangles.len(), "zero-area triangles"),
            (self.non_manifold_edges.len(), "non-manifold edges"),
        ];
        let text: Vec<String> = parts
            .iter()
            .filter(|(n, _)| *n > 0)
            .map(|(n, what)| format!("{n} {what}"))
            .collect();
        write!(f, "{}", text.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    fn wide(p: &[Vec3]) -> Vec<DVec3> {
        p.iter().map(|p| p.as_dvec3()).collect()
    }

    #[test]
    fn reports_every_kind_of_problem() {
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::Z,
            Vec3::NEG_Y,
        ];
        let tris = vec![
            [0, 1, 2], // fine
            [0, 1, 9], // out of range
            [0, 0, 1], // repeated
            [0, 1, 3], // collinear: zero area
            [1, 0, 5], // third on edge (0,1)
            [0, 1, 6], // fourth: (0,1) is non-manifold
        ];
        let r = MeshReport::of_raw(&wide(&p), &tris);
        assert_eq!(r.non_finite_vertices, vec![4]);
        assert_eq!(r.out_of_range_triangles, vec![1]);
        assert_eq!(r.repeated_index_triangles, vec![2]);
        assert_eq!(r.zero_area_triangles, vec![3]);
        assert_eq!(r.non_manifold_edges, vec![(0, 1)]);
        assert!(!r.is_clean());
        assert!(r.to_string().contains("1 zero-area triangles"));
    }

    #[test]
    fn clean_tetrahedron() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let tris = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        let r = MeshReport::of_raw(&wide(&p), &tris);
        assert!(r.is_clean(), "{r}");
    }
}
