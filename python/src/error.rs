//! Library errors as Python exceptions.

use pyo3::PyErr;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};

create_exception!(
    trisplat,
    TrisplatError,
    PyException,
    "An error of the trisplat library; the message names the file, element or option at fault."
);

/// The error and its causes on one line (`error: cause: cause`), as the command line prints
/// them; a cause whose text the error already contains is not repeated.
fn chain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let text = cause.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        source = cause.source();
    }
    message
}

/// A library error as a [`TrisplatError`] with the library's message.
pub fn library(error: &(dyn std::error::Error + 'static)) -> PyErr {
    TrisplatError::new_err(chain(error))
}

/// A library error about one input that is not a file (an array, an argument): `what: error`.
pub fn about(what: &str, error: &(dyn std::error::Error + 'static)) -> PyErr {
    TrisplatError::new_err(format!("{what}: {}", chain(error)))
}

/// A bad argument (shape, name, value): `ValueError`.
pub fn value(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}
