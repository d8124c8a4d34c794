//! Meshing the Gaussians' opacity field (Gaussian Opacity Fields, Yu et al. 2024;
//! docs/conventions.md §6): points at each kept Gaussian's centre and the corners of its
//! 3-sigma box, our exact 3D Delaunay over them, the opacity field at every point (the smallest
//! over views of the opacity accumulated along the view's ray up to the point, [`opacity_at`]),
//! marching tetrahedra at `level` with bisection on every crossing edge, vertex colours from the
//! Gaussians, and optionally only the largest piece by area.
//!
//! - **Input**: [`OpacityGaussians`], plain arrays (this crate never sees a renderer's set);
//!   zero, negative or non-finite scales, non-finite means, zero rotations and opacities
//!   outside [0, 1] are errors naming the Gaussian. Gaussians whose opacity is below
//!   [`OpacityOptions::opacity_cut`] (and the alpha cut) are left out of points and field.
//! - **Views**: every view's bins are built once and held when they fit in 1 GiB (each point
//!   then walks the views from a hint, and certificates per tile skip sure walks); beyond that
//!   they are streamed, one view's bins at a time, so memory does not grow with their number.
//!   Either way the signs and the mesh are the same.
//! - **Determinism**: every point's value depends only on the views in order, never on the
//!   thread count.

mod carry;
mod depth;
mod error;
mod field;
mod gaussians;
mod order;
mod pieces;
mod smooth;
mod tets;
mod view;
mod views;

use std::time::Instant;

use glam::DVec3;
use trisplat_geometry::{Camera, Rgba, TriMesh};

use crate::delaunay3d::Delaunay3d;
use carry::CarriedTets;
use depth::{CarveHint, DepthViews, depth_colors, depth_samples};
use field::{Mode, NO_VIEW, evaluate};
use order::z_order;
use view::CertifyAt;
use views::{HELD_BYTES, Views};

pub use depth::{
    BLEND_SPREAD, DEFAULT_CARVE_VIEWS, DEFAULT_MARGIN, DEFAULT_SAMPLE_STRIDE, DEFAULT_SURFACE,
    DepthRules, DepthView, MAX_CARVE_VIEWS,
};
pub use error::OpacityError;
pub use field::{AlphaRules, RayModel};
pub use gaussians::OpacityGaussians;

use gaussians::{Prepared, tetra_points};

/// Default level of the opacity field the surface is extracted at (GOF: 1/2).
pub const DEFAULT_LEVEL: f32 = 0.5;
/// Default number of bisection steps on each crossing edge: GOF's 8, as issue #34 asks. 4
/// (`--steps 4`) puts every vertex within 1/32 of its edge of GOF's and changes LAM's render
/// consistency by under 0.03 mm at half the bisection's cost (docs/benchmarks.md).
pub const DEFAULT_BISECTION_STEPS: u32 = 8;
/// Default opacity below which a Gaussian is left out (the renderer's alpha cut, 1/255: such a
/// Gaussian never changes a pixel).
pub const DEFAULT_OPACITY_CUT: f32 = 1.0 / 255.0;

/// Share of the tetrahedra an [`OpacityTrack`]'s repair may replace and still carry on:
/// beyond it a repair costs about a rebuild (LAM's points change ~25% of their tetrahedra
/// per frame, docs/benchmarks.md), and the track rebuilds from then on.
pub const CARRY_WORTH_SHARE: f64 = 0.12;

/// Share of the surface's area a piece needs for [`KeepPieces::Major`].
pub const MAJOR_PIECE_FRACTION: f64 = 0.01;

/// Which connected pieces of the surface are kept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum KeepPieces {
    /// Every piece (the default: on LAM the face is a piece of its own and the ~420 small
    /// pieces are hair and fragments the renders show; every piece scores best).
    #[default]
    All,
    /// Every piece with at least [`MAJOR_PIECE_FRACTION`] of the area.
    Major,
    /// Only the largest by area.
    Largest,
}

/// Options of [`opacity_mesh`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpacityOptions {
    /// Level of the field the surface lies at, in (0, 1).
    pub level: f32,
    /// Bisection steps on each crossing edge (0: edge midpoints).
    pub bisection_steps: u32,
    /// Gaussians with a smaller opacity are left out.
    pub opacity_cut: f32,
    /// Compositing rules.
    pub rules: AlphaRules,
    /// Pieces kept.
    pub keep: KeepPieces,
    /// Whether vertices get colours.
    pub colors: bool,
    /// Whether [`opacity_mesh_tracked`] carries the tetrahedralisation from frame to frame
    /// (off by default: on LAM a repair costs more than a rebuild, docs/benchmarks.md).
    pub carry: bool,
    /// Median field ([`median_depth_mesh`]): whether vertices on a rim (just outside them some
    /// views see no median depth) settle too (`DepthViews::settle_with`); off by default (on
    /// LAM rims that keep the margin keep 0.006 more IoU), on for template avatars' flat
    /// Gaussians, whose level set lies on the visual hull (docs/benchmarks.md).
    pub settle_rims: bool,
    /// Median field: Taubin iterations over the vertices that settled (module `smooth`; 0:
    /// none, the default).
    pub smoothing: u32,
}

impl Default for OpacityOptions {
    fn default() -> Self {
        Self {
            level: DEFAULT_LEVEL,
            bisection_steps: DEFAULT_BISECTION_STEPS,
            opacity_cut: DEFAULT_OPACITY_CUT,
            rules: AlphaRules::default(),
            keep: KeepPieces::default(),
            colors: true,
            carry: false,
            settle_rims: false,
            smoothing: 0,
        }
    }
}

/// What [`opacity_mesh`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OpacityStats {
    /// Gaussians kept (opacity at or above the cut).
    pub gaussians: usize,
    /// Points (9 per kept Gaussian).
    pub points: usize,
    /// Of which some view sees (the others are left out).
    pub points_seen: usize,
    /// Finite tetrahedra.
    pub tetrahedra: usize,
    /// Edges crossing the level (= vertices before the piece selection).
    pub crossing_edges: usize,
    /// Connected pieces of the surface before the selection.
    pub pieces: usize,
    /// Share of the surface's area kept by the selection (1 with [`KeepPieces::All`]).
    pub kept_area_fraction: f64,
    /// Whether the tetrahedralisation was carried from the previous frame of an
    /// [`OpacityTrack`] (checked and repaired) rather than built from scratch.
    pub carried: bool,
    /// With `carried`: points whose tetrahedra failed the check and were re-tetrahedralised.
    pub hopped: usize,
    /// With `carried`: tetrahedra replaced by the repair.
    pub replaced: usize,
    /// Milliseconds per stage: field at the points, tetrahedralisation, marching and
    /// bisection, colours.
    pub ms: [f64; 4],
}

/// A mesh of the opacity field and what it took.
#[derive(Clone, Debug)]
pub struct OpacityMesh {
    /// The surface, faces toward lower opacity, vertex colours unless turned off.
    pub mesh: TriMesh,
    /// Counts and timings.
    pub stats: OpacityStats,
}

/// The opacity field of `gaussians` seen by `cameras` at `points` (1 where no camera sees a
/// point, as GOF).
///
/// # Errors
/// As [`opacity_mesh`] for bad Gaussians or no camera.
pub fn opacity_at(
    gaussians: &OpacityGaussians,
    cameras: &[Camera],
    points: &[DVec3],
    options: &OpacityOptions,
) -> Result<Vec<f32>, OpacityError> {
    if cameras.is_empty() {
        return Err(OpacityError::NoCameras);
    }
    let p = Prepared::new(gaussians, options.opacity_cut, options.rules.min_alpha)?;
    let mut views = Views::new(&p, cameras, HELD_BYTES, None);
    let order = z_order(points);
    let field = evaluate(
        &p,
        &mut views,
        points,
        &order,
        None,
        Mode::Exact,
        options.rules,
    );
    Ok(field.value.iter().map(|&v| v as f32).collect())
}

/// Meshes the opacity field of `gaussians` seen by `cameras` (see the module docs).
///
/// # Errors
/// [`OpacityError`]: a bad Gaussian (named), every opacity below the cut, no camera, no point
/// seen by any camera, degenerate (coplanar or coincident) points, or no crossing of the level.
pub fn opacity_mesh(
    gaussians: &OpacityGaussians,
    cameras: &[Camera],
    options: &OpacityOptions,
) -> Result<OpacityMesh, OpacityError> {
    opacity_mesh_within(gaussians, cameras, options, HELD_BYTES, None)
}

/// What [`opacity_mesh_tracked`] keeps from one frame of a bound avatar to the next: the
/// Delaunay tetrahedralisation of the points, with the kept Gaussians it was made for.
#[derive(Clone, Debug, Default)]
pub struct OpacityTrack {
    tets: Option<CarriedTets>,
    /// Set once a repair replaced more than [`CARRY_WORTH_SHARE`] of the tetrahedra or did
    /// not fit: the points change too much from frame to frame for carrying to pay, and the
    /// later frames are rebuilt without trying.
    given_up: bool,
    /// Input index of each kept Gaussian the tetrahedralisation's points came from.
    source: Vec<u32>,
}

/// [`opacity_mesh`] for one frame of a sequence whose Gaussians keep their identity (a bound
/// avatar): the tetrahedralisation of the previous frame in `track` is moved to this frame's
/// points, checked and repaired where it is no longer Delaunay (module `carry`), instead of
/// being rebuilt. The mesh is the one [`opacity_mesh`] gives. Falls back to a rebuild (and
/// says so in [`OpacityStats::carried`]) on the first frame, when the kept Gaussians change,
/// when some point is not seen, or when the repair does not fit; once a repair does not fit or
/// replaces more than [`CARRY_WORTH_SHARE`] of the tetrahedra, every later frame is rebuilt.
///
/// # Errors
/// As [`opacity_mesh`]; `track` is then reset.
pub fn opacity_mesh_tracked(
    gaussians: &OpacityGaussians,
    cameras: &[Camera],
    options: &OpacityOptions,
    track: &mut OpacityTrack,
) -> Result<OpacityMesh, OpacityError> {
    let out = opacity_mesh_within(gaussians, cameras, options, HELD_BYTES, Some(track));
    if out.is_err() {
        *track = OpacityTrack::default();
    }
    out
}

/// The finite tetrahedra of `points`, carried in `track` when it
/// holds them, else built (and kept in `track` when given and every point is a vertex).
fn tetrahedralise(
    points: &[DVec3],
    all_seen: bool,
    source: &[u32],
    track: Option<&mut OpacityTrack>,
    stats: &mut OpacityStats,
) -> Result<Vec<[u32; 4]>, OpacityError> {
    let coords: Vec<[f64; 3]> = points.iter().map(|x| x.to_array()).collect();
    let mut track = track.filter(|t| all_seen && !t.given_up);
    if let Some(t) = track.as_deref_mut()
        && t.source == source
        && let Some(tets) = t.tets.as_mut()
    {
        match tets.update(coords.clone()) {
            Ok(c) => {
                if c.replaced as f64 > CARRY_WORTH_SHARE * tets.live_count() as f64 {
                    t.given_up = true;
                }
                stats.carried = true;
                stats.hopped = c.hopped;
                stats.replaced = c.replaced;
                let out = tets.finite();
                stats.tetrahedra = out.len();
                return Ok(out);
            }
            Err(_) => {
                t.tets = None;
                t.given_up = true;
            }
        }
    }
    let Some(t) = track.filter(|t| !t.given_up) else {
        // Nothing to carry: only the finite tetrahedra, without neighbours or copies.
        let (out, dimension) = Delaunay3d::finite_tetrahedra(&coords)?;
        if dimension < 3 {
            return Err(OpacityError::Degenerate { dimension });
        }
        stats.tetrahedra = out.len();
        return Ok(out);
    };
    let delaunay = Delaunay3d::from_f64(coords)?;
    if delaunay.dimension() < 3 {
        return Err(OpacityError::Degenerate {
            dimension: delaunay.dimension(),
        });
    }
    t.tets = CarriedTets::new(&delaunay);
    t.source = source.to_vec();
    let out = delaunay.tetrahedra().to_vec();
    stats.tetrahedra = out.len();
    Ok(out)
}

/// [`opacity_mesh`], holding the views' bins when they fit in `budget` bytes, carrying the
/// tetrahedralisation in `track` when given.
fn opacity_mesh_within(
    gaussians: &OpacityGaussians,
    cameras: &[Camera],
    options: &OpacityOptions,
    budget: usize,
    track: Option<&mut OpacityTrack>,
) -> Result<OpacityMesh, OpacityError> {
    if cameras.is_empty() {
        return Err(OpacityError::NoCameras);
    }
    let level = f64::from(options.level);
    let sign = Mode::Sign { level };
    let p = Prepared::new(gaussians, options.opacity_cut, options.rules.min_alpha)?;
    let mut stats = OpacityStats {
        gaussians: p.len(),
        ..OpacityStats::default()
    };
    let clock = Instant::now();
    let certify = CertifyAt {
        level,
        max_alpha: options.rules.max_alpha,
        min_alpha: options.rules.min_alpha,
    };
    let mut views = Views::new(&p, cameras, budget, Some(certify));
    let all = tetra_points(&p);
    stats.points = all.len();
    let order = z_order(&all);
    let field = evaluate(&p, &mut views, &all, &order, None, sign, options.rules);
    let mut points = Vec::with_capacity(all.len());
    let mut inside = Vec::with_capacity(all.len());
    let mut decider = Vec::with_capacity(all.len());
    for (k, &x) in all.iter().enumerate() {
        if field.seen[k] {
            points.push(x);
            inside.push(field.value[k] >= level);
            decider.push(field.decider[k]);
        }
    }
    stats.points_seen = points.len();
    if points.is_empty() {
        return Err(OpacityError::NotSeen { points: all.len() });
    }
    drop(all);
    stats.ms[0] = ms(clock);

    let all_seen = points.len() == stats.points;
    // Each edge first walks the view that put its outer end outside.
    let mut hint: Vec<u16> = Vec::new();
    let first_hints =
        |edges: &[[u32; 2]]| -> Vec<u16> { edges.iter().map(|e| decider[e[1] as usize]).collect() };
    let Surface {
        vertices,
        triangles,
        edges,
    } = surface(
        &points,
        &inside,
        all_seen,
        &p.source,
        track,
        options,
        &mut stats,
        |edges, mid, order| {
            if hint.is_empty() {
                hint = first_hints(edges);
            }
            let f = evaluate(&p, &mut views, mid, order, Some(&hint), sign, options.rules);
            let inside: Vec<bool> = f.value.iter().map(|&v| v >= level).collect();
            for (k, h) in hint.iter_mut().enumerate() {
                if !inside[k] && f.decider[k] != NO_VIEW {
                    *h = f.decider[k];
                }
            }
            inside
        },
    )?;
    if hint.is_empty() {
        hint = first_hints(&edges);
    }

    let clock = Instant::now();
    let (mut mesh, kept) = keep_pieces(vertices, triangles, options.keep, &mut stats);
    if options.colors {
        let used_hint: Vec<u16> = kept.iter().map(|&v| hint[v as usize]).collect();
        let colors = field::colors(&p, &mut views, mesh.positions(), &used_hint, options.rules);
        mesh = with_colors(mesh, &colors);
    }
    stats.ms[3] = ms(clock);
    Ok(OpacityMesh { mesh, stats })
}

/// [`opacity_mesh`] with the median-depth field (module `depth`, docs/conventions.md §6):
/// the same points, tetrahedralisation, marching and bisection, with each point's side read
/// from the views' rendered median-depth maps, then the vertices of thick parts settled onto
/// the median depth ([`DepthRules::surface`]); vertex colours from the rendered colours of the
/// view whose median depth lies closest to the vertex. `options.rules` and `options.level` are
/// not used (the level is `-rules.margin`).
///
/// # Errors
/// As [`opacity_mesh`], and [`OpacityError::BadDepthMap`] / [`OpacityError::BadDepthRules`].
pub fn median_depth_mesh(
    gaussians: &OpacityGaussians,
    views: &[DepthView],
    rules: DepthRules,
    options: &OpacityOptions,
    track: Option<&mut OpacityTrack>,
) -> Result<OpacityMesh, OpacityError> {
    let maps = DepthViews::new(views, rules)?;
    let level = maps.level();
    let p = Prepared::new(gaussians, options.opacity_cut, options.rules.min_alpha)?;
    let mut stats = OpacityStats {
        gaussians: p.len(),
        ..OpacityStats::default()
    };
    let clock = Instant::now();
    let mut all = tetra_points(&p);
    let samples = depth_samples(&maps);
    // The samples change from frame to frame: only the Gaussians' points can be carried.
    let track = track.filter(|_| samples.is_empty());
    all.extend(samples);
    stats.points = all.len();
    let all_order = z_order(&all);
    let mut all_hints = vec![CarveHint::default(); all.len()];
    let (all_inside, seen) = maps.sides(&all, level, &all_order, &mut all_hints);
    // Each point's hint: the views that carved it (when outside), by point.
    let mut point_hint = vec![CarveHint::default(); all.len()];
    for (&i, h) in all_order.iter().zip(&all_hints) {
        point_hint[i as usize] = *h;
    }
    drop(all_hints);
    let mut points = Vec::with_capacity(all.len());
    let mut inside = Vec::with_capacity(all.len());
    let mut hint_of = Vec::with_capacity(all.len());
    for (k, &x) in all.iter().enumerate() {
        if seen[k] {
            points.push(x);
            inside.push(all_inside[k]);
            hint_of.push(point_hint[k]);
        }
    }
    drop(point_hint);
    stats.points_seen = points.len();
    if points.is_empty() {
        return Err(OpacityError::NotSeen { points: all.len() });
    }
    drop(all);
    stats.ms[0] = ms(clock);
    let all_seen = points.len() == stats.points;
    let mut edge_hints: Vec<CarveHint> = Vec::new();
    let Surface {
        vertices,
        triangles,
        ..
    } = surface(
        &points,
        &inside,
        all_seen,
        &p.source,
        track,
        options,
        &mut stats,
        |edges, mid, order| {
            // Each edge's first hint: the views that carved its outer end.
            if edge_hints.is_empty() {
                edge_hints = order
                    .iter()
                    .map(|&e| hint_of[edges[e as usize][1] as usize])
                    .collect();
            }
            maps.sides(mid, level, order, &mut edge_hints).0
        },
    )?;
    let settled = maps.settle_with(
        &vertices,
        &vertex_normals(&vertices, &triangles),
        !options.settle_rims,
    );
    // Only the vertices that settled are smoothed: the others keep the margin's level set.
    let free: Vec<bool> = vertices.iter().zip(&settled).map(|(a, b)| a != b).collect();
    let vertices = smooth::taubin_free(settled, &triangles, &free, options.smoothing);
    let clock = Instant::now();
    let (mut mesh, _) = keep_pieces(vertices, triangles, options.keep, &mut stats);
    if options.colors {
        let colors = depth_colors(&maps, mesh.positions());
        mesh = with_colors(mesh, &colors);
    }
    stats.ms[3] = ms(clock);
    Ok(OpacityMesh { mesh, stats })
}

/// What [`surface`] makes: one vertex per crossing edge, the triangles over them, and the
/// crossing edges (inside point, outside point).
struct Surface {
    vertices: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    edges: Vec<[u32; 2]>,
}

/// The surface over `points` whose sides are `inside`: tetrahedralised (carried in `track`
/// when given and `options.carry`), marched, and every crossing edge bisected
/// `options.bisection_steps` times with `side_of(crossing edges, midpoints, their Z-order)`.
/// Returns a [`Surface`].
#[expect(
    clippy::too_many_arguments,
    reason = "the stages' shared state, passed once"
)]
fn surface(
    points: &[DVec3],
    inside: &[bool],
    all_seen: bool,
    source: &[u32],
    track: Option<&mut OpacityTrack>,
    options: &OpacityOptions,
    stats: &mut OpacityStats,
    mut side_of: impl FnMut(&[[u32; 2]], &[DVec3], &[u32]) -> Vec<bool>,
) -> Result<Surface, OpacityError> {
    let clock = Instant::now();
    let tetrahedra = tetralise_or_carry(points, all_seen, source, track, options, stats)?;
    stats.ms[1] = ms(clock);

    let clock = Instant::now();
    let crossings = tets::march(points, &tetrahedra, inside);
    drop(tetrahedra);
    if crossings.triangles.is_empty() {
        return Err(OpacityError::NoSurface {
            level: options.level,
            inside: inside.iter().filter(|&&i| i).count(),
            points: points.len(),
        });
    }
    stats.crossing_edges = crossings.edges.len();
    let mut lo: Vec<DVec3> = crossings
        .edges
        .iter()
        .map(|e| points[e[0] as usize])
        .collect();
    let mut hi: Vec<DVec3> = crossings
        .edges
        .iter()
        .map(|e| points[e[1] as usize])
        .collect();
    let mut mid: Vec<DVec3> = lo.iter().zip(&hi).map(|(a, b)| (*a + *b) * 0.5).collect();
    // The midpoints move by less than their edges: one Z-order serves every step.
    let mid_order = z_order(&mid);
    for step in 0..options.bisection_steps {
        if step > 0 {
            mid.clear();
            mid.extend(lo.iter().zip(&hi).map(|(a, b)| (*a + *b) * 0.5));
        }
        let ins = side_of(&crossings.edges, &mid, &mid_order);
        for (k, m) in mid.iter().enumerate() {
            if ins[k] {
                lo[k] = *m;
            } else {
                hi[k] = *m;
            }
        }
    }
    let vertices: Vec<DVec3> = lo.iter().zip(&hi).map(|(a, b)| (*a + *b) * 0.5).collect();
    stats.ms[2] = ms(clock);
    Ok(Surface {
        vertices,
        triangles: crossings.triangles,
        edges: crossings.edges,
    })
}

/// [`tetrahedralise`], carrying in `track` only when `options.carry` asks for it.
fn tetralise_or_carry(
    points: &[DVec3],
    all_seen: bool,
    source: &[u32],
    track: Option<&mut OpacityTrack>,
    options: &OpacityOptions,
    stats: &mut OpacityStats,
) -> Result<Vec<[u32; 4]>, OpacityError> {
    let track = track.filter(|_| options.carry);
    tetrahedralise(points, all_seen, source, track, stats)
}

/// The pieces `keep` selects (stats: pieces, kept share of the area), as a mesh without the
/// vertices no kept triangle uses; with the index of each kept vertex in `vertices`.
fn keep_pieces(
    vertices: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    keep: KeepPieces,
    stats: &mut OpacityStats,
) -> (TriMesh, Vec<u32>) {
    let (piece, areas) = pieces::pieces(&vertices, &triangles);
    stats.pieces = areas.len();
    let total: f64 = areas.iter().sum();
    let triangles: Vec<[u32; 3]> = match keep {
        KeepPieces::All => {
            stats.kept_area_fraction = 1.0;
            triangles
        }
        KeepPieces::Largest | KeepPieces::Major => {
            let kept = if keep == KeepPieces::Largest {
                1
            } else {
                areas
                    .iter()
                    .take_while(|&&a| a >= MAJOR_PIECE_FRACTION * total)
                    .count()
                    .max(1)
            };
            stats.kept_area_fraction = if total > 0.0 {
                areas[..kept].iter().sum::<f64>() / total
            } else {
                1.0
            };
            triangles
                .iter()
                .zip(&piece)
                .filter(|(_, p)| (**p as usize) < kept)
                .map(|(t, _)| *t)
                .collect()
        }
    };
    // Drop vertices no kept triangle uses, keeping their order.
    let mut remap = vec![u32::MAX; vertices.len()];
    let mut used = Vec::new();
    let mut kept = Vec::new();
    for t in &triangles {
        for &v in t {
            if remap[v as usize] == u32::MAX {
                remap[v as usize] = 0;
            }
        }
    }
    for (v, r) in remap.iter_mut().enumerate() {
        if *r == 0 {
            *r = used.len() as u32;
            used.push(vertices[v]);
            kept.push(v as u32);
        }
    }
    let triangles: Vec<[u32; 3]> = triangles
        .iter()
        .map(|t| t.map(|v| remap[v as usize]))
        .collect();
    (TriMesh::new(used, triangles), kept)
}

/// Area-weighted unit vertex normals of `triangles` (zero where they cancel or no triangle
/// uses the vertex).
fn vertex_normals(vertices: &[DVec3], triangles: &[[u32; 3]]) -> Vec<DVec3> {
    let mut normals = vec![DVec3::ZERO; vertices.len()];
    for t in triangles {
        let [a, b, c] = t.map(|v| vertices[v as usize]);
        let n = (b - a).cross(c - a);
        for &v in t {
            normals[v as usize] += n;
        }
    }
    for n in &mut normals {
        *n = n.normalize_or_zero();
    }
    normals
}

/// `mesh` with `colors` clamped to [0, 1] as its vertex colours (alpha 1).
fn with_colors(mesh: TriMesh, colors: &[[f32; 3]]) -> TriMesh {
    let rgba: Vec<Rgba> = colors
        .iter()
        .map(|c| {
            [
                c[0].clamp(0.0, 1.0),
                c[1].clamp(0.0, 1.0),
                c[2].clamp(0.0, 1.0),
                1.0,
            ]
        })
        .collect();
    mesh.with_colors(rgba)
        .expect("one colour per vertex by construction")
}

fn ms(clock: Instant) -> f64 {
    clock.elapsed().as_secs_f64() * 1000.0
}

#[cfg(test)]
mod tests;
