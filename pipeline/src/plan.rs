//! The stages a run needs, decided from the arguments alone (no file is read), each with the
//! reason it runs or is skipped: what `trisplat extract --explain` prints.

use std::fmt;

use crate::config::GaussianLayout;

use crate::config::{
    AlphaRule, COARSEST_VOXELS_PER_RADIUS, DEFAULT_ALPHA_CEILING_SPACINGS,
    DEFAULT_ALPHA_FLOOR_SPACINGS, DEFAULT_ALPHA_SPACINGS, DEFAULT_VOXELS_PER_RADIUS, ExtractConfig,
    GroundTruth, Method, Mode, OutputTarget, Topology,
};

/// A stage of the main job (docs/conventions.md §1), in the order they run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Read the template and open its animation.
    Animate,
    /// Bind new Gaussians to the template's triangles.
    Bind,
    /// Deform the bound Gaussians to every frame.
    Deform,
    /// Render depth maps of the deformed Gaussians (CPU splatting).
    Render,
    /// Mesh every frame with one method.
    Mesh(Method),
    /// Chamfer, normal consistency and F-score against the ground truth.
    Metrics,
    /// Each mesh against the frame's own Gaussians from held-out views.
    Consistency,
    /// Per-frame PLY files and one animated glTF per method.
    Write,
    /// report.json, report.md, report.html (with thumbnails/), error_vs_time.svg and .png.
    Report,
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Animate => f.write_str("animate"),
            Self::Bind => f.write_str("bind"),
            Self::Deform => f.write_str("deform"),
            Self::Render => f.write_str("render"),
            Self::Mesh(m) => write!(f, "mesh:{m}"),
            Self::Metrics => f.write_str("metrics"),
            Self::Consistency => f.write_str("consistency"),
            Self::Write => f.write_str("write"),
            Self::Report => f.write_str("report"),
        }
    }
}

/// One stage of the plan.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StagePlan {
    /// The stage.
    pub stage: Stage,
    /// Whether it runs.
    pub runs: bool,
    /// Why it runs (and with what) or why it is skipped.
    pub why: String,
}

/// The stages of a run, in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    /// Every stage, run or skipped.
    pub stages: Vec<StagePlan>,
}

impl Plan {
    /// The plan for `config`.
    #[must_use]
    pub fn new(config: &ExtractConfig) -> Self {
        let o = &config.options;
        let methods = config.methods();
        let mut stages = Vec::new();
        let mut push = |stage, runs, why: String| stages.push(StagePlan { stage, runs, why });

        let t = config.template.display();
        let animate = match &config.animation {
            Some(a) => format!("template {t}, animation {a}"),
            None => format!(
                "template {t}; no --animation: its own glTF clip if it has one, else one frame"
            ),
        };
        let animate = match &o.animation.clip_from {
            Some(source) => format!(
                "{animate}; clip {} of {} played on the template's joints by name (looped under \
                 a weights track)",
                o.animation.clip.as_deref().unwrap_or("0"),
                source.display()
            ),
            None => animate,
        };
        let animate = format!(
            "{animate}; template in world space (glTF: node transforms and skins applied), \
             checked against the first frame's scale; vertices split at seams welded by position"
        );
        push(Stage::Animate, true, animate);

        match &config.gaussians {
            Some(g) if o.bind.layout == GaussianLayout::Lam => push(
                Stage::Bind,
                true,
                format!(
                    "--gaussians {} in LAM's per-vertex layout: row i is the offset of a \
                     Gaussian from template vertex i (colour as RGB); each is bound here to the \
                     triangle around its vertex nearest to it ({} convention)",
                    g.display(),
                    if o.animation.mode == Mode::Jacobian {
                        "surfhead"
                    } else {
                        "gaussianavatars"
                    }
                ),
            ),
            Some(g) => push(
                Stage::Bind,
                false,
                format!(
                    "--gaussians {} given: read as bound Gaussians (a file without a triangle \
                     binding, or bound to another template, is refused when the run reads it; \
                     LAM's per-vertex offsets need --layout lam or --avatar)",
                    g.display()
                ),
            ),
            None => push(
                Stage::Bind,
                true,
                format!(
                    "no --gaussians: {} per triangle ({} convention), opaque flat discs",
                    o.bind.per_triangle,
                    if o.animation.mode == Mode::Jacobian {
                        "surfhead"
                    } else {
                        "gaussianavatars"
                    }
                ),
            ),
        }

        let frames = config.frames.as_deref().unwrap_or("all");
        push(
            Stage::Deform,
            true,
            format!("mode {}, frames {frames}", o.animation.mode.name()),
        );

        if methods.contains(&Method::Tsdf) {
            push(
                Stage::Render,
                true,
                format!(
                    "tsdf needs depth maps: {} views of {}x{} px per frame (expected depth, alpha >= 0.5)",
                    o.tsdf.views, o.tsdf.resolution, o.tsdf.resolution
                ),
            );
        } else {
            push(
                Stage::Render,
                false,
                "no tsdf method: nothing needs depth maps".to_owned(),
            );
        }

        for m in Method::ALL {
            if !methods.contains(&m) {
                push(Stage::Mesh(m), false, "not asked for (--method)".to_owned());
                continue;
            }
            let why = match m {
                Method::Tsdf => match o.tsdf.voxel {
                    Some(v) => format!("voxel {v}, trunc 5 voxels"),
                    None => format!(
                        "voxel = Gaussian spacing within template radius / {DEFAULT_VOXELS_PER_RADIUS} ..= / {COARSEST_VOXELS_PER_RADIUS}, trunc 5 voxels"
                    ),
                },
                Method::Delaunay => {
                    let rebuild = match o.delaunay.rebuild_every {
                        0 if o.delaunay.no_auto_rebuild => {
                            "incremental: only charts that Gaussians hop \
                                                   into or out of are redone, whatever it costs"
                                .to_owned()
                        }
                        0 => "incremental: only charts that Gaussians hop into or out of are \
                              redone; rebuilt from scratch while updates cost more"
                            .to_owned(),
                        1 => "--rebuild-every 1: triangulated from scratch every frame".to_owned(),
                        n => format!("incremental, rebuilt from scratch every {n} frames"),
                    };
                    let hop = if o.delaunay.hop_threshold == 0.0 {
                        "hop threshold 0: every frame equals a from-scratch triangulation"
                            .to_owned()
                    } else {
                        format!(
                            "hop threshold {} x mean template edge: fewer charts redone, frames \
                             may differ from a from-scratch triangulation",
                            o.delaunay.hop_threshold
                        )
                    };
                    format!("{rebuild}; {hop}")
                }
                Method::Alpha => match (o.alpha.rule, o.alpha.alpha) {
                    (AlphaRule::Solid, Some(a)) => format!(
                        "boundary of the alpha complex's solid (folds and inner sheets dropped) \
                         at {a}, on the deformed means"
                    ),
                    (AlphaRule::Solid, None) => format!(
                        "boundary of the alpha complex's solid (folds and inner sheets dropped) on \
                         the deformed means, per frame at the smallest alpha from \
                         {DEFAULT_ALPHA_FLOOR_SPACINGS} to {DEFAULT_ALPHA_CEILING_SPACINGS} x mean \
                         Gaussian spacing giving at most {} piece(s)",
                        o.alpha.pieces
                    ),
                    (AlphaRule::Complex, Some(a)) => {
                        format!(
                            "alpha complex (singular triangles kept) at {a}, on the deformed means"
                        )
                    }
                    (AlphaRule::Complex, None) => format!(
                        "alpha complex (singular triangles kept) on the deformed means, per frame at \
                         the smallest alpha from {DEFAULT_ALPHA_FLOOR_SPACINGS} to \
                         {DEFAULT_ALPHA_CEILING_SPACINGS} x mean Gaussian spacing giving at most {} \
                         piece(s)",
                        o.alpha.pieces
                    ),
                    (AlphaRule::Open3d, Some(a)) => {
                        format!("Open3D's alpha shape at {a}, on the deformed means")
                    }
                    (AlphaRule::Open3d, None) => format!(
                        "Open3D's alpha shape at {DEFAULT_ALPHA_SPACINGS} x mean Gaussian spacing, on \
                         the deformed means"
                    ),
                },
                Method::Opacity => format!(
                    "every Gaussian's centre and 3-sigma box corners tetrahedralised, the \
                     opacity field the minimum over the tsdf rig's {} views of {}x{} px, \
                     marching tetrahedra at 1/2 with 8 bisection steps, the largest piece",
                    o.tsdf.views, o.tsdf.resolution, o.tsdf.resolution
                ),
            };
            let t = &o.topology;
            let why = match t.topology {
                Topology::PerFrame => why,
                Topology::Fixed => format!(
                    "{why}; --topology fixed: only the track's first frame, its mesh carried \
                     through the others"
                ),
                Topology::Adaptive => format!(
                    "{why}; --topology adaptive: the track's first frame and each frame where \
                     over {} of the probe Gaussians move {} mean template edges off the carried \
                     mesh, their distances to it change by {} mean template edges on average, \
                     or {} of its area stretches twofold start a key{}, the mesh carried between \
                     keys",
                    t.key_hops,
                    t.hop_distance,
                    t.key_offset,
                    t.key_stretch,
                    t.key_motion.map_or_else(String::new, |m| format!(
                        " (tsdf: also where they move {m} mean template edges on average)"
                    ))
                ),
            };
            push(Stage::Mesh(m), true, why);
        }

        match &config.gt {
            None => push(
                Stage::Metrics,
                false,
                "no --gt: nothing to compare against".to_owned(),
            ),
            Some(_) if methods.is_empty() => push(
                Stage::Metrics,
                false,
                "no method: no mesh to measure".to_owned(),
            ),
            Some(gt) => {
                let against = match gt {
                    GroundTruth::Template => "each frame's deformed template".to_owned(),
                    GroundTruth::Gaussians => {
                        "each frame's surface of the Gaussians' centres (the stored template \
                         with vertex i at Gaussian i)"
                            .to_owned()
                    }
                    GroundTruth::Mesh(p) => format!("the static mesh {}", p.display()),
                    GroundTruth::Sequence(spec) => format!("one mesh per frame from {spec}"),
                };
                push(
                    Stage::Metrics,
                    true,
                    format!(
                        "against {against}: {} samples per mesh, exact distances to the \
                         triangles, F-score at {}; structure (components, holes, area ratio) \
                         and the self-consistency check of each mesh",
                        o.metrics.samples,
                        match o.metrics.tau_fraction {
                            Some(f) => format!(
                                "tau = {f} x each frame's ground-truth bounding-box diagonal"
                            ),
                            None => format!("tau {} (absolute)", o.metrics.tau),
                        }
                    ),
                );
            }
        }

        let views = o.metrics.consistency_views;
        push(
            Stage::Consistency,
            views > 0 && !methods.is_empty(),
            if methods.is_empty() {
                "no method: no mesh to compare".to_owned()
            } else if views == 0 {
                "--consistency-views 0".to_owned()
            } else {
                format!(
                    "each mesh against the frame's Gaussians from {views} held-out views of                      {px}x{px} px (silhouette IoU, depth error, normal angle; docs/conventions.md                      §8), the Gaussians rendered once per frame for all methods",
                    px = o.metrics.consistency_resolution
                )
            },
        );

        let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
        let out = config.output.display();
        let meshes = o.outputs.writes(OutputTarget::Meshes);
        let mut files = Vec::new();
        if meshes {
            files.push(format!("{out}/<method>/frame_NNNNNN.ply"));
        }
        if o.outputs.writes(OutputTarget::Glb) {
            files.push(format!("{out}/<method>.glb"));
        }
        if o.outputs.writes(OutputTarget::Rig) {
            files.push(format!("{out}/<method>_rig.glb"));
        }
        if o.outputs.writes(OutputTarget::Usd) {
            files.push(format!("{out}/<method>.usda"));
        }
        let assembled_only = !meshes && o.outputs.writes_frame_files();
        push(
            Stage::Write,
            !files.is_empty(),
            if files.is_empty() {
                "--targets names neither meshes, glb nor usd".to_owned()
            } else {
                format!(
                    "{} for {}{}",
                    files.join(" and "),
                    names.join(", "),
                    if assembled_only {
                        " (the frame files are removed once assembled: --targets without meshes)"
                    } else {
                        ""
                    }
                )
            },
        );
        let plot = if config.gt.is_some() {
            "Chamfer L1 against ms/frame"
        } else {
            "ms per frame (no --gt: no error to plot)"
        };
        let report = o.outputs.writes(OutputTarget::Report);
        push(
            Stage::Report,
            report,
            if report {
                format!(
                    "report.json, report.md, report.html with a thumbnail of each method's mesh \
                     at the middle frame, error_vs_time.svg and .png ({plot})"
                )
            } else {
                "--targets without report (the journal still records every frame)".to_owned()
            },
        );
        Self { stages }
    }

    /// Whether `stage` runs.
    #[must_use]
    pub fn runs(&self, stage: Stage) -> bool {
        self.stages.iter().any(|s| s.stage == stage && s.runs)
    }
}

impl fmt::Display for Plan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for s in &self.stages {
            let mark = if s.runs { "run " } else { "skip" };
            writeln!(f, "{mark}  {:<14} {}", s.stage.to_string(), s.why)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;
    use crate::config::ExtractOptions;

    fn config(methods: &[Method], gaussians: bool, gt: Option<GroundTruth>) -> ExtractConfig {
        ExtractConfig {
            template: PathBuf::from("t.glb"),
            animation: None,
            gaussians: gaussians.then(|| PathBuf::from("g.ply")),
            methods: methods.to_vec(),
            output: PathBuf::from("out"),
            frames: None,
            gt,
            options: ExtractOptions::default(),
        }
    }

    #[test]
    fn render_only_for_tsdf() {
        let p = Plan::new(&config(&[Method::Delaunay, Method::Alpha], false, None));
        assert!(!p.runs(Stage::Render));
        assert!(p.runs(Stage::Mesh(Method::Delaunay)));
        assert!(p.runs(Stage::Mesh(Method::Alpha)));
        assert!(!p.runs(Stage::Mesh(Method::Tsdf)));
        let p = Plan::new(&config(&[Method::Tsdf], false, None));
        assert!(p.runs(Stage::Render));
        assert!(!p.runs(Stage::Mesh(Method::Delaunay)));
    }

    #[test]
    fn bind_only_without_gaussians() {
        assert!(Plan::new(&config(&[Method::Alpha], false, None)).runs(Stage::Bind));
        let p = Plan::new(&config(&[Method::Alpha], true, None));
        assert!(!p.runs(Stage::Bind));
        assert!(
            p.to_string()
                .contains("g.ply given: read as bound Gaussians")
        );
    }

    #[test]
    fn metrics_only_with_gt() {
        assert!(!Plan::new(&config(&[Method::Alpha], false, None)).runs(Stage::Metrics));
        let p = Plan::new(&config(
            &[Method::Alpha],
            false,
            Some(GroundTruth::Template),
        ));
        assert!(p.runs(Stage::Metrics));
        assert!(p.to_string().contains("deformed template"));
        let p = Plan::new(&config(
            &[Method::Alpha],
            false,
            Some(GroundTruth::Mesh("scan.ply".into())),
        ));
        assert!(p.to_string().contains("scan.ply"));
    }

    #[test]
    fn every_stage_listed_once_in_order() {
        let p = Plan::new(&config(&Method::ALL, true, None));
        let order: Vec<Stage> = p.stages.iter().map(|s| s.stage).collect();
        assert_eq!(
            order,
            vec![
                Stage::Animate,
                Stage::Bind,
                Stage::Deform,
                Stage::Render,
                Stage::Mesh(Method::Tsdf),
                Stage::Mesh(Method::Delaunay),
                Stage::Mesh(Method::Alpha),
                Stage::Mesh(Method::Opacity),
                Stage::Metrics,
                Stage::Consistency,
                Stage::Write,
                Stage::Report,
            ]
        );
        // Every line says run or skip.
        assert_eq!(p.to_string().lines().count(), order.len());
    }

    #[test]
    fn hop_threshold_is_explained() {
        let mut c = config(&[Method::Delaunay], false, None);
        assert!(
            Plan::new(&c)
                .to_string()
                .contains("hop threshold 0: every frame equals")
        );
        c.options.delaunay.hop_threshold = 0.25;
        let text = Plan::new(&c).to_string();
        assert!(
            text.contains("hop threshold 0.25 x mean template edge"),
            "{text}"
        );
    }

    #[test]
    fn rebuild_every_one_is_from_scratch() {
        let mut c = config(&[Method::Delaunay], false, None);
        c.options.delaunay.rebuild_every = 1;
        assert!(
            Plan::new(&c)
                .to_string()
                .contains("from scratch every frame")
        );
    }
}
