//! Surfaces from depth maps and points: `tsdf`, `alpha_shape`, `delaunay`.

use numpy::{AllowTypeChange, PyArray2, PyArrayLike2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use trisplat::extract::alpha_shape::alpha_shape as shape_of;
use trisplat::extract::delaunay3d::Delaunay3d;
use trisplat::extract::tsdf::{ColorImage, DepthImage, TsdfOptions, fuse};
use trisplat::geometry::cleanup::keep_largest_clusters;

use glam::Vec3;

use crate::arrays::{rows_in, rows_out};
use crate::camera::Camera;
use crate::error;
use crate::mesh::Mesh;
use crate::threads;

/// Points as the library's `Vec3`s.
fn points_in(points: &PyArrayLike2<'_, f32, AllowTypeChange>) -> PyResult<Vec<Vec3>> {
    let rows: Vec<[f32; 3]> = rows_in(points, "points")?;
    Ok(rows.into_iter().map(Vec3::from).collect())
}

/// Image `i` of a list, checked against its camera's size.
fn image_size(
    image: &PyReadonlyArray2<'_, f32>,
    camera: &Camera,
    what: &str,
    i: usize,
) -> PyResult<()> {
    let shape = image.shape();
    let (w, h) = (camera.inner.width as usize, camera.inner.height as usize);
    if shape[0] != h || shape[1] != w {
        return Err(error::value(format!(
            "{what}[{i}]: shape {shape:?}, but camera {i} ('{}') is {w}x{h} (expected ({h}, {w}))",
            camera.inner.name
        )));
    }
    Ok(())
}

/// Fuses depth maps into a mesh: TSDF integration with Open3D's legacy per-voxel rules on
/// sparse 8³ voxel blocks, marching cubes, then 2DGS's clean-up (keep the connected pieces at
/// least as large as the ``keep_clusters``-th largest; 0 keeps all).
///
/// ``depths``: one float32 ``(H, W)`` z-depth map per camera (0, NaN, infinite or negative:
/// no surface); ``colors``: optional float32 ``(H, W, 3)`` images in 0..1 for vertex colours.
/// Unset sizes follow 2DGS: ``depth_trunc`` = 2 × the scene radius (from the cameras),
/// ``voxel`` = depth_trunc / 1024, ``trunc`` = 5 voxels.
#[pyfunction]
#[pyo3(signature = (cameras, depths, colors = None, voxel = None, trunc = None, depth_trunc = None, keep_clusters = 1))]
#[expect(
    clippy::too_many_arguments,
    reason = "the fusion's options as keywords"
)]
fn tsdf<'py>(
    py: Python<'py>,
    cameras: Vec<PyRef<'py, Camera>>,
    depths: Vec<PyArrayLike2<'py, f32, AllowTypeChange>>,
    colors: Option<Vec<numpy::PyArrayLike3<'py, f32, AllowTypeChange>>>,
    voxel: Option<f64>,
    trunc: Option<f64>,
    depth_trunc: Option<f64>,
    keep_clusters: usize,
) -> PyResult<Mesh> {
    if depths.len() != cameras.len() {
        return Err(error::value(format!(
            "{} depth maps for {} cameras",
            depths.len(),
            cameras.len()
        )));
    }
    let mut depth_images = Vec::with_capacity(depths.len());
    for (i, (depth, camera)) in depths.iter().zip(&cameras).enumerate() {
        image_size(depth, camera, "depths", i)?;
        let values = match depth.as_slice() {
            Ok(s) => s.to_vec(),
            Err(_) => depth.as_array().iter().copied().collect(),
        };
        let image = DepthImage::try_new(camera.inner.width, camera.inner.height, values)
            .map_err(|e| error::about(&format!("depths[{i}]"), &e))?;
        depth_images.push(image);
    }
    let color_images = match colors {
        None => None,
        Some(colors) => {
            if colors.len() != cameras.len() {
                return Err(error::value(format!(
                    "{} colour images for {} cameras",
                    colors.len(),
                    cameras.len()
                )));
            }
            let mut images = Vec::with_capacity(colors.len());
            for (i, (color, camera)) in colors.iter().zip(&cameras).enumerate() {
                let view = color.as_array();
                let (w, h) = (camera.inner.width as usize, camera.inner.height as usize);
                if view.shape() != [h, w, 3] {
                    return Err(error::value(format!(
                        "colors[{i}]: shape {:?}, expected ({h}, {w}, 3)",
                        view.shape()
                    )));
                }
                let values: Vec<f32> = view.iter().copied().collect();
                let rgb = values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
                let image = ColorImage::try_new(camera.inner.width, camera.inner.height, rgb)
                    .map_err(|e| error::about(&format!("colors[{i}]"), &e))?;
                images.push(image);
            }
            Some(images)
        }
    };
    let cameras: Vec<_> = cameras.iter().map(|c| c.inner.clone()).collect();
    let options = TsdfOptions {
        voxel,
        trunc,
        depth_trunc,
        keep_clusters,
        ..TsdfOptions::default()
    };
    let fused = threads::detach(py, || {
        fuse(&cameras, &depth_images, color_images.as_deref(), &options)
    })
    .map_err(|e| error::about("tsdf", &e))?;
    Ok(Mesh::from_rust(py, fused.mesh))
}

/// The alpha shape of ``points`` (float32 ``(N, 3)``; Open3D's definition): the boundary
/// triangles, oriented outward, of the Delaunay tetrahedra with circumradius <= ``alpha``. Its
/// vertices are the used points in input order. ``keep_clusters`` > 0 keeps only the
/// edge-connected pieces at least as large as the K-th largest. Exact duplicates are skipped;
/// fewer than four distinct or only coplanar points give an empty mesh.
#[pyfunction]
#[pyo3(signature = (points, alpha, keep_clusters = 0))]
fn alpha_shape<'py>(
    py: Python<'py>,
    points: PyArrayLike2<'py, f32, AllowTypeChange>,
    alpha: f64,
    keep_clusters: usize,
) -> PyResult<Mesh> {
    let points = points_in(&points)?;
    let mesh = threads::detach(py, || {
        shape_of(&points, alpha).map(|shape| match keep_clusters {
            0 => shape.mesh,
            k => keep_largest_clusters(&shape.mesh, k),
        })
    })
    .map_err(|e| error::about("alpha_shape", &e))?;
    Ok(Mesh::from_rust(py, mesh))
}

/// The 3D Delaunay tetrahedralisation of ``points`` (float32 ``(N, 3)``; exact predicates with
/// symbolic perturbation): uint32 ``(T, 4)`` indices into ``points``, each tetrahedron
/// positive in Shewchuk's ``orient3d`` convention (``(p1 - p0) × (p2 - p0) · (p3 - p0) < 0``). Exact duplicates are skipped (the first copy is used); coplanar or
/// fewer than four distinct points give no tetrahedra.
#[pyfunction]
fn delaunay<'py>(
    py: Python<'py>,
    points: PyArrayLike2<'py, f32, AllowTypeChange>,
) -> PyResult<Bound<'py, PyArray2<u32>>> {
    let points = points_in(&points)?;
    let tetrahedra = threads::detach(py, || {
        Delaunay3d::new(&points).map(|d| d.tetrahedra().to_vec())
    })
    .map_err(|e| error::about("delaunay", &e))?;
    Ok(rows_out::<[u32; 4], u32>(py, tetrahedra, 4))
}

/// Adds the functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(tsdf, m)?)?;
    m.add_function(wrap_pyfunction!(alpha_shape, m)?)?;
    m.add_function(wrap_pyfunction!(delaunay, m)?)?;
    Ok(())
}
