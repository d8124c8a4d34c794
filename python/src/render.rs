//! render
use pyo3::prelude::*;
/// Adds the classes and functions of this module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> { Ok(()) }
