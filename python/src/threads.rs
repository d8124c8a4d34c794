//! Thread control: `trisplat.set_num_threads(n)` and `trisplat.get_num_threads()`.
//!
//! Every call that runs the library's parallel loops goes through [`detach`]: the GIL is
//! released and the work runs in the pool chosen here. By default that is rayon's global pool
//! (all cores, or `RAYON_NUM_THREADS` when it is set before the first parallel call), as the
//! CLI's `--threads` default; results do not depend on the thread count.

use std::sync::{Arc, PoisonError, RwLock};

use pyo3::prelude::*;
use pyo3::types::PyModule;

use crate::error;

/// The pool set by `set_num_threads`; `None`: rayon's global pool.
static POOL: RwLock<Option<Arc<rayon::ThreadPool>>> = RwLock::new(None);

/// The pool calls run in now (`None`: the global one).
fn current() -> Option<Arc<rayon::ThreadPool>> {
    POOL.read().unwrap_or_else(PoisonError::into_inner).clone()
}

/// Runs `work` with the GIL released, in the pool set by `set_num_threads` (else rayon's
/// global pool).
pub fn detach<T, F>(py: Python<'_>, work: F) -> T
where
    T: Send,
    F: FnOnce() -> T + Send,
{
    let pool = current();
    py.detach(move || match pool {
        Some(pool) => pool.install(work),
        None => work(),
    })
}

/// Sets the number of worker threads of every later call (the CLI's ``--threads``). ``None``
/// or ``0``: back to the default, all cores (or ``RAYON_NUM_THREADS``). Results do not depend
/// on it. A call already running keeps the threads it started with.
#[pyfunction]
#[pyo3(signature = (n = None))]
fn set_num_threads(n: Option<usize>) -> PyResult<()> {
    let pool = match n {
        None | Some(0) => None,
        Some(n) if n > 1024 => {
            return Err(error::value(format!(
                "{n} threads: expected 1 to 1024 (or 0/None for all cores)"
            )));
        }
        Some(n) => Some(Arc::new(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .thread_name(|i| format!("trisplat-{i}"))
                .build()
                .map_err(|e| error::value(format!("{n} threads: {e}")))?,
        )),
    };
    *POOL.write().unwrap_or_else(PoisonError::into_inner) = pool;
    Ok(())
}

/// The number of worker threads calls use now.
#[pyfunction]
fn get_num_threads() -> usize {
    current().map_or_else(rayon::current_num_threads, |p| p.current_num_threads())
}

/// Adds the functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(set_num_threads, m)?)?;
    m.add_function(wrap_pyfunction!(get_num_threads, m)?)?;
    Ok(())
}
