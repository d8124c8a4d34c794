//! One prediction against one ground truth (docs/conventions.md §8): what `trisplat eval`
//! reports (its `--json` object is [`EvalReport`]) and the Python package's `eval` returns.
//!
//! Steps: each side read as a mesh or, for a PLY without faces (or a mesh file without
//! triangles), a point cloud ([`EvalInput::read`]); the shared-vertex test where the inputs
//! are; both sides moved to the ground truth's centre in f64 before any sample is stored in
//! f32, so the scores do not depend on how far from the origin the files are; mesh sides
//! sampled area-uniformly (the ground truth with the seed's independent stream); thresholds
//! resolved against the ground truth's bounding-box diagonal; the metrics and each mesh's
//! structure side by side.

use std::path::Path;

use glam::DVec3;
use trisplat_geometry::io::{self, Format, IoError, ply};
use trisplat_geometry::mesh_stats::MeshStats;
use trisplat_geometry::metrics::{
    self, DEFAULT_TAU_FRACTIONS, Metrics, MetricsError, MetricsOptions, Relation, Shape, Side, Tau,
};
use trisplat_geometry::rng::splitmix64;
use trisplat_geometry::sampling::sample_uniform;
use trisplat_geometry::{MeshError, PointCloud, TriMesh};

/// Samples drawn on each mesh side unless told otherwise.
pub const DEFAULT_SAMPLES: usize = 100_000;

/// Why an evaluation cannot be done; each names the side (its file, or the name it was given).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// A file that cannot be read.
    #[error("{0}")]
    Io(IoError),
    /// A mesh file without triangles whose vertices are no valid point cloud.
    #[error("{name}: vertices: {cause}")]
    Points {
        /// The side.
        name: String,
        /// What is wrong with them.
        cause: MeshError,
    },
    /// A mesh side without area has nothing to sample.
    #[error("{name}: the mesh has zero surface area, nothing to sample")]
    ZeroArea {
        /// The side.
        name: String,
    },
    /// Surface distances were asked for, but neither side is a mesh.
    #[error(
        "{gt}: surface distances need a mesh input (a file with faces), but both inputs are point clouds"
    )]
    SurfaceWithoutMesh {
        /// The ground truth.
        gt: String,
    },
    /// Thresholds relative to the ground truth's diagonal, which is not positive.
    #[error(
        "{gt}: the ground truth's bounding-box diagonal is {diagonal}, so thresholds relative to it are not positive; give absolute ones"
    )]
    NoScale {
        /// The ground truth.
        gt: String,
        /// Its diagonal.
        diagonal: f64,
    },
    /// The metrics failed (an empty side, coordinates beyond the spatial indexes' range).
    #[error("{name}: {cause}")]
    Metrics {
        /// The side at fault.
        name: String,
        /// Why.
        cause: MetricsError,
    },
}

/// One side: a mesh (with its samples once [`EvalInput::sample`]d) or a point cloud.
#[derive(Clone, Debug)]
pub enum EvalInput {
    /// A mesh and its samples (empty until sampled).
    Mesh(TriMesh, PointCloud),
    /// Points used as they are (with their normals if any).
    Points(PointCloud),
}

impl EvalInput {
    /// A mesh side, not yet sampled.
    #[must_use]
    pub fn mesh(mesh: TriMesh) -> Self {
        Self::Mesh(mesh, PointCloud::default())
    }

    /// Reads `path`: a file with faces is a mesh; a PLY without faces, or a mesh file without
    /// triangles, is a point cloud (with its normals if present).
    ///
    /// # Errors
    /// [`EvalError::Io`] naming the file and element, [`EvalError::Points`] for vertices that
    /// are no valid point cloud.
    pub fn read(path: &Path) -> Result<Self, EvalError> {
        let mesh = if Format::from_path(path).map_err(EvalError::Io)? == Format::Ply {
            let bytes = std::fs::read(path).map_err(|e| EvalError::Io(IoError::os(path, e)))?;
            // Float x y z [nx ny nz] clouds straight into vectors; anything else as a document.
            if let Some(points) = ply::read_plain_points(path, &bytes).map_err(EvalError::Io)? {
                return Ok(Self::Points(points));
            }
            let doc = ply::parse_ply(path, &bytes).map_err(EvalError::Io)?;
            drop(bytes);
            let has_faces = doc.element("face").is_some_and(|f| f.count > 0)
                || doc.element("tristrips").is_some_and(|f| f.count > 0);
            if !has_faces {
                let (points, _) = ply::ply_to_points(path, &doc).map_err(EvalError::Io)?;
                return Ok(Self::Points(points));
            }
            ply::ply_to_mesh(path, &doc).map_err(EvalError::Io)?.0
        } else {
            io::read_mesh(path).map_err(EvalError::Io)?
        };
        if mesh.triangle_count() > 0 {
            return Ok(Self::mesh(mesh));
        }
        let name = || path.display().to_string();
        let normals = mesh.normals().map(<[_]>::to_vec);
        let mut points =
            PointCloud::try_new(mesh.positions_f32()).map_err(|cause| EvalError::Points {
                name: name(),
                cause,
            })?;
        if let Some(n) = normals {
            points = points.with_normals(n).map_err(|cause| EvalError::Points {
                name: name(),
                cause,
            })?;
        }
        Ok(Self::Points(points))
    }

    /// The measured shape.
    #[must_use]
    pub fn shape(&self) -> Shape<'_> {
        match self {
            Self::Mesh(mesh, samples) => Shape::mesh(mesh, samples),
            Self::Points(points) => Shape::points(points),
        }
    }

    /// The mesh, for a mesh side.
    #[must_use]
    pub fn as_mesh(&self) -> Option<&TriMesh> {
        match self {
            Self::Mesh(mesh, _) => Some(mesh),
            Self::Points(_) => None,
        }
    }

    /// The diagonal of the bounding box of the mesh's vertices or of the points.
    #[must_use]
    pub fn extent(&self) -> f64 {
        match self {
            Self::Mesh(mesh, _) => mesh.bounds().map_or(0.0, |b| b.diagonal()),
            Self::Points(points) => metrics::bbox_diagonal(points.positions()),
        }
    }

    /// Fraction of `gt`'s mesh vertices that are vertices (or points) of `self`, bit for bit;
    /// `None` unless `gt` is a mesh.
    #[must_use]
    pub fn shared_with(&self, gt: &Self) -> Option<f64> {
        let gt = gt.as_mesh()?.positions();
        match self {
            Self::Mesh(mesh, _) => metrics::shared_vertex_fraction(gt, mesh.positions()),
            Self::Points(points) => {
                let widened: Vec<_> = points.positions().iter().map(|p| p.as_dvec3()).collect();
                metrics::shared_vertex_fraction(gt, &widened)
            }
        }
    }

    /// Centre of the bounding box of the mesh's vertices (f64) or of the points.
    #[must_use]
    pub fn centre(&self) -> Option<DVec3> {
        match self {
            Self::Mesh(mesh, _) => mesh.bounds().map(|b| b.center()),
            Self::Points(points) => points.bounds().map(|b| b.center()),
        }
    }

    /// Moves the side by `offset` (meshes in f64, points computed in f64 and stored as f32).
    pub fn translate(&mut self, offset: DVec3) {
        match self {
            Self::Mesh(mesh, _) => mesh.translate(offset),
            Self::Points(points) => points.translate(offset),
        }
    }

    /// Samples a mesh side (`samples` points, seeded); points pass through.
    ///
    /// # Errors
    /// [`EvalError::ZeroArea`] for a mesh without area (named `name`).
    pub fn sample(self, samples: usize, seed: u64, name: &str) -> Result<Self, EvalError> {
        let Self::Mesh(mesh, _) = self else {
            return Ok(self);
        };
        let sampled = sample_uniform(&mesh, samples, seed);
        if sampled.is_empty() {
            return Err(EvalError::ZeroArea {
                name: name.to_owned(),
            });
        }
        Ok(Self::Mesh(mesh, sampled))
    }
}

/// How to measure.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalOptions {
    /// Points sampled on each mesh side.
    pub samples: usize,
    /// Seed of the prediction's samples; the ground truth's is `splitmix64(seed)`.
    pub seed: u64,
    /// F-score thresholds, absolute or relative to the ground truth's diagonal.
    pub taus: Vec<Tau>,
    /// Exact point-to-triangle distances to mesh sides instead of to their samples.
    pub surface: bool,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            samples: DEFAULT_SAMPLES,
            seed: 0,
            taus: thresholds(&[], &[]),
            surface: false,
        }
    }
}

/// Absolute thresholds then fractions of the diagonal, or [`DEFAULT_TAU_FRACTIONS`] when both
/// are empty.
#[must_use]
pub fn thresholds(absolute: &[f64], fractions: &[f64]) -> Vec<Tau> {
    if absolute.is_empty() && fractions.is_empty() {
        return DEFAULT_TAU_FRACTIONS.map(Tau::Fraction).to_vec();
    }
    let absolute = absolute.iter().map(|&t| Tau::Absolute(t));
    absolute
        .chain(fractions.iter().map(|&f| Tau::Fraction(f)))
        .collect()
}

/// What `eval` reports: [`Metrics`] and the fields below (`trisplat eval --json`,
/// docs/conventions.md §10).
#[derive(Clone, Debug, serde::Serialize)]
pub struct EvalReport {
    /// The metrics.
    #[serde(flatten)]
    pub metrics: Metrics,
    /// Diagonal of the ground truth's bounding box (scales relative thresholds).
    pub gt_bbox_diagonal: f64,
    /// Structure of the prediction when it is a mesh.
    pub pred_structure: Option<MeshStats>,
    /// Structure of the ground truth when it is a mesh.
    pub gt_structure: Option<MeshStats>,
    /// area(P) / area(G) when both are meshes and G has area.
    pub area_ratio: Option<f64>,
    /// Fraction of the ground truth's mesh vertices found bit for bit among P's vertices.
    pub shared_vertex_fraction: Option<f64>,
    /// `accuracy`, or `self-consistency` when P contains G.
    pub relation: Relation,
}

/// A finished evaluation: the report and both sides as measured (centred, sampled).
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// The report.
    pub report: EvalReport,
    /// The prediction as measured.
    pub pred: EvalInput,
    /// The ground truth as measured.
    pub gt: EvalInput,
}

/// Measures `pred` against `gt` (named `names.0` and `names.1` in errors: their files, or
/// what the caller calls them). Sides are sampled and measured in parallel.
///
/// # Errors
/// [`EvalError`] naming the side: a mesh without area, surface distances without a mesh
/// side, relative thresholds on a ground truth without extent, empty sides, coordinates
/// beyond the spatial indexes' range.
pub fn evaluate(
    mut pred: EvalInput,
    mut gt: EvalInput,
    names: (&str, &str),
    options: &EvalOptions,
) -> Result<Evaluation, EvalError> {
    let (pred_name, gt_name) = names;
    // Shared vertices are compared where they are, before moving anything.
    let shared_vertex_fraction = pred.shared_with(&gt);
    if let Some(c) = gt.centre() {
        pred.translate(-c);
        gt.translate(-c);
    }
    let (pred, gt) = rayon::join(
        || pred.sample(options.samples, options.seed, pred_name),
        || gt.sample(options.samples, splitmix64(options.seed), gt_name),
    );
    let (pred, gt) = (pred?, gt?);
    if options.surface && pred.as_mesh().is_none() && gt.as_mesh().is_none() {
        return Err(EvalError::SurfaceWithoutMesh {
            gt: gt_name.to_owned(),
        });
    }
    let diagonal = gt.extent();
    let metrics_options = MetricsOptions {
        taus: metrics::resolve_taus(&options.taus, diagonal).map_err(|_| EvalError::NoScale {
            gt: gt_name.to_owned(),
            diagonal,
        })?,
        surface: options.surface,
    };
    let (result, (pred_structure, gt_structure)) = rayon::join(
        || metrics::evaluate(pred.shape(), gt.shape(), &metrics_options),
        || {
            rayon::join(
                || pred.as_mesh().map(MeshStats::of),
                || gt.as_mesh().map(MeshStats::of),
            )
        },
    );
    let result = result.map_err(|cause| {
        let name = match &cause {
            MetricsError::Empty(Side::Prediction)
            | MetricsError::Spatial {
                side: Side::Prediction,
                ..
            } => pred_name,
            _ => gt_name,
        };
        EvalError::Metrics {
            name: name.to_owned(),
            cause,
        }
    })?;
    let area_ratio = match (&pred_structure, &gt_structure) {
        (Some(p), Some(g)) if g.area > 0.0 => Some(p.area / g.area),
        _ => None,
    };
    let report = EvalReport {
        metrics: result.with_tau_fractions(&options.taus),
        gt_bbox_diagonal: diagonal,
        pred_structure,
        gt_structure,
        area_ratio,
        shared_vertex_fraction,
        relation: Relation::from_shared_fraction(shared_vertex_fraction),
    };
    Ok(Evaluation { report, pred, gt })
}
