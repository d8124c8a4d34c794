//! The frame loop: per frame, deform once, then per method mesh (timed), measure, write.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{
    SequenceLayout, WriteOptions, read_mesh, write_mesh, write_mesh_sequence,
};
use trisplat_splat::GaussianSet;
use trisplat_splat::deform::{Deformer, WorldGeometry};
use trisplat_splat::lbs::LbsDeformer;

pub use crate::output::frame_file;

use crate::config::{ExtractConfig, GroundTruth, Method, Mode};
use crate::deform::{Engine, skinned_gltf};
use crate::error::PipelineError;
use crate::input::{
    Animation, GaussianSource, WeldedTemplate, animation_label, check_scale, check_topology,
    deform_mode, gaussians, open_animation, parse_frames, read_template,
};
use crate::methods::{FrameInput, Mesher, Resolved};
use crate::output::{Created, Inputs};
use crate::plot;
use crate::report::{
    DelaunayFrame, DelaunayStats, FrameRecord, GtSamples, MethodReport, Report, Summary,
    is_watertight, measure,
};

/// File name of the JSON report in the output folder.
pub const REPORT_JSON: &str = "report.json";
/// File name of the Markdown report.
pub const REPORT_MD: &str = "report.md";
/// File name of the plot.
pub const PLOT_PNG: &str = "error_vs_time.png";

/// Progress of a run, for a progress bar.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// Inputs read; `frames` frames will be meshed.
    Started {
        /// Frames to mesh.
        frames: usize,
    },
    /// `done` frames of `total` meshed (all methods).
    Frame {
        /// Frames done.
        done: usize,
        /// Frames in all.
        total: usize,
    },
    /// Writing the sequences, reports and plot.
    Finishing,
}

/// A deformed frame: the world set when the tsdf method needs it, and the means.
struct Deformed {
    world: Option<GaussianSet>,
    means: Vec<Vec3>,
}

/// The deformer of `config`'s mode on the welded template; `lbs` checks the stored template
/// against the animation's rest pose and skins each welded vertex with its first copy.
fn build_engine(
    config: &ExtractConfig,
    stored: &TriMesh,
    welded: &WeldedTemplate,
    animation: &Animation,
    set: &GaussianSet,
) -> Result<Engine, PipelineError> {
    let mode = config.options.mode;
    let template = &welded.mesh;
    if mode != Mode::Lbs {
        return Ok(Engine::Frames(Deformer::new(template, deform_mode(mode))));
    }
    let label = animation_label(config);
    let a_path = PathBuf::from(&label);
    let g = skinned_gltf(animation, stored, &config.template, &label)?;
    let palette = g.palette_at(None)?;
    let skinning = welded.skinning(&g.skinning()).ok_or(PipelineError::Lbs {
        path: a_path.clone(),
        problem: "the skin's vertex count differs from the template's".to_owned(),
    })?;
    let rig = LbsDeformer::new(set, template, &skinning, &palette).map_err(|source| {
        PipelineError::Skinning {
            path: a_path.clone(),
            frame: 0,
            cause: source,
        }
    })?;
    Ok(Engine::Lbs(Box::new(rig)))
}

/// Deforms one frame: the world set when `need_world`, else (binding/jacobian) only the means.
fn deform_frame(
    engine: &Engine,
    animation: &Animation,
    set: &GaussianSet,
    positions: &[Vec3],
    frame: usize,
    need_world: bool,
    label: &str,
) -> Result<Deformed, PipelineError> {
    if let (Engine::Frames(d), false) = (engine, need_world) {
        let mut geometry = WorldGeometry::default();
        d.deform_geometry(set, positions, &mut geometry)
            .map_err(|source| PipelineError::Deform {
                path: label.to_owned(),
                frame,
                cause: source,
            })?;
        return Ok(Deformed {
            world: None,
            means: geometry.means,
        });
    }
    let world = engine.deform(animation, set, positions, frame, label)?;
    let means = world.means().to_vec();
    Ok(Deformed {
        world: need_world.then_some(world),
        means,
    })
}

/// The per-frame meshes of each method, kept for the animated glTF.
pub type Sequences = BTreeMap<Method, Vec<TriMesh>>;

/// Runs the main job and writes every output (see the crate docs); returns the report.
/// `progress` is told when frames are done.
///
/// # Errors
/// Bad inputs (named), an output that would replace an input, a failed method or write. The
/// files this run created are removed again on failure.
pub fn run(
    config: &ExtractConfig,
    progress: &mut dyn FnMut(Progress),
) -> Result<Report, PipelineError> {
    let mut created = Created::default();
    let result = run_inner(config, progress, &mut created);
    if result.is_err() {
        created.remove();
    }
    result
}

#[expect(
    clippy::too_many_lines,
    reason = "the frame loop reads best as one sequence of stages"
)]
fn run_inner(
    config: &ExtractConfig,
    progress: &mut dyn FnMut(Progress),
    created: &mut Created,
) -> Result<Report, PipelineError> {
    let o = &config.options;
    let methods = config.methods();
    if methods.is_empty() {
        return Err(PipelineError::NoMethod);
    }
    if !(o.tau.is_finite() && o.tau > 0.0) {
        return Err(PipelineError::BadOption {
            name: "tau",
            value: o.tau,
            expected: "a finite positive distance",
        });
    }
    if !(o.hop_threshold.is_finite() && o.hop_threshold >= 0.0) {
        return Err(PipelineError::BadOption {
            name: "hop-threshold",
            value: o.hop_threshold,
            expected: "a finite number >= 0 (multiples of the mean template edge)",
        });
    }
    if o.samples == 0 {
        return Err(PipelineError::BadOption {
            name: "samples",
            value: 0.0,
            expected: "at least one sample",
        });
    }
    // Inputs: the template in world space, as its animation poses it (see `read_template`).
    let stored = read_template(&config.template)?;
    if stored.triangle_count() == 0 {
        return Err(PipelineError::EmptyTemplate {
            path: config.template.clone(),
        });
    }
    let (animation, mut input_files) = open_animation(config, &stored)?;
    let anim = animation.get();
    check_topology(&stored, &config.template, anim, &animation_label(config))?;
    // Every later stage sees the template welded at its seams (see `WeldedTemplate`).
    let welded = WeldedTemplate::new(&stored);
    let template = &welded.mesh;
    let frames = parse_frames(config.frames.as_deref(), anim.frame_count())?;
    // The scale-derived defaults come from the template: its frames must share its scale.
    let label = animation_label(config);
    let first_positions = anim.frame(frames.start)?;
    check_scale(
        &stored,
        &config.template,
        &first_positions,
        frames.start,
        &label,
    )?;
    let mut first_positions = Some(first_positions);
    let static_gt = match &config.gt {
        Some(GroundTruth::Mesh(path)) => {
            input_files.push(path.clone());
            let mesh = read_mesh(path)?;
            Some(GtSamples::new(mesh, o.samples).ok_or_else(|| {
                PipelineError::EmptyGroundTruth {
                    gt: path.display().to_string(),
                    frame: frames.start,
                }
            })?)
        }
        _ => None,
    };
    let (set, source) = gaussians(config, template)?;
    let engine = build_engine(config, &stored, &welded, &animation, &set)?;
    let mode = deform_mode(o.mode);
    let mut rest = WorldGeometry::default();
    Deformer::new(template, mode)
        .deform_geometry(&set, template.positions(), &mut rest)
        .map_err(|source| PipelineError::Gaussians {
            path: config.gaussians.clone().unwrap_or_default(),
            template: config.template.clone(),
            cause: source,
        })?;
    let resolved = Resolved::new(o, template, &rest.means)?;

    // Outputs: never over an input.
    input_files.push(config.template.clone());
    if let Some(g) = &config.gaussians {
        input_files.push(g.clone());
    }
    let inputs = Inputs::new(&input_files);
    let out = &config.output;
    for m in &methods {
        let dir = out.join(m.name());
        for f in frames.clone() {
            inputs.check(&dir.join(frame_file(f)))?;
        }
        inputs.check(&out.join(format!("{}.glb", m.name())))?;
    }
    for name in [REPORT_JSON, REPORT_MD, PLOT_PNG] {
        inputs.check(&out.join(name))?;
    }
    for m in &methods {
        let dir = out.join(m.name());
        std::fs::create_dir_all(&dir).map_err(|source| PipelineError::OutputDir {
            path: dir,
            cause: source,
        })?;
    }

    let mut meshers = Vec::with_capacity(methods.len());
    for &m in &methods {
        meshers.push(Mesher::new(
            m,
            o,
            &resolved,
            template,
            &rest.means,
            frames.start,
        )?);
    }

    let need_world = methods.contains(&Method::Tsdf);
    let total = frames.len();
    progress(Progress::Started { frames: total });
    let mut records: BTreeMap<Method, Vec<FrameRecord>> = BTreeMap::new();
    let mut delaunay_frames: Vec<DelaunayFrame> = Vec::new();
    let mut sequences: Sequences = BTreeMap::new();
    let mut frame_times = Vec::with_capacity(total);
    let mut deform_ms = Vec::with_capacity(total);
    for (done, f) in frames.clone().enumerate() {
        let stored_positions = match first_positions.take() {
            Some(p) => p,
            None => anim.frame(f)?,
        };
        let stored_count = stored_positions.len();
        let positions =
            welded
                .positions(stored_positions)
                .ok_or_else(|| PipelineError::Topology {
                    animation: label.clone(),
                    problem: format!(
                        "frame {f} has {stored_count} vertices, the template {} has {}",
                        config.template.display(),
                        welded.stored_vertices
                    ),
                })?;
        let time = anim.frame_time(f).unwrap_or(f as f64 / o.fps);
        let start = Instant::now();
        let deformed = deform_frame(&engine, &animation, &set, &positions, f, need_world, &label)?;
        deform_ms.push(start.elapsed().as_secs_f64() * 1e3);
        frame_times.push(time);
        let frame_gt = match &config.gt {
            Some(GroundTruth::Template) => {
                let mesh = TriMesh::new_unchecked(positions.clone(), template.triangles().to_vec());
                Some(
                    GtSamples::new(mesh, o.samples).ok_or(PipelineError::EmptyGroundTruth {
                        gt: "template".to_owned(),
                        frame: f,
                    })?,
                )
            }
            _ => None,
        };
        let gt = frame_gt.as_ref().or(static_gt.as_ref());
        let input = FrameInput {
            frame: f,
            positions: &positions,
            means: &deformed.means,
            world: deformed.world.as_ref(),
        };
        for (mesher, &m) in meshers.iter_mut().zip(&methods) {
            let result = mesher.mesh(&input)?;
            let metrics = match gt {
                Some(gt) => measure(&result.mesh, gt, o.samples, o.tau).map_err(|source| {
                    PipelineError::Metrics {
                        gt: config
                            .gt
                            .as_ref()
                            .map_or_else(String::new, GroundTruth::label),
                        frame: f,
                        method: m,
                        cause: source,
                    }
                })?,
                None => None,
            };
            if let Some(stats) = &result.delaunay {
                delaunay_frames.push(DelaunayFrame::new(f, stats));
            }
            let path = out.join(m.name()).join(frame_file(f));
            let existed = path.exists();
            write_mesh(&path, &result.mesh, WriteOptions::default())?;
            created.note(&path, existed);
            records.entry(m).or_default().push(FrameRecord {
                frame: f,
                time,
                ms: result.ms,
                render_ms: result.render_ms,
                vertices: result.mesh.vertex_count(),
                faces: result.mesh.triangle_count(),
                watertight: is_watertight(&result.mesh),
                metrics,
            });
            sequences.entry(m).or_default().push(result.mesh);
        }
        progress(Progress::Frame {
            done: done + 1,
            total,
        });
    }
    progress(Progress::Finishing);

    let mut method_reports = BTreeMap::new();
    for (m, frames_of) in records {
        let mut parameters = BTreeMap::new();
        match m {
            Method::Tsdf => {
                parameters.insert("voxel".to_owned(), resolved.voxel);
                parameters.insert("views".to_owned(), o.views as f64);
                parameters.insert("resolution".to_owned(), f64::from(o.resolution));
            }
            Method::Delaunay => {
                parameters.insert("rebuild_every".to_owned(), o.rebuild_every as f64);
                parameters.insert("hop_threshold".to_owned(), o.hop_threshold);
            }
            Method::Alpha => {
                parameters.insert("alpha".to_owned(), resolved.alpha);
            }
        }
        let mean = Summary::of(&frames_of);
        method_reports.insert(
            m.name().to_owned(),
            MethodReport {
                method: m,
                parameters,
                frames: frames_of,
                mean,
                ply_dir: m.name().to_owned(),
                glb: format!("{}.glb", m.name()),
                delaunay: (m == Method::Delaunay).then(|| {
                    DelaunayStats::new(
                        template.triangle_count(),
                        set.len(),
                        std::mem::take(&mut delaunay_frames),
                    )
                }),
            },
        );
    }
    let report = Report {
        version: env!("CARGO_PKG_VERSION").to_owned(),
        template: config.template.display().to_string(),
        template_vertices: welded.stored_vertices,
        welded_vertices: welded.mesh.vertex_count(),
        animation: label,
        gaussians: match source {
            GaussianSource::File(p) => p.display().to_string(),
            GaussianSource::Bound(n) => format!("bound here: {n} per triangle"),
        },
        gaussian_count: set.len(),
        mode: o.mode.name().to_owned(),
        frames: frames.collect(),
        frame_times,
        deform_ms,
        ground_truth: config.gt.as_ref().map(GroundTruth::label),
        samples: o.samples,
        tau: o.tau,
        resolved,
        methods: method_reports,
    };
    write_outputs(out, &report, &sequences, created)?;
    Ok(report)
}

/// Writes one animated glTF per method, the report files and the plot.
fn write_outputs(
    out: &Path,
    report: &Report,
    sequences: &Sequences,
    created: &mut Created,
) -> Result<(), PipelineError> {
    for (m, meshes) in sequences {
        let glb = out.join(format!("{}.glb", m.name()));
        let existed = glb.exists();
        write_mesh_sequence(&glb, meshes, &report.frame_times, SequenceLayout::Auto)?;
        created.note(&glb, existed);
    }
    let json = out.join(REPORT_JSON);
    let existed = json.exists();
    report.write_json(&json)?;
    created.note(&json, existed);
    let md = out.join(REPORT_MD);
    let existed = md.exists();
    report.write_markdown(&md)?;
    created.note(&md, existed);
    let png = out.join(PLOT_PNG);
    let existed = png.exists();
    plot::write_plot(&png, report)?;
    created.note(&png, existed);
    Ok(())
}
