//! Midpoint subdivision, as Open3D's `subdivide_midpoint`.

use std::collections::HashMap;

use glam::Vec3;

use crate::color::Rgba;
use crate::mesh::{MeshError, TriMesh};
use crate::topology::edge_key;

/// Splits every triangle into four, `iterations` times, with one new vertex at the midpoint of
/// every edge (shared by the triangles on both sides). Triangle `(a, b, c)` becomes
/// `(a, ab, ca)`, `(ab, b, bc)`, `(bc, c, ca)`, `(ab, bc, ca)` at indices `4t..4t+4`, and new
/// vertices are appended in order of first use, exactly as Open3D. Midpoints are computed in
/// f64. Per-vertex UVs and colours are averaged like the positions; normals
/// are averaged and re-normalised (Open3D leaves the averages unnormalised).
///
/// # Errors
/// [`MeshError::TooManyVertices`] when the subdivided mesh would need more than `u32::MAX`
/// vertices.
pub fn midpoint(mesh: &TriMesh, iterations: usize) -> Result<TriMesh, MeshError> {
    let (mut positions, mut triangles, mut normals, mut uvs, mut colors) =
        mesh.clone().into_parts();
    for _ in 0..iterations {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::with_capacity(triangles.len() * 2);
        let mut next = Vec::with_capacity(triangles.len() * 4);
        for &[a, b, c] in &triangles {
            let mut split = |p: u32, q: u32| -> Result<u32, MeshError> {
                let key = edge_key(p, q);
                if let Some(&m) = midpoints.get(&key) {
                    return Ok(m);
                }
                let m = u32::try_from(positions.len()).map_err(|_| MeshError::TooManyVertices {
                    count: positions.len() + 1,
                })?;
                let (i, j) = (key.0 as usize, key.1 as usize);
                positions.push((positions[i] + positions[j]) * 0.5);
                if let Some(n) = normals.as_mut() {
                    let avg = mid3(n[i], n[j]);
                    n.push(avg.normalize_or_zero());
                }
                if let Some(uv) = uvs.as_mut() {
                    let avg = (uv[i].as_dvec2() + uv[j].as_dvec2()) * 0.5;
                    uv.push(avg.as_vec2());
                }
                if let Some(col) = colors.as_mut() {
                    let (x, y) = (col[i], col[j]);
                    col.push(mid4(x, y));
                }
                midpoints.insert(key, m);
                Ok(m)
            };
            let ab = split(a, b)?;
            let bc = split(b, c)?;
            let ca = split(c, a)?;
            next.extend_from_slice(&[[a, ab, ca], [ab, b, bc], [bc, c, ca], [ab, bc, ca]]);
        }
        triangles = next;
    }
    let mut out = TriMesh::try_new(positions, triangles)?;
    if let Some(n) = normals {
        out = out.with_normals(n)?;
    }
    if let Some(uv) = uvs {
        out = out.with_uvs(uv)?;
    }
    if let Some(c) = colors {
        out = out.with_colors(c)?;
    }
    Ok(out)
}

#[inline]
fn mid3(a: Vec3, b: Vec3) -> Vec3 {
    ((a.as_dvec3() + b.as_dvec3()) * 0.5).as_vec3()
}

#[inline]
fn mid4(a: Rgba, b: Rgba) -> Rgba {
    std::array::from_fn(|k| ((f64::from(a[k]) + f64::from(b[k])) * 0.5) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_area_and_sharing() {
        let m = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)],
            vec![[0, 1, 2], [1, 3, 2]],
        );
        let s = midpoint(&m, 2).unwrap();
        assert_eq!(s.triangle_count(), 2 * 16);
        // A 2-triangle square split twice is a 5 x 5 vertex grid.
        assert_eq!(s.vertex_count(), 25);
        assert!((s.area() - m.area()).abs() < 1e-12);
        assert_eq!(midpoint(&m, 0).unwrap(), m);
        let one = midpoint(&m, 1).unwrap();
        assert_eq!(one.triangles()[0], [0, 4, 6]);
        assert_eq!(one.positions()[4], glam::DVec3::new(0.5, 0.0, 0.0));
    }
}
