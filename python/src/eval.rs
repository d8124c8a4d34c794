//! `eval`: geometry metrics of a prediction against a ground truth, as `trisplat eval --json`
//! computes them (docs/conventions.md §8, §10).
//!
//! The steps are those of `cli/src/commands/eval.rs`, each a library call: read (a PLY without
//! faces is a point cloud), shared vertices where the inputs are, both moved to the ground
//! truth's centre in f64, mesh sides sampled (the ground truth with the seed's independent
//! stream), thresholds resolved against the ground truth's diagonal, `metrics::evaluate` and
//! each mesh's `MeshStats`. The dict has the keys of the command's JSON object.

use std::path::PathBuf;

use glam::DVec3;
use pyo3::prelude::*;
use pyo3::types::PyAny;
use trisplat::geometry::io::{self, Format, ply};
use trisplat::geometry::mesh_stats::MeshStats;
use trisplat::geometry::metrics::{
    self, DEFAULT_TAU_FRACTIONS, Metrics, MetricsError, MetricsOptions, Relation, Shape, Side, Tau,
};
use trisplat::geometry::rng::splitmix64;
use trisplat::geometry::sampling::sample_uniform;
use trisplat::geometry::{PointCloud as RsPointCloud, TriMesh};
use trisplat::pipeline::config::DEFAULT_MAX_SAMPLES;

use crate::error::{self, TrisplatError};
use crate::json::{json_to_py, to_json};
use crate::mesh::{Mesh, PointCloud};

/// Samples drawn on each mesh input unless `samples` says otherwise (as `trisplat eval`).
const DEFAULT_SAMPLES: usize = 100_000;

/// One side: a mesh (with its samples, once drawn) or a point cloud.
enum Input {
    Mesh(TriMesh, RsPointCloud),
    Points(RsPointCloud),
}

impl Input {
    fn shape(&self) -> Shape<'_> {
        match self {
            Self::Mesh(mesh, samples) => Shape::mesh(mesh, samples),
            Self::Points(points) => Shape::points(points),
        }
    }

    fn mesh(&self) -> Option<&TriMesh> {
        match self {
            Self::Mesh(mesh, _) => Some(mesh),
            Self::Points(_) => None,
        }
    }

    fn extent(&self) -> f64 {
        match self {
            Self::Mesh(mesh, _) => mesh.bounds().map_or(0.0, |b| b.diagonal()),
            Self::Points(points) => metrics::bbox_diagonal(points.positions()),
        }
    }

    fn shared_with(&self, gt: &Self) -> Option<f64> {
        let gt = gt.mesh()?.positions();
        match self {
            Self::Mesh(mesh, _) => metrics::shared_vertex_fraction(gt, mesh.positions()),
            Self::Points(points) => {
                let widened: Vec<_> = points.positions().iter().map(|p| p.as_dvec3()).collect();
                metrics::shared_vertex_fraction(gt, &widened)
            }
        }
    }

    fn centre(&self) -> Option<DVec3> {
        match self {
            Self::Mesh(mesh, _) => mesh.bounds().map(|b| b.center()),
            Self::Points(points) => points.bounds().map(|b| b.center()),
        }
    }

    fn translate(&mut self, offset: DVec3) {
        match self {
            Self::Mesh(mesh, _) => mesh.translate(offset),
            Self::Points(points) => points.translate(offset),
        }
    }

    /// Samples a mesh side; `name` names it in the error of a mesh without area.
    fn sample(self, samples: usize, seed: u64, name: &str) -> PyResult<Self> {
        let Self::Mesh(mesh, _) = self else {
            return Ok(self);
        };
        let sampled = sample_uniform(&mesh, samples, seed);
        if sampled.is_empty() {
            return Err(TrisplatError::new_err(format!(
                "{name}: the mesh has zero surface area, nothing to sample"
            )));
        }
        Ok(Self::Mesh(mesh, sampled))
    }
}

/// A file read as `trisplat eval` reads it: a PLY without faces (or a mesh file without
/// triangles) is a point cloud.
fn read_input(path: &std::path::Path) -> PyResult<Input> {
    let lib = |e: &(dyn std::error::Error + 'static)| error::library(e);
    let mesh = if Format::from_path(path).map_err(|e| lib(&e))? == Format::Ply {
        let doc = ply::read_ply_document(path).map_err(|e| lib(&e))?;
        let has_faces = doc.element("face").is_some_and(|f| f.count > 0)
            || doc.element("tristrips").is_some_and(|f| f.count > 0);
        if !has_faces {
            let (points, _) = ply::ply_to_points(path, &doc).map_err(|e| lib(&e))?;
            return Ok(Input::Points(points));
        }
        ply::ply_to_mesh(path, &doc).map_err(|e| lib(&e))?.0
    } else {
        io::read_mesh(path).map_err(|e| lib(&e))?
    };
    if mesh.triangle_count() == 0 {
        let named = |e: &(dyn std::error::Error + 'static)| {
            error::about(&format!("{}: vertices", path.display()), e)
        };
        let normals = mesh.normals().map(<[_]>::to_vec);
        let mut points = RsPointCloud::try_new(mesh.positions_f32()).map_err(|e| named(&e))?;
        if let Some(n) = normals {
            points = points.with_normals(n).map_err(|e| named(&e))?;
        }
        return Ok(Input::Points(points));
    }
    Ok(Input::Mesh(mesh, RsPointCloud::default()))
}

/// An argument: a path, a `Mesh` or a `PointCloud`; with the name errors give it.
fn input(py: Python<'_>, value: &Bound<'_, PyAny>, side: &str) -> PyResult<(Input, String)> {
    if let Ok(mesh) = value.cast::<Mesh>() {
        return Ok((
            Input::Mesh(mesh.get().to_rust(py)?, RsPointCloud::default()),
            side.to_owned(),
        ));
    }
    if let Ok(points) = value.cast::<PointCloud>() {
        return Ok((Input::Points(points.get().to_rust(py)?), side.to_owned()));
    }
    let path: PathBuf = value.extract().map_err(|_| {
        pyo3::exceptions::PyTypeError::new_err(format!(
            "{side}: expected a path, a Mesh or a PointCloud"
        ))
    })?;
    let name = path.display().to_string();
    Ok((py.detach(|| read_input(&path))?, name))
}

/// What `eval` reports beyond [`Metrics`]: the fields of `trisplat eval --json`.
#[derive(serde::Serialize)]
struct Report {
    #[serde(flatten)]
    metrics: Metrics,
    gt_bbox_diagonal: f64,
    pred_structure: Option<MeshStats>,
    gt_structure: Option<MeshStats>,
    area_ratio: Option<f64>,
    shared_vertex_fraction: Option<f64>,
    relation: Relation,
}

/// Measures ``pred`` against ``gt`` as ``trisplat eval --json`` does and returns its JSON
/// object as a dict (docs/conventions.md §8, §10): ``accuracy``, ``completeness``,
/// ``chamfer_l1``, ``chamfer_l2``, ``normal_consistency``, ``normal_angle_deg``, ``n_pred``,
/// ``n_gt``, ``thresholds`` (a list of ``tau``, ``tau_fraction``, ``precision``, ``recall``,
/// ``fscore``), ``seconds``, ``gt_bbox_diagonal``, ``pred_structure``, ``gt_structure``,
/// ``area_ratio``, ``shared_vertex_fraction``, ``relation``.
///
/// ``pred`` and ``gt``: a file path (a file with faces is a mesh, a PLY without faces a point
/// cloud), a ``Mesh`` or a ``PointCloud``. Meshes are sampled area-uniformly (``samples``
/// points, ``seed``; the ground truth with an independent stream). Thresholds: ``taus``
/// (absolute) and/or ``tau_fractions`` (of the ground truth's bounding-box diagonal); by
/// default the fractions 0.001, 0.0025, 0.005, 0.01. ``surface``: exact point-to-triangle
/// distances to mesh sides.
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
    let thresholds: Vec<Tau> = if taus.is_empty() && fractions.is_empty() {
        DEFAULT_TAU_FRACTIONS.map(Tau::Fraction).to_vec()
    } else {
        let absolute = taus.iter().map(|&t| Tau::Absolute(t));
        absolute
            .chain(fractions.iter().map(|&f| Tau::Fraction(f)))
            .collect()
    };
    let (mut pred, pred_name) = input(py, pred, "prediction")?;
    let (mut gt, gt_name) = input(py, gt, "ground truth")?;
    let report = py.detach(|| -> PyResult<Report> {
        let shared_vertex_fraction = pred.shared_with(&gt);
        if let Some(c) = gt.centre() {
            pred.translate(-c);
            gt.translate(-c);
        }
        let pred = pred.sample(samples, seed, &pred_name)?;
        let gt = gt.sample(samples, splitmix64(seed), &gt_name)?;
        if surface && pred.mesh().is_none() && gt.mesh().is_none() {
            return Err(error::value(format!(
                "{gt_name}: surface=True needs a mesh input (with faces), but both inputs are \
                 point clouds"
            )));
        }
        let diagonal = gt.extent();
        let resolved = metrics::resolve_taus(&thresholds, diagonal).map_err(|_| {
            error::value(format!(
                "{gt_name}: the ground truth's bounding-box diagonal is {diagonal}, so \
                 thresholds relative to it (tau_fractions, the default) are not positive; give \
                 absolute ones with taus"
            ))
        })?;
        let options = MetricsOptions {
            taus: resolved,
            surface,
        };
        let result = metrics::evaluate(pred.shape(), gt.shape(), &options).map_err(|e| {
            let name = match &e {
                MetricsError::Empty(Side::Prediction)
                | MetricsError::Spatial {
                    side: Side::Prediction,
                    ..
                } => &pred_name,
                _ => &gt_name,
            };
            error::about(name, &e)
        })?;
        let (pred_structure, gt_structure) =
            (pred.mesh().map(MeshStats::of), gt.mesh().map(MeshStats::of));
        let area_ratio = match (&pred_structure, &gt_structure) {
            (Some(p), Some(g)) if g.area > 0.0 => Some(p.area / g.area),
            _ => None,
        };
        Ok(Report {
            metrics: result.with_tau_fractions(&thresholds),
            gt_bbox_diagonal: diagonal,
            pred_structure,
            gt_structure,
            area_ratio,
            shared_vertex_fraction,
            relation: Relation::from_shared_fraction(shared_vertex_fraction),
        })
    })?;
    json_to_py(py, &to_json(&report)?)
}

/// Adds the functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(eval, m)?)?;
    Ok(())
}
