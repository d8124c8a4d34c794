//! Point sets with optional per-point normals and colours.

use glam::Vec3;

use crate::color::Rgba;
use crate::mesh::{Aabb, MeshError};

/// A point cloud: positions with optional normals and colours (one per point).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    colors: Option<Vec<Rgba>>,
}

impl PointCloud {
    /// Builds a point cloud, checking that every position is finite.
    ///
    /// # Errors
    /// [`MeshError::NonFinitePosition`] naming the first bad point.
    pub fn try_new(positions: Vec<Vec3>) -> Result<Self, MeshError> {
        if let Some(vertex) = positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::NonFinitePosition { vertex });
        }
        Ok(Self {
            positions,
            normals: None,
            colors: None,
        })
    }

    /// Builds a point cloud from trusted, finite positions.
    #[must_use]
    pub fn new_unchecked(positions: Vec<Vec3>) -> Self {
        Self {
            positions,
            normals: None,
            colors: None,
        }
    }

    /// Attaches normals.
    ///
    /// # Errors
    /// [`MeshError::AttributeLength`] when there is not one normal per point.
    pub fn with_normals(mut self, normals: Vec<Vec3>) -> Result<Self, MeshError> {
        MeshError::check_attribute_len("normals", normals.len(), self.positions.len())?;
        self.normals = Some(normals);
        Ok(self)
    }

    /// Attaches colours.
    ///
    /// # Errors
    /// [`MeshError::AttributeLength`] when there is not one colour per point.
    pub fn with_colors(mut self, colors: Vec<Rgba>) -> Result<Self, MeshError> {
        MeshError::check_attribute_len("colors", colors.len(), self.positions.len())?;
        self.colors = Some(colors);
        Ok(self)
    }

    /// Point positions.
    #[must_use]
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Per-point normals, if present.
    #[must_use]
    pub fn normals(&self) -> Option<&[Vec3]> {
        self.normals.as_deref()
    }

    /// Per-point colours, if present.
    #[must_use]
    pub fn colors(&self) -> Option<&[Rgba]> {
        self.colors.as_deref()
    }

    /// Moves every point by `offset`, computed in f64 and stored as f32 (see
    /// [`crate::TriMesh::translate`]).
    pub fn translate(&mut self, offset: glam::DVec3) {
        for p in &mut self.positions {
            *p = (p.as_dvec3() + offset).as_vec3();
        }
    }

    /// Number of points.
    #[must_use]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there are no points.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Bounds of the points, `None` when empty.
    #[must_use]
    pub fn bounds(&self) -> Option<Aabb> {
        Aabb::from_points(&self.positions)
    }

    /// Splits the cloud into its raw arrays: positions, normals, colours.
    #[must_use]
    pub fn into_parts(self) -> (Vec<Vec3>, Option<Vec<Vec3>>, Option<Vec<Rgba>>) {
        (self.positions, self.normals, self.colors)
    }
}
