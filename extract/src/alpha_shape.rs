//! Alpha shapes with Open3D's definition (`TriangleMesh.create_from_point_cloud_alpha_shape`):
//! keep the Delaunay tetrahedra whose circumradius is at most α and output the triangles that
//! belong to exactly one kept tetrahedron.
//!
//! Differences from Open3D, all deliberate:
//! - The tetrahedralisation is our exact one ([`crate::delaunay3d`]) instead of Qhull's: it
//!   succeeds on co-spherical and coplanar inputs (8 cube corners, grids, points on a plane),
//!   where Open3D 0.20 fails with Qhull error QH6239 or returns nothing. On generic inputs the
//!   Delaunay tetrahedralisation is unique, so the boundary triangles are the same.
//! - Triangles are oriented *outward*: each is written in the order whose normal points away
//!   from its kept tetrahedron (Open3D sorts the three indices, so about half its triangles
//!   face inward). A closed result therefore has positive signed volume.
//! - Vertices are the input points used by a triangle, **in input order** (Open3D keeps the
//!   referenced vertices in Qhull's order); [`AlphaShape::vertex_ids`] maps each output vertex
//!   to its input index.
//! - Circumradii are computed in `f64` relative to a tetrahedron vertex (Open3D uses 4x4
//!   determinants of absolute coordinates, which lose digits far from the origin); a tetrahedron
//!   whose circumradius is within rounding of α can be decided differently.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;

use crate::delaunay3d::{Delaunay3d, DelaunayError, Duplicate, FACE_VERTICES};

/// Why an alpha shape cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AlphaError {
    /// α is NaN.
    #[error("alpha must be a number, got {0}")]
    InvalidAlpha(f64),
    /// The points cannot be tetrahedralised (non-finite or huge coordinates).
    #[error(transparent)]
    Delaunay(#[from] DelaunayError),
}

/// An alpha shape: the boundary of the union of Delaunay tetrahedra with circumradius <= α.
#[derive(Debug, Clone)]
pub struct AlphaShape {
    /// The boundary triangles, oriented outward; vertices are the used input points in input
    /// order.
    pub mesh: TriMesh,
    /// Input index of each mesh vertex.
    pub vertex_ids: Vec<u32>,
    /// Number of tetrahedra kept (circumradius <= α).
    pub kept_tetrahedra: usize,
    /// Input points skipped as exact duplicates of earlier ones.
    pub duplicates: Vec<Duplicate>,
}

/// The alpha shape of `points` (Open3D's definition; see the module docs). A negative α gives
/// an empty mesh, `f64::INFINITY` the convex hull; fewer than four distinct or coplanar points
/// give an empty mesh (no tetrahedra).
///
/// # Errors
/// [`AlphaError::InvalidAlpha`] for a NaN α, [`AlphaError::Delaunay`] for non-finite or huge
/// coordinates (naming the point).
pub fn alpha_shape(points: &[Vec3], alpha: f64) -> Result<AlphaShape, AlphaError> {
    if alpha.is_nan() {
        return Err(AlphaError::InvalidAlpha(alpha));
    }
    let delaunay = Delaunay3d::new(points)?;
    alpha_shape_from_delaunay(&delaunay, alpha)
}

/// The alpha shape from an existing tetrahedralisation (reuse it for several α).
///
/// # Errors
/// [`AlphaError::InvalidAlpha`] for a NaN α.
pub fn alpha_shape_from_delaunay(
    delaunay: &Delaunay3d,
    alpha: f64,
) -> Result<AlphaShape, AlphaError> {
    if alpha.is_nan() {
        return Err(AlphaError::InvalidAlpha(alpha));
    }
    let points = delaunay.points();
    let tets = delaunay.tetrahedra();
    let neighbours = delaunay.neighbours();
    let keep: Vec<bool> = tets
        .par_iter()
        .map(|t| circumradius_at_most(t.map(|v| points[v as usize]), alpha))
        .collect();
    let kept_tetrahedra = keep.iter().filter(|&&k| k).count();
    let keep = &keep;
    let boundary: Vec<[u32; 3]> = (0..tets.len())
        .into_par_iter()
        .filter(|&t| keep[t])
        .flat_map_iter(|t| {
            let tet = tets[t];
            let nb = neighbours[t];
            (0..4).filter_map(move |i| {
                let other = nb[i] as usize;
                let open = other >= keep.len() || !keep[other];
                open.then(|| FACE_VERTICES[i].map(|k| tet[k]))
            })
        })
        .collect();
    let (mesh, vertex_ids) = compact(points, &boundary);
    Ok(AlphaShape {
        mesh,
        vertex_ids,
        kept_tetrahedra,
        duplicates: delaunay.duplicates().to_vec(),
    })
}

/// The mesh of `triangles` over the used `points` in input order, and their input indices.
pub(crate) fn compact(points: &[[f64; 3]], triangles: &[[u32; 3]]) -> (TriMesh, Vec<u32>) {
    let mut index = vec![u32::MAX; points.len()];
    for tri in triangles {
        for &v in tri {
            index[v as usize] = 0;
        }
    }
    let mut vertex_ids = Vec::new();
    for (i, slot) in index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = vertex_ids.len() as u32;
            vertex_ids.push(i as u32);
        }
    }
    let positions: Vec<Vec3> = vertex_ids
        .iter()
        .map(|&i| {
            let p = points[i as usize];
            // Exact: the points came from f32 (or are rounded once when given as f64).
            Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32)
        })
        .collect();
    let triangles = triangles
        .iter()
        .map(|t| t.map(|v| index[v as usize]))
        .collect();
    (TriMesh::new_unchecked(positions, triangles), vertex_ids)
}

/// Circumradius of the tetrahedron `p` (`f64::INFINITY` when it is flat in floating point).
#[must_use]
pub fn circumradius(p: [[f64; 3]; 4]) -> f64 {
    let (num_sq, den) = circumradius_parts(p);
    if den == 0.0 {
        return f64::INFINITY;
    }
    num_sq.sqrt() / den.abs()
}

/// Whether the circumradius of `p` is at most `alpha` (compared as `|num|^2 <= alpha^2 den^2`,
/// without division).
fn circumradius_at_most(p: [[f64; 3]; 4], alpha: f64) -> bool {
    if alpha < 0.0 {
        return false;
    }
    let (num_sq, den) = circumradius_parts(p);
    if den == 0.0 {
        return alpha == f64::INFINITY;
    }
    num_sq <= alpha * alpha * den * den
}

/// `(|n|^2, d)` with circumcentre = `a + n / d`, relative to the first vertex `a`:
/// `n = |b'|^2 (c' x d') + |c'|^2 (d' x b') + |d'|^2 (b' x c')`, `d = 2 b' . (c' x d')`.
fn circumradius_parts(p: [[f64; 3]; 4]) -> (f64, f64) {
    let [a, b, c, d] = p.map(DVec3::from_array);
    let (b, c, d) = (b - a, c - a, d - a);
    let cd = c.cross(d);
    let n =
        b.length_squared() * cd + c.length_squared() * d.cross(b) + d.length_squared() * b.cross(c);
    (n.length_squared(), 2.0 * b.dot(cd))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circumradius_of_known_tetrahedra() {
        let corner = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        // Circumcentre (0.5, 0.5, 0.5): radius sqrt(3)/2.
        assert!((circumradius(corner) - 0.75f64.sqrt()).abs() < 1e-15);
        let shifted = corner.map(|q| [q[0] + 1e4, q[1] - 3e3, q[2] + 7.0]);
        assert!((circumradius(shifted) - 0.75f64.sqrt()).abs() < 1e-12);
        let flat = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
        assert_eq!(circumradius(flat), f64::INFINITY);
        assert!(circumradius_at_most(corner, 0.9));
        assert!(!circumradius_at_most(corner, 0.8));
        assert!(!circumradius_at_most(corner, -1.0));
    }
}
