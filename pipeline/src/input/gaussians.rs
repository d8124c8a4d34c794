//! The Gaussians of a run: read bound from a file or bound here, checked against the
//! template, and the deform mode they follow.

use std::path::{Path, PathBuf};

use trisplat_geometry::TriMesh;
use trisplat_splat::Convention;
use trisplat_splat::GaussianSet;
use trisplat_splat::ply::read_gaussians;
use trisplat_splat::{BindOptions, init_bound};
use trisplat_splat::{DeformMode, Deformer};

use crate::config::{BIND_NORMAL_SCALE, BIND_OPACITY, BIND_TANGENT_SCALE, Mode};
use crate::error::PipelineError;

/// The deform mode of the library for a pipeline mode (`lbs` bakes its rest pose in binding
/// mode).
#[must_use]
pub fn deform_mode(mode: Mode) -> DeformMode {
    match mode {
        Mode::Jacobian => DeformMode::Jacobian,
        Mode::Binding | Mode::Lbs => DeformMode::Binding,
    }
}

/// Where the Gaussians came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GaussianSource {
    /// Read from this bound file.
    File(PathBuf),
    /// Bound here: this many per triangle.
    Bound(u32),
    /// LAM's per-vertex Gaussians read from this file, bound here around their vertices.
    Lam(PathBuf),
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

/// Binds new Gaussians to `template` (read from `template_path`) for `mode`:
/// `per_triangle` per triangle, opaque flat discs (see [`BIND_OPACITY`] and
/// [`BIND_NORMAL_SCALE`]), in the GaussianAvatars convention, or SurFhead's for `jacobian`.
///
/// # Errors
/// [`PipelineError::Bind`] naming the template.
pub fn bind_here(
    template: &TriMesh,
    template_path: &Path,
    mode: Mode,
    per_triangle: u32,
) -> Result<GaussianSet, PipelineError> {
    let convention = if mode == Mode::Jacobian {
        Convention::SurfHead
    } else {
        Convention::GaussianAvatars
    };
    let options = BindOptions {
        per_triangle: per_triangle as usize,
        convention,
        opacity: BIND_OPACITY,
    };
    let set = init_bound(template, &options).map_err(|source| PipelineError::Bind {
        path: template_path.to_path_buf(),
        cause: source,
    })?;
    Ok(flatten(set, convention))
}

/// Multiplies the local scale along the triangle normal by [`BIND_NORMAL_SCALE`] (local y for
/// GaussianAvatars, local z for SurfHead) and in the plane by [`BIND_TANGENT_SCALE`].
fn flatten(set: GaussianSet, convention: Convention) -> GaussianSet {
    let ln = BIND_NORMAL_SCALE.ln();
    let lt = BIND_TANGENT_SCALE.ln();
    let mut parts = set.into_parts();
    for s in &mut parts.log_scales {
        match convention {
            Convention::GaussianAvatars => {
                s.y += ln;
                s.x += lt;
                s.z += lt;
            }
            Convention::SurfHead => {
                s.z += ln;
                s.x += lt;
                s.y += lt;
            }
        }
    }
    // Only finite log-scales were shifted by a finite amount: the set stays valid.
    GaussianSet::new_unchecked(parts)
}
