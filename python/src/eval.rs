//! `eval`: `trisplat eval`'s measurement (`pipeline::eval`) on files or arrays, its `--json`
//! object as a dict (docs/conventions.md §8, §10).

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyAny;
use trisplat::pipeline::config::DEFAULT_MAX_SAMPLES;
use trisplat::pipeline::eval::{self as measure, DEFAULT_SAMPLES, EvalInput, EvalOptions};

use crate::error;
use crate::json::{json_to_py, to_json};
use crate::mesh::{Mesh, PointCloud};
use crate::threads;

/// An argument: a path, a `Mesh` or a `PointCloud`; with the name errors give it (the path,
/// else `side`).
fn input(py: Python<'_>, value: &Bound<'_, PyAny>, side: &str) -> PyResult<(EvalInput, String)> {
    if let Ok(mesh) = value.cast::<Mesh>() {
        let mesh = mesh.get().to_rust(py)?;
        return Ok((EvalInput::mesh(mesh), side.to_owned()));
    }
    if let Ok(points) = value.cast::<PointCloud>() {
        let points = points.get().to_rust(py)?;
        return Ok((EvalInput::Points(points), side.to_owned()));
    }
    let path: PathBuf = value.extract().map_err(|_| {
        pyo3::exceptions::PyTypeError::new_err(format!(
            "{side}: expected a path, a Mesh or a PointCloud"
        ))
    })?;
    let read = threads::detach(py, || EvalInput::read(&path)).map_err(|e| error::library(&e))?;
    Ok((read, path.display().to_string()))
}

/// Measures ``pred`` against ``gt`` as ``trisplat eval --json`` does and returns its JSON
/// object as a dict (docs/conventions.md §8, §10): ``command`` (``"eval"``), ``accuracy``,
/// ``completeness``, ``chamfer_l1``, ``chamfer_l2``, ``normal_consistency``,
/// ``normal_angle_deg``, ``n_pred``, ``n_gt``, ``thresholds`` (a list of ``tau``,
/// ``tau_fraction``, ``precision``, ``recall``, ``fscore``), ``seconds``,
/// ``gt_bbox_diagonal``, ``pred_structure``, ``gt_structure``, ``area_ratio``,
/// ``shared_vertex_fraction``, ``relation``.
///
/// ``pred`` and ``gt``: a file path (a file with faces is a mesh, a PLY without faces a point
/// cloud), a ``Mesh`` or a ``PointCloud``. Meshes are sampled area-uniformly (``samples``
/// points, ``seed``; the ground truth with an independent stream). Thresholds: ``taus``
/// (absolute) then ``tau_fractions`` (of the ground truth's bounding-box diagonal); by
/// default the fractions 0.001, 0.0025, 0.005, 0.01. ``surface``: exact point-to-triangle
/// distances to mesh sides. Both sides are moved to the ground truth's centre (in float64)
/// before they are sampled in float32.
#[pyfunction]
#[pyo3(signature = (pred, gt, samples = DEFAULT_SAMPLES, seed = 0, taus = None, tau_fractions = None, surface = false, max_samples = DEFAULT_MAX_SAMPLES))]
#[expect(
    clippy::too_many_arguments,
    reason = "the command's options as keywords"
)]
fn eval<'py>(
    py: Python<'py>,
    pred: &Bound<'py, PyAny>,
    gt: &Bound<'py, PyAny>,
    samples: usize,
    seed: u64,
    taus: Option<Vec<f64>>,
    tau_fractions: Option<Vec<f64>>,
    surface: bool,
    max_samples: usize,
) -> PyResult<Bound<'py, PyAny>> {
    if samples == 0 || samples > max_samples {
        return Err(error::value(format!(
            "samples {samples}: expected 1 to max_samples ({max_samples})"
        )));
    }
    let (taus, fractions) = (taus.unwrap_or_default(), tau_fractions.unwrap_or_default());
    if let Some(t) = taus
        .iter()
        .chain(&fractions)
        .find(|t| !(t.is_finite() && **t > 0.0))
    {
        return Err(error::value(format!(
            "threshold {t}: expected a finite positive number"
        )));
    }
    let options = EvalOptions {
        samples,
        seed,
        taus: measure::thresholds(&taus, &fractions),
        surface,
    };
    let (pred, pred_name) = input(py, pred, "prediction")?;
    let (gt, gt_name) = input(py, gt, "ground truth")?;
    let done = threads::detach(py, || {
        measure::evaluate(pred, gt, (&pred_name, &gt_name), &options)
    })
    .map_err(|e| error::library(&e))?;
    let mut object = to_json(&done.report)?;
    if let serde_json::Value::Object(fields) = &mut object {
        fields.insert("command".into(), "eval".into());
    }
    json_to_py(py, &object)
}

/// Adds the functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(eval, m)?)?;
    Ok(())
}
