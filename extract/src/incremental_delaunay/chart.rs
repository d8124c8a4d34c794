//! One chart: a template triangle laid flat in its own plane and triangulated with spade's
//! constrained Delaunay over its three corners and the Gaussians assigned to it.

use glam::{DVec2, DVec3};
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

/// A rest triangle in 2D: corners `(0, 0)`, `(|e1| / L, 0)`, `(x, y)` with `y > 0` and `L` the
/// longest edge (a similarity, so Delaunay is the same as in the triangle's 3D plane, and
/// coordinates stay in `[-1, 1]` at any template scale). Counter-clockwise in 2D is the
/// template's winding.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ChartFrame {
    corners: [DVec2; 3],
    /// The rest triangle is degenerate (no Gaussians are meshed in it).
    pub(crate) degenerate: bool,
}

impl ChartFrame {
    /// The frame of the rest corners `v`; degenerate when the longest edge is 0 or
    /// `|(v1 - v0) × (v2 - v0)| <= tol · L²` (twice the area against the longest edge squared).
    pub(crate) fn new(v: [DVec3; 3], tol: f64) -> Self {
        let e1 = v[1] - v[0];
        let e2 = v[2] - v[0];
        let longest = e1.length().max(e2.length()).max((v[2] - v[1]).length());
        let n = e1.cross(e2);
        let ok = longest > 0.0 && longest.is_finite() && n.length() > tol * longest * longest;
        if !ok {
            return Self {
                corners: [DVec2::ZERO, DVec2::X, DVec2::Y],
                degenerate: true,
            };
        }
        // |e1| > 0 here: otherwise n = 0.
        let x = e1 / e1.length();
        let y = n.cross(e1).normalize_or_zero();
        let s = longest.recip();
        Self {
            corners: [
                DVec2::ZERO,
                DVec2::new(e1.length() * s, 0.0),
                DVec2::new(e2.dot(x) * s, e2.dot(y) * s),
            ],
            degenerate: false,
        }
    }

    /// The 2D point of a Gaussian with (possibly negative) barycentric weights `bary` of its
    /// projection onto the triangle's plane, mapped strictly inside:
    /// - inside (all weights `≥ 0`): the homothety `c + (1 - 3m)(b - c)` toward the centroid
    ///   `c`, which keeps Delaunay among such points;
    /// - outside: along the ray from the centroid, into the band between that shrunk triangle
    ///   and `c + (1 - 1.5m)(b_exit - c)`, where `b_exit` is where the ray leaves the triangle;
    ///   farther points go closer to the outer edge of the band. The map is one-to-one, so
    ///   distinct Gaussians stay distinct points.
    pub(crate) fn point(&self, bary: [f64; 3], margin: f64) -> Point2<f64> {
        const THIRD: f64 = 1.0 / 3.0;
        let u = bary.map(|b| b - THIRD);
        // Fraction of the way to `bary` at which the ray from the centroid exits (1 inside).
        let exit = u
            .iter()
            .filter(|&&x| x < 0.0)
            .map(|&x| THIRD / -x)
            .fold(1.0f64, f64::min);
        let scale = if exit >= 1.0 || !exit.is_finite() {
            1.0 - 3.0 * margin
        } else {
            exit * ((1.0 - 3.0 * margin) + 1.5 * margin * (1.0 - exit))
        };
        let w = u.map(|x| THIRD + scale * x);
        let p = self.corners[0] * w[0] + self.corners[1] * w[1] + self.corners[2] * w[2];
        Point2::new(p.x, p.y)
    }
}

/// Outcome of triangulating one chart.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct ChartMesh {
    /// Triangles in output vertex ids, counter-clockwise as the template triangle.
    pub(crate) triangles: Vec<[u32; 3]>,
    /// Gaussians of the chart that are not vertices (duplicates of an earlier one, or every
    /// Gaussian of a degenerate chart).
    pub(crate) unmeshed: u32,
}

/// Triangulates a chart: `corners` are the template vertex ids, `members` the Gaussians as
/// `(output vertex id, barycentric weights)` in ascending id order (the insertion order, so
/// co-circular ties resolve the same way every time).
pub(crate) fn triangulate(
    frame: &ChartFrame,
    corners: [u32; 3],
    members: &[(u32, [f64; 3])],
    margin: f64,
) -> ChartMesh {
    let [a, b, c] = corners;
    let whole = |unmeshed: usize| ChartMesh {
        triangles: vec![corners],
        unmeshed: unmeshed as u32,
    };
    if frame.degenerate || members.is_empty() {
        return whole(members.len());
    }
    if let [(g, _)] = members {
        // One point strictly inside a triangle has one triangulation: the fan.
        return ChartMesh {
            triangles: vec![[a, b, *g], [b, c, *g], [c, a, *g]],
            unmeshed: 0,
        };
    }
    WORK.with_borrow_mut(|work| {
        let Work { cdt, ids } = work;
        // `clear` keeps the allocations and resets the hint generator: the same state as a
        // new triangulation, so the result does not depend on earlier charts.
        cdt.clear();
        ids.clear();
        triangulate_with(frame, corners, members, margin, cdt, ids)
            .unwrap_or_else(|| whole(members.len()))
    })
}

/// A chart triangulation and its vertex-id map, reused between charts on one thread (a fresh
/// spade triangulation per chart spent much of its time allocating).
#[derive(Default)]
struct Work {
    cdt: ConstrainedDelaunayTriangulation<Point2<f64>>,
    ids: Vec<u32>,
}

thread_local! {
    /// This thread's triangulation buffers.
    static WORK: std::cell::RefCell<Work> = std::cell::RefCell::default();
}

/// [`triangulate`] into the cleared `cdt` and `ids`; `None` when the chart falls back to the
/// template triangle.
fn triangulate_with(
    frame: &ChartFrame,
    corners: [u32; 3],
    members: &[(u32, [f64; 3])],
    margin: f64,
    cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>,
    ids: &mut Vec<u32>,
) -> Option<ChartMesh> {
    let a = corners[0];
    let mut handles = [spade::handles::FixedVertexHandle::from_index(0); 3];
    for (slot, p) in handles.iter_mut().zip(frame.corners) {
        *slot = cdt.insert(Point2::new(p.x, p.y)).ok()?;
    }
    // The corners are distinct (the frame is not degenerate), so there are three vertices.
    if cdt.num_vertices() != 3 {
        return None;
    }
    // Vertex handles are dense indices in insertion order; `ids` maps them to output ids.
    ids.resize(3, u32::MAX);
    for (h, id) in handles.iter().zip(corners) {
        if let Some(slot) = ids.get_mut(h.index()) {
            *slot = id;
        }
    }
    // The constraints are the hull of a triangle and its interior points; they document (and
    // enforce, should rounding ever put a point on an edge) that the template edges survive.
    cdt.add_constraint(handles[0], handles[1]);
    cdt.add_constraint(handles[1], handles[2]);
    cdt.add_constraint(handles[2], handles[0]);
    let mut unmeshed = 0u32;
    for &(g, bary) in members {
        let before = cdt.num_vertices();
        if cdt.insert(frame.point(bary, margin)).is_err() {
            unmeshed += 1;
            continue;
        }
        if cdt.num_vertices() == before {
            // A duplicate of an earlier point: spade kept one vertex.
            unmeshed += 1;
        } else {
            ids.push(g);
        }
    }
    // Every point is strictly inside, so the hull is the three corners; anything else means
    // rounding pushed a point out and the chart falls back to the template triangle.
    if cdt.convex_hull_size() != 3 || ids.len() != cdt.num_vertices() {
        return None;
    }
    let triangles = cdt
        .inner_faces()
        .map(|f| {
            f.vertices()
                .map(|v| ids.get(v.fix().index()).copied().unwrap_or(a))
        })
        .collect();
    Some(ChartMesh {
        triangles,
        unmeshed,
    })
}
