//! `Gaussians` as numpy arrays, their files (INRIA PLY, SPZ, glTF `KHR_gaussian_splatting`),
//! binding to a mesh and deformation with it.

use std::path::{Path, PathBuf};

use glam::Vec3;
use numpy::{
    AllowTypeChange, PyArray1, PyArray2, PyArrayLike1, PyArrayLike2, PyArrayMethods,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use trisplat::geometry::TriId;
use trisplat::splat::Axes;
use trisplat::splat::Convention;
use trisplat::splat::gltf_splat::{read_gltf_gaussians, write_gltf_gaussians};
use trisplat::splat::ply::{
    PlyEncoding, PlyWriteOptions, read_gaussians as read_ply, write_gaussians as write_ply,
};
use trisplat::splat::spz::{SpzReadOptions, SpzWriteOptions, read_spz, write_spz};
use trisplat::splat::{
    AttachLimits, BindOptions, attach as attach_set, attach_checked, init_bound,
};
use trisplat::splat::{
    Binding, BindingEncoding, ExtraProperty, GaussianParts, GaussianSet, ParameterSpace, ScaleDims,
    sh_coeffs_per_channel,
};
use trisplat::splat::{DeformMode, Deformer as RsDeformer};

use crate::arrays::{CloneBound, rows_in, rows_out, vec_in, vec_out};
use crate::error;
use crate::mesh::Mesh;
use crate::threads;

/// What a set carries beyond its arrays, kept so a file read and written back is unchanged.
#[derive(Clone, Debug, Default)]
struct Kept {
    encoding: BindingEncoding,
    extras: Vec<ExtraProperty>,
    material: Option<trisplat::splat::material::Material>,
    property_order: Option<Vec<String>>,
}

/// Gaussians as arrays (3DGS conventions, docs/conventions.md §3): ``means`` float32
/// ``(N, 3)``, ``log_scales`` float32 ``(N, 3)`` (natural log; the third is ignored for
/// 2DGS ``surfels``), ``rotations`` float32 ``(N, 4)`` as ``w, x, y, z`` (normalised on use),
/// ``opacity_logits`` float32 ``(N,)`` (opacity = sigmoid), ``sh`` float32
/// ``(N, 3 (degree + 1)²)`` in the INRIA PLY's order (``f_dc_0..2``, then ``f_rest``
/// channel-major), ``binding`` uint32 ``(N,)`` (each Gaussian's triangle) or None, and
/// ``local``: whether means, rotations and scales are in their triangle's frame (a bound set,
/// GaussianAvatars) rather than in world space.
///
/// Properties of a file beyond these (``extra_names``) and its property order are kept for
/// writing it back bit for bit; they follow the Gaussians only while their number is unchanged.
#[pyclass(module = "trisplat", frozen)]
pub struct Gaussians {
    /// Centres, float32 ``(N, 3)``.
    #[pyo3(get)]
    means: Py<PyArray2<f32>>,
    /// Natural-log scales, float32 ``(N, 3)``.
    #[pyo3(get)]
    log_scales: Py<PyArray2<f32>>,
    /// Rotation quaternions ``w, x, y, z``, float32 ``(N, 4)``.
    #[pyo3(get)]
    rotations: Py<PyArray2<f32>>,
    /// Opacity logits, float32 ``(N,)``.
    #[pyo3(get)]
    opacity_logits: Py<PyArray1<f32>>,
    /// SH coefficients, float32 ``(N, 3 (degree + 1)²)``, INRIA PLY order.
    #[pyo3(get)]
    sh: Py<PyArray2<f32>>,
    /// Each Gaussian's triangle, uint32 ``(N,)``, or None.
    #[pyo3(get)]
    binding: Option<Py<PyArray1<u32>>>,
    /// SH degree, 0..=3.
    #[pyo3(get)]
    sh_degree: u8,
    /// True for 2DGS surfels (two scales).
    #[pyo3(get)]
    surfels: bool,
    /// True when the parameters are in the bound triangles' local frames.
    #[pyo3(get)]
    local: bool,
    kept: Kept,
}

#[pymethods]
impl Gaussians {
    #[new]
    #[pyo3(signature = (means, log_scales, rotations, opacity_logits, sh = None, binding = None, local = false, surfels = false))]
    #[expect(
        clippy::too_many_arguments,
        reason = "one argument per array, as in Python"
    )]
    fn new<'py>(
        py: Python<'py>,
        means: PyArrayLike2<'py, f32, AllowTypeChange>,
        log_scales: PyArrayLike2<'py, f32, AllowTypeChange>,
        rotations: PyArrayLike2<'py, f32, AllowTypeChange>,
        opacity_logits: PyArrayLike1<'py, f32, AllowTypeChange>,
        sh: Option<PyArrayLike2<'py, f32, AllowTypeChange>>,
        binding: Option<PyArrayLike1<'py, u32, AllowTypeChange>>,
        local: bool,
        surfels: bool,
    ) -> PyResult<Self> {
        let means: Bound<'py, PyArray2<f32>> = means.clone_bound();
        let n = means.shape()[0];
        let sh: Bound<'py, PyArray2<f32>> = match sh {
            Some(sh) => sh.clone_bound(),
            None => PyArray2::zeros(py, [n, 3], false),
        };
        let columns = sh.shape()[1];
        let Some(sh_degree) = (0..=3u8).find(|&d| 3 * sh_coeffs_per_channel(d) == columns) else {
            return Err(error::value(format!(
                "sh: {columns} columns, expected 3, 12, 27 or 48 (SH degree 0 to 3)"
            )));
        };
        let set = Self {
            means: means.unbind(),
            log_scales: log_scales.clone_bound().unbind(),
            rotations: rotations.clone_bound().unbind(),
            opacity_logits: opacity_logits.clone_bound().unbind(),
            sh: sh.unbind(),
            binding: binding.map(|b| b.clone_bound().unbind()),
            sh_degree,
            surfels,
            local,
            kept: Kept::default(),
        };
        // Every length, value and quaternion checked now rather than at first use.
        set.to_rust(py)?;
        Ok(set)
    }

    fn __len__(&self, py: Python<'_>) -> usize {
        self.means.bind(py).shape()[0]
    }

    /// Names of the file's per-Gaussian properties beyond the standard ones (kept for writing).
    #[getter]
    fn extra_names(&self) -> Vec<String> {
        self.kept.extras.iter().map(|e| e.name.clone()).collect()
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "Gaussians({} Gaussians, SH degree {}{}{}{})",
            self.__len__(py),
            self.sh_degree,
            if self.surfels { ", surfels" } else { "" },
            if self.binding.is_some() {
                ", bound"
            } else {
                ""
            },
            if self.local { ", local frames" } else { "" },
        )
    }
}

impl Gaussians {
    /// The library's set (a copy of the arrays), checked.
    ///
    /// # Errors
    /// `ValueError` for a wrong shape, `TrisplatError` naming the first invalid Gaussian.
    pub fn to_rust(&self, py: Python<'_>) -> PyResult<GaussianSet> {
        let means: Vec<[f32; 3]> = rows_in(&self.means.bind(py).readonly(), "means")?;
        let log_scales: Vec<[f32; 3]> =
            rows_in(&self.log_scales.bind(py).readonly(), "log_scales")?;
        let rotations: Vec<[f32; 4]> = rows_in(&self.rotations.bind(py).readonly(), "rotations")?;
        let sh = self.sh.bind(py).readonly();
        let sh = match sh.as_slice() {
            Ok(s) => s.to_vec(),
            Err(_) => sh.as_array().iter().copied().collect(),
        };
        let binding = self.binding.as_ref().map(|b| Binding {
            triangles: vec_in(&b.bind(py).readonly())
                .into_iter()
                .map(TriId)
                .collect(),
            encoding: self.kept.encoding,
        });
        let parts = GaussianParts {
            means: means.into_iter().map(Vec3::from).collect(),
            log_scales: log_scales.into_iter().map(Vec3::from).collect(),
            scale_dims: if self.surfels {
                ScaleDims::Two
            } else {
                ScaleDims::Three
            },
            rotations,
            opacity_logits: vec_in(&self.opacity_logits.bind(py).readonly()),
            sh_degree: self.sh_degree,
            sh,
            binding,
            space: if self.local {
                ParameterSpace::Local
            } else {
                ParameterSpace::World
            },
            material: self.kept.material.clone(),
            extras: self.kept.extras.clone(),
            property_order: self.kept.property_order.clone(),
        };
        GaussianSet::try_new(parts).map_err(|e| error::about("gaussians", &e))
    }

    /// The library's set as arrays, moved (no copy).
    pub fn from_rust(py: Python<'_>, set: GaussianSet) -> Self {
        let parts = set.into_parts();
        let per = 3 * sh_coeffs_per_channel(parts.sh_degree);
        let n = parts.means.len();
        let sh = vec_out(py, parts.sh)
            .reshape([n, per])
            .expect("3 (degree + 1)² coefficients per Gaussian");
        let encoding = parts
            .binding
            .as_ref()
            .map(|b| b.encoding)
            .unwrap_or_default();
        Self {
            means: rows_out::<Vec3, f32>(py, parts.means, 3).unbind(),
            log_scales: rows_out::<Vec3, f32>(py, parts.log_scales, 3).unbind(),
            rotations: rows_out::<[f32; 4], f32>(py, parts.rotations, 4).unbind(),
            opacity_logits: vec_out(py, parts.opacity_logits).unbind(),
            sh: sh.unbind(),
            binding: parts
                .binding
                .map(|b| vec_out(py, b.triangles.into_iter().map(|t| t.0).collect()).unbind()),
            sh_degree: parts.sh_degree,
            surfels: parts.scale_dims == ScaleDims::Two,
            local: parts.space == ParameterSpace::Local,
            kept: Kept {
                encoding,
                extras: parts.extras,
                material: parts.material,
                property_order: parts.property_order,
            },
        }
    }
}

/// The file's format, from its extension.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Format {
    Ply,
    Spz,
    Gltf,
}

fn format_of(path: &Path) -> PyResult<Format> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("ply") => Ok(Format::Ply),
        Some("spz") => Ok(Format::Spz),
        Some("glb" | "gltf") => Ok(Format::Gltf),
        _ => Err(error::value(format!(
            "{}: not a Gaussian file (expected .ply, .spz, .glb or .gltf)",
            path.display()
        ))),
    }
}

/// SPZ axes: one of the 16 names (``rdf``, ``rub``, ...) or None.
fn parse_axes(axes: Option<&str>) -> PyResult<Option<Axes>> {
    axes.map(|a| a.parse::<Axes>().map_err(error::value))
        .transpose()
}

/// Reads Gaussians by extension: INRIA 3DGS PLY (bound GaussianAvatars files too), Niantic
/// SPZ, glTF/GLB with ``KHR_gaussian_splatting``. ``axes`` (SPZ only): the axes the set is
/// returned in (SPZ stores RUB); ``"rdf"``, the 3DGS training frame, by default; None keeps
/// the stored values.
#[pyfunction]
#[pyo3(signature = (path, axes = Some("rdf")))]
fn read_gaussians(py: Python<'_>, path: PathBuf, axes: Option<&str>) -> PyResult<Gaussians> {
    let axes = parse_axes(axes)?;
    let format = format_of(&path)?;
    let set = threads::detach(py, || match format {
        Format::Ply => read_ply(&path).map_err(|e| error::library(&e)),
        Format::Spz => read_spz(&path, &SpzReadOptions { axes })
            .map(|f| f.gaussians)
            .map_err(|e| error::library(&e)),
        Format::Gltf => read_gltf_gaussians(&path)
            .map(|f| f.gaussians)
            .map_err(|e| error::library(&e)),
    })?;
    Ok(Gaussians::from_rust(py, set))
}

/// Writes Gaussians atomically by extension: .ply (INRIA, binary unless ``ascii``; the only
/// format for bound sets), .spz (``spz_version`` 2, 3 or 4; ``axes`` as in
/// ``read_gaussians``), .glb/.gltf (``KHR_gaussian_splatting``).
#[pyfunction]
#[pyo3(signature = (path, gaussians, ascii = false, axes = Some("rdf"), spz_version = 3))]
fn write_gaussians(
    py: Python<'_>,
    path: PathBuf,
    gaussians: &Gaussians,
    ascii: bool,
    axes: Option<&str>,
    spz_version: u32,
) -> PyResult<()> {
    let axes = parse_axes(axes)?;
    let format = format_of(&path)?;
    let set = gaussians.to_rust(py)?;
    threads::detach(py, || match format {
        Format::Ply => {
            let encoding = if ascii {
                PlyEncoding::Ascii
            } else {
                PlyEncoding::BinaryLittleEndian
            };
            write_ply(&path, &set, &PlyWriteOptions { encoding }).map_err(|e| error::library(&e))
        }
        Format::Spz => write_spz(
            &path,
            &set,
            &SpzWriteOptions {
                version: spz_version,
                axes,
                ..SpzWriteOptions::default()
            },
        )
        .map_err(|e| error::library(&e)),
        Format::Gltf => write_gltf_gaussians(&path, &set).map_err(|e| error::library(&e)),
    })
}

fn convention(name: &str) -> PyResult<Convention> {
    match name {
        "gaussian_avatars" => Ok(Convention::GaussianAvatars),
        "surfhead" => Ok(Convention::SurfHead),
        _ => Err(error::value(format!(
            "convention {name:?}: expected \"gaussian_avatars\" or \"surfhead\""
        ))),
    }
}

fn deform_mode(name: &str) -> PyResult<DeformMode> {
    match name {
        "binding" => Ok(DeformMode::Binding),
        "jacobian" => Ok(DeformMode::Jacobian),
        _ => Err(error::value(format!(
            "mode {name:?}: expected \"binding\" or \"jacobian\""
        ))),
    }
}

/// New Gaussians bound to every triangle of ``mesh`` (GaussianAvatars' initialisation):
/// ``per_triangle`` per triangle (the centroid for one, spread points otherwise), identity
/// rotation, local scale 1, the given ``opacity``, grey SH degree 0, in local frames
/// (``convention`` ``"gaussian_avatars"`` or ``"surfhead"``).
#[pyfunction]
#[pyo3(signature = (mesh, per_triangle = 1, opacity = 0.1, convention = "gaussian_avatars"))]
fn bind(
    py: Python<'_>,
    mesh: &Mesh,
    per_triangle: usize,
    opacity: f32,
    convention: &str,
) -> PyResult<Gaussians> {
    let options = BindOptions {
        per_triangle,
        convention: self::convention(convention)?,
        opacity,
    };
    let mesh = mesh.to_rust(py)?;
    let set =
        threads::detach(py, || init_bound(&mesh, &options)).map_err(|e| error::library(&e))?;
    Ok(Gaussians::from_rust(py, set))
}

/// World-space ``gaussians`` attached to their nearest triangles of ``mesh``: the result is
/// bound, in local frames. With ``checked`` (default), an implausible attachment (other units
/// or frames than the mesh, Gaussians far from it or piled on one triangle) raises
/// ``TrisplatError`` naming the number at fault.
#[pyfunction]
#[pyo3(signature = (gaussians, mesh, convention = "gaussian_avatars", checked = true))]
fn attach(
    py: Python<'_>,
    gaussians: &Gaussians,
    mesh: &Mesh,
    convention: &str,
    checked: bool,
) -> PyResult<Gaussians> {
    let convention = self::convention(convention)?;
    let (set, mesh) = (gaussians.to_rust(py)?, mesh.to_rust(py)?);
    let bound = threads::detach(py, || {
        if checked {
            attach_checked(&set, &mesh, convention, &AttachLimits::default()).map(|r| r.0)
        } else {
            attach_set(&set, &mesh, convention)
        }
    })
    .map_err(|e| error::library(&e))?;
    Ok(Gaussians::from_rust(py, bound))
}

/// Deforms bound Gaussians with a template, frame after frame: ``Deformer(template, mode)``
/// once, then ``deform(gaussians, vertices)`` per frame. ``mode``: ``"binding"``
/// (GaussianAvatars: rigid frame and uniform scale per triangle) or ``"jacobian"``
/// (SurFhead: the triangle's deformation gradient, from the template's rest positions).
#[pyclass(module = "trisplat", frozen)]
pub struct Deformer {
    inner: RsDeformer,
}

#[pymethods]
impl Deformer {
    #[new]
    #[pyo3(signature = (template, mode = "binding"))]
    fn new(py: Python<'_>, template: &Mesh, mode: &str) -> PyResult<Self> {
        let mode = deform_mode(mode)?;
        let template = template.to_rust(py)?;
        let inner = threads::detach(py, || RsDeformer::new(&template, mode));
        Ok(Self { inner })
    }

    /// World-space Gaussians (viewer-ready: SH, opacities and extra properties kept, no
    /// binding) with the template's vertices at ``vertices`` (float64 ``(V, 3)``).
    fn deform<'py>(
        &self,
        py: Python<'py>,
        gaussians: &Gaussians,
        vertices: PyArrayLike2<'py, f64, AllowTypeChange>,
    ) -> PyResult<Gaussians> {
        let positions: Vec<[f64; 3]> = rows_in(&vertices, "vertices")?;
        let positions: Vec<glam::DVec3> = positions.into_iter().map(glam::DVec3::from).collect();
        let set = gaussians.to_rust(py)?;
        let world = threads::detach(py, || self.inner.deform(&set, &positions))
            .map_err(|e| error::library(&e))?;
        Ok(Gaussians::from_rust(py, world))
    }
}

/// One frame: ``Deformer(template, mode).deform(gaussians, vertices)``.
#[pyfunction]
#[pyo3(signature = (template, gaussians, vertices, mode = "binding"))]
fn deform<'py>(
    py: Python<'py>,
    template: &Mesh,
    gaussians: &Gaussians,
    vertices: PyArrayLike2<'py, f64, AllowTypeChange>,
    mode: &str,
) -> PyResult<Gaussians> {
    Deformer::new(py, template, mode)?.deform(py, gaussians, vertices)
}

/// Adds the classes and functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Gaussians>()?;
    m.add_class::<Deformer>()?;
    m.add_function(wrap_pyfunction!(read_gaussians, m)?)?;
    m.add_function(wrap_pyfunction!(write_gaussians, m)?)?;
    m.add_function(wrap_pyfunction!(bind, m)?)?;
    m.add_function(wrap_pyfunction!(attach, m)?)?;
    m.add_function(wrap_pyfunction!(deform, m)?)?;
    Ok(())
}
