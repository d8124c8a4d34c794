//! Deforming bound Gaussians to the frames of an animation: the one engine of the main job
//! and `trisplat deform` (both through [`crate::session::Session`]).

use std::path::{Path, PathBuf};

use glam::{DMat4, DVec3};
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{AnimatedTemplate, GltfTemplate};
use trisplat_splat::GaussianSet;
use trisplat_splat::LbsDeformer;
use trisplat_splat::{Collapsed, DeformError, Deformer, FrameHold, WorldGeometry};

use crate::config::Mode;
use crate::error::PipelineError;
use crate::input::{Animation, WeldedTemplate, check_set, deform_mode};

/// Largest difference between the template's positions and a skinned animation's rest pose
/// that `lbs` accepts, relative to the template's bounding-box diagonal (f32 storage of both).
pub const LBS_REST_TOLERANCE: f64 = 1e-5;

/// How frames are deformed.
#[derive(Debug)]
pub enum Engine {
    /// `binding` or `jacobian`: from each frame's template positions, a collapsed triangle
    /// keeping its last valid frame (docs/numerics.md, "The degenerate-triangle policy").
    Frames(FrameEngine),
    /// `lbs`: from each frame's skinning palette (the animation is a skinned glTF), moved to
    /// the template's local origin.
    Lbs(Box<LbsDeformer>, DVec3),
}

/// The `binding`/`jacobian` engine: the deformer and the last valid frame of every triangle.
#[derive(Debug)]
pub struct FrameEngine {
    /// The deformer.
    pub deformer: Deformer,
    hold: FrameHold,
    /// The frame the hold was last updated with.
    last: Option<usize>,
}

impl FrameEngine {
    /// Whether deforming `frame` next needs the hold filled from earlier frames first (the
    /// first frame deformed, or a jump): see [`FrameEngine::fill_from_history`].
    #[must_use]
    pub fn needs_history(&self, frame: usize) -> bool {
        frame > 0 && !matches!(self.last, Some(l) if l == frame || l + 1 == frame)
    }

    /// Starts the hold over for `frame` (template at `positions`): for each triangle
    /// degenerate there, its last valid frame among `frame - 1, frame - 2, …, 0`, whose
    /// positions `earlier` gives, stopping as soon as every such triangle has one. Results
    /// then do not depend on where a run starts (shards, `--resume`).
    ///
    /// # Errors
    /// What `earlier` returns; a deformation error naming the frame.
    pub fn fill_from_history(
        &mut self,
        frame: usize,
        positions: &[DVec3],
        label: &str,
        mut earlier: impl FnMut(usize) -> Result<Vec<DVec3>, PipelineError>,
    ) -> Result<(), PipelineError> {
        self.hold = FrameHold::new();
        let mut wanted = self
            .deformer
            .degenerate_triangles(positions)
            .map_err(deform_error(label, frame))?;
        let mut f = frame;
        while !wanted.is_empty() && f > 0 {
            f -= 1;
            let p = earlier(f)?;
            wanted = self
                .deformer
                .fill_hold(&p, &mut self.hold, &wanted)
                .map_err(deform_error(label, f))?;
        }
        self.last = frame.checked_sub(1);
        Ok(())
    }
}

/// What an [`Engine`] is built from.
#[derive(Clone, Copy, Debug)]
pub struct EngineInputs<'a> {
    /// The deformation mode.
    pub mode: Mode,
    /// The template as stored (`lbs` checks it against the skinned rest pose).
    pub stored: &'a TriMesh,
    /// The template the Gaussians are deformed on (welded at its seams in the main job).
    pub welded: &'a WeldedTemplate,
    /// The local origin the templates are relative to (`lbs` moves its palettes there).
    pub origin: DVec3,
    /// The template file, for messages.
    pub template_path: &'a Path,
    /// The Gaussians file, for messages (empty when bound here).
    pub gaussians_path: &'a Path,
    /// The animation's label, for messages.
    pub label: &'a str,
    /// Scale Gaussians by √(area ratio) of their triangle (binding and lbs).
    pub adaptive_scale: bool,
}

impl Engine {
    /// Forgets the frames deformed so far: the next frame deformed starts as the first of a
    /// run (after frames deformed out of order for another purpose, such as sampling poses).
    pub fn restart(&mut self) {
        if let Self::Frames(e) = self {
            e.hold = FrameHold::new();
            e.last = None;
        }
    }

    /// The engine of `inputs.mode` for `set` on the welded template; `lbs` checks the stored
    /// template against the animation's skinned rest pose and skins each welded vertex with
    /// its first copy.
    ///
    /// # Errors
    /// Gaussians that do not fit the template (bindings, local parameters), `lbs` without a
    /// skinned glTF animation, `--adaptive-scale` with `jacobian`.
    pub fn build(
        inputs: &EngineInputs<'_>,
        animation: &Animation,
        set: &GaussianSet,
    ) -> Result<Self, PipelineError> {
        let template = &inputs.welded.mesh;
        if inputs.mode != Mode::Lbs {
            if inputs.adaptive_scale && inputs.mode == Mode::Jacobian {
                return Err(PipelineError::BadCombination {
                    problem: "--adaptive-scale: jacobian mode already carries the area change \
                              in J; use it with binding or lbs",
                });
            }
            let mut d = Deformer::new(template, deform_mode(inputs.mode));
            if inputs.adaptive_scale {
                d = d.with_adaptive_scale(template);
            }
            check_set(&d, set, inputs.gaussians_path, inputs.template_path)?;
            return Ok(Self::Frames(FrameEngine {
                deformer: d,
                hold: FrameHold::new(),
                last: None,
            }));
        }
        let a_path = PathBuf::from(inputs.label);
        let g = skinned_gltf(
            animation,
            inputs.stored,
            inputs.origin,
            inputs.template_path,
            inputs.label,
        )?;
        let palette = to_local_palette(g.palette_at(None)?, inputs.origin);
        let skinning = inputs
            .welded
            .skinning(&g.skinning())
            .ok_or(PipelineError::Lbs {
                path: a_path.clone(),
                problem: "the skin's vertex count differs from the template's".to_owned(),
            })?;
        let rig = LbsDeformer::new(set, template, &skinning, &palette).map_err(|source| {
            PipelineError::Skinning {
                path: a_path,
                frame: 0,
                cause: source,
            }
        })?;
        Ok(Self::Lbs(
            Box::new(if inputs.adaptive_scale {
                rig.with_adaptive_scale(template)
            } else {
                rig
            }),
            inputs.origin,
        ))
    }

    /// The deformed means of animation frame `frame` (template positions `positions`) into
    /// `scratch`, reused from frame to frame: only the geometry is computed in `binding` and
    /// `jacobian` modes (no SH copied); `lbs` deforms the whole set.
    ///
    /// # Errors
    /// As [`Engine::deform`].
    pub fn deform_means(
        &mut self,
        animation: &Animation,
        set: &GaussianSet,
        positions: &[DVec3],
        frame: usize,
        label: &str,
        scratch: &mut WorldGeometry,
    ) -> Result<Collapsed, PipelineError> {
        match self {
            Self::Frames(e) => {
                let collapsed = e
                    .deformer
                    .deform_geometry_held(set, positions, &mut e.hold, scratch)
                    .map_err(deform_error(label, frame))?;
                e.last = Some(frame);
                Ok(collapsed)
            }
            Self::Lbs(..) => {
                let (world, collapsed) = self.deform(animation, set, positions, frame, label)?;
                scratch.means.clear();
                scratch.means.extend_from_slice(world.means());
                Ok(collapsed)
            }
        }
    }

    /// The world-space Gaussians of animation frame `frame`, whose template positions are
    /// `positions` (used by `lbs` only for its adaptive scale), and the frame's collapsed
    /// triangles (none in `lbs`); `label` names the animation in errors. Frames are expected
    /// in order: see [`FrameEngine::needs_history`].
    ///
    /// # Errors
    /// [`PipelineError::Deform`] or [`PipelineError::Skinning`] naming the frame; an animation
    /// error evaluating the palette.
    pub fn deform(
        &mut self,
        animation: &Animation,
        set: &GaussianSet,
        positions: &[DVec3],
        frame: usize,
        label: &str,
    ) -> Result<(GaussianSet, Collapsed), PipelineError> {
        match self {
            Self::Frames(e) => {
                let out = e
                    .deformer
                    .deform_held(set, positions, &mut e.hold)
                    .map_err(deform_error(label, frame))?;
                e.last = Some(frame);
                Ok(out)
            }
            Self::Lbs(rig, origin) => {
                let Animation::Gltf(g) = animation else {
                    return Err(PipelineError::Internal {
                        what: "lbs engine without a glTF animation",
                    });
                };
                let palette = to_local_palette(g.frame_palette(frame)?, *origin);
                let positions = rig.adaptive_scale().then_some(positions);
                rig.deform(set, &palette, positions)
                    .map(|set| (set, Collapsed::default()))
                    .map_err(|source| PipelineError::Skinning {
                        path: PathBuf::from(label),
                        frame,
                        cause: source,
                    })
            }
        }
    }
}

/// A deformation error of frame `frame` of the animation `label`.
fn deform_error(label: &str, frame: usize) -> impl FnOnce(DeformError) -> PipelineError + '_ {
    move |cause| PipelineError::Deform {
        path: label.to_owned(),
        frame,
        cause,
    }
}

/// Skinning matrices `M` (rest to posed, world coordinates) for positions relative to
/// `origin`: `x ↦ M (x + origin) − origin`, in f64.
fn to_local_palette(mut palette: Vec<DMat4>, origin: DVec3) -> Vec<DMat4> {
    if origin != DVec3::ZERO {
        for m in &mut palette {
            let t = m.transform_point3(origin) - origin;
            m.w_axis = t.extend(1.0);
        }
    }
    palette
}

/// The skinned glTF of an `lbs` run: `animation` must be a glTF with a skin, and `template`
/// (read from `template_path`, relative to `origin`) its rest shape within
/// [`LBS_REST_TOLERANCE`]; `label` names the animation.
///
/// # Errors
/// [`PipelineError::Lbs`] naming the animation or the template.
pub fn skinned_gltf<'a>(
    animation: &'a Animation,
    template: &TriMesh,
    origin: DVec3,
    template_path: &Path,
    label: &str,
) -> Result<&'a GltfTemplate, PipelineError> {
    let lbs = |path: &Path, problem: String| PipelineError::Lbs {
        path: path.to_path_buf(),
        problem,
    };
    let Animation::Gltf(g) = animation else {
        return Err(lbs(
            Path::new(label),
            "lbs mode needs a skinned glTF animation".to_owned(),
        ));
    };
    if !g.is_skinned() {
        return Err(lbs(
            Path::new(label),
            "lbs mode needs a skinned glTF (this file has no skin with joint weights)".to_owned(),
        ));
    }
    let rest = g.rest().positions();
    if rest.len() != template.vertex_count() {
        return Err(lbs(
            template_path,
            format!(
                "the template has {} vertices, the rest pose of {label} has {}",
                template.vertex_count(),
                rest.len()
            ),
        ));
    }
    let diag = template.bounds().map_or(0.0, |b| b.diagonal());
    let worst = template
        .positions()
        .iter()
        .zip(rest)
        .map(|(a, b)| (*a + origin - *b).length())
        .fold(0.0, f64::max);
    if worst > LBS_REST_TOLERANCE * diag.max(f64::MIN_POSITIVE) {
        return Err(lbs(
            template_path,
            format!(
                "the template's positions differ from the rest pose of {label} by up to \
                 {worst:.3e}; lbs needs the template to be the animation's rest shape (e.g. \
                 the same file)"
            ),
        ));
    }
    Ok(g)
}
