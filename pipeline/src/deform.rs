//! Deforming bound Gaussians to the frames of an animation: the engine shared by
//! `trisplat deform` and the main job.

use std::path::{Path, PathBuf};

use glam::Vec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{AnimatedTemplate, GltfTemplate};
use trisplat_splat::GaussianSet;
use trisplat_splat::deform::Deformer;
use trisplat_splat::lbs::LbsDeformer;
use trisplat_splat::ply::read_gaussians;

use crate::error::PipelineError;
use crate::input::Animation;

/// Largest difference between the template's positions and a skinned animation's rest pose
/// that `lbs` accepts, relative to the template's bounding-box diagonal (f32 storage of both).
pub const LBS_REST_TOLERANCE: f64 = 1e-5;

/// How frames are deformed.
#[derive(Debug)]
pub enum Engine {
    /// `binding` or `jacobian`: from each frame's template positions.
    Frames(Deformer),
    /// `lbs`: from each frame's skinning palette (the animation is a skinned glTF).
    Lbs(Box<LbsDeformer>),
}

impl Engine {
    /// The world-space Gaussians of animation frame `frame`, whose template positions are
    /// `positions` (used by `lbs` only for its adaptive scale); `label` names the animation
    /// in errors.
    ///
    /// # Errors
    /// [`PipelineError::Deform`] or [`PipelineError::Skinning`] naming the frame; an animation
    /// error evaluating the palette.
    pub fn deform(
        &self,
        animation: &Animation,
        set: &GaussianSet,
        positions: &[Vec3],
        frame: usize,
        label: &str,
    ) -> Result<GaussianSet, PipelineError> {
        match self {
            Self::Frames(d) => d
                .deform(set, positions)
                .map_err(|source| PipelineError::Deform {
                    path: label.to_owned(),
                    frame,
                    cause: source,
                }),
            Self::Lbs(rig) => {
                let Animation::Gltf(g) = animation else {
                    return Err(PipelineError::Internal {
                        what: "lbs engine without a glTF animation",
                    });
                };
                let palette = g.frame_palette(frame)?;
                let positions = rig.adaptive_scale().then_some(positions);
                rig.deform(set, &palette, positions)
                    .map_err(|source| PipelineError::Skinning {
                        path: PathBuf::from(label),
                        frame,
                        cause: source,
                    })
            }
        }
    }
}

/// The skinned glTF of an `lbs` run: `animation` must be a glTF with a skin, and `template`
/// (read from `template_path`) its rest shape within [`LBS_REST_TOLERANCE`]; `label` names the
/// animation.
///
/// # Errors
/// [`PipelineError::Lbs`] naming the animation or the template.
pub fn skinned_gltf<'a>(
    animation: &'a Animation,
    template: &TriMesh,
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
    let diag = f64::from(template.bounds().map_or(0.0, |b| b.diagonal()));
    let worst = template
        .positions()
        .iter()
        .zip(rest)
        .map(|(a, b)| f64::from((*a - *b).length()))
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

/// Reads bound Gaussians from `path` and checks them against `template` (read from
/// `template_path`): they must carry a triangle binding and pass their validity report
/// (finite values, bindings within the template's triangles).
///
/// # Errors
/// An unreadable file, [`PipelineError::NotBound`], [`PipelineError::GaussianIssue`].
pub fn read_bound(
    path: &Path,
    template: &TriMesh,
    template_path: &Path,
) -> Result<GaussianSet, PipelineError> {
    let set = read_gaussians(path)?;
    if set.binding().is_none() {
        return Err(PipelineError::NotBound {
            path: path.to_path_buf(),
        });
    }
    if let Some(issue) = set
        .report(Some(template.triangle_count()))
        .issues
        .into_iter()
        .next()
    {
        return Err(PipelineError::GaussianIssue {
            path: path.to_path_buf(),
            template: template_path.to_path_buf(),
            issue: issue.to_string(),
        });
    }
    Ok(set)
}

/// Checks that `deformer` can deform `set` (bindings within its template, local parameters).
///
/// # Errors
/// [`PipelineError::Gaussians`] naming both files.
pub fn check_set(
    deformer: &Deformer,
    set: &GaussianSet,
    path: &Path,
    template_path: &Path,
) -> Result<(), PipelineError> {
    deformer
        .check(set)
        .map_err(|source| PipelineError::Gaussians {
            path: path.to_path_buf(),
            template: template_path.to_path_buf(),
            cause: source,
        })
}
