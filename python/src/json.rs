//! Library results as the command line's JSON, then as Python dicts: the keys of a dict are
//! those of the matching `--json` output (docs/conventions.md §10).

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::error;

/// A value serialised as the command line's JSON would be.
///
/// # Errors
/// A value serde cannot represent (a library bug).
pub fn to_json<T: serde::Serialize + ?Sized>(value: &T) -> PyResult<serde_json::Value> {
    serde_json::to_value(value).map_err(|e| error::value(e.to_string()))
}

/// JSON as Python objects: objects become dicts (keys in the serialised order), arrays lists,
/// numbers int or float, null None.
///
/// # Errors
/// A failed Python allocation.
pub fn json_to_py<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => pyo3::types::PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_u64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any(),
            (None, Some(u)) => u.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(json_to_py(py, item)?)?;
            }
            list.into_any()
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (k, v) in map {
                dict.set_item(k, json_to_py(py, v)?)?;
            }
            dict.into_any()
        }
    })
}
