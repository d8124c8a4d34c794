//! 3D Delaunay tetrahedralisation: Bowyer-Watson cavity insertion with exact predicates.
//!
//! - **Predicates**: exact `orient3d`/`insphere` (Shewchuk's adaptive arithmetic, `robust`
//!   crate) with symbolic perturbation of the lifting map ("perturb by index", as CGAL's and
//!   geogram's SoS): point `i` is lifted to `|p_i|^2 + eps^(N - i)`, so when five points are
//!   exactly co-spherical the sign is that of the first non-zero `orient3d` minor in order of
//!   decreasing point index. Coordinates are not perturbed; a point exactly coplanar with a
//!   convex-hull face conflicts with the outside iff it conflicts with the tetrahedron behind
//!   that face. The result is *the* Delaunay tetrahedralisation of the perturbed points, so
//!   co-spherical inputs (cube corners, grids, points on a sphere) get a valid, deterministic
//!   tetrahedralisation, never a flat tetrahedron.
//! - **Infinite vertex**: the convex hull faces are closed by "infinite" tetrahedra sharing a
//!   vertex at infinity, so no enclosing box and no special cases for points outside the hull.
//! - **Order**: BRIO rounds in Hilbert order; **point location** by a stochastic visibility walk
//!   from the last created tetrahedron.
//! - **Storage**: flat arrays, tetrahedra as `[u32; 4]` and neighbours as `[u32; 4]`
//!   (`neighbours[t][i]` is across the face opposite vertex `i`); cavity buffers are reused, so
//!   an insertion allocates nothing once the buffers have grown.
//!
//! Degenerate inputs by design: duplicated points are skipped (listed by
//! [`Delaunay3d::duplicates`]); fewer than four distinct points, or all points coplanar, give an
//! *empty* tetrahedralisation (`Ok`, [`Delaunay3d::dimension`] < 3). Non-finite or huge
//! coordinates are an error naming the point.

mod predicates;
mod sort;

use std::fmt;

use glam::Vec3;
use predicates::insphere;
pub(crate) use predicates::{insphere_sos, orient3d};

/// Largest accepted coordinate magnitude. The in-sphere determinant is a degree-5 polynomial of
/// coordinate differences: with |x| <= 1e30 its terms stay far below `f64::MAX`, so the exact
/// predicates cannot overflow. (`f32` inputs can reach 3.4e38, whose fifth power overflows.)
pub const MAX_COORDINATE: f64 = 1e30;

/// The largest number of input points (indices are `u32`; two values are reserved).
pub const MAX_POINTS: usize = (u32::MAX >> 1) as usize;

/// The largest number of tetrahedra (finite and infinite) held at once (`u32` indices; a few
/// values are reserved as markers).
pub const MAX_TETRAHEDRA: usize = (u32::MAX - 3) as usize;

/// The vertex at infinity (in the internal arrays).
pub(crate) const INF: u32 = u32::MAX;
/// Vertex marker of a deleted tetrahedron slot.
const DEAD: u32 = u32::MAX - 1;

/// Why a point set cannot be tetrahedralised.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DelaunayError {
    /// A coordinate is NaN or infinite.
    #[error("point {index}: non-finite coordinate {value}")]
    NonFinite {
        /// Index of the point in the input.
        index: usize,
        /// The offending coordinate.
        value: f64,
    },
    /// A coordinate exceeds [`MAX_COORDINATE`] in magnitude.
    #[error(
        "point {index}: coordinate {value:e} exceeds the supported magnitude {MAX_COORDINATE:e}"
    )]
    TooLarge {
        /// Index of the point in the input.
        index: usize,
        /// The offending coordinate.
        value: f64,
    },
    /// The tetrahedralisation would need more than [`MAX_TETRAHEDRA`] tetrahedra (only for
    /// pathological inputs such as points on two skew lines, whose count grows quadratically).
    #[error("the tetrahedralisation needs more than {MAX_TETRAHEDRA} tetrahedra")]
    TooManyTetrahedra,
    /// More than [`MAX_POINTS`] points.
    #[error("{count} points exceed the supported maximum of {MAX_POINTS}")]
    TooManyPoints {
        /// Number of input points.
        count: usize,
    },
}

/// A point that was not inserted because an earlier point has exactly the same coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Duplicate {
    /// Index of the skipped point.
    pub skipped: u32,
    /// Index of the kept point with the same coordinates (the smallest such index).
    pub kept: u32,
}

/// A broken invariant found by [`Delaunay3d::sanity_check`].
#[derive(Debug, Clone, PartialEq)]
pub enum Violation {
    /// A tetrahedron references a vertex out of range or twice.
    BadVertices {
        /// Tetrahedron (internal index).
        tet: u32,
        /// Its vertices.
        vertices: [u32; 4],
    },
    /// A finite tetrahedron with `orient3d <= 0`.
    NotPositive {
        /// Tetrahedron.
        tet: u32,
    },
    /// `neighbours[tet][face]` does not point back, or the two do not share that face.
    Asymmetric {
        /// Tetrahedron.
        tet: u32,
        /// Local face index.
        face: u8,
    },
    /// An input point strictly inside the circumsphere of a finite tetrahedron.
    NotEmpty {
        /// Tetrahedron.
        tet: u32,
        /// The point inside.
        point: u32,
    },
    /// An input point strictly outside a convex-hull face.
    OutsideHull {
        /// The infinite tetrahedron holding the hull face.
        tet: u32,
        /// The point outside.
        point: u32,
    },
    /// A distinct input point that is no vertex of the tetrahedralisation.
    Missing {
        /// The point.
        point: u32,
    },
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadVertices { tet, vertices } => {
                write!(f, "tetrahedron {tet}: bad vertices {vertices:?}")
            }
            Self::NotPositive { tet } => write!(f, "tetrahedron {tet}: not positively oriented"),
            Self::Asymmetric { tet, face } => {
                write!(
                    f,
                    "tetrahedron {tet}: neighbour across face {face} does not match"
                )
            }
            Self::NotEmpty { tet, point } => {
                write!(
                    f,
                    "tetrahedron {tet}: point {point} inside its circumsphere"
                )
            }
            Self::OutsideHull { tet, point } => {
                write!(
                    f,
                    "hull face of tetrahedron {tet}: point {point} outside the hull"
                )
            }
            Self::Missing { point } => write!(f, "point {point}: not a vertex"),
        }
    }
}

/// For each local vertex `i`, the other three vertices of the tetrahedron in the order whose
/// normal (right-hand rule, Shewchuk's `orient3d` convention) points away from vertex `i`:
/// for a positive tetrahedron `orient3d(face..., v_i) > 0`. Each row is an even permutation of
/// `0 1 2 3` with `i` last.
pub const FACE_VERTICES: [[usize; 3]; 4] = [[1, 3, 2], [0, 2, 3], [0, 3, 1], [0, 1, 2]];

/// A 3D Delaunay tetrahedralisation.
///
/// Finite tetrahedra come first in the internal arrays ([`Self::tetrahedra`] is that prefix);
/// the faces of the convex hull are closed by infinite tetrahedra stored after them, so a
/// neighbour index `>= tetrahedra().len()` means "this face is on the convex hull".
#[derive(Debug, Clone)]
pub struct Delaunay3d {
    points: Vec<[f64; 3]>,
    tets: Vec<[u32; 4]>,
    neighbours: Vec<[u32; 4]>,
    finite: usize,
    duplicates: Vec<Duplicate>,
    dimension: u8,
}

impl Delaunay3d {
    /// Tetrahedralises `points` (`f32`, converted exactly to `f64`).
    ///
    /// # Errors
    /// [`DelaunayError`] for non-finite or huge coordinates (naming the point) or too many
    /// points. Degenerate sets are not errors: see the module docs.
    pub fn new(points: &[Vec3]) -> Result<Self, DelaunayError> {
        Self::from_f64(
            points
                .iter()
                .map(|p| [f64::from(p.x), f64::from(p.y), f64::from(p.z)])
                .collect(),
        )
    }

    /// Tetrahedralises `points` given in `f64`.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn from_f64(points: Vec<[f64; 3]>) -> Result<Self, DelaunayError> {
        if points.len() > MAX_POINTS {
            return Err(DelaunayError::TooManyPoints {
                count: points.len(),
            });
        }
        validate(&points)?;
        let (unique, duplicates) = dedupe(&points);
        let order = sort::brio_order(&points, &unique);
        let mut builder = Builder::new(&points);
        let dimension = builder.build(&order);
        if builder.overflow {
            return Err(DelaunayError::TooManyTetrahedra);
        }
        let (tets, neighbours, finite) = builder.compact();
        Ok(Self {
            points,
            tets,
            neighbours,
            finite,
            duplicates,
            dimension,
        })
    }

    /// Only the finite tetrahedra of `points` (as [`Self::tetrahedra`] of
    /// [`Self::from_f64`], in the same order) and the affine dimension, without the neighbours,
    /// the infinite tetrahedra or a copy of the points: for large inputs that need only the
    /// tetrahedra (at 9M points the neighbours and the compaction's copies are ~2 GB).
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn finite_tetrahedra(points: &[[f64; 3]]) -> Result<(Vec<[u32; 4]>, u8), DelaunayError> {
        if points.len() > MAX_POINTS {
            return Err(DelaunayError::TooManyPoints {
                count: points.len(),
            });
        }
        validate(points)?;
        let (unique, _) = dedupe(points);
        let order = sort::brio_order(points, &unique);
        drop(unique);
        let mut builder = Builder::new(points);
        let dimension = builder.build(&order);
        drop(order);
        if builder.overflow {
            return Err(DelaunayError::TooManyTetrahedra);
        }
        Ok((builder.into_finite(), dimension))
    }

    /// The input points (as `f64`), indexed like the input.
    #[must_use]
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points
    }

    /// The finite tetrahedra, each positively oriented (`orient3d(v0, v1, v2, v3) > 0` in
    /// Shewchuk's convention; [`FACE_VERTICES`] gives outward faces). Empty for degenerate
    /// inputs.
    #[must_use]
    pub fn tetrahedra(&self) -> &[[u32; 4]] {
        &self.tets[..self.finite]
    }

    /// Neighbours of the finite tetrahedra: `neighbours()[t][i]` is the tetrahedron across the
    /// face opposite vertex `i`; a value `>= tetrahedra().len()` marks a convex-hull face.
    #[must_use]
    pub fn neighbours(&self) -> &[[u32; 4]] {
        &self.neighbours[..self.finite]
    }

    /// Every tetrahedron, the finite ones first, then the infinite ones closing the convex
    /// hull (one vertex [`INF`], positive when it is replaced by a far point beyond the hull
    /// face), with their neighbours (`[t][i]` across the face opposite vertex `i`).
    pub(crate) fn all_tetrahedra(&self) -> (&[[u32; 4]], &[[u32; 4]]) {
        (&self.tets, &self.neighbours)
    }

    /// Points skipped because an earlier point has the same coordinates.
    #[must_use]
    pub fn duplicates(&self) -> &[Duplicate] {
        &self.duplicates
    }

    /// Affine dimension of the distinct input points (0 to 3; -1 as 0 for an empty input);
    /// the tetrahedralisation is empty below 3.
    #[must_use]
    pub fn dimension(&self) -> u8 {
        self.dimension
    }

    /// Number of convex-hull faces (infinite tetrahedra).
    #[must_use]
    pub fn hull_face_count(&self) -> usize {
        self.tets.len() - self.finite
    }

    /// Checks every invariant and lists the violations (empty when valid): vertex ranges,
    /// positive orientation of finite tetrahedra, neighbour symmetry and shared faces, every
    /// distinct point being a vertex, and, when `brute_force` is set, the empty-sphere property
    /// and hull convexity against every input point (O(tetrahedra x points): small inputs only).
    /// Empty spheres are checked without perturbation: no point *strictly* inside.
    #[must_use]
    pub fn sanity_check(&self, brute_force: bool) -> Vec<Violation> {
        let mut out = Vec::new();
        let n = self.points.len() as u32;
        let ntets = self.tets.len();
        let mut is_vertex = vec![false; self.points.len()];
        for (t, tet) in self.tets.iter().enumerate() {
            let t = t as u32;
            let finite = (t as usize) < self.finite;
            let infinite_count = tet.iter().filter(|&&v| v == INF).count();
            let in_range = tet.iter().all(|&v| v < n || v == INF);
            let distinct = (0..4).all(|i| (i + 1..4).all(|j| tet[i] != tet[j]));
            if !in_range || !distinct || infinite_count != usize::from(!finite) {
                out.push(Violation::BadVertices {
                    tet: t,
                    vertices: *tet,
                });
                continue;
            }
            for &v in tet {
                if v != INF {
                    is_vertex[v as usize] = true;
                }
            }
            if finite {
                let [a, b, c, d] = tet.map(|v| self.points[v as usize]);
                if orient3d(a, b, c, d) <= 0.0 {
                    out.push(Violation::NotPositive { tet: t });
                }
            }
            for face in 0..4u8 {
                let nb = self.neighbours[t as usize][face as usize];
                let ok = (nb as usize) < ntets && {
                    let other = self.tets[nb as usize];
                    let back = self.neighbours[nb as usize].iter().position(|&x| x == t);
                    back.is_some_and(|j| {
                        let mut mine: Vec<u32> = (0..4)
                            .filter(|&k| k != face as usize)
                            .map(|k| tet[k])
                            .collect();
                        let mut theirs: Vec<u32> =
                            (0..4).filter(|&k| k != j).map(|k| other[k]).collect();
                        mine.sort_unstable();
                        theirs.sort_unstable();
                        mine == theirs
                    })
                };
                if !ok {
                    out.push(Violation::Asymmetric { tet: t, face });
                }
            }
        }
        if self.dimension == 3 {
            let skipped: std::collections::HashSet<u32> =
                self.duplicates.iter().map(|d| d.skipped).collect();
            for (i, &v) in is_vertex.iter().enumerate() {
                if !v && !skipped.contains(&(i as u32)) {
                    out.push(Violation::Missing { point: i as u32 });
                }
            }
        }
        if brute_force {
            for (t, tet) in self.tets.iter().enumerate() {
                if tet.iter().any(|&v| v >= n && v != INF) {
                    continue;
                }
                let t32 = t as u32;
                if t < self.finite {
                    let [a, b, c, d] = tet.map(|v| self.points[v as usize]);
                    for (i, &p) in self.points.iter().enumerate() {
                        if insphere(a, b, c, d, p) > 0.0 {
                            out.push(Violation::NotEmpty {
                                tet: t32,
                                point: i as u32,
                            });
                        }
                    }
                } else {
                    for (i, &p) in self.points.iter().enumerate() {
                        let q = tet.map(|v| if v == INF { p } else { self.points[v as usize] });
                        if orient3d(q[0], q[1], q[2], q[3]) > 0.0 {
                            out.push(Violation::OutsideHull {
                                tet: t32,
                                point: i as u32,
                            });
                        }
                    }
                }
            }
        }
        out
    }
}

/// Rejects NaN, infinite and huge coordinates, naming the first bad point.
fn validate(points: &[[f64; 3]]) -> Result<(), DelaunayError> {
    for (index, p) in points.iter().enumerate() {
        for &value in p {
            if !value.is_finite() {
                return Err(DelaunayError::NonFinite { index, value });
            }
            if value.abs() > MAX_COORDINATE {
                return Err(DelaunayError::TooLarge { index, value });
            }
        }
    }
    Ok(())
}

/// The bit patterns of a point's coordinates, with -0.0 mapped to +0.0 (`x + 0.0`), so that
/// equal coordinates have equal bits.
fn coordinate_bits(p: [f64; 3]) -> [u64; 3] {
    [
        (p[0] + 0.0).to_bits(),
        (p[1] + 0.0).to_bits(),
        (p[2] + 0.0).to_bits(),
    ]
}

/// Distinct points (smallest index of each coordinate triple) and the skipped duplicates.
fn dedupe(points: &[[f64; 3]]) -> (Vec<u32>, Vec<Duplicate>) {
    let key = |i: u32| coordinate_bits(points[i as usize]);
    let mut keyed: Vec<([u64; 3], u32)> = (0..points.len() as u32).map(|i| (key(i), i)).collect();
    keyed.sort_unstable();
    let ids: Vec<u32> = keyed.iter().map(|&(_, i)| i).collect();
    let mut unique = Vec::with_capacity(ids.len());
    let mut duplicates = Vec::new();
    let mut kept = None;
    for &i in &ids {
        match kept {
            Some(k) if key(k) == key(i) => duplicates.push(Duplicate {
                skipped: i,
                kept: k,
            }),
            _ => {
                kept = Some(i);
                unique.push(i);
            }
        }
    }
    unique.sort_unstable();
    duplicates.sort_unstable_by_key(|d| d.skipped);
    (unique, duplicates)
}

/// A tetrahedron slot of the builder: vertices and the neighbours across the faces opposite
/// them.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Cell {
    v: [u32; 4],
    n: [u32; 4],
}

/// One slot of the edge table that links the new tetrahedra of a cavity.
#[derive(Clone, Copy)]
struct EdgeSlot {
    stamp: u32,
    key: u64,
    tet: u32,
    face: u8,
}

/// A boundary face of the cavity: its vertices (oriented away from the cavity), the
/// tetrahedron outside it and that tetrahedron's local index of the face.
#[derive(Clone, Copy)]
struct BoundaryFace {
    vertices: [u32; 3],
    outside: u32,
    outside_face: u8,
}

/// The incremental construction state (the buffers are reused across insertions).
struct Builder<'a> {
    points: &'a [[f64; 3]],
    /// Vertices and neighbours of every tetrahedron slot, side by side (one cache line holds
    /// two).
    cells: Vec<Cell>,
    /// Per tetrahedron: `2 * stamp` when in the current cavity, `2 * stamp + 1` when tested
    /// and not in conflict (stale values from earlier insertions mean "not tested").
    marks: Vec<u32>,
    stamp: u32,
    free: Vec<u32>,
    cavity: Vec<u32>,
    stack: Vec<u32>,
    boundary: Vec<BoundaryFace>,
    new_tets: Vec<u32>,
    edges: Vec<EdgeSlot>,
    edge_stamp: u32,
    last: u32,
    rng: u64,
    /// Set when the tetrahedra no longer fit `u32` indices (the build stops).
    overflow: bool,
}

impl<'a> Builder<'a> {
    fn new(points: &'a [[f64; 3]]) -> Self {
        let cap = points.len() * 7;
        Self {
            points,
            cells: Vec::with_capacity(cap),
            marks: Vec::with_capacity(cap),
            stamp: 0,
            free: Vec::new(),
            cavity: Vec::new(),
            stack: Vec::new(),
            boundary: Vec::new(),
            new_tets: Vec::new(),
            edges: Vec::new(),
            edge_stamp: 0,
            last: 0,
            rng: 0x9E37_79B9_7F4A_7C15,
            overflow: false,
        }
    }

    #[inline(always)]
    fn p(&self, v: u32) -> [f64; 3] {
        self.points[v as usize]
    }

    /// Inserts the points of `order`; returns the affine dimension found.
    fn build(&mut self, order: &[u32]) -> u8 {
        let Some((simplex, dimension)) = self.initial_simplex(order) else {
            return 0;
        };
        if dimension < 3 {
            return dimension;
        }
        self.create_initial(simplex);
        for &v in order {
            if simplex.contains(&v) {
                continue;
            }
            self.insert(v);
            if self.overflow {
                break;
            }
        }
        3
    }

    /// Four affinely independent points, taken greedily along `order`, or the dimension.
    fn initial_simplex(&self, order: &[u32]) -> Option<([u32; 4], u8)> {
        let &a = order.first()?;
        let pa = self.p(a);
        let Some(&b) = order.iter().find(|&&v| self.p(v) != pa) else {
            return Some(([a; 4], 0));
        };
        let pb = self.p(b);
        let Some(&c) = order.iter().find(|&&v| !collinear(pa, pb, self.p(v))) else {
            return Some(([a, b, b, b], 1));
        };
        let pc = self.p(c);
        let Some(&d) = order
            .iter()
            .find(|&&v| orient3d(pa, pb, pc, self.p(v)) != 0.0)
        else {
            return Some(([a, b, c, c], 2));
        };
        Some(([a, b, c, d], 3))
    }

    /// The first tetrahedron and the four infinite tetrahedra around it.
    fn create_initial(&mut self, [a, b, c, d]: [u32; 4]) {
        let first = if orient3d(self.p(a), self.p(b), self.p(c), self.p(d)) > 0.0 {
            [a, b, c, d]
        } else {
            [b, a, c, d]
        };
        self.cells.push(Cell {
            v: first,
            n: [1, 2, 3, 4],
        });
        self.marks.push(0);
        for (i, face) in FACE_VERTICES.iter().enumerate() {
            // Reversed face + infinity: positive when infinity is replaced by a far point on
            // the outer side of the face.
            let [x, y, z] = face.map(|k| first[k]);
            self.cells.push(Cell {
                v: [x, z, y, INF],
                n: [u32::MAX, u32::MAX, u32::MAX, 0],
            });
            self.marks.push(0);
            debug_assert_eq!(self.cells[0].n[i], i as u32 + 1);
        }
        // Link the infinite tetrahedra to each other by their shared faces (brute force).
        for t in 1..5u32 {
            for f in 0..3 {
                let mine = face_key(self.cells[t as usize].v, f);
                for u in 1..5u32 {
                    if u == t {
                        continue;
                    }
                    for g in 0..4 {
                        if face_key(self.cells[u as usize].v, g) == mine {
                            self.cells[t as usize].n[f] = u;
                        }
                    }
                }
            }
        }
        self.last = 0;
    }

    #[inline(always)]
    fn next_random(&mut self) -> u64 {
        // xorshift64: only used to vary the walk's first face.
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        self.rng
    }

    /// Whether the tetrahedron `t` conflicts with point `v` (perturbed predicates).
    #[inline]
    fn in_conflict(&self, t: u32, v: u32) -> bool {
        let tet = self.cells[t as usize].v;
        let p = self.p(v);
        if let Some(k) = tet.iter().position(|&x| x == INF) {
            let q = |i: usize| if tet[i] == INF { p } else { self.p(tet[i]) };
            let o = orient3d(q(0), q(1), q(2), q(3));
            if o != 0.0 {
                return o > 0.0;
            }
            // Coplanar with the hull face: as the finite tetrahedron behind it.
            let behind = self.cells[t as usize].n[k];
            return self.finite_conflict(behind, v);
        }
        self.finite_conflict(t, v)
    }

    #[inline]
    fn finite_conflict(&self, t: u32, v: u32) -> bool {
        let tet = self.cells[t as usize].v;
        let ids = [tet[0], tet[1], tet[2], tet[3], v];
        let pts = [
            self.p(tet[0]),
            self.p(tet[1]),
            self.p(tet[2]),
            self.p(tet[3]),
            self.p(v),
        ];
        insphere_sos(pts, ids) > 0
    }

    /// A tetrahedron in conflict with `v`: the finite one containing it, or an infinite one
    /// whose hull face `v` sees strictly from outside (visibility walk from `last`).
    fn locate(&mut self, v: u32) -> u32 {
        let p = self.p(v);
        let mut t = self.last;
        if self.cells[t as usize].v[0] == DEAD {
            t = self.any_live();
        }
        if let Some(k) = self.cells[t as usize].v.iter().position(|&x| x == INF) {
            t = self.cells[t as usize].n[k];
        }
        let mut came_from = u32::MAX;
        let limit = self.cells.len() + 16;
        for _ in 0..limit {
            let tet = self.cells[t as usize].v;
            let start = (self.next_random() & 3) as usize;
            let mut moved = false;
            for j in 0..4 {
                let i = (start + j) & 3;
                let nb = self.cells[t as usize].n[i];
                if nb == came_from {
                    continue;
                }
                let [x, y, z] = FACE_VERTICES[i];
                if orient3d(self.p(tet[x]), self.p(tet[y]), self.p(tet[z]), p) < 0.0 {
                    came_from = t;
                    t = nb;
                    moved = true;
                    break;
                }
            }
            if !moved || self.cells[t as usize].v.contains(&INF) {
                return t;
            }
        }
        // The walk did not settle (it cannot in a Delaunay triangulation; kept as a guard):
        // scan for any conflicting tetrahedron.
        self.scan_for_conflict(v)
    }

    #[cold]
    fn scan_for_conflict(&self, v: u32) -> u32 {
        (0..self.cells.len() as u32)
            .find(|&t| self.cells[t as usize].v[0] != DEAD && self.in_conflict(t, v))
            .unwrap_or(0)
    }

    #[cold]
    fn any_live(&self) -> u32 {
        (0..self.cells.len() as u32)
            .find(|&t| self.cells[t as usize].v[0] != DEAD)
            .unwrap_or(0)
    }

    /// Inserts point `v` (Bowyer-Watson: delete the conflict region, star its boundary).
    fn insert(&mut self, v: u32) {
        let start = self.locate(v);
        if !self.in_conflict(start, v) {
            // Only for a point equal to a vertex, excluded by the de-duplication.
            return;
        }
        self.stamp += 1;
        let in_mark = 2 * self.stamp;
        let out_mark = in_mark + 1;
        self.cavity.clear();
        self.stack.clear();
        self.boundary.clear();
        self.marks[start as usize] = in_mark;
        self.stack.push(start);
        while let Some(t) = self.stack.pop() {
            self.cavity.push(t);
            for (i, &[f0, f1, f2]) in FACE_VERTICES.iter().enumerate() {
                let nb = self.cells[t as usize].n[i];
                let m = self.marks[nb as usize];
                let inside = if m == in_mark {
                    continue;
                } else if m == out_mark {
                    false
                } else if self.in_conflict(nb, v) {
                    self.marks[nb as usize] = in_mark;
                    self.stack.push(nb);
                    true
                } else {
                    self.marks[nb as usize] = out_mark;
                    false
                };
                if !inside {
                    let tet = self.cells[t as usize].v;
                    let outside_face = self.cells[nb as usize]
                        .n
                        .iter()
                        .position(|&x| x == t)
                        .unwrap_or(0) as u8;
                    self.boundary.push(BoundaryFace {
                        vertices: [tet[f0], tet[f1], tet[f2]],
                        outside: nb,
                        outside_face,
                    });
                }
            }
        }
        // Free the cavity, then star the boundary from v.
        for &t in &self.cavity {
            self.cells[t as usize].v = [DEAD; 4];
            self.free.push(t);
        }
        self.new_tets.clear();
        for bi in 0..self.boundary.len() {
            let face = self.boundary[bi];
            let [x, y, z] = face.vertices;
            let t = match self.free.pop() {
                Some(t) => {
                    self.cells[t as usize] = Cell {
                        v: [x, y, z, v],
                        n: [u32::MAX, u32::MAX, u32::MAX, face.outside],
                    };
                    t
                }
                None if self.cells.len() >= MAX_TETRAHEDRA => {
                    self.overflow = true;
                    return;
                }
                None => {
                    self.cells.push(Cell {
                        v: [x, y, z, v],
                        n: [u32::MAX, u32::MAX, u32::MAX, face.outside],
                    });
                    self.marks.push(0);
                    (self.cells.len() - 1) as u32
                }
            };
            self.cells[face.outside as usize].n[face.outside_face as usize] = t;
            self.new_tets.push(t);
        }
        self.link_new_tets();
        if let Some(&t) = self
            .new_tets
            .iter()
            .find(|&&t| !self.cells[t as usize].v.contains(&INF))
            .or(self.new_tets.first())
        {
            self.last = t;
        }
    }

    /// Links the new tetrahedra `[x, y, z, v]` to each other: the face opposite `x` is shared
    /// with the new tetrahedron whose boundary face has the directed edge `z -> y`, etc.
    fn link_new_tets(&mut self) {
        let needed = (self.new_tets.len() * 3 * 2).next_power_of_two().max(16);
        if self.edges.len() < needed {
            self.edges = vec![
                EdgeSlot {
                    stamp: 0,
                    key: 0,
                    tet: 0,
                    face: 0,
                };
                needed
            ];
            self.edge_stamp = 0;
        }
        self.edge_stamp += 1;
        let stamp = self.edge_stamp;
        let mask = self.edges.len() - 1;
        let bits = self.edges.len().trailing_zeros();
        for ni in 0..self.new_tets.len() {
            let t = self.new_tets[ni];
            let tet = self.cells[t as usize].v;
            // Face opposite local vertex f (0..3) of [x, y, z, v] is the edge
            // (tet[(f + 1) % 3], tet[(f + 2) % 3]) plus v.
            for f in 0..3 {
                let a = tet[(f + 1) % 3];
                let b = tet[(f + 2) % 3];
                let key = (u64::from(a.min(b)) << 32) | u64::from(a.max(b));
                let mut slot = (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize;
                loop {
                    let s = self.edges[slot];
                    if s.stamp != stamp {
                        self.edges[slot] = EdgeSlot {
                            stamp,
                            key,
                            tet: t,
                            face: f as u8,
                        };
                        break;
                    }
                    if s.key == key {
                        self.cells[t as usize].n[f] = s.tet;
                        self.cells[s.tet as usize].n[s.face as usize] = t;
                        break;
                    }
                    slot = (slot + 1) & mask;
                }
            }
        }
    }

    /// The live finite tetrahedra in slot order (the order [`Self::compact`] gives them),
    /// freeing the builder's other arrays first.
    fn into_finite(mut self) -> Vec<[u32; 4]> {
        self.marks = Vec::new();
        self.free = Vec::new();
        self.edges = Vec::new();
        let count = self
            .cells
            .iter()
            .filter(|c| c.v[0] != DEAD && !c.v.contains(&INF))
            .count();
        let mut out = Vec::with_capacity(count);
        out.extend(
            self.cells
                .iter()
                .filter(|c| c.v[0] != DEAD && !c.v.contains(&INF))
                .map(|c| c.v),
        );
        out
    }

    /// Final arrays: live tetrahedra, finite first, with remapped neighbours.
    fn compact(self) -> (Vec<[u32; 4]>, Vec<[u32; 4]>, usize) {
        let mut remap = vec![u32::MAX; self.cells.len()];
        let mut next = 0u32;
        for pass_finite in [true, false] {
            for (t, cell) in self.cells.iter().enumerate() {
                let tet = &cell.v;
                if tet[0] == DEAD || tet.contains(&INF) == pass_finite {
                    continue;
                }
                remap[t] = next;
                next += 1;
            }
        }
        let live = next as usize;
        let mut tets = vec![[0u32; 4]; live];
        let mut neighbours = vec![[0u32; 4]; live];
        let mut finite = 0;
        for (t, &r) in remap.iter().enumerate() {
            if r == u32::MAX {
                continue;
            }
            let tet = self.cells[t].v;
            if !tet.contains(&INF) {
                finite += 1;
            }
            tets[r as usize] = tet;
            neighbours[r as usize] = self.cells[t]
                .n
                .map(|n| remap.get(n as usize).copied().unwrap_or(u32::MAX));
        }
        (tets, neighbours, finite)
    }
}

/// Sorted vertex set of the face opposite local vertex `f`.
fn face_key(tet: [u32; 4], f: usize) -> [u32; 3] {
    let mut k = [0u32; 3];
    let mut j = 0;
    for (i, &v) in tet.iter().enumerate() {
        if i != f {
            k[j] = v;
            j += 1;
        }
    }
    k.sort_unstable();
    k
}

/// Whether three points are exactly collinear (all three coordinate-plane projections of the
/// triangle have zero signed area, decided exactly).
fn collinear(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> bool {
    let proj = |p: [f64; 3], i: usize, j: usize| robust::Coord { x: p[i], y: p[j] };
    [(0, 1), (1, 2), (0, 2)]
        .iter()
        .all(|&(i, j)| robust::orient2d(proj(a, i, j), proj(b, i, j), proj(c, i, j)) == 0.0)
}
