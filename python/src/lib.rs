//! trisplat for Python: the library's entry points as one extension module (`import trisplat`),
//! numpy arrays in and out.
//!
//! Arrays leave Rust without a copy: the library's buffers (`Vec<DVec3>`, `Vec<[u32; 3]>`, image
//! `Vec<f32>`) are handed to numpy as they are ([`arrays`]). Arrays coming in are converted to
//! the library's dtype if needed and copied once into the library's owned types, which own
//! their buffers. Heavy work runs with the GIL released, in the pool `set_num_threads` chose
//! ([`threads`]). Library errors become
//! `trisplat.TrisplatError` with the library's message ([`error`]).
//!
//! | module | Python |
//! |---|---|
//! | [`mesh`] | `Mesh`, `PointCloud`, `read_mesh`, `write_mesh`, `read_points`, `write_points` |
//! | [`gaussians`] | `Gaussians`, `read_gaussians`, `write_gaussians`, `bind`, `attach`, `Deformer`, `deform` |
//! | [`camera`] | `Camera`, `read_cameras`, `sphere_rig` |
//! | [`render`] | `render` |
//! | [`extract`] | `tsdf`, `alpha_shape`, `delaunay` |
//! | [`eval`] | `eval` |
//! | [`session`] | `Session` |
//! | [`threads`] | `set_num_threads`, `get_num_threads` |
//!
//! The signatures, with types, are in `python/trisplat.pyi`; usage in `python/README.md`.

use pyo3::prelude::*;

pub mod arrays;
pub mod camera;
pub mod error;
pub mod eval;
pub mod extract;
pub mod gaussians;
pub mod json;
pub mod mesh;
pub mod render;
pub mod session;
pub mod threads;

/// The `trisplat` extension module.
#[pymodule(name = "trisplat")]
fn init(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("TrisplatError", m.py().get_type::<error::TrisplatError>())?;
    mesh::register(m)?;
    gaussians::register(m)?;
    camera::register(m)?;
    render::register(m)?;
    extract::register(m)?;
    eval::register(m)?;
    session::register(m)?;
    threads::register(m)?;
    Ok(())
}
