//! `Session`: the main job (`trisplat extract`) frame by frame, its meshes in memory
//! (`pipeline::Session`; nothing is written).

use std::path::PathBuf;
use std::sync::Mutex;
use trisplat::pipeline::config::{
    AlphaOptions, AnimationOptions, BindOptions, DelaunayOptions, MetricOptions, Topology,
    TopologyOptions, TsdfOptions, VisibilityRule,
};

use pyo3::prelude::*;
use pyo3::types::PyDict;
use trisplat::pipeline::avatar::AvatarFolder;
use trisplat::pipeline::config::GaussianLayout;
use trisplat::pipeline::config::{
    DepthKind, ExtractConfig, ExtractOptions, GroundTruth, Method, Mode, SplatDepthRule,
};
use trisplat::pipeline::records::DelaunayFrame;
use trisplat::pipeline::{FrameResult, Session as RsSession};

use crate::arrays::rows_out;
use crate::error;
use crate::gaussians::Gaussians;
use crate::json::{json_to_py, to_json};
use crate::mesh::Mesh;
use crate::threads;

/// The main job of ``trisplat extract``, frame by frame, in memory: the inputs are read once
/// when the session opens, then ``frame(i)`` deforms the Gaussians to animation frame ``i``
/// and meshes them with each method (docs/conventions.md §1, §6).
///
/// ``template``: the template mesh (a glTF plays its own first clip unless ``animation`` is
/// given); ``animation``: a glTF, a folder or pattern of OBJ/PLY frames, or a LAM/ARKit weights
/// JSON; ``gaussians``: a bound Gaussian PLY (None: Gaussians are bound here,
/// ``per_triangle`` per triangle); ``methods``: any of ``"tsdf"``, ``"delaunay"``, ``"alpha"``, ``"opacity"``;
/// ``frames``: ``"A..B"``, ``"A..=B"``, ``"A.."``, ``"..B"`` or ``"A"``; ``gt``: None (no
/// metrics), ``"template"`` (each frame's deformed template), ``"gaussians"`` or a mesh file;
/// ``mode``: ``"binding"``, ``"jacobian"`` or ``"lbs"``. ``template`` may be a LAM avatar
/// folder (``skin.glb``, ``offset.ply``, ``vertex_order.json``: as ``extract --avatar``).
/// ``gt_sequence``: a folder or pattern of one ground-truth mesh per frame (instead of ``gt``).
/// The other keywords are ``trisplat extract``'s options of the same names (``layout``:
/// ``"bound"`` or ``"lam"``; ``tsdf_depth``: ``"median"`` or ``"expected"``; ``tsdf_splat_depth``: ``"ray"`` or
/// ``"mean"``; ``tau`` absolute,
/// instead of ``tau_fraction``; ``floater_std_ratio`` None: no floater rule); None keeps their
/// scale-derived defaults. ``strict`` refuses a
/// weights track with channels that drive nothing.
#[pyclass(module = "trisplat", frozen)]
pub struct Session {
    inner: Mutex<RsSession>,
}

/// The choice of `all` whose `name_of` is `name`, or a `ValueError` naming the keyword and
/// the choices (`"a", "b" or "c"`).
fn by_name<T: Copy>(
    keyword: &str,
    name: &str,
    all: &[T],
    name_of: fn(T) -> &'static str,
) -> PyResult<T> {
    all.iter()
        .copied()
        .find(|&v| name_of(v) == name)
        .ok_or_else(|| {
            let quoted: Vec<String> = all.iter().map(|&v| format!("{:?}", name_of(v))).collect();
            let choices = match quoted.split_last() {
                Some((last, [])) => last.clone(),
                Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
                None => String::new(),
            };
            error::value(format!("{keyword} {name:?}: expected {choices}"))
        })
}

fn method(name: &str) -> PyResult<Method> {
    by_name("method", name, &Method::ALL, Method::name)
}

fn mode(name: &str) -> PyResult<Mode> {
    by_name(
        "mode",
        name,
        &[Mode::Binding, Mode::Jacobian, Mode::Lbs],
        Mode::name,
    )
}

impl Session {
    /// The session. Long calls lock it inside `threads::detach` and drop the guard there, before
    /// taking the GIL back: a thread that waits for it with the GIL held is never waited for.
    fn lock(&self) -> PyResult<std::sync::MutexGuard<'_, RsSession>> {
        self.inner
            .lock()
            .map_err(|_| error::value("the session failed in another thread"))
    }
}

/// A frame's result as a dict (see ``Session.frame``): per method its record, as the run's
/// events and report.json carry it (`MethodFrame::record`), with its mesh and what the
/// incremental update did.
fn frame_dict<'py>(py: Python<'py>, result: FrameResult) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    dict.set_item("frame", result.frame)?;
    dict.set_item("time", result.time)?;
    dict.set_item("deform_ms", result.deform_ms)?;
    let methods = PyDict::new(py);
    for m in result.methods {
        let record = m.record(result.frame, result.time);
        let entry = json_to_py(py, &to_json(&record)?)?.cast_into::<PyDict>()?;
        let delaunay = match &m.output.delaunay {
            Some(stats) => json_to_py(py, &to_json(&DelaunayFrame::new(result.frame, stats))?)?,
            None => py.None().into_bound(py),
        };
        entry.set_item("delaunay", delaunay)?;
        entry.set_item("mesh", Mesh::from_rust(py, m.output.mesh))?;
        methods.set_item(m.method.name(), entry)?;
    }
    dict.set_item("methods", methods)?;
    Ok(dict)
}

fn layout(name: &str) -> PyResult<GaussianLayout> {
    by_name(
        "layout",
        name,
        &[GaussianLayout::Bound, GaussianLayout::Lam],
        GaussianLayout::name,
    )
}

fn tsdf_depth(name: &str) -> PyResult<DepthKind> {
    by_name(
        "tsdf_depth",
        name,
        &[DepthKind::Median, DepthKind::Expected],
        DepthKind::name,
    )
}

fn topology(name: &str) -> PyResult<Topology> {
    by_name(
        "topology",
        name,
        &[Topology::PerFrame, Topology::Fixed, Topology::Adaptive],
        Topology::name,
    )
}

fn tsdf_splat_depth(name: &str) -> PyResult<SplatDepthRule> {
    by_name(
        "tsdf_splat_depth",
        name,
        &[SplatDepthRule::Ray, SplatDepthRule::Mean],
        SplatDepthRule::name,
    )
}

#[pymethods]
impl Session {
    #[new]
    #[pyo3(signature = (template, animation = None, gaussians = None, methods = vec!["delaunay".to_owned()], frames = None, gt = None, mode = "binding", per_triangle = None, voxel = None, views = None, resolution = None, alpha = None, hop_threshold = None, samples = None, tau_fraction = None, gt_sequence = None, clip = None, clip_from = None, fps = None, layout = "bound", tsdf_depth = "median", tsdf_splat_depth = "ray", tsdf_colors = false, alpha_keep_clusters = 0, rebuild_every = 0, tau = None, strict = false, tsdf_alpha_cut = None, min_contribution = None, floater_std_ratio = None, floater_neighbors = None, topology = "adaptive"))]
    #[expect(
        clippy::too_many_arguments,
        reason = "the command's options as keywords"
    )]
    fn new(
        py: Python<'_>,
        template: PathBuf,
        animation: Option<String>,
        gaussians: Option<PathBuf>,
        methods: Vec<String>,
        frames: Option<String>,
        gt: Option<String>,
        mode: &str,
        per_triangle: Option<u32>,
        voxel: Option<f64>,
        views: Option<usize>,
        resolution: Option<u32>,
        alpha: Option<f64>,
        hop_threshold: Option<f64>,
        samples: Option<usize>,
        tau_fraction: Option<f64>,
        gt_sequence: Option<String>,
        clip: Option<String>,
        clip_from: Option<PathBuf>,
        fps: Option<f64>,
        layout: &str,
        tsdf_depth: &str,
        tsdf_splat_depth: &str,
        tsdf_colors: bool,
        alpha_keep_clusters: usize,
        rebuild_every: usize,
        tau: Option<f64>,
        strict: bool,
        tsdf_alpha_cut: Option<f32>,
        min_contribution: Option<f32>,
        floater_std_ratio: Option<f64>,
        floater_neighbors: Option<usize>,
        topology: &str,
    ) -> PyResult<Self> {
        if gt.is_some() && gt_sequence.is_some() {
            return Err(error::value("give gt or gt_sequence, not both"));
        }
        if tau.is_some() && tau_fraction.is_some() {
            return Err(error::value("give tau or tau_fraction, not both"));
        }
        if let Some(t) = tau.filter(|t| !(t.is_finite() && *t > 0.0)) {
            return Err(error::value(format!(
                "tau {t}: expected a finite positive number"
            )));
        }
        if let Some(f) = fps.filter(|f| !(f.is_finite() && *f > 0.0)) {
            return Err(error::value(format!(
                "fps {f}: expected a finite positive number"
            )));
        }
        let defaults = ExtractOptions::default();
        let mut layout = self::layout(layout)?;
        // A LAM avatar folder stands for its template and per-vertex Gaussians, as in
        // `trisplat extract --avatar DIR`.
        let (template, gaussians) = if template.is_dir() {
            if let Some(g) = &gaussians {
                return Err(error::value(format!(
                    "gaussians {}: the avatar folder {} brings its own",
                    g.display(),
                    template.display()
                )));
            }
            let avatar = AvatarFolder::open(&template).map_err(|e| error::library(&e))?;
            layout = GaussianLayout::Lam;
            (avatar.template, Some(avatar.gaussians))
        } else {
            (template, gaussians)
        };
        let options = ExtractOptions {
            animation: AnimationOptions {
                clip,
                clip_from,
                fps: fps.unwrap_or(defaults.animation.fps),
                strict,
                mode: self::mode(mode)?,
            },
            bind: BindOptions {
                layout,
                per_triangle: per_triangle.unwrap_or(defaults.bind.per_triangle),
            },
            tsdf: TsdfOptions {
                depth: self::tsdf_depth(tsdf_depth)?,
                splat_depth: self::tsdf_splat_depth(tsdf_splat_depth)?,
                colors: tsdf_colors,
                alpha_cut: tsdf_alpha_cut.unwrap_or(defaults.tsdf.alpha_cut),
                front_alpha: defaults.tsdf.front_alpha,
                anchor: defaults.tsdf.anchor,
                voxel,
                views: views.unwrap_or(defaults.tsdf.views),
                resolution: resolution.unwrap_or(defaults.tsdf.resolution),
            },
            alpha: AlphaOptions {
                keep_clusters: alpha_keep_clusters,
                alpha,
                ..defaults.alpha
            },
            visibility: VisibilityRule {
                min_contribution: min_contribution.unwrap_or(defaults.visibility.min_contribution),
                floater_std_ratio,
                floater_neighbors: floater_neighbors
                    .unwrap_or(defaults.visibility.floater_neighbors),
            },
            delaunay: DelaunayOptions {
                rebuild_every,
                hop_threshold: hop_threshold.unwrap_or(defaults.delaunay.hop_threshold),
                ..defaults.delaunay
            },
            topology: TopologyOptions {
                topology: self::topology(topology)?,
                ..defaults.topology
            },
            metrics: MetricOptions {
                tau: tau.unwrap_or(defaults.metrics.tau),
                samples: samples.unwrap_or(defaults.metrics.samples),
                tau_fraction: if tau.is_some() {
                    None
                } else {
                    tau_fraction.or(defaults.metrics.tau_fraction)
                },
                ..defaults.metrics
            },
            ..defaults
        };
        let config = ExtractConfig {
            template,
            animation,
            gaussians,
            methods: methods.iter().map(|m| method(m)).collect::<PyResult<_>>()?,
            // A session writes nothing; `trisplat extract` gives it its output folder.
            output: PathBuf::new(),
            frames,
            gt: gt
                .as_deref()
                .map(GroundTruth::parse)
                .or(gt_sequence.map(GroundTruth::Sequence)),
            options,
        };
        let session =
            threads::detach(py, || RsSession::open(&config)).map_err(|e| error::library(&e))?;
        Ok(Self {
            inner: Mutex::new(session),
        })
    }

    /// The names of the weights track's channels that drive no morph target (ignored; a
    /// session opened with ``strict=True`` refuses them instead).
    #[getter]
    fn unused_channels(&self) -> PyResult<Vec<String>> {
        Ok(self.lock()?.unused_channels().to_vec())
    }

    /// Which Gaussians delaunay and alpha mesh (decided when the session opened, from the
    /// rest pose and frames sampled over the whole track, docs/conventions.md §6): a dict of ``total``,
    /// ``kept``, ``hidden``, ``floaters``, ``poses`` and the rule (``min_contribution``,
    /// ``floater_std_ratio``, ``floater_neighbors``), as ``gaussians_used`` in report.json.
    #[getter]
    fn gaussians_used<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let used = self.lock()?.visibility().used;
        json_to_py(py, &to_json(&used)?)
    }

    /// The animation frame indices the session runs, in order.
    #[getter]
    fn frames(&self) -> PyResult<Vec<usize>> {
        Ok(self.lock()?.frames().collect())
    }

    /// The template as the session uses it (world space, as its animation poses it).
    #[getter]
    fn template(&self, py: Python<'_>) -> PyResult<Mesh> {
        let mesh = self.lock()?.template().clone();
        Ok(Mesh::from_rust(py, mesh))
    }

    /// The bound Gaussians (read or bound when the session opened).
    #[getter]
    fn gaussians(&self, py: Python<'_>) -> PyResult<Gaussians> {
        let set = self.lock()?.gaussians().clone();
        Ok(Gaussians::from_rust(py, set))
    }

    /// The template's vertices at animation frame ``frame``, float64 ``(V, 3)``, in world
    /// coordinates (the session works relative to a local origin far from the world's).
    fn positions<'py>(
        &self,
        py: Python<'py>,
        frame: usize,
    ) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
        let positions = threads::detach(py, || {
            let mut session = self.lock()?;
            let origin = session.origin();
            let local = session.positions(frame).map_err(|e| error::library(&e))?;
            PyResult::Ok(local.into_iter().map(|p| p + origin).collect::<Vec<_>>())
        })?;
        Ok(rows_out::<glam::DVec3, f64>(py, positions, 3))
    }

    /// The world-space Gaussians of animation frame ``frame`` (what ``trisplat deform``
    /// writes).
    fn world(&self, py: Python<'_>, frame: usize) -> PyResult<Gaussians> {
        let set = threads::detach(py, || {
            self.lock()?.world(frame).map_err(|e| error::library(&e))
        })?;
        Ok(Gaussians::from_rust(py, set))
    }

    /// Deforms and meshes animation frame ``frame`` and returns a dict: ``frame``, ``time``
    /// (seconds), ``deform_ms``, and ``methods``: per method name its frame record as in
    /// report.json (``ms``, the method's own time; ``render_ms``, tsdf; ``vertices``,
    /// ``faces``, ``watertight``; ``metrics`` against ``gt``, None without ``gt``) with
    /// ``mesh`` (a ``Mesh``) and ``delaunay`` (what the incremental update did, as in
    /// report.json).
    fn frame<'py>(&self, py: Python<'py>, frame: usize) -> PyResult<Bound<'py, PyDict>> {
        let result = threads::detach(py, || {
            self.lock()?.frame(frame).map_err(|e| error::library(&e))
        })?;
        frame_dict(py, result)
    }

    fn __repr__(&self) -> PyResult<String> {
        let session = self.lock()?;
        let frames = session.frames();
        Ok(format!(
            "Session({}, frames {}..{})",
            session.template_path().display(),
            frames.start,
            frames.end
        ))
    }
}

/// Adds the class of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Session>()?;
    Ok(())
}
