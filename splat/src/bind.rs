//! Binding Gaussians to the triangles of a template (docs/conventions.md §4): initialising bound Gaussians on a
//! mesh, and attaching existing world-space Gaussians to their nearest triangle, which turns any
//! 3DGS file plus a template into a bound avatar.
//!
//! Local parameters are expressed in the frame of the convention's triangle frame at the
//! template's current positions (for [`Convention::GaussianAvatars`] the posed frame, for
//! [`Convention::SurfHead`] the canonical frame): `mu_local = R_fᵀ (mu - c_f) / k_f`,
//! `R_local = R_fᵀ R`, `log_s_local = log_s - ln k_f`. Deforming the result with the same
//! template at rest ([`crate::deform`], `binding` mode for GaussianAvatars, `jacobian` mode for
//! SurFhead) gives the world-space Gaussians back.

use glam::{DQuat, Vec3};
use rayon::prelude::*;
use trisplat_geometry::spatial::{TriangleBvh, closest_point_on_triangle};
use trisplat_geometry::{TriId, TriMesh};

use crate::frames::{Convention, FrameOptions, corners_of, frame};
use crate::gaussians::{
    Binding, BindingEncoding, GaussianParts, GaussianSet, ParameterSpace, logit, normalize_wxyz,
    quat_from_rotation, to_wxyz,
};

/// Initial opacity of bound Gaussians (GaussianAvatars: 0.1).
pub const DEFAULT_INITIAL_OPACITY: f32 = 0.1;

/// Options of [`init_bound`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BindOptions {
    /// Gaussians per triangle (GaussianAvatars: 1).
    pub per_triangle: usize,
    /// Frame convention.
    pub convention: Convention,
    /// Initial opacity ([`DEFAULT_INITIAL_OPACITY`]).
    pub opacity: f32,
}

impl Default for BindOptions {
    fn default() -> Self {
        Self {
            per_triangle: 1,
            convention: Convention::GaussianAvatars,
            opacity: DEFAULT_INITIAL_OPACITY,
        }
    }
}

/// Errors of binding.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BindError {
    /// The template has no triangles.
    #[error("the template has no triangles")]
    NoTriangles,
    /// `per_triangle` is 0.
    #[error("at least one Gaussian per triangle is needed")]
    NoGaussians,
    /// Attaching needs world-space Gaussians.
    #[error("the Gaussians are already in local triangle frames")]
    NotWorld,
    /// Nearest-triangle search failed (non-finite or huge means).
    #[error("nearest triangle search: {0}")]
    Search(String),
    /// Too many Gaussians for `u32` triangle ids or counts.
    #[error("too many Gaussians or triangles")]
    TooMany,
    /// A per-vertex attachment's vertex list does not fit the Gaussians or the mesh.
    #[error("per-vertex binding: {0}")]
    VertexMap(String),
    /// The attachment is not plausible (see [`AttachLimits`]): the message names the numbers.
    #[error("{0}")]
    Implausible(String),
}

/// Plausibility limits of [`attach_checked`]: a binding that breaks one is almost always a
/// mistake of units or frames (Gaussians in another coordinate frame than the template, offsets
/// taken for positions), and the avatar it makes is garbage even though every Gaussian has a
/// triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttachLimits {
    /// Largest ratio (either way) of the bounding-box diagonals of the Gaussian means and the
    /// template (3: hair and accessories make real avatars' Gaussians up to ~1.5x their mesh).
    pub max_size_ratio: f64,
    /// Largest median distance from a Gaussian centre to its triangle, in mean template edge
    /// lengths (25: LAM's real Gaussians sit a median 7.5 edges off their dense head mesh).
    pub max_median_distance_edges: f64,
    /// Largest share of all Gaussians on one triangle (0.25), checked from 64 Gaussians and 16
    /// triangles up.
    pub max_triangle_share: f64,
}

impl Default for AttachLimits {
    fn default() -> Self {
        Self {
            max_size_ratio: 3.0,
            max_median_distance_edges: 25.0,
            max_triangle_share: 0.25,
        }
    }
}

/// What [`attach_checked`] measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttachStats {
    /// Bounding-box diagonal of the Gaussian means over the template's.
    pub size_ratio: f64,
    /// Median distance from a centre to its triangle, in mean template edge lengths.
    pub median_distance_edges: f64,
    /// Largest share of the Gaussians bound to one triangle, and that triangle.
    pub triangle_share: (f64, u32),
}

/// The `j`-th of `n` sample points in a triangle, as (u, v) weights of the edges `v1 - v0`,
/// `v2 - v0`: the centroid for `n = 1`, else a Kronecker (R2) sequence folded into the triangle.
fn sample_uv(j: usize, n: usize) -> (f64, f64) {
    if n == 1 {
        return (1.0 / 3.0, 1.0 / 3.0);
    }
    // R2 sequence constants (plastic number).
    const A1: f64 = 0.754_877_666_246_692_8;
    const A2: f64 = 0.569_840_290_998_053_3;
    let u = (0.5 + A1 * (j as f64 + 1.0)).fract();
    let v = (0.5 + A2 * (j as f64 + 1.0)).fract();
    if u + v > 1.0 {
        (1.0 - u, 1.0 - v)
    } else {
        (u, v)
    }
}

/// Bound Gaussians on every triangle of `mesh` (docs/conventions.md §4 init): `per_triangle` per triangle (the
/// centroid for one, spread points otherwise), local scale 1 (log-scale `-½ ln per_triangle`
/// so the set covers the same area), identity rotation, the given opacity, grey SH degree 0.
///
/// # Errors
/// [`BindError::NoTriangles`], [`BindError::NoGaussians`], [`BindError::TooMany`].
pub fn init_bound(mesh: &TriMesh, options: &BindOptions) -> Result<GaussianSet, BindError> {
    let tris = mesh.triangles();
    if tris.is_empty() {
        return Err(BindError::NoTriangles);
    }
    let per = options.per_triangle;
    if per == 0 {
        return Err(BindError::NoGaussians);
    }
    let n = tris.len().checked_mul(per).ok_or(BindError::TooMany)?;
    if u32::try_from(tris.len()).is_err() || u32::try_from(n).is_err() {
        return Err(BindError::TooMany);
    }
    let fo = FrameOptions::for_positions(mesh.positions());
    let means: Vec<Vec3> = (0..n)
        .into_par_iter()
        .map(|g| {
            let (t, j) = (g / per, g % per);
            let v = corners_of(mesh.positions(), tris[t]);
            let f = frame(options.convention, v, &fo);
            let (u, w) = sample_uv(j, per);
            let p = v[0] + (v[1] - v[0]) * u + (v[2] - v[0]) * w;
            (f.rotation.transpose() * (p - f.origin) / f.scale).as_vec3()
        })
        .collect();
    let log_s = (-0.5 * (per as f64).ln()) as f32;
    let parts = GaussianParts {
        means,
        log_scales: vec![Vec3::splat(log_s); n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacity_logits: vec![logit(options.opacity); n],
        sh: vec![0.0; 3 * n],
        binding: Some(Binding {
            triangles: (0..n).map(|g| TriId((g / per) as u32)).collect(),
            encoding: BindingEncoding::Float,
        }),
        space: ParameterSpace::Local,
        ..GaussianParts::default()
    };
    Ok(GaussianSet::new_unchecked(parts))
}

/// Attaches world-space Gaussians to their nearest triangle of `mesh` (closest point on the
/// surface, BVH) and expresses them in that triangle's frame. Colour, opacity, extras and the
/// property order are kept; the binding is written as `binding_0`.
///
/// # Errors
/// [`BindError::NotWorld`], [`BindError::NoTriangles`], [`BindError::Search`].
pub fn attach(
    world: &GaussianSet,
    mesh: &TriMesh,
    convention: Convention,
) -> Result<GaussianSet, BindError> {
    attach_with_distances(world, mesh, convention).map(|(set, _)| set)
}

/// [`attach`], refused when the result is implausible (see [`AttachLimits`]); returns the
/// bound set and what was measured.
///
/// # Errors
/// As [`attach`], and [`BindError::Implausible`] naming the number that broke its limit.
pub fn attach_checked(
    world: &GaussianSet,
    mesh: &TriMesh,
    convention: Convention,
    limits: &AttachLimits,
) -> Result<(GaussianSet, AttachStats), BindError> {
    let (set, distances) = attach_with_distances(world, mesh, convention)?;
    let stats = attach_stats(world, mesh, &set, distances);
    let n = world.len();
    if stats.size_ratio > limits.max_size_ratio || stats.size_ratio < 1.0 / limits.max_size_ratio {
        return Err(BindError::Implausible(format!(
            "the Gaussians span {:.3}x the template's bounding-box diagonal (limit {}x either \
             way): are they in the template's units and coordinate frame?",
            stats.size_ratio, limits.max_size_ratio
        )));
    }
    if stats.median_distance_edges > limits.max_median_distance_edges {
        return Err(BindError::Implausible(format!(
            "the median Gaussian centre lies {:.1} mean template edges from its triangle (limit \
             {}): are the Gaussians placed on this template?",
            stats.median_distance_edges, limits.max_median_distance_edges
        )));
    }
    let (share, triangle) = stats.triangle_share;
    if n >= 64 && mesh.triangle_count() >= 16 && share > limits.max_triangle_share {
        return Err(BindError::Implausible(format!(
            "{:.1}% of the {n} Gaussians bind to triangle {triangle} alone (limit {}%): the \
             Gaussians are not spread over the template",
            100.0 * share,
            100.0 * limits.max_triangle_share
        )));
    }
    Ok((set, stats))
}

/// The plausibility numbers of an attachment (`distances`: each centre to its triangle).
fn attach_stats(
    world: &GaussianSet,
    mesh: &TriMesh,
    bound: &GaussianSet,
    mut distances: Vec<f64>,
) -> AttachStats {
    let diagonal = |b: Option<trisplat_geometry::Aabb>| b.map_or(0.0, |b| b.diagonal());
    let template = diagonal(mesh.bounds());
    let gaussians = diagonal(trisplat_geometry::Aabb::from_points(world.means()));
    let size_ratio = if template > 0.0 {
        gaussians / template
    } else {
        1.0
    };
    let (edge_sum, edges) = mesh.triangles().iter().fold((0.0, 0usize), |(s, n), t| {
        let [a, b, c] = corners_of(mesh.positions(), *t);
        (
            s + (b - a).length() + (c - b).length() + (a - c).length(),
            n + 3,
        )
    });
    let mean_edge = if edges > 0 {
        edge_sum / edges as f64
    } else {
        0.0
    };
    distances.sort_by(f64::total_cmp);
    let median = distances.get(distances.len() / 2).copied().unwrap_or(0.0);
    let median_distance_edges = if mean_edge > 0.0 {
        median / mean_edge
    } else {
        0.0
    };
    let mut counts = vec![0u32; mesh.triangle_count()];
    for t in bound.binding().map_or(&[][..], |b| b.triangles.as_slice()) {
        if let Some(c) = counts.get_mut(t.0 as usize) {
            *c += 1;
        }
    }
    let (triangle, most) = counts
        .iter()
        .enumerate()
        .max_by_key(|(_, c)| **c)
        .map_or((0, 0), |(t, c)| (t as u32, *c));
    AttachStats {
        size_ratio,
        median_distance_edges,
        triangle_share: (f64::from(most) / world.len().max(1) as f64, triangle),
    }
}

/// [`attach`] and the distance from each centre to its triangle.
fn attach_with_distances(
    world: &GaussianSet,
    mesh: &TriMesh,
    convention: Convention,
) -> Result<(GaussianSet, Vec<f64>), BindError> {
    check_world_and_triangles(world, mesh)?;
    let nearest = if world.is_empty() {
        Vec::new()
    } else {
        let bvh = TriangleBvh::new(mesh).map_err(|e| BindError::Search(e.to_string()))?;
        bvh.closest_points(world.means())
            .map_err(|e| BindError::Search(e.to_string()))?
    };
    let triangles: Vec<TriId> = nearest.iter().map(|c| TriId(c.triangle)).collect();
    let set = express_locally(world, mesh, convention, triangles);
    let distances = nearest.iter().map(|c| c.distance).collect();
    Ok((set, distances))
}

/// Attaches world-space Gaussians to the given triangles (`triangles[i]` for Gaussian `i`),
/// expressed in their frames as [`attach`] does: for callers that choose the triangles
/// themselves (the re-initialisation's new Gaussians inherit the triangle of the old Gaussian
/// they copy). Deforming the result at rest gives the Gaussians back.
///
/// # Errors
/// [`BindError::NotWorld`], [`BindError::NoTriangles`]; [`BindError::VertexMap`] when
/// `triangles` does not have one entry per Gaussian or names a triangle past the mesh.
pub fn attach_to_triangles(
    world: &GaussianSet,
    mesh: &TriMesh,
    triangles: &[TriId],
    convention: Convention,
) -> Result<GaussianSet, BindError> {
    check_world_and_triangles(world, mesh)?;
    if triangles.len() != world.len() {
        return Err(BindError::VertexMap(format!(
            "{} triangles for {} Gaussians",
            triangles.len(),
            world.len()
        )));
    }
    if let Some((i, t)) = triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.index() >= mesh.triangle_count())
    {
        return Err(BindError::VertexMap(format!(
            "Gaussian {i}: triangle {} is past the template's {} triangles",
            t.index(),
            mesh.triangle_count()
        )));
    }
    Ok(express_locally(world, mesh, convention, triangles.to_vec()))
}

/// The inputs every `attach*` needs: world-space Gaussians and a template with triangles.
fn check_world_and_triangles(world: &GaussianSet, mesh: &TriMesh) -> Result<(), BindError> {
    if world.space() != ParameterSpace::World {
        return Err(BindError::NotWorld);
    }
    if mesh.triangles().is_empty() {
        return Err(BindError::NoTriangles);
    }
    Ok(())
}

/// Attaches world-space Gaussians that belong to mesh vertices (one vertex per Gaussian,
/// `vertex_of[i]` for Gaussian `i`, as in LAM's per-vertex avatars) to a triangle around their
/// vertex: of the triangles using the vertex, the one whose surface is nearest the Gaussian's
/// centre. Unlike [`attach`], a Gaussian far from the surface (hair, a LAM offset of several
/// centimetres) stays with the part of the mesh it was made for instead of jumping to whatever
/// surface happens to be nearest. Deforming the result at rest gives the Gaussians back.
///
/// # Errors
/// [`BindError::NotWorld`], [`BindError::NoTriangles`]; [`BindError::VertexMap`] when
/// `vertex_of` does not have one entry per Gaussian, names a vertex out of range, or a vertex
/// that no triangle uses.
pub fn attach_to_vertices(
    world: &GaussianSet,
    mesh: &TriMesh,
    vertex_of: &[u32],
    convention: Convention,
) -> Result<GaussianSet, BindError> {
    check_world_and_triangles(world, mesh)?;
    if vertex_of.len() != world.len() {
        return Err(BindError::VertexMap(format!(
            "{} vertices given for {} Gaussians",
            vertex_of.len(),
            world.len()
        )));
    }
    let n = mesh.vertex_count();
    // Triangles around each vertex, as offsets into one list (CSR).
    let mut start = vec![0u32; n + 1];
    for t in mesh.triangles() {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..n {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut around = vec![0u32; start[n] as usize];
    for (t, tri) in mesh.triangles().iter().enumerate() {
        for &v in tri {
            around[fill[v as usize] as usize] = t as u32;
            fill[v as usize] += 1;
        }
    }
    let positions = mesh.positions();
    let triangles = (0..world.len())
        .into_par_iter()
        .map(|i| {
            let v = vertex_of[i] as usize;
            if v >= n {
                return Err(BindError::VertexMap(format!(
                    "Gaussian {i} belongs to vertex {v}, but the template has {n} vertices"
                )));
            }
            let p = world.means()[i].as_dvec3();
            around[start[v] as usize..start[v + 1] as usize]
                .iter()
                .map(|&t| {
                    let [a, b, c] = corners_of(positions, mesh.triangles()[t as usize]);
                    let (q, _) = closest_point_on_triangle(p, a, b, c);
                    (t, q.distance_squared(p))
                })
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .map(|(t, _)| TriId(t))
                .ok_or_else(|| {
                    BindError::VertexMap(format!(
                        "Gaussian {i} belongs to vertex {v}, which no triangle uses"
                    ))
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(express_locally(world, mesh, convention, triangles))
}

/// `world` expressed in the frames of the given triangles of `mesh` (one per Gaussian), bound
/// to them (`binding_0`); colour, opacity, extras and the property order are kept.
fn express_locally(
    world: &GaussianSet,
    mesh: &TriMesh,
    convention: Convention,
    triangles: Vec<TriId>,
) -> GaussianSet {
    let fo = FrameOptions::for_positions(mesh.positions());
    let frames: Vec<_> = mesh
        .triangles()
        .par_iter()
        .map(|t| frame(convention, corners_of(mesh.positions(), *t), &fo))
        .collect();
    let local: Vec<(Vec3, [f32; 4], Vec3)> = (0..world.len())
        .into_par_iter()
        .map(|i| {
            let f = &frames[triangles[i].0 as usize];
            let mu = (f.rotation.transpose() * (world.means()[i].as_dvec3() - f.origin)) / f.scale;
            let q_f = quat_from_rotation(f.rotation);
            let q = normalize_wxyz(world.rotations()[i]).unwrap_or(DQuat::IDENTITY);
            let q_local = to_wxyz((q_f.conjugate() * q).normalize());
            let ls = world.log_scales()[i] - Vec3::splat(f.scale.ln() as f32);
            (mu.as_vec3(), q_local, ls)
        })
        .collect();
    let mut parts = world.clone().into_parts();
    for (i, (mu, q, ls)) in local.into_iter().enumerate() {
        parts.means[i] = mu;
        parts.rotations[i] = q;
        parts.log_scales[i] = match world.scale_dims() {
            crate::gaussians::ScaleDims::Three => ls,
            crate::gaussians::ScaleDims::Two => Vec3::new(ls.x, ls.y, 0.0),
        };
    }
    parts.binding = Some(Binding {
        triangles,
        encoding: BindingEncoding::Float,
    });
    parts.space = ParameterSpace::Local;
    GaussianSet::new_unchecked(parts)
}
