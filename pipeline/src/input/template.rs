//! The template: read in the frames' space, checked against them (scale, topology) and welded
//! at its seams.

use std::path::Path;

use glam::DVec3;
use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate, VertexSkinning};
use trisplat_geometry::cleanup::weld_vertices;
use trisplat_geometry::io::read_mesh;
use trisplat_geometry::{TriMesh, bounding_sphere};

use crate::error::PipelineError;

/// Reads the template in world space, as the animation evaluates it.
///
pub(super) fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

pub(super) fn is_gltf(path: &Path) -> bool {
    matches!(extension(path).as_str(), "gltf" | "glb")
}

/// A glTF/GLB template is its stored scene posed as [`GltfTemplate`] poses it: node transforms,
/// skins and the meshes' default morph weights applied (glTF 2.0: a skinned mesh is placed
/// by its joints and ignores its own node's transform). The static reader
/// ([`read_mesh`], like trimesh) applies the node transform to a skinned mesh instead, which
/// puts a mesh whose node scales it and whose joints scale it back (LAM's `skin.glb`: node
/// scale 0.01) at another scale than every frame of its animation; binding, the
/// scale-derived defaults and `lbs` all need the frames' space. Other formats are read as
/// stored.
///
/// # Errors
/// An unreadable file (named).
pub fn read_template(path: &Path) -> Result<TriMesh, PipelineError> {
    if is_gltf(path) {
        let g = GltfTemplate::open(path, &Clip::None)?;
        return Ok(g.rest().clone());
    }
    Ok(read_mesh(path)?)
}

/// Largest ratio, either way, between the bounding radius of the first frame meshed and that
/// of the template before a run refuses the pair as being at different scales. A pose moves
/// the radius (about the box centre) by far less (CesiumMan's walk: within 5% of its rest
/// pose's); a change of units by far more (cm/m: 100, inch/m: 39.4, mm/m: 1000).
pub const SCALE_MISMATCH: f64 = 10.0;

/// Checks that `frame` (the positions of animation frame `index`, named by `label`) is at the
/// scale of `template` (read from `template_path`): their bounding radii differ by at most
/// [`SCALE_MISMATCH`] either way. The scale-derived defaults (TSDF voxel, alpha) come from the
/// template; frames at another scale would get a voxel or an alpha that many times off.
///
/// # Errors
/// [`PipelineError::ScaleMismatch`]; [`PipelineError::Topology`] for a frame without finite
/// positions.
pub fn check_scale(
    template: &TriMesh,
    template_path: &Path,
    frame: &[DVec3],
    index: usize,
    label: &str,
) -> Result<(), PipelineError> {
    let radius = |vertices: &[DVec3]| bounding_sphere(vertices, &[]).map(|(_, r)| r);
    let (Some(template_radius), Some(frame_radius)) = (radius(template.positions()), radius(frame))
    else {
        return Err(PipelineError::Topology {
            animation: label.to_owned(),
            problem: format!(
                "frame {index} or the template {} has no finite vertex",
                template_path.display()
            ),
        });
    };
    let ratio = frame_radius / template_radius;
    if (1.0 / SCALE_MISMATCH..=SCALE_MISMATCH).contains(&ratio) {
        return Ok(());
    }
    Err(PipelineError::ScaleMismatch {
        animation: label.to_owned(),
        template: template_path.to_path_buf(),
        frame: index,
        frame_radius,
        template_radius,
        ratio,
    })
}

/// Checks that the animation's frames have the vertices and triangles of `template` (read
/// from `template_path`); `label` names the animation.
///
/// # Errors
/// [`PipelineError::Topology`] naming the first difference.
pub fn check_topology(
    template: &TriMesh,
    template_path: &Path,
    anim: &dyn AnimatedTemplate,
    label: &str,
) -> Result<(), PipelineError> {
    let rest = anim.rest();
    let err = |problem: String| PipelineError::Topology {
        animation: label.to_owned(),
        problem,
    };
    if rest.vertex_count() != template.vertex_count() {
        return Err(err(format!(
            "the animation has {} vertices, the template {} has {}",
            rest.vertex_count(),
            template_path.display(),
            template.vertex_count()
        )));
    }
    if rest.triangles() != template.triangles() {
        let first = rest
            .triangles()
            .iter()
            .zip(template.triangles())
            .position(|(x, y)| x != y)
            .unwrap_or(rest.triangle_count().min(template.triangle_count()));
        return Err(err(format!(
            "the animation's triangles differ from those of the template {} (triangle {first}; \
             {} vs {} triangles)",
            template_path.display(),
            rest.triangle_count(),
            template.triangle_count()
        )));
    }
    Ok(())
}

/// The template with its duplicated vertices welded by position (tolerance 0: equal
/// positions; see [`weld_vertices`]).
///
/// glTF (and OBJ) files split a vertex wherever its UV or normal changes, so a closed surface
/// is stored as open patches (CesiumMan: 3,273 vertices, 2,338 positions). Meshing the
/// welded template makes the methods' output watertight wherever the surface is (the
/// incremental Delaunay is watertight whenever its template is). Triangles keep their order,
/// so Gaussian bindings to triangle ids stay valid.
///
/// Each frame of the animation is stored per original vertex; a welded vertex takes the
/// position of its first (lowest-index) original vertex. Duplicates of a seam share their
/// position in the rest pose; where an animation moved them apart (copies skinned or morphed
/// differently), the seam is pinned to the first copy. `lbs` skins a welded vertex with the
/// first copy's weights, for the same reason.
#[derive(Clone, Debug)]
pub struct WeldedTemplate {
    /// The welded template.
    pub mesh: TriMesh,
    /// For each welded vertex, its first original vertex.
    pub first: Vec<u32>,
    /// For each original vertex, its welded vertex.
    pub of_stored: Vec<u32>,
    /// Vertices of the template as stored.
    pub stored_vertices: usize,
}

impl WeldedTemplate {
    /// Welds `template` by position.
    #[must_use]
    pub fn new(template: &TriMesh) -> Self {
        let (mesh, map) = weld_vertices(template, 0.0);
        let mut first = Vec::with_capacity(mesh.vertex_count());
        for (old, &new) in map.iter().enumerate() {
            if new as usize == first.len() {
                first.push(old as u32);
            }
        }
        Self {
            mesh,
            first,
            of_stored: map,
            stored_vertices: template.vertex_count(),
        }
    }

    /// `template` as stored, nothing welded (`trisplat deform` writes Gaussians deformed on
    /// the stored template).
    #[must_use]
    pub fn unwelded(template: &TriMesh) -> Self {
        let n = u32::try_from(template.vertex_count()).unwrap_or(u32::MAX);
        Self {
            mesh: template.clone(),
            first: (0..n).collect(),
            of_stored: (0..n).collect(),
            stored_vertices: template.vertex_count(),
        }
    }

    /// Whether welding merged any vertex.
    #[must_use]
    pub fn merged(&self) -> bool {
        self.first.len() != self.stored_vertices
    }

    /// A frame's positions (one per original vertex) on the welded vertices. `None` when the
    /// frame does not have the stored template's vertex count.
    #[must_use]
    pub fn positions(&self, frame: Vec<DVec3>) -> Option<Vec<DVec3>> {
        if frame.len() != self.stored_vertices {
            return None;
        }
        if !self.merged() {
            return Some(frame);
        }
        Some(self.first.iter().map(|&v| frame[v as usize]).collect())
    }

    /// Skin weights of the original vertices on the welded vertices (each welded vertex takes
    /// its first copy's row). `None` when `skinning` does not have the stored vertex count.
    #[must_use]
    pub fn skinning(&self, skinning: &VertexSkinning) -> Option<VertexSkinning> {
        if skinning.offsets.len() != self.stored_vertices + 1
            || skinning.base_positions.len() != self.stored_vertices
        {
            return None;
        }
        let mut out = VertexSkinning {
            offsets: Vec::with_capacity(self.first.len() + 1),
            palette_len: skinning.palette_len,
            ..VertexSkinning::default()
        };
        out.offsets.push(0);
        for &v in &self.first {
            let v = v as usize;
            let (a, b) = (
                skinning.offsets[v] as usize,
                skinning.offsets[v + 1] as usize,
            );
            out.entries.extend_from_slice(skinning.entries.get(a..b)?);
            out.weights.extend_from_slice(skinning.weights.get(a..b)?);
            out.offsets.push(u32::try_from(out.entries.len()).ok()?);
            out.base_positions.push(skinning.base_positions[v]);
        }
        Some(out)
    }
}
