//! The alpha complex with singular faces (CGAL's `Alpha_shape_3` in `GENERAL` mode), and the
//! smallest α that holds it together.
//!
//! [`crate::alpha_shape`] keeps Open3D's *regularised* rule: only the faces of kept tetrahedra
//! (circumradius <= α). On points sampled from a surface, the Delaunay tetrahedra that lie along
//! the surface are flat slivers whose circumradius is large even where the samples are dense, so
//! the regularised shape breaks into hundreds of pieces (isolated kept tetrahedra among rejected
//! slivers) unless α is large enough to fill the volume, which makes it blobby. The alpha
//! complex also keeps the **singular** triangles: a Delaunay triangle belongs to the complex at
//! α when its own smallest circumsphere is empty (no vertex of either adjacent tetrahedron
//! strictly inside, CGAL's "unattached" test) and has radius <= α, even if neither adjacent
//! tetrahedron is kept. Those are exactly the surface triangles of a dense sample, so the thin
//! sheets that connect the pieces stay.
//!
//! Per triangle `f` with adjacent tetrahedra `c1`, `c2` (circumradius `r`, infinite for the
//! outside of the convex hull), CGAL's spectrum: `α_min(f)` = the radius of `f`'s smallest
//! circumsphere if that sphere is empty, else `min(r(c1), r(c2))`. At α the triangle is
//! - *interior* (not output) if both `c1` and `c2` are kept,
//! - *regular* (output, oriented away from the kept tetrahedron) if exactly one is kept,
//! - *singular* (output) if neither is kept but `α_min(f) <= α`,
//! - *exterior* (not output) otherwise.
//!
//! Singular triangles are two-sided; each is oriented to agree with its neighbours across the
//! edges that two output triangles share, starting from the regular ones (a sheet touching no
//! regular triangle keeps the orientation of its first triangle's tetrahedron).
//!
//! **The solid's boundary** ([`Surface::Solid`], the default): the complex is not manifold (on
//! surface samples about a sixth of its edges carry three or more triangles: folds where both
//! diagonals of a nearly planar quadrilateral pass the emptiness test, sheets inside the
//! object), so its area exceeds the surface's by a quarter. The solid keeps only what can be
//! seen from outside: a tetrahedron is *exterior* when it can be reached from the outside of the
//! convex hull by crossing only triangles that are not in the complex (neither regular nor
//! singular) into tetrahedra that are not kept; every other tetrahedron is the solid. The
//! output is the triangles between an exterior tetrahedron (or the outside of the hull) and a
//! solid one, oriented away from the solid; each is a regular or singular triangle of the
//! complex. Folds, doubled sheets and interior faces lie inside the solid and are dropped;
//! a sheet with the outside on both sides (a dangling fin) is dropped too. Every edge of the
//! output has an even number of triangles (the boundary of a union of tetrahedra), two except
//! where two parts of the solid touch along an edge.
//!
//! [`smallest_connected_alpha`] is CGAL's `find_optimal_alpha(1)` in spirit: the smallest α on a
//! geometric ladder whose output has at most a given number of edge-connected pieces.
//!
//! Radii and the emptiness test are computed in `f64` (not exact predicates): a triangle whose
//! sphere passes within rounding of a vertex, or whose radius is within rounding of α, can be
//! classified either way.

use glam::DVec3;
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::topology::{TriangleClusters, adjacency_lists, sorted_edge_uses};

use crate::alpha_shape::{AlphaError, AlphaShape, circumradius, compact};
use crate::delaunay3d::{Delaunay3d, FACE_VERTICES};

/// Which triangles of the alpha complex make the mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Surface {
    /// Every regular and singular triangle (CGAL's GENERAL mode): one piece at a small α, but
    /// not manifold (folds, interior sheets, fins).
    General,
    /// The boundary of the solid the complex encloses: the complex's triangles between a
    /// tetrahedron reachable from outside and one that is not (module docs).
    #[default]
    Solid,
}

/// A triangle's place in the complex at one α.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Not output (exterior, or between two kept tetrahedra).
    Out,
    /// Bounds exactly one kept tetrahedron (`flip`: the kept one is `outer`).
    Regular {
        /// Whether the stored order must be reversed to face outward.
        flip: bool,
    },
    /// In the complex without a kept tetrahedron on either side.
    Singular,
}

/// One Delaunay triangle with its two tetrahedra and its smallest circumsphere's verdict.
#[derive(Debug, Clone, Copy)]
struct Facet {
    /// Input indices, ordered so that the normal points away from `inner`.
    tri: [u32; 3],
    /// The finite tetrahedron that owns the triangle.
    inner: u32,
    /// The tetrahedron on the other side; `>=` the finite count for a convex-hull face.
    outer: u32,
    /// The radius of the smallest circumsphere when that sphere is empty, else infinity.
    gabriel_radius: f64,
}

impl Facet {
    /// Whether the triangle's own smallest circumsphere puts it in the complex at `alpha`.
    fn singular_at(&self, alpha: f64) -> bool {
        self.gabriel_radius <= alpha
    }
}

/// The alpha complex's spectrum over a tetrahedralisation: every tetrahedron's circumradius and
/// every triangle's smallest empty circumsphere, computed once and reused for any α.
#[derive(Debug)]
pub struct AlphaComplex<'a> {
    delaunay: &'a Delaunay3d,
    radius: Vec<f64>,
    facets: Vec<Facet>,
    /// `facet_of[t][i]`: the index in `facets` of tetrahedron `t`'s face opposite vertex `i`.
    facet_of: Vec<[u32; 4]>,
}

impl<'a> AlphaComplex<'a> {
    /// The spectrum of `delaunay` (parallel; O(tetrahedra)).
    #[must_use]
    pub fn new(delaunay: &'a Delaunay3d) -> Self {
        let points = delaunay.points();
        let tets = delaunay.tetrahedra();
        let neighbours = delaunay.neighbours();
        let finite = tets.len();
        let radius: Vec<f64> = tets
            .par_iter()
            .map(|t| circumradius(t.map(|v| points[v as usize])))
            .collect();
        let facets: Vec<Facet> = (0..finite)
            .into_par_iter()
            .flat_map_iter(|t| {
                let tet = tets[t];
                let nb = neighbours[t];
                (0..4).filter_map(move |i| {
                    let other = nb[i] as usize;
                    // Each interior triangle once, from its lower-numbered tetrahedron.
                    (other >= finite || t < other).then(|| {
                        let tri = FACE_VERTICES[i].map(|k| tet[k]);
                        let mut opposite = vec![tet[i]];
                        if other < finite {
                            let far = tets[other];
                            if let Some(&v) = far.iter().find(|v| !tri.contains(v)) {
                                opposite.push(v);
                            }
                        }
                        Facet {
                            tri,
                            inner: t as u32,
                            outer: nb[i],
                            gabriel_radius: gabriel_radius(points, tri, &opposite),
                        }
                    })
                })
            })
            .collect();
        let mut facet_of = vec![[u32::MAX; 4]; finite];
        for (k, f) in facets.iter().enumerate() {
            for t in [f.inner, f.outer] {
                if let Some(slots) = facet_of.get_mut(t as usize) {
                    let other = if t == f.inner { f.outer } else { f.inner };
                    // The face opposite the vertex that is not on the triangle.
                    let tet = tets[t as usize];
                    if let Some(i) = (0..4).find(|&i| !f.tri.contains(&tet[i])) {
                        debug_assert_eq!(neighbours[t as usize][i], other);
                        slots[i] = k as u32;
                    }
                }
            }
        }
        Self {
            delaunay,
            radius,
            facets,
            facet_of,
        }
    }

    /// The tetrahedralisation this spectrum was computed on.
    #[must_use]
    pub fn delaunay(&self) -> &Delaunay3d {
        self.delaunay
    }

    fn kept(&self, tet: u32, alpha: f64) -> bool {
        self.radius.get(tet as usize).is_some_and(|&r| r <= alpha)
    }

    /// Each triangle's state at `alpha`.
    fn classify(&self, alpha: f64) -> Vec<State> {
        self.facets
            .par_iter()
            .map(
                |f| match (self.kept(f.inner, alpha), self.kept(f.outer, alpha)) {
                    (true, true) => State::Out,
                    (true, false) => State::Regular { flip: false },
                    (false, true) => State::Regular { flip: true },
                    (false, false) if f.singular_at(alpha) => State::Singular,
                    (false, false) => State::Out,
                },
            )
            .collect()
    }

    /// The output triangles at `alpha` by `surface`, oriented (see [`Self::shape`]).
    fn triangles(&self, alpha: f64, surface: Surface) -> Vec<[u32; 3]> {
        match surface {
            Surface::General => {
                let (mut triangles, regular) = self.select(alpha);
                orient_sheets(&mut triangles, &regular);
                triangles
            }
            Surface::Solid => self.solid_boundary(alpha),
        }
    }

    /// Which finite tetrahedra are exterior at `alpha`: reachable from outside the convex hull
    /// across triangles not in the complex, into tetrahedra not kept.
    fn exterior(&self, alpha: f64) -> Vec<bool> {
        let neighbours = self.delaunay.neighbours();
        let finite = self.radius.len();
        let mut exterior = vec![false; finite];
        // Crossing face `i` of `t` into `t` itself (from its neighbour) is open when `t` is not
        // kept and the face is not singular (a kept neighbour makes it regular: it is never
        // crossed because the flood never stands in a kept tetrahedron).
        let open_into = |t: usize, i: usize| {
            self.radius[t] > alpha && !self.facets[self.facet_of[t][i] as usize].singular_at(alpha)
        };
        let mut stack: Vec<u32> = Vec::new();
        for t in 0..finite {
            if (0..4).any(|i| neighbours[t][i] as usize >= finite && open_into(t, i)) {
                exterior[t] = true;
                stack.push(t as u32);
            }
        }
        while let Some(t) = stack.pop() {
            for &u in &neighbours[t as usize] {
                let u = u as usize;
                if u >= finite || exterior[u] {
                    continue;
                }
                // The face of `u` that looks back at `t`.
                let Some(i) = (0..4).find(|&i| neighbours[u][i] == t) else {
                    continue;
                };
                if open_into(u, i) {
                    exterior[u] = true;
                    stack.push(u as u32);
                }
            }
        }
        exterior
    }

    /// The triangles between an exterior tetrahedron (or the hull's outside) and the solid,
    /// oriented away from the solid.
    fn solid_boundary(&self, alpha: f64) -> Vec<[u32; 3]> {
        let exterior = self.exterior(alpha);
        let outside = |t: u32| exterior.get(t as usize).is_none_or(|&e| e);
        self.facets
            .par_iter()
            .filter_map(|f| match (outside(f.inner), outside(f.outer)) {
                (false, true) => Some(f.tri),
                (true, false) => Some([f.tri[0], f.tri[2], f.tri[1]]),
                _ => None,
            })
            .collect()
    }

    /// The general complex's triangles at `alpha` (regular oriented outward, singular as
    /// stored) and whether each is regular.
    fn select(&self, alpha: f64) -> (Vec<[u32; 3]>, Vec<bool>) {
        let state = self.classify(alpha);
        self.facets
            .iter()
            .zip(&state)
            .filter_map(|(f, s)| match s {
                State::Out => None,
                State::Regular { flip: false } => Some((f.tri, true)),
                State::Regular { flip: true } => Some(([f.tri[0], f.tri[2], f.tri[1]], true)),
                State::Singular => Some((f.tri, false)),
            })
            .unzip()
    }

    /// Number of kept tetrahedra at `alpha`.
    #[must_use]
    pub fn kept_tetrahedra(&self, alpha: f64) -> usize {
        self.radius.par_iter().filter(|&&r| r <= alpha).count()
    }

    /// The alpha complex at `alpha` as a mesh by `surface`: [`Surface::General`], the regular
    /// triangles oriented outward plus the singular ones, oriented to agree with their
    /// neighbours; [`Surface::Solid`], the boundary of the enclosed solid, oriented outward.
    /// Vertices are the used input points in input order (as
    /// [`crate::alpha_shape::alpha_shape`]). A negative α gives an empty mesh,
    /// `f64::INFINITY` the convex hull.
    ///
    /// # Errors
    /// [`AlphaError::InvalidAlpha`] for a NaN α.
    pub fn shape(&self, alpha: f64, surface: Surface) -> Result<AlphaShape, AlphaError> {
        if alpha.is_nan() {
            return Err(AlphaError::InvalidAlpha(alpha));
        }
        let triangles = self.triangles(alpha, surface);
        let (mesh, vertex_ids) = compact(self.delaunay.points(), &triangles);
        Ok(AlphaShape {
            mesh,
            vertex_ids,
            kept_tetrahedra: self.kept_tetrahedra(alpha),
            duplicates: self.delaunay.duplicates().to_vec(),
        })
    }

    /// Number of edge-connected pieces of [`Self::shape`] at `alpha` (0 when it is empty).
    #[must_use]
    pub fn pieces(&self, alpha: f64, surface: Surface) -> usize {
        let triangles = match surface {
            Surface::General => self.select(alpha).0,
            Surface::Solid => self.solid_boundary(alpha),
        };
        let mesh = TriMesh::new_unchecked(
            self.delaunay
                .points()
                .iter()
                .map(|p| glam::DVec3::from_array(*p))
                .collect(),
            triangles,
        );
        TriangleClusters::of(&mesh).count()
    }
}

/// The radius of the smallest circumsphere of `tri` if no point of `opposite` lies strictly
/// inside it, else infinity (also for a triangle collinear in floating point).
fn gabriel_radius(points: &[[f64; 3]], tri: [u32; 3], opposite: &[u32]) -> f64 {
    let p = |i: u32| DVec3::from_array(points[i as usize]);
    let a = p(tri[0]);
    let u = p(tri[1]) - a;
    let v = p(tri[2]) - a;
    let w = u.cross(v);
    let ww = w.length_squared();
    if ww == 0.0 {
        return f64::INFINITY;
    }
    // Circumcentre relative to a: (|u|^2 (v x w) + |v|^2 (w x u)) / (2 |w|^2).
    let centre = (u.length_squared() * v.cross(w) + v.length_squared() * w.cross(u)) / (2.0 * ww);
    let r2 = centre.length_squared();
    let inside = opposite
        .iter()
        .any(|&o| (p(o) - a - centre).length_squared() < r2);
    if inside || !r2.is_finite() {
        f64::INFINITY
    } else {
        r2.sqrt()
    }
}

/// Orients the non-regular triangles to agree with their neighbours across edges shared by
/// exactly two triangles, spreading from the regular ones (which are never flipped).
fn orient_sheets(triangles: &mut [[u32; 3]], regular: &[bool]) {
    if regular.iter().all(|&r| r) {
        return;
    }
    let uses = sorted_edge_uses(triangles);
    // Pairs of triangles across a manifold edge, as adjacency lists.
    let pairs: Vec<(u32, u32)> = uses
        .chunk_by(|a, b| a.0 == b.0)
        .filter(|run| run.len() == 2)
        .map(|run| (run[0].1, run[1].1))
        .collect();
    let (offsets, adjacent) = adjacency_lists(triangles.len(), &pairs);
    let mut done: Vec<bool> = regular.to_vec();
    let mut stack: Vec<u32> = (0..triangles.len() as u32)
        .filter(|&t| regular[t as usize])
        .collect();
    let mut next_seed = 0usize;
    loop {
        while let Some(s) = stack.pop() {
            let st = triangles[s as usize];
            for &t in &adjacent[offsets[s as usize] as usize..offsets[s as usize + 1] as usize] {
                if done[t as usize] {
                    continue;
                }
                done[t as usize] = true;
                let tt = &mut triangles[t as usize];
                if shares_direction(st, *tt) {
                    tt.swap(1, 2);
                }
                stack.push(t);
            }
        }
        while next_seed < triangles.len() && done[next_seed] {
            next_seed += 1;
        }
        if next_seed == triangles.len() {
            break;
        }
        done[next_seed] = true;
        stack.push(next_seed as u32);
    }
}

/// Whether `s` and `t` run along a shared edge in the same direction (inconsistent
/// orientation).
fn shares_direction(s: [u32; 3], t: [u32; 3]) -> bool {
    (0..3).any(|i| {
        let (a, b) = (s[i], s[(i + 1) % 3]);
        (0..3).any(|j| t[j] == a && t[(j + 1) % 3] == b)
    })
}

/// How [`smallest_connected_alpha`] searches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlphaSearch {
    /// The smallest α tried.
    pub floor: f64,
    /// The largest α tried (the ladder stops at the first step at or above it).
    pub ceiling: f64,
    /// Ladder steps per doubling of α (α grows by `2^(1/steps)` per step).
    pub steps_per_doubling: u32,
    /// Accept the first α whose output has at most this many edge-connected pieces.
    pub max_pieces: usize,
    /// Which triangles make the output.
    pub surface: Surface,
}

/// The α [`smallest_connected_alpha`] chose and what it saw on the way.
#[derive(Debug, Clone, PartialEq)]
pub struct AlphaChoice {
    /// The chosen α.
    pub alpha: f64,
    /// Edge-connected pieces of the output at that α.
    pub pieces: usize,
    /// Whether the piece target was met (otherwise `alpha` is the ladder's α with the fewest
    /// pieces, the smallest among ties).
    pub met: bool,
    /// Every `(α, pieces)` tried, in order.
    pub tried: Vec<(f64, usize)>,
}

/// The smallest α on the ladder `floor · 2^(k / steps)` (up to `ceiling`) whose alpha complex
/// has at most `max_pieces` edge-connected pieces (and at least one triangle); if none does,
/// the α with the fewest pieces. A complex without tetrahedra (fewer than four distinct or
/// coplanar points) gives `floor` with 0 pieces, `met` false.
///
/// # Errors
/// [`AlphaError::InvalidAlpha`] when `floor` or `ceiling` is not finite and positive, when
/// `ceiling < floor`, or when `steps_per_doubling` is 0.
pub fn smallest_connected_alpha(
    complex: &AlphaComplex<'_>,
    search: &AlphaSearch,
) -> Result<AlphaChoice, AlphaError> {
    for bound in [search.floor, search.ceiling] {
        if !(bound.is_finite() && bound > 0.0) {
            return Err(AlphaError::InvalidAlpha(bound));
        }
    }
    if search.ceiling < search.floor {
        return Err(AlphaError::InvalidAlpha(search.ceiling));
    }
    if search.steps_per_doubling == 0 {
        return Err(AlphaError::InvalidAlpha(0.0));
    }
    let step = 2f64.powf(1.0 / f64::from(search.steps_per_doubling));
    let mut tried = Vec::new();
    let mut best: Option<(f64, usize)> = None;
    let mut k = 0i32;
    loop {
        let alpha = (search.floor * step.powi(k)).min(search.ceiling);
        let pieces = complex.pieces(alpha, search.surface);
        tried.push((alpha, pieces));
        if pieces > 0 && pieces <= search.max_pieces {
            return Ok(AlphaChoice {
                alpha,
                pieces,
                met: true,
                tried,
            });
        }
        if pieces > 0 && best.is_none_or(|(_, p)| pieces < p) {
            best = Some((alpha, pieces));
        }
        if alpha >= search.ceiling {
            break;
        }
        k += 1;
    }
    let (alpha, pieces) = best.unwrap_or((search.floor, 0));
    Ok(AlphaChoice {
        alpha,
        pieces,
        met: false,
        tried,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alpha_shape::alpha_shape_from_delaunay;
    use glam::Vec3;
    use std::collections::BTreeSet;

    /// `n` points on the unit sphere (Fibonacci lattice): a surface sample, mean spacing about
    /// `sqrt(4 pi / n)`.
    fn sphere(n: usize) -> Vec<Vec3> {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - y * y).sqrt();
                let t = golden * i as f64;
                Vec3::new((r * t.cos()) as f32, y as f32, (r * t.sin()) as f32)
            })
            .collect()
    }

    fn sorted(mesh: &TriMesh, ids: &[u32]) -> BTreeSet<[u32; 3]> {
        mesh.triangles()
            .iter()
            .map(|t| {
                let mut v = t.map(|i| ids[i as usize]);
                v.sort_unstable();
                v
            })
            .collect()
    }

    #[test]
    fn a_lone_triangle_is_singular() {
        // The tetrahedron's circumradius is about 5; the base triangle's smallest circumsphere
        // (radius 0.707) holds no vertex, so at alpha 1 it is the complex's only triangle.
        let pts = [
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 10.0),
        ];
        let d = Delaunay3d::new(&pts).expect("finite");
        let complex = AlphaComplex::new(&d);
        let shape = complex.shape(1.0, Surface::General).expect("alpha");
        assert_eq!(shape.mesh.triangle_count(), 1);
        assert_eq!(shape.kept_tetrahedra, 0);
        assert_eq!(shape.vertex_ids, vec![0, 1, 2]);
        assert_eq!(
            alpha_shape_from_delaunay(&d, 1.0)
                .expect("alpha")
                .mesh
                .triangle_count(),
            0
        );
        assert_eq!(
            complex
                .shape(0.7, Surface::General)
                .expect("alpha")
                .mesh
                .triangle_count(),
            0
        );
        // An attached triangle is not singular: (0,0,0), (1,0,0), (0,0,10) has the base's
        // opposite vertex (0,1,0) outside too, but its radius 5.02 is above alpha.
        assert_eq!(complex.pieces(1.0, Surface::General), 1);
        assert_eq!(complex.pieces(0.5, Surface::General), 0);
    }

    #[test]
    fn infinite_alpha_is_the_hull_and_negative_is_empty() {
        let pts = sphere(200);
        let d = Delaunay3d::new(&pts).expect("finite");
        let complex = AlphaComplex::new(&d);
        let hull = complex
            .shape(f64::INFINITY, Surface::General)
            .expect("alpha");
        let open3d = alpha_shape_from_delaunay(&d, f64::INFINITY).expect("alpha");
        assert_eq!(
            sorted(&hull.mesh, &hull.vertex_ids),
            sorted(&open3d.mesh, &open3d.vertex_ids)
        );
        let solid = complex.shape(f64::INFINITY, Surface::Solid).expect("alpha");
        assert_eq!(
            sorted(&solid.mesh, &solid.vertex_ids),
            sorted(&open3d.mesh, &open3d.vertex_ids)
        );
        assert_eq!(
            complex
                .shape(-1.0, Surface::Solid)
                .expect("alpha")
                .mesh
                .triangle_count(),
            0
        );
        assert_eq!(
            complex
                .shape(-1.0, Surface::General)
                .expect("alpha")
                .mesh
                .triangle_count(),
            0
        );
        assert!(matches!(
            complex.shape(f64::NAN, Surface::General),
            Err(AlphaError::InvalidAlpha(_))
        ));
    }

    /// The search for one piece from 0.5 to 4 sample spacings.
    fn one_piece(spacing: f64, surface: Surface) -> AlphaSearch {
        AlphaSearch {
            floor: 0.5 * spacing,
            ceiling: 4.0 * spacing,
            steps_per_doubling: 4,
            max_pieces: 1,
            surface,
        }
    }

    #[test]
    fn a_sampled_sphere_is_one_piece_where_the_regularised_shape_is_not() {
        let pts = sphere(800);
        let spacing = (4.0 * std::f64::consts::PI / 800.0).sqrt();
        let d = Delaunay3d::new(&pts).expect("finite");
        let complex = AlphaComplex::new(&d);
        let choice = smallest_connected_alpha(&complex, &one_piece(spacing, Surface::General))
            .expect("valid search");
        assert!(choice.met, "{choice:?}");
        assert_eq!(choice.pieces, 1);
        // The ladder stopped at the first success.
        assert!(
            choice.tried[..choice.tried.len() - 1]
                .iter()
                .all(|&(_, p)| p != 1)
        );
        let shape = complex
            .shape(choice.alpha, Surface::General)
            .expect("alpha");
        assert_eq!(TriangleClusters::of(&shape.mesh).count(), 1);
        // Every point is used and the mesh covers the sphere once: area within 3% of 4 pi
        // (the inscribed polyhedron is a little smaller), every vertex near radius 1.
        assert_eq!(shape.vertex_ids.len(), 800);
        let area: f64 = shape.mesh.triangle_areas().iter().sum();
        let sphere_area = 4.0 * std::f64::consts::PI;
        assert!((area / sphere_area - 0.985).abs() < 0.02, "area {area}");
        // Open3D's rule at the same alpha: the flat tetrahedra under the surface are rejected,
        // so almost nothing is left.
        let open3d = alpha_shape_from_delaunay(&d, choice.alpha).expect("alpha");
        assert!(open3d.mesh.triangle_count() < shape.mesh.triangle_count() / 4);
        // Orientation: across every edge two triangles share, they run opposite ways.
        let uses = sorted_edge_uses(shape.mesh.triangles());
        for run in uses.chunk_by(|a, b| a.0 == b.0).filter(|r| r.len() == 2) {
            let s = shape.mesh.triangles()[run[0].1 as usize];
            let t = shape.mesh.triangles()[run[1].1 as usize];
            assert!(!shares_direction(s, t), "{s:?} {t:?}");
        }
    }

    #[test]
    fn degenerate_inputs_give_empty_results_or_errors() {
        // Coplanar grid: no tetrahedra, an empty mesh, a search that reports 0 pieces.
        let plane: Vec<Vec3> = (0..25)
            .map(|i| Vec3::new((i % 5) as f32, (i / 5) as f32, 0.0))
            .collect();
        let d = Delaunay3d::new(&plane).expect("finite");
        let complex = AlphaComplex::new(&d);
        assert_eq!(
            complex
                .shape(2.0, Surface::General)
                .expect("alpha")
                .mesh
                .triangle_count(),
            0
        );
        let search = AlphaSearch {
            floor: 0.5,
            ceiling: 4.0,
            steps_per_doubling: 2,
            max_pieces: 1,
            surface: Surface::General,
        };
        let choice = smallest_connected_alpha(&complex, &search).expect("valid search");
        assert_eq!((choice.pieces, choice.met), (0, false));
        assert_eq!(choice.alpha, 0.5);
        // Co-spherical cube corners with a duplicate: the hull's 12 triangles at alpha 2 (a
        // symbolic perturbation decides the diagonals), one piece.
        let mut cube: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        cube.push(cube[3]);
        let d = Delaunay3d::new(&cube).expect("finite");
        let complex = AlphaComplex::new(&d);
        let shape = complex.shape(2.0, Surface::General).expect("alpha");
        assert_eq!(shape.mesh.triangle_count(), 12);
        assert_eq!(shape.duplicates.len(), 1);
        assert_eq!(complex.pieces(2.0, Surface::General), 1);
        assert_eq!(
            complex
                .shape(2.0, Surface::Solid)
                .expect("alpha")
                .mesh
                .triangle_count(),
            12
        );
        assert_eq!(complex.pieces(2.0, Surface::Solid), 1);
        // Bad searches are errors, not panics.
        for bad in [
            AlphaSearch {
                floor: f64::NAN,
                ..search
            },
            AlphaSearch {
                floor: 0.0,
                ..search
            },
            AlphaSearch {
                ceiling: f64::INFINITY,
                ..search
            },
            AlphaSearch {
                ceiling: 0.1,
                ..search
            },
            AlphaSearch {
                steps_per_doubling: 0,
                ..search
            },
        ] {
            assert!(smallest_connected_alpha(&complex, &bad).is_err(), "{bad:?}");
        }
    }

    /// Signed volume of a closed mesh (positive when its triangles face outward).
    fn signed_volume(mesh: &TriMesh) -> f64 {
        let p = mesh.positions();
        mesh.triangles()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| p[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn the_solid_of_a_sphere_with_an_inner_disc_is_the_sphere_alone() {
        // A sphere sample plus a disc of points across its equator at the same spacing: the
        // general complex holds the disc as a sheet inside the ball; the solid's boundary is
        // the sphere only, closed, manifold and facing outward.
        let n = 800;
        let spacing = (4.0 * std::f64::consts::PI / n as f64).sqrt();
        let mut pts = sphere(n);
        let rings = (0.9 / spacing) as usize;
        for k in 1..=rings {
            let r = k as f64 * spacing;
            let m = (2.0 * std::f64::consts::PI * r / spacing).round() as usize;
            for j in 0..m {
                let a = 2.0 * std::f64::consts::PI * (j as f64 + 0.5 * (k % 2) as f64) / m as f64;
                pts.push(Vec3::new((r * a.cos()) as f32, 0.013, (r * a.sin()) as f32));
            }
        }
        let d = Delaunay3d::new(&pts).expect("finite");
        let complex = AlphaComplex::new(&d);
        let choice = smallest_connected_alpha(&complex, &one_piece(spacing, Surface::Solid))
            .expect("valid search");
        assert!(choice.met, "{choice:?}");
        let solid = complex.shape(choice.alpha, Surface::Solid).expect("alpha");
        let general = complex
            .shape(choice.alpha, Surface::General)
            .expect("alpha");
        let area = |m: &TriMesh| m.triangle_areas().iter().sum::<f64>();
        let sphere_area = 4.0 * std::f64::consts::PI;
        assert!((area(&solid.mesh) / sphere_area - 0.985).abs() < 0.02);
        // The disc (area about pi) is in the general complex, not in the solid's boundary.
        assert!(
            area(&general.mesh) > area(&solid.mesh) + 2.0,
            "{}",
            area(&general.mesh)
        );
        // Only sphere points are used.
        assert!(solid.vertex_ids.iter().all(|&v| (v as usize) < n));
        // Closed and manifold: every edge has exactly two triangles, running opposite ways.
        let uses = sorted_edge_uses(solid.mesh.triangles());
        for run in uses.chunk_by(|a, b| a.0 == b.0) {
            assert_eq!(run.len(), 2, "edge {:?}", run[0].0);
            let s = solid.mesh.triangles()[run[0].1 as usize];
            let t = solid.mesh.triangles()[run[1].1 as usize];
            assert!(!shares_direction(s, t), "{s:?} {t:?}");
        }
        // Outward: the enclosed volume is the inscribed polyhedron's, a little under 4 pi / 3.
        let volume = signed_volume(&solid.mesh);
        assert!(
            (volume / (4.0 * std::f64::consts::PI / 3.0) - 0.98).abs() < 0.02,
            "{volume}"
        );
    }

    #[test]
    fn a_solid_with_a_hole_larger_than_alpha_is_flooded() {
        // A sphere sample without its top cap (a hole much wider than alpha): the outside
        // reaches the inside through the hole, so the surface sheet has the outside on both
        // sides and is not output; at an alpha that spans the hole the solid is whole again.
        let pts: Vec<Vec3> = sphere(800).into_iter().filter(|p| p.y < 0.8).collect();
        let spacing = (4.0 * std::f64::consts::PI / 800.0).sqrt();
        let d = Delaunay3d::new(&pts).expect("finite");
        let complex = AlphaComplex::new(&d);
        let alpha = 1.5 * spacing;
        let general = complex.shape(alpha, Surface::General).expect("alpha");
        let solid = complex.shape(alpha, Surface::Solid).expect("alpha");
        assert!(general.mesh.triangle_count() > 1000);
        assert!(
            solid.mesh.triangle_count() < general.mesh.triangle_count() / 4,
            "{} of {}",
            solid.mesh.triangle_count(),
            general.mesh.triangle_count()
        );
        let closed = complex.shape(2.0, Surface::Solid).expect("alpha");
        assert_eq!(complex.pieces(2.0, Surface::Solid), 1);
        assert!(signed_volume(&closed.mesh) > 3.0);
    }
}
