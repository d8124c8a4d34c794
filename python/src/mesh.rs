//! `Mesh` and `PointCloud`: the library's types as numpy arrays, and their files.

use std::path::PathBuf;

use glam::{DVec3, Vec2, Vec3};
use numpy::{AllowTypeChange, PyArray2, PyArrayLike2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use trisplat::geometry::io::{self, WriteOptions};
use trisplat::geometry::mesh_stats::MeshStats;
use trisplat::geometry::{PointCloud as RsPointCloud, TriMesh};

use crate::arrays::{CloneBound, rows_in, rows_out};
use crate::error;
use crate::json::{json_to_py, to_json};
use crate::threads;

/// A triangle mesh: ``vertices`` float64 ``(N, 3)``, ``triangles`` uint32 ``(M, 3)``, and
/// optional per-vertex ``normals`` float32 ``(N, 3)``, ``uvs`` float32 ``(N, 2)``, ``colors``
/// float32 RGBA in 0..1 ``(N, 4)``.
///
/// The arrays are the object's own (read-only attributes, writable arrays): edit them in place
/// or build a new ``Mesh``. Arrays given to the constructor are converted to these dtypes when
/// needed (``np.asarray``), else kept without a copy. Indices and finiteness are checked when
/// the mesh is handed to the library.
#[pyclass(module = "trisplat", frozen)]
pub struct Mesh {
    /// Vertex positions, float64 ``(N, 3)``.
    #[pyo3(get)]
    vertices: Py<PyArray2<f64>>,
    /// Vertex indices of each triangle, uint32 ``(M, 3)``.
    #[pyo3(get)]
    triangles: Py<PyArray2<u32>>,
    /// Per-vertex normals, float32 ``(N, 3)``, or None.
    #[pyo3(get)]
    normals: Option<Py<PyArray2<f32>>>,
    /// Per-vertex texture coordinates, float32 ``(N, 2)``, or None.
    #[pyo3(get)]
    uvs: Option<Py<PyArray2<f32>>>,
    /// Per-vertex RGBA colours in 0..1, float32 ``(N, 4)``, or None.
    #[pyo3(get)]
    colors: Option<Py<PyArray2<f32>>>,
}

/// `(rows, cols)` of a held array must be `(_, cols)`.
fn check_cols<T: numpy::Element>(
    array: &Bound<'_, PyArray2<T>>,
    cols: usize,
    what: &str,
) -> PyResult<usize> {
    let shape = array.shape();
    if shape[1] != cols {
        return Err(error::value(format!(
            "{what}: expected an array of shape (N, {cols}), got {shape:?}"
        )));
    }
    Ok(shape[0])
}

/// An optional per-vertex array of `cols` columns and `n` rows.
fn optional<'py>(
    array: Option<PyArrayLike2<'py, f32, AllowTypeChange>>,
    n: usize,
    cols: usize,
    what: &str,
) -> PyResult<Option<Py<PyArray2<f32>>>> {
    let Some(array) = array else {
        return Ok(None);
    };
    let array: Bound<'py, PyArray2<f32>> = array.clone_bound();
    let rows = check_cols(&array, cols, what)?;
    if rows != n {
        return Err(error::value(format!(
            "{what}: {rows} rows, expected one per vertex ({n})"
        )));
    }
    Ok(Some(array.unbind()))
}

#[pymethods]
impl Mesh {
    #[new]
    #[pyo3(signature = (vertices, triangles, normals = None, uvs = None, colors = None))]
    fn new<'py>(
        vertices: PyArrayLike2<'py, f64, AllowTypeChange>,
        triangles: PyArrayLike2<'py, u32, AllowTypeChange>,
        normals: Option<PyArrayLike2<'py, f32, AllowTypeChange>>,
        uvs: Option<PyArrayLike2<'py, f32, AllowTypeChange>>,
        colors: Option<PyArrayLike2<'py, f32, AllowTypeChange>>,
    ) -> PyResult<Self> {
        let vertices: Bound<'py, PyArray2<f64>> = vertices.clone_bound();
        let triangles: Bound<'py, PyArray2<u32>> = triangles.clone_bound();
        let n = check_cols(&vertices, 3, "vertices")?;
        check_cols(&triangles, 3, "triangles")?;
        Ok(Self {
            normals: optional(normals, n, 3, "normals")?,
            uvs: optional(uvs, n, 2, "uvs")?,
            colors: optional(colors, n, 4, "colors")?,
            vertices: vertices.unbind(),
            triangles: triangles.unbind(),
        })
    }

    /// Number of vertices.
    #[getter]
    fn vertex_count(&self, py: Python<'_>) -> usize {
        self.vertices.bind(py).shape()[0]
    }

    /// Number of triangles.
    #[getter]
    fn triangle_count(&self, py: Python<'_>) -> usize {
        self.triangles.bind(py).shape()[0]
    }

    /// Surface area (sum of the triangle areas, in float64).
    fn area(&self, py: Python<'_>) -> PyResult<f64> {
        let mesh = self.to_rust(py)?;
        Ok(threads::detach(py, || mesh.area()))
    }

    /// Signed volume (positive for a closed mesh with outward faces), in float64.
    fn volume(&self, py: Python<'_>) -> PyResult<f64> {
        let mesh = self.to_rust(py)?;
        Ok(threads::detach(py, || mesh.signed_volume()))
    }

    /// The structure of the mesh (``eval``'s ``pred_structure``): ``vertices``, ``triangles``,
    /// ``area``, ``components``, ``largest_component_area_fraction``, ``boundary_edges``,
    /// ``non_manifold_edges``, ``watertight``, ``winding_consistent`` (docs/conventions.md §8).
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let mesh = self.to_rust(py)?;
        let stats = threads::detach(py, || MeshStats::of(&mesh));
        json_to_py(py, &to_json(&stats)?)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "Mesh({} vertices, {} triangles)",
            self.vertex_count(py),
            self.triangle_count(py)
        )
    }
}

impl Mesh {
    /// The library's mesh (a copy of the arrays), checked.
    ///
    /// # Errors
    /// `TrisplatError` naming the first invalid index or value.
    pub fn to_rust(&self, py: Python<'_>) -> PyResult<TriMesh> {
        let positions: Vec<[f64; 3]> = rows_in(&self.vertices.bind(py).readonly(), "vertices")?;
        let triangles: Vec<[u32; 3]> = rows_in(&self.triangles.bind(py).readonly(), "triangles")?;
        let mut mesh =
            TriMesh::try_new(positions, triangles).map_err(|e| error::about("mesh", &e))?;
        if let Some(normals) = &self.normals {
            let normals: Vec<[f32; 3]> = rows_in(&normals.bind(py).readonly(), "normals")?;
            mesh = mesh
                .with_normals(normals.into_iter().map(Vec3::from).collect())
                .map_err(|e| error::about("mesh normals", &e))?;
        }
        if let Some(uvs) = &self.uvs {
            let uvs: Vec<[f32; 2]> = rows_in(&uvs.bind(py).readonly(), "uvs")?;
            mesh = mesh
                .with_uvs(uvs.into_iter().map(Vec2::from).collect())
                .map_err(|e| error::about("mesh uvs", &e))?;
        }
        if let Some(colors) = &self.colors {
            let colors: Vec<[f32; 4]> = rows_in(&colors.bind(py).readonly(), "colors")?;
            mesh = mesh
                .with_colors(colors)
                .map_err(|e| error::about("mesh colors", &e))?;
        }
        Ok(mesh)
    }

    /// The library's mesh as arrays, moved (no copy).
    pub fn from_rust(py: Python<'_>, mesh: TriMesh) -> Self {
        let (positions, triangles, normals, uvs, colors) = mesh.into_parts();
        Self {
            vertices: rows_out::<DVec3, f64>(py, positions, 3).unbind(),
            triangles: rows_out::<[u32; 3], u32>(py, triangles, 3).unbind(),
            normals: normals.map(|n| rows_out::<Vec3, f32>(py, n, 3).unbind()),
            uvs: uvs.map(|u| rows_out::<Vec2, f32>(py, u, 2).unbind()),
            colors: colors.map(|c| rows_out::<[f32; 4], f32>(py, c, 4).unbind()),
        }
    }
}

/// A point cloud: ``points`` float32 ``(N, 3)`` and optional ``normals`` float32 ``(N, 3)``,
/// ``colors`` float32 RGBA in 0..1 ``(N, 4)`` (arrays as in ``Mesh``).
#[pyclass(module = "trisplat", frozen)]
pub struct PointCloud {
    /// Positions, float32 ``(N, 3)``.
    #[pyo3(get)]
    points: Py<PyArray2<f32>>,
    /// Normals, float32 ``(N, 3)``, or None.
    #[pyo3(get)]
    normals: Option<Py<PyArray2<f32>>>,
    /// RGBA colours in 0..1, float32 ``(N, 4)``, or None.
    #[pyo3(get)]
    colors: Option<Py<PyArray2<f32>>>,
}

#[pymethods]
impl PointCloud {
    #[new]
    #[pyo3(signature = (points, normals = None, colors = None))]
    fn new<'py>(
        points: PyArrayLike2<'py, f32, AllowTypeChange>,
        normals: Option<PyArrayLike2<'py, f32, AllowTypeChange>>,
        colors: Option<PyArrayLike2<'py, f32, AllowTypeChange>>,
    ) -> PyResult<Self> {
        let points: Bound<'py, PyArray2<f32>> = points.clone_bound();
        let n = check_cols(&points, 3, "points")?;
        Ok(Self {
            normals: optional(normals, n, 3, "normals")?,
            colors: optional(colors, n, 4, "colors")?,
            points: points.unbind(),
        })
    }

    fn __len__(&self, py: Python<'_>) -> usize {
        self.points.bind(py).shape()[0]
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!("PointCloud({} points)", self.__len__(py))
    }
}

impl PointCloud {
    /// The library's point cloud (a copy of the arrays), checked.
    ///
    /// # Errors
    /// `TrisplatError` naming the first non-finite value or a length mismatch.
    pub fn to_rust(&self, py: Python<'_>) -> PyResult<RsPointCloud> {
        let points: Vec<[f32; 3]> = rows_in(&self.points.bind(py).readonly(), "points")?;
        let mut cloud = RsPointCloud::try_new(points.into_iter().map(Vec3::from).collect())
            .map_err(|e| error::about("points", &e))?;
        if let Some(normals) = &self.normals {
            let normals: Vec<[f32; 3]> = rows_in(&normals.bind(py).readonly(), "normals")?;
            cloud = cloud
                .with_normals(normals.into_iter().map(Vec3::from).collect())
                .map_err(|e| error::about("point normals", &e))?;
        }
        if let Some(colors) = &self.colors {
            let colors: Vec<[f32; 4]> = rows_in(&colors.bind(py).readonly(), "colors")?;
            cloud = cloud
                .with_colors(colors)
                .map_err(|e| error::about("point colors", &e))?;
        }
        Ok(cloud)
    }

    /// The library's point cloud as arrays, moved (no copy).
    pub fn from_rust(py: Python<'_>, cloud: RsPointCloud) -> Self {
        let (points, normals, colors) = cloud.into_parts();
        Self {
            points: rows_out::<Vec3, f32>(py, points, 3).unbind(),
            normals: normals.map(|n| rows_out::<Vec3, f32>(py, n, 3).unbind()),
            colors: colors.map(|c| rows_out::<[f32; 4], f32>(py, c, 4).unbind()),
        }
    }
}

/// Reads a triangle mesh: PLY, OBJ (the file's vertex order), glTF/GLB (its rest state, node
/// transforms applied), chosen by extension.
///
/// Raises ``TrisplatError`` naming the file and the element at fault.
#[pyfunction]
fn read_mesh(py: Python<'_>, path: PathBuf) -> PyResult<Mesh> {
    let mesh = threads::detach(py, || io::read_mesh(&path)).map_err(|e| error::library(&e))?;
    Ok(Mesh::from_rust(py, mesh))
}

/// Writes a mesh atomically, format by extension (.ply binary unless ``ascii``, .obj, .gltf,
/// .glb).
#[pyfunction]
#[pyo3(signature = (path, mesh, ascii = false))]
fn write_mesh(py: Python<'_>, path: PathBuf, mesh: &Mesh, ascii: bool) -> PyResult<()> {
    let mesh = mesh.to_rust(py)?;
    threads::detach(py, || io::write_mesh(&path, &mesh, WriteOptions { ascii }))
        .map_err(|e| error::library(&e))
}

/// Reads a point cloud: a PLY's vertices (with ``nx ny nz`` and colours when present), or the
/// vertices of any mesh file.
#[pyfunction]
fn read_points(py: Python<'_>, path: PathBuf) -> PyResult<PointCloud> {
    let cloud = threads::detach(py, || io::read_points(&path)).map_err(|e| error::library(&e))?;
    Ok(PointCloud::from_rust(py, cloud))
}

/// Writes a point cloud as PLY (binary unless ``ascii``), atomically.
#[pyfunction]
#[pyo3(signature = (path, cloud, ascii = false))]
fn write_points(py: Python<'_>, path: PathBuf, cloud: &PointCloud, ascii: bool) -> PyResult<()> {
    let cloud = cloud.to_rust(py)?;
    threads::detach(py, || {
        io::write_points(&path, &cloud, WriteOptions { ascii })
    })
    .map_err(|e| error::library(&e))
}

/// Adds the classes and functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Mesh>()?;
    m.add_class::<PointCloud>()?;
    m.add_function(wrap_pyfunction!(read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(write_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(read_points, m)?)?;
    m.add_function(wrap_pyfunction!(write_points, m)?)?;
    Ok(())
}
