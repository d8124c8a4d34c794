//! The indexed triangle mesh: f64 positions, u32 triangles, optional per-vertex attributes.

use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3};
use rayon::prelude::*;

use crate::base_color::BaseColor;
use crate::color::Rgba;

/// Axis-aligned bounding box, in f64 (it bounds f32 point sets exactly too).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: DVec3,
    /// Maximum corner.
    pub max: DVec3,
}

impl Aabb {
    /// Bounds of f32 `points`, or `None` when there are none (or none finite).
    #[must_use]
    pub fn from_points(points: &[Vec3]) -> Option<Self> {
        Self::from_iter(points.iter().map(|p| p.as_dvec3()))
    }

    /// Bounds of f64 `points`, or `None` when there are none (or none finite).
    #[must_use]
    pub fn from_dpoints(points: &[DVec3]) -> Option<Self> {
        Self::from_iter(points.iter().copied())
    }

    fn from_iter(points: impl Iterator<Item = DVec3>) -> Option<Self> {
        let mut iter = points.filter(|p| p.is_finite());
        let first = iter.next()?;
        let (min, max) = iter.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
        Some(Self { min, max })
    }

    /// Length of the diagonal: the scene scale that relative tolerances refer to.
    #[must_use]
    pub fn diagonal(&self) -> f64 {
        (self.max - self.min).length()
    }

    /// Centre of the box.
    #[must_use]
    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    /// The origin to store coordinates inside this box relative to, in `f32`, when the box
    /// is far from the world origin (docs/conventions.md §3, "Precision"): zero when the box's
    /// centre is within [`LOCAL_ORIGIN_REACH`] diagonals of the world origin (no change for
    /// objects modelled around it), else the centre rounded to a multiple of the power of two
    /// at or above the diagonal, so `p - origin` is exact in `f64` for every point of the box
    /// and small enough for `f32` to keep its relative precision.
    #[must_use]
    pub fn local_origin(&self) -> DVec3 {
        let size = self.diagonal();
        let centre = self.center();
        if !(size > 0.0 && size.is_finite() && centre.is_finite())
            || centre.abs().max_element() <= LOCAL_ORIGIN_REACH * size
        {
            return DVec3::ZERO;
        }
        let grid = 2f64.powf(size.log2().ceil());
        (centre / grid).round() * grid
    }
}

/// How many bounding-box diagonals from the world origin a point set's centre may lie before
/// [`Aabb::local_origin`] moves its coordinates to a local origin.
pub const LOCAL_ORIGIN_REACH: f64 = 4.0;

/// Errors from building a [`TriMesh`] out of raw arrays.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum MeshError {
    /// A triangle refers to a vertex that does not exist.
    #[error(
        "triangle {triangle} refers to vertex {vertex}, but the mesh has {vertex_count} vertices"
    )]
    IndexOutOfRange {
        /// Triangle index.
        triangle: usize,
        /// The offending vertex index.
        vertex: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// A vertex position is NaN or infinite.
    #[error("vertex {vertex} has a non-finite position")]
    NonFinitePosition {
        /// Vertex index.
        vertex: usize,
    },
    /// An attribute array does not have one entry per vertex.
    #[error("{attribute} has {len} entries, but the mesh has {vertex_count} vertices")]
    AttributeLength {
        /// `"normals"`, `"uvs"` or `"colors"`.
        attribute: &'static str,
        /// Entries found.
        len: usize,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// A per-triangle attribute does not have one entry per triangle.
    #[error("{attribute} has {len} entries, but the mesh has {triangle_count} triangles")]
    TriangleAttributeLength {
        /// `"base colour"`.
        attribute: &'static str,
        /// Entries found.
        len: usize,
        /// Number of triangles.
        triangle_count: usize,
    },
    /// More vertices than a `u32` index can address.
    #[error("{count} vertices do not fit in u32 indices")]
    TooManyVertices {
        /// Number of vertices.
        count: usize,
    },
}

impl MeshError {
    /// `Ok` when an attribute of `len` entries has one per vertex, else
    /// [`MeshError::AttributeLength`] (meshes and point clouds alike).
    pub(crate) fn check_attribute_len(
        attribute: &'static str,
        len: usize,
        vertex_count: usize,
    ) -> Result<(), Self> {
        if len == vertex_count {
            Ok(())
        } else {
            Err(Self::AttributeLength {
                attribute,
                len,
                vertex_count,
            })
        }
    }
}

/// An indexed triangle mesh.
///
/// Positions are f64 from the file to every derived quantity (triangle frames, deformation
/// gradients, areas): a mesh is small next to the Gaussians and point clouds (f32), and f32
/// storage of its vertices, amplified by sliver triangles, was the largest error in deformed
/// covariances (docs/numerics.md).
///
/// Invariants (checked by [`TriMesh::try_new`]): every triangle index is `< vertex_count`, every
/// position is finite, optional attributes have one entry per vertex and the optional base
/// colour one entry per triangle. Triangles may still be
/// degenerate (zero area, repeated indices) or non-manifold: [`TriMesh::report`] lists those, and
/// [`crate::cleanup`] removes them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    normals: Option<Vec<Vec3>>,
    uvs: Option<Vec<Vec2>>,
    colors: Option<Vec<Rgba>>,
    /// Per-triangle base colour (material, texture, corner uvs); shared by clones.
    base_color: Option<Arc<BaseColor>>,
}

impl TriMesh {
    /// Builds a mesh from positions and triangles, checking indices and finiteness.
    ///
    /// # Errors
    /// [`MeshError`] naming the first offending vertex or triangle.
    pub fn try_new<P: Into<DVec3>>(
        positions: Vec<P>,
        triangles: Vec<[u32; 3]>,
    ) -> Result<Self, MeshError> {
        let positions: Vec<DVec3> = positions.into_iter().map(Into::into).collect();
        if u32::try_from(positions.len()).is_err() {
            return Err(MeshError::TooManyVertices {
                count: positions.len(),
            });
        }
        if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition { vertex });
        }
        let n = positions.len();
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&v) = tri.iter().find(|&&v| v as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    triangle: t,
                    vertex: v,
                    vertex_count: n,
                });
            }
        }
        Ok(Self::new_unchecked(positions, triangles))
    }

    /// Like [`TriMesh::try_new`].
    ///
    /// # Panics
    /// When `try_new` would return an error.
    #[must_use]
    pub fn new<P: Into<DVec3>>(positions: Vec<P>, triangles: Vec<[u32; 3]>) -> Self {
        match Self::try_new(positions, triangles) {
            Ok(mesh) => mesh,
            Err(e) => panic!("invalid mesh: {e}"),
        }
    }

    /// Builds a mesh without checks, for trusted hot paths (e.g. output of our own algorithms).
    /// Indices must be in range and positions finite; other code relies on it. f32 positions
    /// are widened exactly.
    #[must_use]
    pub fn new_unchecked<P: Into<DVec3>>(positions: Vec<P>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            positions: positions.into_iter().map(Into::into).collect(),
            triangles,
            normals: None,
            uvs: None,
            colors: None,
            base_color: None,
        }
    }

    /// Attaches per-vertex normals.
    ///
    /// # Errors
    /// [`MeshError::AttributeLength`] when there is not one normal per vertex.
    pub fn with_normals(mut self, normals: Vec<Vec3>) -> Result<Self, MeshError> {
        self.check_len("normals", normals.len())?;
        self.normals = Some(normals);
        Ok(self)
    }

    /// Attaches per-vertex texture coordinates.
    ///
    /// # Errors
    /// [`MeshError::AttributeLength`] when there is not one uv per vertex.
    pub fn with_uvs(mut self, uvs: Vec<Vec2>) -> Result<Self, MeshError> {
        self.check_len("uvs", uvs.len())?;
        self.uvs = Some(uvs);
        Ok(self)
    }

    /// Attaches per-vertex colours.
    ///
    /// # Errors
    /// [`MeshError::AttributeLength`] when there is not one colour per vertex.
    pub fn with_colors(mut self, colors: Vec<Rgba>) -> Result<Self, MeshError> {
        self.check_len("colors", colors.len())?;
        self.colors = Some(colors);
        Ok(self)
    }

    /// Attaches a base colour (material, texture and corner uvs per triangle; see
    /// [`crate::base_color`]). It stays with clones and [`TriMesh::set_positions`];
    /// [`crate::cleanup::weld_vertices`] keeps it (triangles keep their order), operations that
    /// rebuild the triangles drop it.
    ///
    /// # Errors
    /// [`MeshError::TriangleAttributeLength`] when it does not describe one entry per triangle.
    pub fn with_base_color(mut self, base_color: Arc<BaseColor>) -> Result<Self, MeshError> {
        if base_color.triangle_count() != self.triangles.len() {
            return Err(MeshError::TriangleAttributeLength {
                attribute: "base colour",
                len: base_color.triangle_count(),
                triangle_count: self.triangles.len(),
            });
        }
        self.base_color = Some(base_color);
        Ok(self)
    }

    fn check_len(&self, attribute: &'static str, len: usize) -> Result<(), MeshError> {
        MeshError::check_attribute_len(attribute, len, self.positions.len())
    }

    /// Vertex positions (f64).
    #[must_use]
    pub fn positions(&self) -> &[DVec3] {
        &self.positions
    }

    /// Vertex positions rounded to f32, for consumers that store bulk data in f32 (BVHs,
    /// renderers, point samples). Allocates.
    #[must_use]
    pub fn positions_f32(&self) -> Vec<Vec3> {
        self.positions.iter().map(|p| p.as_vec3()).collect()
    }

    /// Triangles as vertex index triples (counter-clockwise = front).
    #[must_use]
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Per-vertex normals, if present.
    #[must_use]
    pub fn normals(&self) -> Option<&[Vec3]> {
        self.normals.as_deref()
    }

    /// Per-vertex texture coordinates, if present.
    #[must_use]
    pub fn uvs(&self) -> Option<&[Vec2]> {
        self.uvs.as_deref()
    }

    /// Per-vertex colours, if present.
    #[must_use]
    pub fn colors(&self) -> Option<&[Rgba]> {
        self.colors.as_deref()
    }

    /// Per-triangle base colour, if attached ([`TriMesh::with_base_color`]).
    #[must_use]
    pub fn base_color(&self) -> Option<&Arc<BaseColor>> {
        self.base_color.as_ref()
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Replaces the positions, keeping topology and attributes (e.g. after smoothing or
    /// deformation).
    ///
    /// # Errors
    /// [`MeshError::AttributeLength`] when the count changes, [`MeshError::NonFinitePosition`]
    /// when a position is not finite.
    pub fn set_positions<P: Into<DVec3>>(&mut self, positions: Vec<P>) -> Result<(), MeshError> {
        let positions: Vec<DVec3> = positions.into_iter().map(Into::into).collect();
        self.check_len("positions", positions.len())?;
        if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition { vertex });
        }
        self.positions = positions;
        Ok(())
    }

    /// Moves every vertex by `offset` (f64). Metrics move both sides to the ground truth's
    /// centre this way before anything is stored in f32 (docs/conventions.md §8), so scores do
    /// not depend on how far from the origin the meshes are.
    pub fn translate(&mut self, offset: DVec3) {
        self.positions.par_iter_mut().for_each(|p| *p += offset);
    }

    /// Drops stored vertex normals (they go stale when positions change).
    pub fn clear_normals(&mut self) {
        self.normals = None;
    }

    /// Splits the mesh into its raw arrays: positions, triangles, normals, uvs, colours (the
    /// base colour, if any, is dropped).
    #[must_use]
    #[expect(
        clippy::type_complexity,
        reason = "a plain destructuring of the fields"
    )]
    pub fn into_parts(
        self,
    ) -> (
        Vec<DVec3>,
        Vec<[u32; 3]>,
        Option<Vec<Vec3>>,
        Option<Vec<Vec2>>,
        Option<Vec<Rgba>>,
    ) {
        (
            self.positions,
            self.triangles,
            self.normals,
            self.uvs,
            self.colors,
        )
    }

    /// The three corner positions of triangle `t`.
    #[inline]
    #[must_use]
    pub fn corners(&self, t: usize) -> [DVec3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Cross product `(b - a) x (c - a)` of triangle `t` in f64: twice the area times the normal.
    #[inline]
    #[must_use]
    pub fn triangle_cross(&self, t: usize) -> DVec3 {
        let [a, b, c] = self.corners(t);
        (b - a).cross(c - a)
    }

    /// Area of every triangle (computed in f64).
    #[must_use]
    pub fn triangle_areas(&self) -> Vec<f64> {
        (0..self.triangles.len())
            .into_par_iter()
            .map(|t| 0.5 * self.triangle_cross(t).length())
            .collect()
    }

    /// Total surface area.
    #[must_use]
    pub fn area(&self) -> f64 {
        self.triangle_areas().iter().sum()
    }

    /// Unit face normals; zero for degenerate triangles.
    #[must_use]
    pub fn face_normals(&self) -> Vec<Vec3> {
        (0..self.triangles.len())
            .into_par_iter()
            .map(|t| self.triangle_cross(t).normalize_or_zero().as_vec3())
            .collect()
    }

    /// Area-weighted unit vertex normals (sum of un-normalised face cross products, as Open3D's
    /// `compute_vertex_normals` and trimesh's default). Vertices with no non-degenerate triangle
    /// get zero.
    #[must_use]
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut sums = vec![DVec3::ZERO; self.positions.len()];
        for t in 0..self.triangles.len() {
            let n = self.triangle_cross(t);
            for &v in &self.triangles[t] {
                sums[v as usize] += n;
            }
        }
        sums.into_iter()
            .map(|n| n.normalize_or_zero().as_vec3())
            .collect()
    }

    /// Axis-aligned bounds of the vertices, `None` for an empty mesh.
    #[must_use]
    pub fn bounds(&self) -> Option<Aabb> {
        Aabb::from_dpoints(&self.positions)
    }

    /// Signed volume enclosed by the mesh (positive for closed, outward-oriented meshes).
    #[must_use]
    pub fn signed_volume(&self) -> f64 {
        let origin = self.bounds().map_or(DVec3::ZERO, |b| b.center());
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t).map(|p| p - origin);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit cube corners with outward-facing triangles.
    fn cube() -> TriMesh {
        let p: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        let t = vec![
            [0, 2, 1],
            [1, 2, 3], // z = 0
            [4, 5, 6],
            [5, 7, 6], // z = 1
            [0, 1, 4],
            [1, 5, 4], // y = 0
            [2, 6, 3],
            [3, 6, 7], // y = 1
            [0, 4, 2],
            [2, 4, 6], // x = 0
            [1, 3, 5],
            [3, 7, 5], // x = 1
        ];
        TriMesh::new(p, t)
    }

    #[test]
    fn cube_area_volume_normals_bounds() {
        let m = cube();
        assert!((m.area() - 6.0).abs() < 1e-12);
        assert!((m.signed_volume() - 1.0).abs() < 1e-12);
        let b = m.bounds().unwrap();
        assert_eq!((b.min, b.max), (DVec3::ZERO, DVec3::ONE));
        assert!((b.diagonal() - 3f64.sqrt()).abs() < 1e-15);
        assert_eq!(m.face_normals()[0], Vec3::NEG_Z);
        // Corner 7 touches +x, +y, +z faces with equal area: normal along (1,1,1).
        let n7 = m.vertex_normals()[7];
        assert!((n7 - Vec3::ONE.normalize()).length() < 1e-6, "{n7}");
        assert!(m.report().is_clean());
    }

    #[test]
    fn try_new_rejects_bad_input() {
        assert_eq!(
            TriMesh::try_new(vec![Vec3::ZERO], vec![[0, 0, 1]]),
            Err(MeshError::IndexOutOfRange {
                triangle: 0,
                vertex: 1,
                vertex_count: 1
            })
        );
        assert_eq!(
            TriMesh::try_new(vec![Vec3::ZERO, Vec3::splat(f32::INFINITY)], vec![]),
            Err(MeshError::NonFinitePosition { vertex: 1 })
        );
        let m = TriMesh::new(vec![Vec3::ZERO], vec![]);
        assert!(matches!(
            m.clone().with_normals(vec![]),
            Err(MeshError::AttributeLength {
                attribute: "normals",
                ..
            })
        ));
        let mut m2 = m;
        assert!(m2.set_positions(vec![Vec3::NAN]).is_err());
        assert!(m2.set_positions(vec![Vec3::ONE]).is_ok());
    }

    #[test]
    fn degenerate_triangles_have_zero_normals_not_nan() {
        let m = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            vec![[0, 1, 2], [0, 0, 1]],
        );
        assert!(m.face_normals().iter().all(|n| *n == Vec3::ZERO));
        assert!(m.vertex_normals().iter().all(|n| *n == Vec3::ZERO));
        assert_eq!(m.area(), 0.0);
        assert!(TriMesh::default().bounds().is_none());
    }
}
