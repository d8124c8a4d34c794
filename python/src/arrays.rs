//! numpy arrays to and from the library's buffers.
//!
//! Out: a `Vec` of fixed-size rows (`DVec3`, `[u32; 3]`, `[f32; 4]`, ...) is reinterpreted as a
//! flat `Vec` of its scalars (same allocation, `bytemuck::allocation::try_cast_vec`) and moved
//! into a numpy array: no copy. In: any array-like is converted to the dtype if needed (numpy's
//! rules, as `np.asarray(x, dtype)`), checked for its shape, then copied once into the rows
//! the library's types own (one pass over a contiguous array).

use bytemuck::{AnyBitPattern, NoUninit};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    Element, IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2,
};
use pyo3::prelude::*;

use crate::error;

/// `rows` (each of `C` scalars `T`) as a numpy array of shape `(len, C)`, without a copy.
///
/// # Panics
/// When `R` is not `C` scalars of `T` (a programming error of the caller).
pub fn rows_out<'py, R: NoUninit, T: AnyBitPattern + Element>(
    py: Python<'py>,
    rows: Vec<R>,
    cols: usize,
) -> Bound<'py, PyArray2<T>> {
    assert_eq!(std::mem::size_of::<R>(), cols * std::mem::size_of::<T>());
    let n = rows.len();
    let flat = flat(rows);
    Array2::from_shape_vec((n, cols), flat)
        .expect("n * cols scalars")
        .into_pyarray(py)
}

/// A flat buffer of `n` values as a numpy array of shape `(n,)`, without a copy.
pub fn vec_out<T: Element>(py: Python<'_>, values: Vec<T>) -> Bound<'_, PyArray1<T>> {
    Array1::from_vec(values).into_pyarray(py)
}

/// A row-major image buffer of `h × w × c` values as `(h, w, c)`, or `(h, w)` when `c` is 1,
/// without a copy.
///
/// # Errors
/// A buffer of another length (a library bug).
pub fn image_out<'py>(
    py: Python<'py>,
    values: Vec<f32>,
    (h, w, c): (usize, usize, usize),
) -> PyResult<Bound<'py, PyAny>> {
    if c == 1 {
        let a = Array2::from_shape_vec((h, w), values).map_err(|e| error::value(e.to_string()))?;
        Ok(a.into_pyarray(py).into_any())
    } else {
        let a =
            Array3::from_shape_vec((h, w, c), values).map_err(|e| error::value(e.to_string()))?;
        Ok(PyArray3::from_owned_array(py, a).into_any())
    }
}

/// The scalars of `rows`, same allocation when the layout allows (it always does for rows of
/// one scalar type), else copied.
fn flat<R: NoUninit, T: AnyBitPattern>(rows: Vec<R>) -> Vec<T> {
    match bytemuck::allocation::try_cast_vec(rows) {
        Ok(flat) => flat,
        Err((_, rows)) => bytemuck::cast_slice(&rows).to_vec(),
    }
}

/// A 2-D array (an argument converted with `PyArrayLike2<T, AllowTypeChange>`, or an array
/// held by a class) of shape `(N, C)` as `N` rows of `C` scalars, named `what` in errors.
///
/// # Errors
/// `ValueError` for another shape.
pub fn rows_in<T: Element + Copy, const C: usize>(
    array: &PyReadonlyArray2<'_, T>,
    what: &str,
) -> PyResult<Vec<[T; C]>> {
    let view = array.as_array();
    if view.ncols() != C {
        return Err(error::value(format!(
            "{what}: expected an array of shape (N, {C}), got {:?}",
            view.shape()
        )));
    }
    if let Ok(slice) = array.as_slice() {
        return Ok(slice
            .chunks_exact(C)
            .map(|row| std::array::from_fn(|k| row[k]))
            .collect());
    }
    Ok(view
        .rows()
        .into_iter()
        .map(|row| std::array::from_fn(|k| row[k]))
        .collect())
}

/// A 1-D array as a `Vec`.
pub fn vec_in<T: Element + Copy>(array: &PyReadonlyArray1<'_, T>) -> Vec<T> {
    match array.as_slice() {
        Ok(slice) => slice.to_vec(),
        Err(_) => array.as_array().iter().copied().collect(),
    }
}

/// The array behind a converted argument, kept by a class (the conversion's read-only borrow
/// ends with the argument).
pub trait CloneBound<'py, T: Element, D> {
    /// The array itself (no copy).
    fn clone_bound(&self) -> Bound<'py, numpy::PyArray<T, D>>;
}

impl<'py, T: Element, D: numpy::ndarray::Dimension> CloneBound<'py, T, D>
    for numpy::PyReadonlyArray<'py, T, D>
{
    fn clone_bound(&self) -> Bound<'py, numpy::PyArray<T, D>> {
        std::ops::Deref::deref(self).clone()
    }
}
