//! Avatars in LAM's layout (docs/conventions.md §4, "LAM avatars"): a folder holding
//! `skin.glb` (the head mesh with its ARKit morph targets and skin), `offset.ply` (one Gaussian
//! per mesh vertex) and `vertex_order.json`, as exported by LAM (aigc3d/LAM, `save_ply(...,
//! offset2xyz=True)`) for its web renderer.
//!
//! What the files mean, established from LAM's exporter and pinned by tests on a cut-down LAM
//! avatar (`fixtures/data/lam_mini`):
//! - Row `i` of `offset.ply` belongs to vertex `i` of `skin.glb`, in the order the glTF stores
//!   them. Its `x, y, z` are not a position but the Gaussian's offset from that vertex in the
//!   mesh's rest frame (LAM animates `vertex + offset` by the vertex's skinning; the offsets
//!   are within ±0.1 m, LAM's `xyz_offset_max_step`).
//! - `f_dc_0..2` hold the colour as RGB in [0, 1] (LAM predicts RGB and exports it with
//!   `rgb2sh=False`), not degree-0 spherical-harmonic coefficients; they are converted here.
//! - Opacity (logit), log-scales and `rot_0..3` (w, x, y, z) are as in any 3DGS PLY, in the
//!   rest frame (LAM does not rotate its Gaussians when it animates them).
//! - `vertex_order.json` is the order of the mesh's vertices sorted by height, which LAM's
//!   exporter computes for its web renderer; it is not a map between the two files (mapping
//!   through it scatters neighbouring offsets, see the tests). It is checked to be a
//!   permutation of the vertices and otherwise unused.
//!
//! Bound here, each Gaussian goes to a triangle around its vertex
//! ([`trisplat_splat::attach_to_vertices`]), so it follows that part of the mesh in every
//! deformation mode; at rest the bound set renders exactly the Gaussians LAM placed.

use std::path::{Path, PathBuf};

use trisplat_geometry::TriMesh;
use trisplat_geometry::mesh_render::{MeshRenderOptions, MeshRenderer};
use trisplat_geometry::sphere_rig;
use trisplat_splat::Convention;
use trisplat_splat::attach_to_vertices;
use trisplat_splat::ply::read_gaussians;
use trisplat_splat::render::{Outputs, RenderOptions, render};
use trisplat_splat::rgb_to_dc;
use trisplat_splat::{GaussianSet, ParameterSpace};

use crate::error::PipelineError;

/// The template of a LAM avatar folder.
pub const LAM_TEMPLATE: &str = "skin.glb";
/// The per-vertex Gaussians of a LAM avatar folder.
pub const LAM_GAUSSIANS: &str = "offset.ply";
/// The vertex order file of a LAM avatar folder.
pub const LAM_VERTEX_ORDER: &str = "vertex_order.json";

/// The files of a LAM avatar folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AvatarFolder {
    /// `skin.glb`.
    pub template: PathBuf,
    /// `offset.ply`.
    pub gaussians: PathBuf,
}

impl AvatarFolder {
    /// The LAM avatar in folder `dir`.
    ///
    /// # Errors
    /// [`PipelineError::Avatar`] when `dir` is not a folder or lacks `skin.glb` or
    /// `offset.ply`.
    pub fn open(dir: &Path) -> Result<Self, PipelineError> {
        let bad = |problem: String| PipelineError::Avatar {
            path: dir.to_path_buf(),
            problem,
        };
        if !dir.is_dir() {
            return Err(bad(
                "not a folder (an avatar folder holds skin.glb and offset.ply, as LAM exports)"
                    .into(),
            ));
        }
        let template = dir.join(LAM_TEMPLATE);
        let gaussians = dir.join(LAM_GAUSSIANS);
        let missing: Vec<&str> = [(&template, LAM_TEMPLATE), (&gaussians, LAM_GAUSSIANS)]
            .into_iter()
            .filter(|(p, _)| !p.is_file())
            .map(|(_, name)| name)
            .collect();
        if !missing.is_empty() {
            return Err(bad(format!(
                "no {} (a LAM avatar folder holds {LAM_TEMPLATE} and {LAM_GAUSSIANS})",
                missing.join(" and ")
            )));
        }
        Ok(Self {
            template,
            gaussians,
        })
    }

    /// Whether `dir` is a folder holding a LAM avatar (what [`AvatarFolder::open`] accepts).
    #[must_use]
    pub fn is_avatar(dir: &Path) -> bool {
        dir.is_dir() && dir.join(LAM_TEMPLATE).is_file() && dir.join(LAM_GAUSSIANS).is_file()
    }
}

/// LAM's per-vertex Gaussians from `path` as world-space Gaussians on `stored` (the template
/// as its file stores it, in world space at rest): each mean is its vertex plus its offset,
/// colours converted from RGB to SH. A `vertex_order.json` beside `path` is checked.
///
/// # Errors
/// An unreadable file; [`PipelineError::Avatar`] naming the file when it is already bound,
/// its row count is not the template's vertex count, or `vertex_order.json` is not a
/// permutation of the vertices.
pub fn read_lam_gaussians(
    path: &Path,
    stored: &TriMesh,
    template_path: &Path,
) -> Result<GaussianSet, PipelineError> {
    let bad = |problem: String| PipelineError::Avatar {
        path: path.to_path_buf(),
        problem,
    };
    let set = read_gaussians(path)?;
    if set.binding().is_some() || set.space() != ParameterSpace::World {
        return Err(bad(
            "already bound to triangles (binding_0): not LAM's per-vertex layout; read it \
             with --layout bound"
                .into(),
        ));
    }
    let n = stored.vertex_count();
    if set.len() != n {
        return Err(bad(format!(
            "{} Gaussians, but the template {} has {n} vertices (LAM's layout has one \
             Gaussian per vertex, row i for vertex i)",
            set.len(),
            template_path.display()
        )));
    }
    if let Some(order) = path.parent().map(|d| d.join(LAM_VERTEX_ORDER))
        && order.is_file()
    {
        check_vertex_order(&order, n)?;
    }
    let mut parts = set.into_parts();
    for (mean, vertex) in parts.means.iter_mut().zip(stored.positions()) {
        *mean = (mean.as_dvec3() + *vertex).as_vec3();
    }
    let coeffs = parts.sh.len() / n.max(1);
    for g in 0..n {
        for c in 0..3 {
            let dc = &mut parts.sh[g * coeffs + c];
            *dc = rgb_to_dc(*dc);
        }
    }
    GaussianSet::try_new(parts).map_err(|e| bad(e.to_string()))
}

/// Binds LAM's per-vertex Gaussians in `path` to `template` (triangles in the order of
/// `stored`, whose vertex `v` is `template`'s vertex `vertex_map[v]`, as welding leaves them).
///
/// # Errors
/// As [`read_lam_gaussians`]; [`PipelineError::Bind`] naming the template.
pub fn bind_lam(
    path: &Path,
    stored: &TriMesh,
    template: &TriMesh,
    vertex_map: &[u32],
    template_path: &Path,
    convention: Convention,
) -> Result<GaussianSet, PipelineError> {
    let world = read_lam_gaussians(path, stored, template_path)?;
    attach_to_vertices(&world, template, vertex_map, convention).map_err(|cause| {
        PipelineError::Bind {
            path: template_path.to_path_buf(),
            cause,
        }
    })
}

/// Checks that `path` holds a JSON array that is a permutation of `0..n`.
fn check_vertex_order(path: &Path, n: usize) -> Result<(), PipelineError> {
    let bad = |problem: String| PipelineError::Avatar {
        path: path.to_path_buf(),
        problem,
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(format!("cannot read: {e}")))?;
    let order: Vec<u64> = serde_json::from_str(&text)
        .map_err(|e| bad(format!("not a JSON array of indices: {e}")))?;
    if order.len() != n {
        return Err(bad(format!(
            "{} entries, but the template has {n} vertices",
            order.len()
        )));
    }
    let mut seen = vec![false; n];
    for (i, &v) in order.iter().enumerate() {
        match usize::try_from(v).ok().and_then(|v| seen.get_mut(v)) {
            Some(s) if !*s => *s = true,
            Some(_) => return Err(bad(format!("entry {i}: vertex {v} appears twice"))),
            None => {
                return Err(bad(format!(
                    "entry {i}: vertex {v} out of range (the template has {n} vertices)"
                )));
            }
        }
    }
    Ok(())
}

/// How the silhouettes of Gaussians and a mesh agree in one view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Silhouettes {
    /// Intersection over union.
    pub iou: f64,
    /// Share of the Gaussians' silhouette inside the mesh's (1: nothing outside the mesh).
    pub inside: f64,
    /// Share of the mesh's silhouette the Gaussians cover (1: no part of the mesh bare).
    pub covered: f64,
}

/// Silhouette agreement per view of `world` (world-space Gaussians, e.g. a bound avatar deformed at
/// rest) against `mesh`: both rendered from `views` cameras spread over a sphere around the
/// mesh ([`sphere_rig`], framing its bounding sphere, `resolution`² pixels, 40° field of
/// view); a pixel is inside the Gaussians' silhouette where their alpha is at least 0.5, inside
/// the mesh's where a ray hits it. 1 means the Gaussians cover exactly the mesh's outline.
///
/// # Errors
/// [`PipelineError::Avatar`] naming `label` when the mesh is empty or cannot be indexed, or a
/// render fails.
pub fn silhouette_iou(
    world: &GaussianSet,
    mesh: &TriMesh,
    views: usize,
    resolution: u32,
    label: &Path,
) -> Result<Vec<Silhouettes>, PipelineError> {
    let bad = |problem: String| PipelineError::Avatar {
        path: label.to_path_buf(),
        problem,
    };
    let bounds = mesh
        .bounds()
        .ok_or_else(|| bad("the template has no vertices".into()))?;
    let center = (bounds.min + bounds.max) * 0.5;
    let radius = mesh
        .positions()
        .iter()
        .map(|p| p.distance(center))
        .fold(0.0, f64::max);
    let cameras = sphere_rig(center, radius, views, (resolution, resolution), 40.0)
        .map_err(|e| bad(format!("cameras: {e}")))?;
    let caster = MeshRenderer::new(mesh, MeshRenderOptions::default())
        .map_err(|e| bad(format!("indexing the template: {e}")))?;
    let options = RenderOptions {
        outputs: Outputs {
            alpha: true,
            ..Outputs::NONE
        },
        ..RenderOptions::default()
    };
    cameras
        .iter()
        .map(|camera| {
            let splats = render(world, camera, &options)
                .map_err(|e| bad(format!("rendering {}: {e}", camera.name)))?;
            let alpha = splats.images.alpha.unwrap_or_default();
            let hits = caster.render(camera).mask;
            let (mut both, mut either, mut splats, mut mesh) = (0usize, 0usize, 0usize, 0usize);
            for (a, m) in alpha.iter().zip(&hits) {
                let (a, m) = (*a >= 0.5, *m > 0.5);
                both += usize::from(a && m);
                either += usize::from(a || m);
                splats += usize::from(a);
                mesh += usize::from(m);
            }
            let share = |part: usize, whole: usize| {
                if whole == 0 {
                    1.0
                } else {
                    part as f64 / whole as f64
                }
            };
            Ok(Silhouettes {
                iou: share(both, either),
                inside: share(both, splats),
                covered: share(both, mesh),
            })
        })
        .collect()
}
