//! `Camera`: pinhole cameras (OpenCV axes: x right, y down, z forward; docs/conventions.md §2),
//! camera files and rigs.

use std::path::PathBuf;

use glam::{DMat3, DVec3};
use numpy::{AllowTypeChange, PyArray1, PyArray2, PyArrayLike1, PyArrayLike2};
use pyo3::prelude::*;
use trisplat::geometry::Camera as RsCamera;
use trisplat::geometry::{read_cameras_json, read_transforms_json, sphere_rig as rig};

use crate::arrays::rows_in;
use crate::error;
use crate::threads;

/// A pinhole camera: image ``width`` × ``height`` pixels, focal lengths ``fx``, ``fy`` and
/// principal point ``cx``, ``cy`` in pixels, ``rotation`` (camera-to-world, float64 ``(3, 3)``:
/// its columns are the camera's x, y, z axes in world space, OpenCV axes) and ``position``
/// (the centre, float64 ``(3,)``).
#[pyclass(module = "trisplat", frozen)]
#[derive(Clone)]
pub struct Camera {
    /// The library's camera.
    pub inner: RsCamera,
}

fn vec3(array: &PyArrayLike1<'_, f64, AllowTypeChange>, what: &str) -> PyResult<DVec3> {
    let v = array.as_array();
    if v.len() != 3 {
        return Err(error::value(format!(
            "{what}: expected 3 values, got {}",
            v.len()
        )));
    }
    Ok(DVec3::new(v[0], v[1], v[2]))
}

#[pymethods]
impl Camera {
    #[new]
    #[pyo3(signature = (width, height, fx, fy, cx, cy, rotation, position, name = String::new(), id = 0))]
    #[expect(
        clippy::too_many_arguments,
        reason = "the camera's fields, as in Python"
    )]
    fn new(
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        rotation: PyArrayLike2<'_, f64, AllowTypeChange>,
        position: PyArrayLike1<'_, f64, AllowTypeChange>,
        name: String,
        id: i64,
    ) -> PyResult<Self> {
        let rows: Vec<[f64; 3]> = rows_in(&rotation, "rotation")?;
        let rows: [[f64; 3]; 3] = rows
            .try_into()
            .map_err(|_| error::value("rotation: expected a (3, 3) array"))?;
        let rotation = DMat3::from_cols_array_2d(&rows).transpose();
        let position = vec3(&position, "position")?;
        let inner = RsCamera::try_new(
            id,
            name,
            width,
            height,
            (fx, fy),
            (cx, cy),
            rotation,
            position,
        )
        .map_err(|e| error::about("camera", &e))?;
        Ok(Self { inner })
    }

    /// A camera at ``eye`` looking at ``target``, the image's up as close to ``up`` as
    /// possible, vertical field of view ``fov_y`` degrees, square pixels, principal point at
    /// the image centre.
    #[staticmethod]
    #[pyo3(signature = (eye, target, width, height, fov_y = 40.0, up = None, name = String::from("camera")))]
    fn look_at(
        eye: PyArrayLike1<'_, f64, AllowTypeChange>,
        target: PyArrayLike1<'_, f64, AllowTypeChange>,
        width: u32,
        height: u32,
        fov_y: f64,
        up: Option<PyArrayLike1<'_, f64, AllowTypeChange>>,
        name: String,
    ) -> PyResult<Self> {
        let up = up.map_or(Ok(DVec3::Y), |u| vec3(&u, "up"))?;
        let inner = RsCamera::look_at(
            name,
            vec3(&eye, "eye")?,
            vec3(&target, "target")?,
            up,
            (width, height),
            fov_y,
        )
        .map_err(|e| error::about("camera", &e))?;
        Ok(Self { inner })
    }

    /// Image name (3DGS ``img_name``).
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// Image width in pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width
    }

    /// Image height in pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height
    }

    /// Focal length along x, pixels.
    #[getter]
    fn fx(&self) -> f64 {
        self.inner.fx
    }

    /// Focal length along y, pixels.
    #[getter]
    fn fy(&self) -> f64 {
        self.inner.fy
    }

    /// Principal point x, pixels.
    #[getter]
    fn cx(&self) -> f64 {
        self.inner.cx
    }

    /// Principal point y, pixels.
    #[getter]
    fn cy(&self) -> f64 {
        self.inner.cy
    }

    /// Camera-to-world rotation, float64 ``(3, 3)``.
    #[getter]
    fn rotation<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let rows = self.inner.rotation().transpose().to_cols_array_2d();
        PyArray2::from_owned_array(
            py,
            numpy::ndarray::Array2::from_shape_fn((3, 3), |(i, j)| rows[i][j]),
        )
    }

    /// Camera centre in world space, float64 ``(3,)``.
    #[getter]
    fn position<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.position().to_array())
    }

    fn __repr__(&self) -> String {
        format!(
            "Camera({:?}, {}x{}, fx={}, fy={})",
            self.inner.name, self.inner.width, self.inner.height, self.inner.fx, self.inner.fy
        )
    }
}

/// The cameras of a 3DGS ``cameras.json`` (a list) or a NeRF ``transforms.json`` (an object;
/// ``size`` = ``(width, height)`` when the file gives none).
#[pyfunction]
#[pyo3(signature = (path, size = None))]
fn read_cameras(py: Python<'_>, path: PathBuf, size: Option<(u32, u32)>) -> PyResult<Vec<Camera>> {
    let cameras = threads::detach(py, || {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| trisplat::geometry::io::IoError::os(&path, e))?;
        if text.trim_start().starts_with('{') {
            read_transforms_json(&path, size)
        } else {
            read_cameras_json(&path)
        }
    })
    .map_err(|e| error::library(&e))?;
    Ok(cameras.into_iter().map(|inner| Camera { inner }).collect())
}

/// ``count`` cameras spread evenly over a sphere around ``center`` (a Fibonacci lattice), all
/// looking at it, far enough that a ball of ``radius`` fits the vertical field of view
/// ``fov_y`` (degrees) with a 10% margin; world up +y; named ``view_000``, ...
#[pyfunction]
#[pyo3(signature = (center, radius, count, width, height, fov_y = 40.0))]
fn sphere_rig(
    center: PyArrayLike1<'_, f64, AllowTypeChange>,
    radius: f64,
    count: usize,
    width: u32,
    height: u32,
    fov_y: f64,
) -> PyResult<Vec<Camera>> {
    let cameras = rig(
        vec3(&center, "center")?,
        radius,
        count,
        (width, height),
        fov_y,
    )
    .map_err(|e| error::about("sphere_rig", &e))?;
    Ok(cameras.into_iter().map(|inner| Camera { inner }).collect())
}

/// Adds the classes and functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Camera>()?;
    m.add_function(wrap_pyfunction!(read_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(sphere_rig, m)?)?;
    Ok(())
}
