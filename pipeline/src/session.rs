//! The one frame loop: [`Session::open`] reads every input once, [`Session::frame`] deforms
//! and meshes one animation frame, and the caller writes what it returns.
//!
//! `trisplat extract` ([`crate::run()`]), `trisplat deform` ([`Session::world`]) and the bench
//! sweep all go through a session. It owns what lives for the whole run: the template (read
//! and welded once), the animation (a glTF parsed once), the Gaussians, the deformation
//! engine, the rest-pose means (deformed once), the meshers with their state, a static ground
//! truth's samples and BVH, and the buffers a frame reuses.
//!
//! The [`Plan`] decides what a session does: it is made from the same [`Plan::new`] that
//! `--explain` prints, and every stage the session runs is asked of the plan first
//! ([`Plan::runs`]) and recorded ([`Session::executed`]), so the printed plan and the run
//! cannot disagree. A frame deforms only the geometry (means, no SH) unless the plan renders
//! (tsdf) or the caller asks for the world-space set ([`Session::world`]).
//!
//! A template far from the world origin is worked on relative to a local origin
//! ([`Session::origin`], [`trisplat_geometry::Aabb::local_origin`]: zero for templates modelled
//! around the world origin), so the `f32` Gaussian means, renders, TSDF, Delaunay and alpha
//! shapes keep their precision at any offset: the template, its frame positions, the rest
//! means and [`Session::deform`] are local; what leaves the session ([`Session::world`], the
//! meshes and ground truths of [`Session::frame`]) is in world coordinates again, moved back
//! in `f64`.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::MeshSequence;
use trisplat_geometry::io::read_mesh;
use trisplat_splat::Convention;
use trisplat_splat::GaussianSet;
use trisplat_splat::{Collapsed, Deformer, WorldGeometry};

use crate::avatar::bind_lam;
use crate::config::GaussianLayout;
use crate::config::{
    DEFAULT_RESOLUTION, DEFAULT_VIEWS, ExtractConfig, ExtractOptions, GroundTruth, Method, Mode,
    TopologyOptions,
};
use crate::consistency::{GaussianViews, RenderConsistency, held_out_rig};
use crate::deform::{Engine, EngineInputs};
use crate::error::{PipelineError, first_error_in_order};
use crate::event::Event;
use crate::finish::Finish;
use crate::input::{
    Animation, GaussianSource, WeldedTemplate, animation_label, bind_here, check_scale,
    check_topology, deform_mode, open_template_and_animation, parse_frames, read_bound,
    shard_frames,
};
use crate::methods::{FrameInput, Mesher, MethodOutput, parameters};
use crate::metrics::{GtSamples, ScoreCache, is_watertight, measure_cached};
use crate::option_checks::check_options;
use crate::plan::{Plan, Stage};
use crate::records::{FrameMetrics, FrameRecord, Resolved, ShardRecord, TopologyFrame};
use crate::report::Report;
use crate::topology::{Carrier, CarryContext, mean_edge};
use crate::visibility::{Pose, VISIBILITY_FRAMES, Visibility, decide};
use trisplat_geometry::metrics::Tau;

mod ground_truth;
mod keys;
mod rig_inputs;

/// What a session needs beyond [`ExtractConfig`] (`trisplat deform`'s options).
#[derive(Clone, Debug)]
pub struct SessionOptions {
    /// Weld the template's vertices split at seams ([`WeldedTemplate`]); `trisplat deform`
    /// deforms on the template as stored.
    pub weld: bool,
    /// Folder of blendshape targets (a weights JSON with an OBJ/PLY template).
    pub targets: Option<PathBuf>,
    /// Scale Gaussians by √(area ratio) of their triangle (binding and lbs).
    pub adaptive_scale: bool,
}

impl Default for SessionOptions {
    fn default() -> Self {
        Self {
            weld: true,
            targets: None,
            adaptive_scale: false,
        }
    }
}

/// One method's result on one frame.
#[derive(Clone, Debug)]
pub struct MethodFrame {
    /// The method.
    pub method: Method,
    /// Its mesh and timings.
    pub output: MethodOutput,
    /// Metrics against the ground truth (when the plan measures and the mesh has area).
    pub metrics: Option<FrameMetrics>,
    /// Render consistency against the frame's Gaussians (when the plan measures it).
    pub consistency: Option<RenderConsistency>,
    /// The carried mesh's key and drift (`--topology fixed|adaptive`).
    pub topology: Option<TopologyFrame>,
}

impl MethodFrame {
    /// This method's record of animation frame `frame` at `time` seconds: its timings, the
    /// size of its mesh, whether that is watertight, and its metrics (what the journal, the
    /// run's events and the report hold).
    #[must_use]
    pub fn record(&self, frame: usize, time: f64) -> FrameRecord {
        FrameRecord {
            frame,
            time,
            ms: self.output.ms,
            render_ms: self.output.render_ms,
            vertices: self.output.mesh.vertex_count(),
            faces: self.output.mesh.triangle_count(),
            watertight: is_watertight(&self.output.mesh),
            metrics: self.metrics,
            consistency: self.consistency,
            topology: self.topology,
            simplify: self.output.simplify,
        }
    }
}

/// Everything one frame produced.
#[derive(Clone, Debug)]
pub struct FrameResult {
    /// Animation frame index.
    pub frame: usize,
    /// Its time in seconds.
    pub time: f64,
    /// Milliseconds spent deforming the Gaussians.
    pub deform_ms: f64,
    /// Triangles of the template that were degenerate in this frame (each kept its last valid
    /// frame, or took the fallback frame when it had none).
    pub collapsed: Collapsed,
    /// One entry per method, in report order.
    pub methods: Vec<MethodFrame>,
}

/// An opened run: inputs read once, then one [`Session::frame`] per frame (see the module
/// documentation).
pub struct Session {
    plan: Plan,
    template_path: PathBuf,
    label: String,
    welded: WeldedTemplate,
    animation: Animation,
    frames: Range<usize>,
    /// The first frame's positions (local), read while checking the scale.
    first_positions: Option<Vec<DVec3>>,
    /// The local origin the session works relative to (see the module documentation).
    origin: DVec3,
    set: GaussianSet,
    /// `set` without SH beyond degree 0 and without extras: what rendering depth needs.
    render_set: Option<GaussianSet>,
    source: GaussianSource,
    engine: Engine,
    rest_means: Vec<Vec3>,
    resolved: Resolved,
    /// The Gaussians the point methods (delaunay, alpha) use.
    visibility: Visibility,
    /// The kept Gaussians' means of the current frame (when some are left out).
    kept_means: Vec<Vec3>,
    /// Each method's mesher and the topology of its meshes through the track.
    meshers: Vec<(Method, Mesher, Carrier)>,
    /// Each method's scoring state (one per mesher): what a carried mesh's next frame reuses.
    score_caches: Vec<ScoreCache>,
    /// `--topology` and its thresholds.
    topology: TopologyOptions,
    /// Decimation and vertex colours of every mesh made.
    finish: Finish,
    /// Each Gaussian's template triangle (what a carried mesh's vertices bind by).
    gaussian_triangles: Vec<u32>,
    /// The mean edge of the welded template at rest (the unit of `--hop-distance`).
    mean_edge: f64,
    gt: Option<GroundTruth>,
    static_gt: Option<GtSamples>,
    /// The last frame's ground truth, whose index the next frame's refits.
    previous_gt: Option<GtSamples>,
    /// `--gt-sequence`: the ground-truth mesh file of each animation frame.
    gt_files: Vec<PathBuf>,
    /// `--gt gaussians`: the stored template's triangles, over the Gaussians (Gaussian `i`
    /// is stored vertex `i`).
    gaussian_gt_triangles: Vec<[u32; 3]>,
    samples: usize,
    /// The F-score threshold (a fraction is of each frame's ground-truth diagonal).
    tau: Tau,
    fps: f64,
    input_files: Vec<PathBuf>,
    /// Channels of the driving track that move nothing (reported, see
    /// [`Session::unused_channels`]).
    unused_channels: Vec<String>,
    scratch: WorldGeometry,
    executed: Vec<Stage>,
    /// Run the methods of a frame one after another instead of side by side.
    serial_methods: bool,
    /// The shard of the track this run is (`--shard`), as its report records it.
    shard: Option<ShardRecord>,
    /// Views and resolution of each frame's render consistency, when the plan measures it.
    consistency_rig: Option<(usize, u32)>,
}

impl std::fmt::Debug for Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("template", &self.template_path)
            .field("animation", &self.label)
            .field("frames", &self.frames)
            .field("gaussians", &self.set.len())
            .field("executed", &self.executed)
            .finish_non_exhaustive()
    }
}

impl Session {
    /// Opens the run of `config` (see [`Session::open_with`]).
    ///
    /// # Errors
    /// As [`Session::open_with`].
    pub fn open(config: &ExtractConfig) -> Result<Self, PipelineError> {
        Self::open_with(config, &SessionOptions::default())
    }

    /// Reads and checks every input of `config` once: the template in world space (welded
    /// unless `options.weld` is false), its animation, the frame range, a static ground
    /// truth, the Gaussians (read, or bound here when the plan binds); builds the
    /// deformation engine, deforms the rest pose once, resolves the scale-derived defaults
    /// and builds the meshers the plan runs.
    ///
    /// # Errors
    /// Bad options, unreadable or mismatched inputs (named), a mesher that cannot be built.
    pub fn open_with(
        config: &ExtractConfig,
        options: &SessionOptions,
    ) -> Result<Self, PipelineError> {
        let o = &config.options;
        check_options(config)?;
        let plan = Plan::new(config);
        let mut executed = vec![Stage::Animate];
        let label = animation_label(config);

        let (mut stored, animation, mut input_files) =
            open_template_and_animation(config, options.targets.as_deref())?;
        let origin = stored.bounds().map_or(DVec3::ZERO, |b| b.local_origin());
        stored.translate(-origin);
        if stored.triangle_count() == 0 {
            return Err(PipelineError::EmptyTemplate {
                path: config.template.clone(),
            });
        }
        let anim = animation.get();
        let unused_channels: Vec<String> = anim
            .unused_channels()
            .into_iter()
            .map(str::to_owned)
            .collect();
        if o.animation.strict && !unused_channels.is_empty() {
            return Err(PipelineError::BadAnimation {
                path: PathBuf::from(&label),
                problem: format!(
                    "{} channel(s) drive no morph target: {} (--strict)",
                    unused_channels.len(),
                    unused_channels.join(", ")
                ),
            });
        }
        check_topology(&stored, &config.template, anim, &label)?;
        let welded = if options.weld {
            WeldedTemplate::new(&stored)
        } else {
            WeldedTemplate::unwelded(&stored)
        };
        let selected = parse_frames(config.frames.as_deref(), anim.frame_count())?;
        let (frames, shard) = shard_frames(&o.shard, selected)?;
        // The scale-derived defaults come from the template: its frames must share its scale.
        let first_positions = to_local(anim.frame(frames.start)?, origin);
        check_scale(
            &stored,
            &config.template,
            &first_positions,
            frames.start,
            &label,
        )?;

        let static_gt = match (&config.gt, plan.runs(Stage::Metrics)) {
            (Some(GroundTruth::Mesh(path)), true) => {
                input_files.push(path.clone());
                let mesh = read_mesh(path)?;
                Some(GtSamples::new(mesh, o.metrics.samples).ok_or_else(|| {
                    PipelineError::EmptyGroundTruth {
                        gt: path.display().to_string(),
                        frame: frames.start,
                    }
                })?)
            }
            _ => None,
        };
        // Per-frame ground truth: the file list now, each mesh when its frame comes.
        let gt_files = match (&config.gt, plan.runs(Stage::Metrics)) {
            (Some(GroundTruth::Sequence(spec)), true) => {
                let sequence = MeshSequence::from_pattern(spec)?;
                let files = sequence.files().to_vec();
                if files.len() < frames.end {
                    return Err(PipelineError::GtSequence {
                        spec: spec.clone(),
                        problem: format!(
                            "{} mesh file(s), but frame {} needs {} (one per animation frame, \
                             in order)",
                            files.len(),
                            frames.end - 1,
                            frames.end
                        ),
                    });
                }
                input_files.extend(files.iter().cloned());
                files
            }
            _ => Vec::new(),
        };

        let template = &welded.mesh;
        let gaussians_path = config.gaussians.clone().unwrap_or_default();
        let (set, source) = if config.gaussians.is_none() {
            executed.push(Stage::Bind);
            let set = bind_here(
                template,
                &config.template,
                o.animation.mode,
                o.bind.per_triangle,
            )?;
            (set, GaussianSource::Bound(o.bind.per_triangle))
        } else if o.bind.layout == GaussianLayout::Lam {
            executed.push(Stage::Bind);
            let convention = if o.animation.mode == Mode::Jacobian {
                Convention::SurfHead
            } else {
                Convention::GaussianAvatars
            };
            let set = bind_lam(
                &gaussians_path,
                &stored,
                template,
                &welded.of_stored,
                &config.template,
                convention,
            )?;
            (set, GaussianSource::Lam(gaussians_path.clone()))
        } else {
            let set = read_bound(&gaussians_path, template, &config.template)?;
            (set, GaussianSource::File(gaussians_path.clone()))
        };
        let engine = Engine::build(
            &EngineInputs {
                mode: o.animation.mode,
                stored: &stored,
                welded: &welded,
                origin,
                template_path: &config.template,
                gaussians_path: &gaussians_path,
                label: &label,
                adaptive_scale: options.adaptive_scale,
            },
            &animation,
            &set,
        )?;
        // The rest pose, deformed once: the meshers' canonical means and the defaults' scale.
        // Local parameters are in the rest triangles' frames in every mode (`lbs` bakes its
        // rest pose in binding mode), so the rest means come from the template itself, not
        // from a frame of the animation.
        let rest_means = Deformer::new(template, deform_mode(o.animation.mode))
            .means(&set, template.positions())
            .map_err(|cause| PipelineError::Gaussians {
                path: gaussians_path.clone(),
                template: config.template.clone(),
                cause,
            })?;
        let resolved = Resolved::new(o, template, &rest_means)?;
        // Rendered for the tsdf's depth maps and the meshes' render consistency; the opacity
        // method evaluates its field from the same set.
        // Vertex colours weight the Gaussians by their deformed densities.
        let finish = Finish::new(&o.finish);
        let render_set = (plan.runs(Stage::Render)
            || plan.runs(Stage::Consistency)
            || plan.runs(Stage::Mesh(Method::Opacity))
            || (finish.colors() && !config.methods.is_empty()))
        .then(|| geometry_only(&set));
        let consistency_rig = plan.runs(Stage::Consistency).then_some((
            o.metrics.consistency_views,
            o.metrics.consistency_resolution,
        ));
        let gaussian_gt_triangles = match (&config.gt, plan.runs(Stage::Metrics)) {
            (Some(GroundTruth::Gaussians), true) => {
                if !matches!(source, GaussianSource::Lam(_)) {
                    return Err(PipelineError::GtGaussians {
                        problem: format!("the Gaussians are {}", source_words(&source)),
                    });
                }
                if set.len() != stored.vertex_count() {
                    return Err(PipelineError::GtGaussians {
                        problem: format!(
                            "{} Gaussians for {} template vertices",
                            set.len(),
                            stored.vertex_count()
                        ),
                    });
                }
                stored.triangles().to_vec()
            }
            _ => Vec::new(),
        };

        input_files.push(config.template.clone());
        input_files.extend(config.gaussians.clone());
        input_files.extend(options.targets.clone());
        let mut session = Self {
            plan,
            template_path: config.template.clone(),
            label,
            welded,
            animation,
            frames,
            first_positions: Some(first_positions),
            origin,
            set,
            render_set,
            source,
            engine,
            rest_means,
            resolved,
            visibility: Visibility::all(0),
            kept_means: Vec::new(),
            meshers: Vec::new(),
            score_caches: Vec::new(),
            topology: o.topology,
            finish,
            gaussian_triangles: Vec::new(),
            mean_edge: 0.0,
            gt: config.gt.clone(),
            static_gt,
            previous_gt: None,
            gt_files,
            gaussian_gt_triangles,
            samples: o.metrics.samples,
            tau: o.metrics.threshold(),
            fps: o.animation.fps,
            input_files,
            unused_channels,
            scratch: WorldGeometry::default(),
            executed,
            serial_methods: false,
            shard,
            consistency_rig,
        };
        session.visibility = session.decide_visibility(o, &gaussians_path)?;
        let mut kept_rest_means = Vec::new();
        session
            .visibility
            .gather(&session.rest_means, &mut kept_rest_means);
        for m in Method::ALL {
            if session.plan.runs(Stage::Mesh(m)) {
                let mesher = Mesher::new(
                    m,
                    o,
                    &session.resolved,
                    session.template(),
                    // The tsdf renders every Gaussian, so its rig frames them all.
                    if m == Method::Tsdf {
                        &session.rest_means
                    } else {
                        &kept_rest_means
                    },
                    session.frames.start,
                )
                .map_err(|e| e.on_vertices_of(&config.template.display().to_string()))?;
                session
                    .meshers
                    .push((m, mesher, Carrier::new(o.topology.topology)));
                session.score_caches.push(ScoreCache::default());
            }
        }
        if o.topology.topology.carries() {
            let welded = &session.welded.mesh;
            session.mean_edge = mean_edge(welded.positions(), welded.triangles());
            session.gaussian_triangles = session
                .set
                .binding()
                .map(|b| b.triangles.iter().map(|t| t.0).collect())
                .ok_or(PipelineError::Internal {
                    what: "the main job's Gaussians are bound to the template",
                })?;
        }
        Ok(session)
    }

    /// Which Gaussians the point methods use ([`crate::Visibility`]): the Gaussians' geometry
    /// rendered at the rest pose and at up to [`VISIBILITY_FRAMES`] frames spread over the whole
    /// track (whatever frames this run meshes, so that shards decide as one run does),
    /// by the tsdf rig with at least the default views and resolution (a coarse rig would miss
    /// small Gaussians between its pixel centres). A sampled frame that cannot be deformed is
    /// skipped (the run reports it when it gets there).
    fn decide_visibility(
        &mut self,
        o: &ExtractOptions,
        gaussians_path: &Path,
    ) -> Result<Visibility, PipelineError> {
        let rule = o.visibility;
        let point_methods = [Method::Delaunay, Method::Alpha]
            .iter()
            .any(|&m| self.plan.runs(Stage::Mesh(m)));
        if !point_methods || rule.keeps_all() {
            return Ok(Visibility::all(self.set.len()));
        }
        // Moved out of the session while its frames are deformed, and back at the end (an
        // error ends the opening session anyway).
        let kept_render_set = self.render_set.is_some();
        let geometry = self
            .render_set
            .take()
            .unwrap_or_else(|| geometry_only(&self.set));
        let template = self.template();
        let rest_positions = template.positions().to_vec();
        let rest = Deformer::new(template, deform_mode(o.animation.mode))
            .deform(&geometry, &rest_positions)
            .map_err(|cause| PipelineError::Gaussians {
                path: gaussians_path.to_path_buf(),
                template: self.template_path.clone(),
                cause,
            })?;
        let mut posed = Vec::new();
        // Sampled over the whole track, not the run's frames, so that every shard of a track
        // decides the same (docs/shards.md: shards merged equal one run).
        let track = 0..self.animation.get().frame_count();
        for frame in sample_frames(track, VISIBILITY_FRAMES) {
            let Ok(positions) = self.positions(frame) else {
                continue;
            };
            if self.ready_engine(frame, &positions).is_err() {
                continue;
            }
            if let Ok((world, _)) =
                self.engine
                    .deform(&self.animation, &geometry, &positions, frame, &self.label)
            {
                posed.push((world, positions));
            }
        }
        // The run's first frame starts the degenerate-triangle hold as if nothing came before.
        self.engine.restart();
        let mut poses = vec![Pose {
            set: &rest,
            positions: &rest_positions,
        }];
        poses.extend(posed.iter().map(|(set, positions)| Pose { set, positions }));
        let views = o.tsdf.views.max(DEFAULT_VIEWS);
        let resolution = o.tsdf.resolution.max(DEFAULT_RESOLUTION);
        let decided = decide(&poses, views, resolution, &rule);
        if kept_render_set {
            self.render_set = Some(geometry);
        }
        decided.map_err(|cause| PipelineError::Visibility {
            path: gaussians_path.to_path_buf(),
            cause,
        })
    }

    /// What this run is, as [`crate::Event::Started`] tells it: the report without frames or
    /// methods (the inputs, the options of `config` that decide the scores, the scale-derived
    /// parameters), each method's parameters, and the template's triangles.
    #[must_use]
    pub fn started(&self, config: &ExtractConfig, frames: usize) -> Event {
        let o = &config.options;
        let methods = config.methods();
        let report = Report {
            version: env!("CARGO_PKG_VERSION").to_owned(),
            template: config.template.display().to_string(),
            template_vertices: self.welded.stored_vertices,
            welded_vertices: self.template().vertex_count(),
            animation: self.label.clone(),
            unused_channels: self.unused_channels.clone(),
            gaussians: match &self.source {
                GaussianSource::File(p) => p.display().to_string(),
                GaussianSource::Bound(n) => format!("bound here: {n} per triangle"),
                GaussianSource::Lam(p) => {
                    format!(
                        "{} (LAM per-vertex, bound here around its vertices)",
                        p.display()
                    )
                }
            },
            gaussian_count: self.set.len(),
            mode: o.animation.mode.name().to_owned(),
            frames: Vec::new(),
            frame_times: Vec::new(),
            deform_ms: Vec::new(),
            collapsed_triangles: Vec::new(),
            failed_frames: Vec::new(),
            ground_truth: config.gt.as_ref().map(GroundTruth::label),
            samples: o.metrics.samples,
            tau: o.metrics.tau_fraction.is_none().then_some(o.metrics.tau),
            tau_fraction: o.metrics.tau_fraction,
            resolved: self.resolved,
            gaussians_used: methods
                .iter()
                .any(|m| matches!(m, Method::Delaunay | Method::Alpha))
                .then_some(self.visibility.used),
            serial_methods: self.serial_methods,
            shard: self.shard,
            methods: BTreeMap::new(),
            glb_storage: BTreeMap::new(),
            thumbnails: None,
        };
        Event::Started {
            frames,
            report: Box::new(report),
            parameters: methods
                .iter()
                .map(|&m| (m, parameters(m, o, &self.resolved)))
                .collect(),
            charts: self.template().triangle_count(),
        }
    }

    /// Runs the methods of each frame one after another (`serial`) or side by side (the
    /// default). Side by side the whole frame takes less time, and each method's
    /// [`MethodOutput::ms`] includes the time it waited for cores the others held; one after
    /// another it is the method's time alone. The meshes are the same either way.
    pub fn set_serial_methods(&mut self, serial: bool) {
        self.serial_methods = serial;
    }

    /// Channels of the driving weights track that match no morph target or blendshape and so
    /// move nothing (empty for other animations); `--strict` refuses such a track instead.
    #[must_use]
    pub fn unused_channels(&self) -> &[String] {
        &self.unused_channels
    }

    /// The plan this session follows.
    #[must_use]
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The stages this session has run so far, each once, in the order first run.
    #[must_use]
    pub fn executed(&self) -> &[Stage] {
        &self.executed
    }

    /// The animation frames of the run.
    #[must_use]
    pub fn frames(&self) -> Range<usize> {
        self.frames.clone()
    }

    /// The template the Gaussians are deformed on (welded unless opened otherwise).
    #[must_use]
    pub fn template(&self) -> &TriMesh {
        &self.welded.mesh
    }

    /// The template with its weld map.
    #[must_use]
    pub fn welded(&self) -> &WeldedTemplate {
        &self.welded
    }

    /// The bound Gaussians (local parameters).
    #[must_use]
    pub fn gaussians(&self) -> &GaussianSet {
        &self.set
    }

    /// Where the Gaussians came from.
    #[must_use]
    pub fn source(&self) -> &GaussianSource {
        &self.source
    }

    /// The Gaussians' means on the rest template.
    #[must_use]
    pub fn rest_means(&self) -> &[Vec3] {
        &self.rest_means
    }

    /// Which Gaussians the point methods (delaunay, alpha) use, decided once when the session
    /// opened, from the rest pose and frames sampled over the whole track ([`crate::Visibility`]).
    #[must_use]
    pub fn visibility(&self) -> &Visibility {
        &self.visibility
    }

    /// The scale-derived parameters.
    #[must_use]
    pub fn resolved(&self) -> &Resolved {
        &self.resolved
    }

    /// The animation's label (its argument, or the template file).
    #[must_use]
    pub fn label(&self) -> &str {
        &self.label
    }

    /// Every file the run reads: outputs must not replace them.
    #[must_use]
    pub fn input_files(&self) -> &[PathBuf] {
        &self.input_files
    }

    /// The template file.
    #[must_use]
    pub fn template_path(&self) -> &Path {
        &self.template_path
    }

    /// The time of animation frame `frame` in seconds.
    #[must_use]
    pub fn frame_time(&self, frame: usize) -> f64 {
        self.animation
            .get()
            .frame_time(frame)
            .unwrap_or(frame as f64 / self.fps)
    }

    fn record(&mut self, stage: Stage) {
        if !self.executed.contains(&stage) {
            self.executed.push(stage);
        }
    }

    /// The local origin: the session's template, positions, rest means and
    /// [`Session::deform`] are relative to it (zero unless the template is far from the
    /// world origin; see the module documentation).
    #[must_use]
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The template's positions at animation frame `frame` (welded), relative to
    /// [`Session::origin`].
    ///
    /// # Errors
    /// An animation error, or a frame without the template's vertices.
    pub fn positions(&mut self, frame: usize) -> Result<Vec<DVec3>, PipelineError> {
        let stored = match self.first_positions.take() {
            Some(p) if frame == self.frames.start => p,
            _ => to_local(self.animation.get().frame(frame)?, self.origin),
        };
        weld_frame(
            &self.welded,
            stored,
            frame,
            &self.label,
            &self.template_path,
        )
    }

    /// Readies the engine for deforming `frame` (template at `positions`) when it does not
    /// follow the last frame deformed: the last valid frame of each triangle degenerate there
    /// is looked up in earlier frames, so a collapsed triangle is treated alike whether the
    /// run started before it or at it.
    fn ready_engine(&mut self, frame: usize, positions: &[DVec3]) -> Result<(), PipelineError> {
        let Engine::Frames(engine) = &mut self.engine else {
            return Ok(());
        };
        if !engine.needs_history(frame) {
            return Ok(());
        }
        let (animation, welded, label, path, origin) = (
            &self.animation,
            &self.welded,
            self.label.as_str(),
            self.template_path.as_path(),
            self.origin,
        );
        engine.fill_from_history(frame, positions, label, |f| {
            let stored = to_local(animation.get().frame(f)?, origin);
            weld_frame(welded, stored, f, label, path)
        })
    }

    /// The world-space Gaussians of animation frame `frame` (every attribute, SH included):
    /// what `trisplat deform` writes.
    ///
    /// # Errors
    /// As [`Session::positions`]; a failed deformation naming the frame.
    pub fn world(&mut self, frame: usize) -> Result<GaussianSet, PipelineError> {
        self.world_counted(frame).map(|(set, _)| set)
    }

    /// [`Session::world`] and the frame's collapsed template triangles (docs/numerics.md,
    /// "The degenerate-triangle policy").
    ///
    /// # Errors
    /// As [`Session::world`].
    pub fn world_counted(
        &mut self,
        frame: usize,
    ) -> Result<(GaussianSet, Collapsed), PipelineError> {
        let positions = self.positions(frame)?;
        self.ready_engine(frame, &positions)?;
        self.record(Stage::Deform);
        let (set, collapsed) =
            self.engine
                .deform(&self.animation, &self.set, &positions, frame, &self.label)?;
        Ok((moved(set, self.origin), collapsed))
    }

    /// The template's positions and the Gaussians' deformed means at animation frame
    /// `frame` (geometry only: no SH copied, buffers reused from frame to frame).
    ///
    /// # Errors
    /// As [`Session::positions`]; a failed deformation naming the frame.
    pub fn deform(&mut self, frame: usize) -> Result<(Vec<DVec3>, &[Vec3]), PipelineError> {
        let positions = self.positions(frame)?;
        self.ready_engine(frame, &positions)?;
        self.record(Stage::Deform);
        self.means_into_scratch(frame, &positions)?;
        Ok((positions, &self.scratch.means))
    }

    /// The deformed means of frame `frame` (template at `positions`) into the scratch buffers.
    fn means_into_scratch(
        &mut self,
        frame: usize,
        positions: &[DVec3],
    ) -> Result<Collapsed, PipelineError> {
        self.engine.deform_means(
            &self.animation,
            &self.set,
            positions,
            frame,
            &self.label,
            &mut self.scratch,
        )
    }

    /// Deforms frame `frame` for the meshers: the means into the scratch buffers, and the
    /// world-space set (geometry and opacity only) when the plan renders. Returns the
    /// positions, that set, the frame's collapsed triangles and the milliseconds spent
    /// deforming.
    fn deform_frame(&mut self, frame: usize) -> Result<DeformedFrame, PipelineError> {
        let positions = self.positions(frame)?;
        self.ready_engine(frame, &positions)?;
        self.record(Stage::Deform);
        let start = Instant::now();
        let (world, collapsed) = if let Some(render_set) = &self.render_set {
            let (world, collapsed) =
                self.engine
                    .deform(&self.animation, render_set, &positions, frame, &self.label)?;
            self.scratch.means.clear();
            self.scratch.means.extend_from_slice(world.means());
            (Some(world), collapsed)
        } else {
            (None, self.means_into_scratch(frame, &positions)?)
        };
        Ok(DeformedFrame {
            positions,
            world,
            collapsed,
            ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }

    /// Shows each method's [`Carrier`] the frames it must see before `frame` (the track's
    /// first key; `adaptive`, every frame since the last it saw), meshing only at keys.
    fn replay(&mut self, frame: usize) {
        let ranges: Vec<Range<usize>> = self
            .meshers
            .iter()
            .map(|(_, _, carrier)| carrier.history(frame))
            .collect();
        let Some(start) = ranges
            .iter()
            .filter(|r| !r.is_empty())
            .map(|r| r.start)
            .min()
        else {
            return;
        };
        for g in start..frame {
            // A frame that cannot be deformed failed on its own (the run went on without it):
            // it is left out of the key decisions here as it was there, so that a split run
            // decides as one run does.
            let Ok(deformed) = self.deform_frame(g) else {
                continue;
            };
            let means = if self.visibility.kept().is_some() {
                self.visibility
                    .gather(&self.scratch.means, &mut self.kept_means);
                &self.kept_means
            } else {
                &self.scratch.means
            };
            let input = FrameInput {
                frame: g,
                positions: &deformed.positions,
                means,
                world: deformed.world.as_ref(),
            };
            let context = CarryContext {
                options: &self.topology,
                triangles: self.welded.mesh.triangles(),
                gaussian_triangles: &self.gaussian_triangles,
                all_means: &self.scratch.means,
                mean_edge: self.mean_edge,
                finish: &self.finish,
            };
            for ((method, mesher, carrier), range) in self.meshers.iter_mut().zip(&ranges) {
                if range.contains(&g) {
                    // Likewise a frame whose meshing failed: the carrier has seen it (as the
                    // run that met the failure had) and keeps its key.
                    let _ = carrier.frame(*method, mesher, &input, &context, true);
                }
            }
        }
    }

    /// Deforms and meshes animation frame `frame` with every method of the plan, and measures
    /// each mesh when the plan measures (the ground truth sampled and indexed once for all
    /// methods).
    ///
    /// # Errors
    /// As [`Session::positions`]; a failed deformation, method or metric, naming the frame.
    pub fn frame(&mut self, frame: usize) -> Result<FrameResult, PipelineError> {
        self.frame_with(frame, |_, _| ()).map(|(result, ())| result)
    }

    /// [`Session::frame`], then `after` with the frame's result (its meshes may be changed,
    /// e.g. coloured) and its ground truth, sampled and indexed (`None` when the plan does not
    /// measure): per-vertex distances or pictures that need the ground truth are made here,
    /// without building it again.
    ///
    /// # Errors
    /// As [`Session::frame`].
    pub fn frame_with<T>(
        &mut self,
        frame: usize,
        after: impl FnOnce(&mut FrameResult, Option<&GtSamples>) -> T,
    ) -> Result<(FrameResult, T), PipelineError> {
        let time = self.frame_time(frame);
        self.replay(frame);
        let DeformedFrame {
            positions,
            world,
            collapsed,
            ms: deform_ms,
        } = self.deform_frame(frame)?;
        let frame_gt = self.frame_ground_truth(frame, &positions)?;
        // The point methods mesh the kept means; the tsdf renders every Gaussian, so what a
        // frame exposes (an opening mouth) is in its depth maps.
        let means = if self.visibility.kept().is_some() {
            self.visibility
                .gather(&self.scratch.means, &mut self.kept_means);
            &self.kept_means
        } else {
            &self.scratch.means
        };
        let input = FrameInput {
            frame,
            positions: &positions,
            means,
            world: world.as_ref(),
        };
        let gt = frame_gt.as_ref().or(self.static_gt.as_ref());
        // What the frame's Gaussians show from the held-out rig, rendered once for all methods
        // (in the run's local frame, as the meshes before they are moved back by `origin`).
        let gaussian_views = match (self.consistency_rig, world.as_ref()) {
            (Some((views, resolution)), Some(world)) => {
                let cameras = held_out_rig(world, views, resolution)?;
                Some(GaussianViews::render(world, &cameras)?)
            }
            _ => None,
        };
        let (samples, tau, origin) = (self.samples, self.tau, self.origin);
        let label = self.label.as_str();
        let gt_label = self
            .gt
            .as_ref()
            .map_or_else(String::new, GroundTruth::label);
        let context = CarryContext {
            options: &self.topology,
            triangles: self.welded.mesh.triangles(),
            gaussian_triangles: &self.gaussian_triangles,
            all_means: &self.scratch.means,
            mean_edge: self.mean_edge,
            finish: &self.finish,
        };
        let mesh_and_measure = |((method, mesher, carrier), cache): (
            &mut (Method, Mesher, Carrier),
            &mut ScoreCache,
        )|
         -> Result<MethodFrame, PipelineError> {
            let (mut output, topology) = carrier
                .frame(*method, mesher, &input, &context, false)
                .map_err(|e| e.on_vertices_of(label))?
                .ok_or(PipelineError::Internal {
                    what: "a carrier gives every frame it is not replaying",
                })?;
            let consistency = match &gaussian_views {
                Some(views) if output.mesh.triangle_count() > 0 => Some(views.score(&output.mesh)?),
                _ => None,
            };
            output.mesh.translate(origin);
            let metrics = match gt {
                Some(gt) => {
                    measure_cached(&output.mesh, gt, samples, tau, cache).map_err(|source| {
                        PipelineError::Metrics {
                            gt: gt_label.clone(),
                            frame,
                            method: *method,
                            cause: source,
                        }
                    })?
                }
                None => None,
            };
            Ok(MethodFrame {
                method: *method,
                output,
                metrics,
                consistency,
                topology,
            })
        };
        // Side by side, each method's own parallel loops share the cores with the others';
        // one after another, each method's time is its own.
        let methods: Vec<MethodFrame> = if self.serial_methods {
            self.meshers
                .iter_mut()
                .zip(&mut self.score_caches)
                .map(mesh_and_measure)
                .collect::<Result<_, _>>()?
        } else {
            // Every method runs; the first failure in method order is reported, as one after
            // another.
            first_error_in_order(
                self.meshers
                    .par_iter_mut()
                    .zip(&mut self.score_caches)
                    .map(mesh_and_measure),
            )?
        };
        let mut ran = Vec::new();
        for m in &methods {
            if m.method == Method::Tsdf {
                ran.push(Stage::Render);
            }
            ran.push(Stage::Mesh(m.method));
            if gt.is_some() {
                ran.push(Stage::Metrics);
            }
            if m.consistency.is_some() {
                ran.push(Stage::Consistency);
            }
        }
        let measured = gt.is_some();
        for stage in ran {
            self.record(stage);
        }
        let mut result = FrameResult {
            frame,
            time,
            deform_ms,
            collapsed,
            methods,
        };
        let gt = if measured {
            frame_gt.as_ref().or(self.static_gt.as_ref())
        } else {
            None
        };
        let extra = after(&mut result, gt);
        self.previous_gt = frame_gt;
        Ok((result, extra))
    }
}

/// One frame deformed for the meshers (see `Session::deform_frame`).
struct DeformedFrame {
    positions: Vec<DVec3>,
    world: Option<GaussianSet>,
    collapsed: Collapsed,
    ms: f64,
}

/// `positions` relative to `origin` (exact in f64 for positions near it; no work at zero).
fn to_local(mut positions: Vec<DVec3>, origin: DVec3) -> Vec<DVec3> {
    if origin != DVec3::ZERO {
        for p in &mut positions {
            *p -= origin;
        }
    }
    positions
}

/// `set` (world-space Gaussians relative to `origin`) moved back to world coordinates.
fn moved(set: GaussianSet, origin: DVec3) -> GaussianSet {
    if origin == DVec3::ZERO {
        return set;
    }
    let mut parts = set.into_parts();
    for m in &mut parts.means {
        *m = (m.as_dvec3() + origin).as_vec3();
    }
    GaussianSet::new_unchecked(parts)
}

/// The welded positions of animation frame `frame` from its stored ones.
fn weld_frame(
    welded: &WeldedTemplate,
    stored: Vec<DVec3>,
    frame: usize,
    label: &str,
    template_path: &Path,
) -> Result<Vec<DVec3>, PipelineError> {
    let count = stored.len();
    welded
        .positions(stored)
        .ok_or_else(|| PipelineError::Topology {
            animation: label.to_owned(),
            problem: format!(
                "frame {frame} has {count} vertices, the template {} has {}",
                template_path.display(),
                welded.stored_vertices
            ),
        })
}

/// How the Gaussians came, for an error message.
fn source_words(source: &GaussianSource) -> String {
    match source {
        GaussianSource::File(path) => format!("bound to triangles in {}", path.display()),
        GaussianSource::Bound(n) => format!("bound here, {n} per triangle"),
        GaussianSource::Lam(path) => format!("LAM's, from {}", path.display()),
    }
}

/// Up to `count` frames of `frames`, evenly spaced from its first to its last (all of them
/// when it has no more).
fn sample_frames(frames: Range<usize>, count: usize) -> Vec<usize> {
    let n = frames.len();
    if n <= count {
        return frames.collect();
    }
    (0..count)
        .map(|i| frames.start + i * (n - 1) / (count - 1).max(1))
        .collect()
}

/// `set` with only the SH degree-0 coefficients and no extra properties: the geometry and
/// opacity rendering depth needs, so a frame copies 3 SH values per Gaussian instead of up
/// to 48.
fn geometry_only(set: &GaussianSet) -> GaussianSet {
    let mut parts = set.clone().into_parts();
    if parts.sh_degree > 0 {
        // Per Gaussian, `f_dc_0..2` come first (see `GaussianParts::sh`).
        let stride = parts.sh.len() / parts.means.len().max(1);
        parts.sh = parts
            .sh
            .chunks_exact(stride.max(3))
            .flat_map(|c| [c[0], c[1], c[2]])
            .collect();
        parts.sh_degree = 0;
    }
    parts.extras.clear();
    parts.property_order = None;
    GaussianSet::new_unchecked(parts)
}
