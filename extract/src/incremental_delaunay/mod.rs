//! Incremental Delaunay meshing of triangle-bound Gaussians (docs/conventions.md §6).
//!
//! # Design
//! A bound Gaussian has a fixed place on the template, so a triangulation made in the
//! template's rest (canonical) domain stays valid while the template moves: each frame only
//! moves vertices. Every template triangle is a *chart*: it is laid flat in its own plane
//! (module `chart`) and triangulated with spade's constrained Delaunay over its three corners and the
//! Gaussians assigned to it. There are no points on template edges, so two charts meet exactly
//! along the template edge they share and the union is watertight whenever the template is
//! (every template edge lies in exactly the two charts that share it; interior edges lie in two
//! triangles of one chart). Triangles keep the template's winding.
//!
//! **Assignment.** At every frame each Gaussian is assigned to the deformed template triangle
//! nearest to its deformed mean (exact point-triangle distance, ties to the smallest triangle
//! id, found with geometry's `TriangleBvh` over the deformed triangles, refitted per frame). A Gaussian *hops* when that
//! triangle is no longer its chart; only the charts it leaves and enters are re-triangulated.
//! With a hop threshold `τ > 0` ([`DelaunayOptions::hop_threshold`]) a Gaussian stays in its
//! chart until another triangle is nearer by more than `τ` times the mean template edge length
//! (hysteresis: fewer hops, but a Gaussian may be meshed in a chart it has left). A full
//! rebuild every `N` frames ([`DelaunayOptions::rebuild_every`]) re-assigns every Gaussian to
//! its nearest triangle and bounds that drift; at `τ = 0` a rebuild changes nothing. Updates
//! that cost more than a rebuild (large non-rigid motion, Gaussians far off their triangles)
//! are followed by rebuilds ([`AutoRebuild`], on by default).
//!
//! **Hop detection** (module `certify`). Proving that the other ~99.7% of the Gaussians did
//! not hop is most of an update, so it is done with motion-bounded certificates (Verlet-list
//! style) instead of a search per Gaussian. Each chart keeps a *snapshot* of the triangles
//! near it (and the BVH *frontier* holding all the others); each frame it fits an affine map
//! from the snapshot to the current neighbourhood and measures how far the neighbourhood's
//! vertices are from following it. An exact check of a Gaussian leaves a certificate: its
//! position pulled back to the snapshot, an upper bound of its own distance and lower bounds
//! of every other distance, with the (up to [`MAX_CLOSE`]) competitors within
//! [`CLOSE_GAP_REL`] of the chart size listed apart, each with its own bound. Point-triangle
//! distances change by at most the motion of the point and of the corners, and scale by at
//! most the extreme singular values of the fit, so as long as the bounds keep the own triangle
//! strictly nearest (by more than [`FILTER_MARGIN_REL`]), nothing is computed; otherwise the
//! own distance is computed exactly and compared with the bounds again, and only the listed
//! competitors whose bound is still inconclusive are compared with their exact distances
//! (ties resolve as in a full search); triangles outside the snapshot are excluded by testing
//! the frontier's boxes against the chart's reach. Gaussians whose certificate fails get the
//! exact search (one per chart against the snapshot's triangles) and a new certificate; a
//! chart where an outside triangle comes near takes a new snapshot.
//! Rebuilds do not compute certificates; the next update does.
//!
//! **Canonical coordinates.** In chart `T`, Gaussian `i` sits at the barycentric weights of its
//! canonical (rest-pose) mean projected onto the plane of the *rest* triangle `T`, mapped
//! strictly inside `T`: points inside shrink toward the centroid by
//! [`DelaunayOptions::interior_margin`] (a homothety, so their Delaunay triangulation is the
//! same), points outside (Gaussians beside their triangle, or that hopped in) go one-to-one
//! into the thin band left between that shrunk triangle and the edges. These depend only on
//! `(i, T)`, never on the frame, so a chart's triangulation depends only on which Gaussians
//! it holds. Consequence (tested): at `τ = 0` the incremental mesh of every frame equals, as a
//! set of triangles over the same vertex ids, the mesh a fresh [`IncrementalDelaunay`] builds
//! from scratch at that frame; at any `τ` it equals a from-scratch triangulation of the
//! current assignment ([`IncrementalDelaunay::triangulate_all`]).
//!
//! **Lifting.** Output vertex `v < V` is template vertex `v` at its deformed position; vertex
//! `V + i` is Gaussian `i`, placed by [`Lift`]: at its deformed mean (default), or by the
//! chart triangle's own motion: its canonical (unshrunk, possibly negative) barycentric
//! weights on the deformed triangle plus its canonical plane offset along the deformed unit
//! normal (at rest this gives the canonical mean back).
//!
//! # Degenerate input
//! - Duplicate Gaussians (same chart, same canonical weights): the lowest id becomes the vertex,
//!   the others are left unreferenced (counted in [`FrameStats::unmeshed`]).
//! - Gaussians on template edges or vertices: the interior margin moves them inside one chart.
//! - Zero-area (or collinear, per [`DelaunayOptions::degenerate_tol`]) rest triangles: the chart
//!   is the template triangle itself; Gaussians assigned to it stay unreferenced.
//! - NaN, infinite or huge coordinates (template, canonical or deformed means), wrong array
//!   lengths, bad options: a [`DelaunayError`]; nothing panics.
//!
//! # Error against run time
//! `cargo run --release -p trisplat-bench -- delaunay`: FLAME template (5,023 vertices, 9,976
//! triangles), 99,760 bound Gaussians (10 per triangle, normal offset ±0.15 k, in-plane jitter
//! ±0.3 k), 60 frames of a jaw-like bend plus twist (the twist shears the whole head by ~0.5%
//! per frame, the bend's blend band stretches by up to ~5% per frame), 2 threads on the shared
//! 2-core machine (load average ~1.5 while measuring). Deforming the Gaussians
//! (~1.3 ms/frame) is not included; the times include collecting the triangle list. At `τ = 0`,
//! 0.33% of the Gaussians hop per frame (6.1% of the charts are redone), 5.1% get a full check
//! (the others are settled by their certificates), and the incremental mesh equals the
//! rebuilt one on all 60 frames. Medians over frames 1-59: see `docs/benchmarks.md` for the
//! runs behind the ≥ 5× claim (update ~9-10 ms against a ~48-55 ms rebuild wall, ~16-18 ms
//! against ~90 ms of process CPU, one thread ~17 ms against ~92 ms; the machine's noise moves
//! single runs by ±10%).
//!
//! Where an update's time goes (one thread, ~17 ms): the certificate pass over every Gaussian
//! (its means loaded batch by batch, 64 charts at a time, so the loads stream instead of
//! missing the cache chart by chart), exact distances for the ~45% of Gaussians whose bounds
//! are inconclusive (mostly near-ties: a Gaussian almost as near to a neighbouring triangle
//! as to its own, which no motion bound can settle), per chart the affine fit and the test
//! of the frontier's boxes (~1.5 ms each), the full checks of the ~5% whose certificate
//! failed, re-triangulating the charts Gaussians left or entered, and collecting the 210k
//! output triangles. Two measures removed most of the rest: snapshots *rebase* when their
//! neighbourhood drifts ([`REBASE_REL`]), so bounds pay the drift once instead of every frame;
//! and since most hops at `τ = 0` are a Gaussian near a tie going back where it was, each
//! chart keeps its last three meshes by member list and takes one again instead of
//! triangulating (55% of the touched charts).
//!
//! | τ (× mean edge) | rebuild every | ms/frame (mean, rebuilds incl.) | ms/frame (median) | hopped/frame | Chamfer L1 | flipped triangles |
//! |---:|---:|---:|---:|---:|---:|---:|
//! | 0 | never | 9.6 | 8.8 | 0.33% | 4.468e-4 | 2.27% |
//! | 0 | 10 | 16.4 | 8.7 | 0.30% | 4.468e-4 | 2.27% |
//! | 0.05 | never | 5.7 | 5.0 | 0.01% | 4.454e-4 | 2.82% |
//! | 0.05 | 10 | 12.3 | 4.4 | 0.00% | 4.470e-4 | 2.39% |
//! | 0.1 | never | 5.4 | 4.5 | 0.01% | 4.468e-4 | 2.85% |
//! | 0.1 | 10 | 12.0 | 4.1 | 0.00% | 4.471e-4 | 2.39% |
//! | 0.25 | never | 4.9 | 4.1 | 0.00% | 4.459e-4 | 2.86% |
//! | 0.25 | 10 | 11.9 | 4.0 | 0.00% | 4.469e-4 | 2.39% |
//! | 0.5 | never | 4.7 | 3.9 | 0.00% | 4.463e-4 | 2.86% |
//! | 0.5 | 10 | 12.2 | 3.9 | 0.00% | 4.469e-4 | 2.39% |
//!
//! (Load average ~1.5 during the table; the full rebuild took 50.4 ms/frame in the same
//! run.) With a rebuild period the update after each rebuild checks every Gaussian again to
//! issue new certificates, which is most of the difference between the mean and the median.
//! Chamfer (surface mode, 20k samples per side, every 5th frame, against the deformed
//! template) hardly moves: with [`Lift::Means`] the vertices are the Gaussian means wherever
//! they are meshed, and the Gaussians' own offsets dominate it. The sensitive error is the
//! share of output triangles facing against their chart's deformed triangle, which grows from
//! 2.27% (exact assignment) to 2.86% when Gaussians stay in charts they have left; a rebuild
//! every 10 frames keeps it at 2.39%.
//!
//! Work is split over Gaussians and charts with rayon; every item is computed independently and
//! collected in order, so results do not depend on the thread count.

mod certify;
mod chart;

use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::spatial::{MAX_COORDINATE, SpatialError, TriangleBvh};

use self::certify::is_flat;
use self::certify::{Bounds, Certificate, Close, Competitors, Fit, LocalFrame, Snapshot};
pub use self::certify::{CLOSE_GAP_REL, FLAT_RATIO, MAX_CLOSE, REBASE_REL, SNAPSHOT_MARGIN_REL};
use self::chart::{ChartFrame, ChartMesh, triangulate};

/// Default hop threshold (relative to the mean template edge length): 0, every change of
/// nearest triangle is a hop, and the result equals a from-scratch triangulation of the frame.
pub const DEFAULT_HOP_THRESHOLD: f64 = 0.0;

/// Default shrink of canonical barycentric weights toward the centroid (`b' = (1 - 3m) b + m`):
/// a point on an edge ends up `m` (relative) inside, far above the rounding of the 2D
/// coordinates (~1e-16) and far below anything visible.
pub const DEFAULT_INTERIOR_MARGIN: f64 = 1e-3;

/// A candidate triangle is dismissed by a lower bound only when the bound exceeds the needed
/// distance by this fraction of the template's bounding-box diagonal, far above the f64
/// rounding of the distances (so the answer is the same as the exact search's).
pub const FILTER_MARGIN_REL: f64 = 1e-9;

/// Default degeneracy tolerance of rest triangles: degenerate when twice the area is at most
/// this times the longest edge squared (height below 1e-9 of the longest edge).
pub const DEFAULT_DEGENERATE_TOL: f64 = 1e-9;

/// Where Gaussian vertices are placed each frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Lift {
    /// At the Gaussian's deformed mean.
    #[default]
    Means,
    /// Moved with the chart triangle: canonical plane barycentric weights on the deformed
    /// triangle plus the canonical plane offset along its unit normal.
    Surface,
}

/// Options of [`IncrementalDelaunay`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DelaunayOptions {
    /// Hop hysteresis `τ`, relative to the mean template edge length: a Gaussian leaves its
    /// chart only when another triangle is nearer by more than `τ` times that length
    /// ([`DEFAULT_HOP_THRESHOLD`]). Finite and `≥ 0`.
    pub hop_threshold: f64,
    /// Rebuild from scratch every this many updates (0: never).
    pub rebuild_every: usize,
    /// Rebuild from scratch instead of updating while updates cost more than rebuilds (see
    /// [`AutoRebuild`]); `false` keeps updating whatever the motion.
    pub auto_rebuild: bool,
    /// Placement of Gaussian vertices.
    pub lift: Lift,
    /// Shrink of canonical weights toward the centroid ([`DEFAULT_INTERIOR_MARGIN`]), in
    /// `(0, 1/3)`.
    pub interior_margin: f64,
    /// Degeneracy tolerance of rest triangles ([`DEFAULT_DEGENERATE_TOL`]), finite and `≥ 0`.
    pub degenerate_tol: f64,
}

impl Default for DelaunayOptions {
    fn default() -> Self {
        Self {
            hop_threshold: DEFAULT_HOP_THRESHOLD,
            rebuild_every: 0,
            auto_rebuild: true,
            lift: Lift::Means,
            interior_margin: DEFAULT_INTERIOR_MARGIN,
            degenerate_tol: DEFAULT_DEGENERATE_TOL,
        }
    }
}

/// Errors of incremental Delaunay meshing.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DelaunayError {
    /// The template has no triangles.
    #[error("the template has no triangles")]
    NoTriangles,
    /// A template triangle names a vertex the template does not have.
    #[error("template triangle {triangle} names vertex {vertex}, but there are {vertex_count}")]
    BadTriangle {
        /// Triangle index.
        triangle: usize,
        /// The vertex it names.
        vertex: u32,
        /// Template vertices.
        vertex_count: usize,
    },
    /// An option is out of range.
    #[error("option {name} is out of range")]
    InvalidOption {
        /// Which option.
        name: &'static str,
    },
    /// A position array has the wrong length.
    #[error("{what} has {got} entries, expected {expected}")]
    Count {
        /// Which array.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// A coordinate is NaN, infinite or larger than `MAX_COORDINATE` in magnitude.
    #[error("{what} {index} is not finite or too large")]
    BadCoordinate {
        /// Which array (template vertex, canonical mean, deformed vertex, deformed mean).
        what: &'static str,
        /// Index in it.
        index: usize,
    },
    /// Template vertices plus Gaussians exceed `u32` vertex ids.
    #[error("{count} output vertices do not fit u32 ids")]
    TooMany {
        /// Vertices needed.
        count: usize,
    },
    /// The triangle BVH refused the deformed template (not expected after the checks above).
    #[error("deformed template: {0}")]
    Bvh(#[from] SpatialError),
}

/// What one update did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Number of updates before this one.
    pub frame: usize,
    /// Whether this update rebuilt everything (first frame or rebuild period).
    pub rebuilt: bool,
    /// Gaussians that changed chart (all assigned Gaussians on a rebuild are not counted).
    pub hopped: usize,
    /// Charts whose mesh was replaced: triangulated, or (on an update) taken back from the
    /// chart's last meshes when its members are again what they were then.
    pub charts_redone: usize,
    /// Gaussians whose full nearest-triangle check ran (the others were settled by their
    /// motion certificate, possibly with an exact comparison against a few listed close
    /// competitors; see module `certify`).
    pub searches: usize,
    /// Gaussians that are not vertices of the mesh (duplicates, degenerate charts).
    pub unmeshed: usize,
    /// Wall time of the update in milliseconds.
    pub millis: f64,
}

/// Meshes each chart keeps of the member lists it held before (see
/// `IncrementalDelaunay::remesh`).
const CACHED_MESHES: usize = 3;

/// Charts per task of the hop search (their means are loaded together).
const CHART_BATCH: usize = 64;

/// Room left in each chart's member and certificate lists for Gaussians hopping in, so that
/// they are rarely moved away from their neighbours in memory.
const SPARE_CAPACITY: usize = 4;

/// At hop threshold τ > 0 (where the choice changes the meshes and must not depend on the
/// machine), an update that fully checks more than this fraction of the Gaussians (their
/// motion certificates failed) is judged to cost more than a rebuild: on the LAM head (20k
/// Gaussians up to centimetres off their triangles, the head turning every frame) 13% checks
/// cost 1.4x a rebuild, 23% 1.8x, 50% 3.5-5x; on the FLAME benchmark 5% cost a fifth of one.
pub const AUTO_REBUILD_CHECKED: f64 = 0.10;
/// At τ > 0, an update that redoes more than this fraction of the charts is judged to cost
/// about a rebuild.
pub const AUTO_REBUILD_CHARTS: f64 = 0.25;
/// Rebuilds before the first probe of the update path after a costly update. A probe is
/// dear (the first update after a rebuild certifies every Gaussian: 0.5-1.2 s on the LAM head
/// against a 37 ms rebuild), hence long runs of rebuilds between probes.
const AUTO_BACKOFF_FIRST: usize = 64;
/// Factor by which a costly probe lengthens the next run of rebuilds.
const AUTO_BACKOFF_GROWTH: usize = 4;
/// Longest run of rebuilds between probes.
const AUTO_BACKOFF_MAX: usize = 1024;

/// The automatic choice between updating and rebuilding ([`DelaunayOptions::auto_rebuild`]).
/// An update judged costly is followed by a run of rebuilds; after it the update path is
/// probed again, and a probe judged costly makes the next run [`AUTO_BACKOFF_GROWTH`] times
/// longer ([`AUTO_BACKOFF_FIRST`] up to [`AUTO_BACKOFF_MAX`]). The first update after a
/// rebuild certifies every Gaussian and is not judged; the second is.
///
/// The verdict: at hop threshold 0 an update equals a rebuild (tested), so the choice changes
/// only the time and is made by the clock (the update took longer than the last rebuild); at
/// τ > 0 a rebuild resets the hysteresis and changes the meshes, so the choice counts work
/// instead ([`AUTO_REBUILD_CHECKED`], [`AUTO_REBUILD_CHARTS`]) and a run gives the same meshes
/// on any machine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AutoRebuild {
    /// Rebuilds still to do before the next probe.
    rebuilds_left: usize,
    /// Rebuilds after the next costly update.
    backoff: usize,
    /// Wall time of the last rebuild, milliseconds.
    rebuild_ms: f64,
}

impl Default for AutoRebuild {
    fn default() -> Self {
        Self {
            rebuilds_left: 0,
            backoff: AUTO_BACKOFF_FIRST,
            rebuild_ms: f64::INFINITY,
        }
    }
}

impl AutoRebuild {
    /// Whether an update that took `update_ms` with these counts cost more than a rebuild.
    fn costly(
        &self,
        stats: &FrameStats,
        update_ms: f64,
        by_clock: bool,
        gaussians: usize,
        charts: usize,
    ) -> bool {
        if by_clock {
            update_ms > self.rebuild_ms
        } else {
            stats.searches as f64 > AUTO_REBUILD_CHECKED * gaussians as f64
                || stats.charts_redone as f64 > AUTO_REBUILD_CHARTS * charts as f64
        }
    }

    /// Takes the verdict on a judged update.
    fn judge(&mut self, costly: bool) {
        if costly {
            self.rebuilds_left = self.backoff;
            self.backoff = (self.backoff * AUTO_BACKOFF_GROWTH).min(AUTO_BACKOFF_MAX);
        } else {
            self.backoff = AUTO_BACKOFF_FIRST;
        }
    }
}

/// Shared inputs of the per-chart hop search of one frame.
struct SearchContext<'a> {
    bvh: &'a TriangleBvh,
    positions: &'a [DVec3],
    /// Flat triangles (see [`FLAT_RATIO`]); `None` when there are none.
    flat: Option<&'a [bool]>,
}

/// Per-thread buffers of the hop search.
#[derive(Default)]
struct Scratch {
    stack: Vec<u32>,
    found: Vec<u32>,
    /// Candidate triangles: id, padded box (min, max), squared box distance from the centroid.
    candidates: Vec<(u32, DVec3, DVec3, f64)>,
    /// Gaussians to check exactly: index in the chart, id, deformed mean, squared distance
    /// to the chart.
    pending: Vec<(usize, u32, DVec3, f64)>,
    /// Per BVH node, the token of the last frontier computation that marked it.
    marks: Vec<u32>,
    token: u32,
    frontier: Vec<u32>,
    /// The deformed means of a batch of charts' members.
    gathered: Vec<DVec3>,
    /// A snapshot's vertices while it is rebased.
    saved: Vec<DVec3>,
    /// A snapshot's vertices at their current positions (see `Snapshot::fit`).
    vertices: Vec<DVec3>,
    /// Per member while rebasing: its current bounds (own, listed competitors, others).
    current: Vec<(f64, [f64; MAX_CLOSE], f64)>,
    /// Members whose certificate did not settle them at once.
    unsettled: Vec<Unsettled>,
    /// Members checked against their exact own distance this frame: index in the chart,
    /// own distance, lower bounds of the listed competitors' and of every other distance.
    exact: Vec<(usize, f64, [f64; MAX_CLOSE], f64)>,
}

impl Scratch {
    /// A fresh token for `marks`, sized to `len` nodes.
    fn next_token(&mut self, len: usize) -> u32 {
        if self.marks.len() != len || self.token == u32::MAX {
            self.marks.clear();
            self.marks.resize(len, 0);
            self.token = 0;
        }
        self.token += 1;
        self.token
    }
}

thread_local! {
    /// Buffers of the hop search on this thread, kept between frames.
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
}

/// A chart's certificate state.
#[derive(Clone, Debug, Default)]
struct ChartState {
    /// Certificates of the chart's members, in the order of its member list.
    certificates: Vec<Certificate>,
    /// Their competitors' side, in the same order.
    competitors: Vec<Competitors>,
    /// The neighbourhood snapshot the certificates refer to.
    snapshot: Option<Snapshot>,
}

impl ChartState {
    /// `len` members without certificates and no snapshot.
    fn empty(len: usize) -> Self {
        let mut certificates = Vec::with_capacity(len + SPARE_CAPACITY);
        certificates.resize(len, Certificate::NONE);
        let mut competitors = Vec::with_capacity(len + SPARE_CAPACITY);
        competitors.resize(len, Competitors::NONE);
        Self {
            certificates,
            competitors,
            snapshot: None,
        }
    }

    /// Drops member `k`'s certificate (the member left the chart).
    fn remove(&mut self, k: usize) {
        if k < self.certificates.len() {
            self.certificates.remove(k);
            self.competitors.remove(k);
        }
    }

    /// Makes room for a member without a certificate at `k` (a Gaussian hopped in).
    fn insert_empty(&mut self, k: usize) {
        if k <= self.certificates.len() {
            self.certificates.insert(k, Certificate::NONE);
            self.competitors.insert(k, Competitors::NONE);
        }
    }

    /// Forgets every certificate (`len` members).
    fn clear(&mut self, len: usize) {
        self.certificates.clear();
        self.certificates.resize(len, Certificate::NONE);
        self.competitors.clear();
        self.competitors.resize(len, Competitors::NONE);
    }
}

/// A chart member whose certificate did not settle it at once (see
/// [`IncrementalDelaunay::hops_of_chart`]).
#[derive(Clone, Copy, Debug)]
struct Unsettled {
    /// Index in the chart's member list.
    k: usize,
    /// Deformed mean.
    q: DVec3,
    /// Distance of `q` from the chart's centroid.
    from_centre: f64,
    /// The certificate's bounds now.
    bounds: Bounds,
}

/// The charts' part of a frame update, gathered per rayon task.
#[derive(Default)]
struct Outcome {
    /// (Gaussian, new chart).
    moves: Vec<(u32, u32)>,
    /// Gaussians checked exactly.
    checked: usize,
    /// Gaussians checked against their close competitors only.
    checked_close: usize,
    /// Charts that took a new snapshot.
    refreshed: usize,
}

impl Outcome {
    fn merge(mut self, mut other: Self) -> Self {
        self.moves.append(&mut other.moves);
        self.checked += other.checked;
        self.checked_close += other.checked_close;
        self.refreshed += other.refreshed;
        self
    }
}

/// A chart mesh kept for when the chart holds the same Gaussians again.
#[derive(Clone, Debug)]
struct CachedChart {
    /// The chart's members when the mesh was made.
    members: Vec<u32>,
    mesh: ChartMesh,
}

/// Per-Gaussian placement in its chart.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Anchor {
    /// Barycentric weights of the canonical mean's projection onto the rest chart triangle's
    /// plane (not shrunk; negative outside the triangle).
    bary: [f64; 3],
    /// Signed distance of the canonical mean from that plane (along the unit normal).
    offset: f64,
}

/// Incremental Delaunay mesh of bound Gaussians over an animated template (see the module
/// documentation).
#[derive(Debug)]
pub struct IncrementalDelaunay {
    options: DelaunayOptions,
    triangles: Vec<[u32; 3]>,
    vertex_count: usize,
    rest_corners: Vec<[DVec3; 3]>,
    rest_normals: Vec<DVec3>,
    frames: Vec<ChartFrame>,
    canonical: Vec<DVec3>,
    /// Nearest rest triangle of each canonical mean (seeds the rebuild searches).
    rest_nearest: Vec<u32>,
    /// Hop threshold in world units.
    hop_distance: f64,
    /// Bounding-box diagonal of the rest template (margins of the motion filter).
    diagonal: f64,
    // State after the last update.
    assigned: Vec<u32>,
    anchors: Vec<Anchor>,
    members: Vec<Vec<u32>>,
    charts: Vec<ChartMesh>,
    /// Per chart: its last [`CACHED_MESHES`] meshes before the current one, most recent
    /// first, with the member lists they were made from.
    previous: Vec<Vec<CachedChart>>,
    /// The deformed template's triangles, refitted every frame, rebuilt with the charts.
    bvh: Option<TriangleBvh>,
    /// Per triangle of the deformed template: flat in the sense of [`FLAT_RATIO`].
    flat: Vec<bool>,
    vertices: Vec<DVec3>,
    /// Per chart: its snapshot and its members' certificates (module `certify`), in the
    /// order of `members`; valid only while `certified`.
    states: Vec<ChartState>,
    /// Whether `states` belong to the current state (false after a
    /// rebuild, which does not compute them: the next update does).
    certified: bool,
    updates: usize,
    since_rebuild: usize,
    auto: AutoRebuild,
}

/// The first point that is not finite or exceeds [`MAX_COORDINATE`] is an error. Chunks are
/// scanned without early exit (a branch-free pass the compiler vectorises; rayon's
/// `position_first` per point cost more than the update it guards), and the offending index
/// is looked up only in the first bad chunk.
fn check_coordinates<P: Coordinates>(
    points: &[P],
    what: &'static str,
) -> Result<(), DelaunayError> {
    const CHUNK: usize = 4096;
    let bad = |p: &P| !p.within_limit();
    let chunk = points
        .par_chunks(CHUNK)
        .position_first(|c| c.iter().fold(false, |any, p| any | bad(p)));
    match chunk.and_then(|c| {
        let start = c * CHUNK;
        points[start..].iter().position(bad).map(|i| start + i)
    }) {
        Some(index) => Err(DelaunayError::BadCoordinate { what, index }),
        None => Ok(()),
    }
}

/// Points whose coordinates [`check_coordinates`] checks: template vertices (f64) and
/// Gaussian means (f32).
trait Coordinates: Sync {
    /// Finite and at most [`MAX_COORDINATE`] in magnitude (`max_element` skips NaN, hence the
    /// separate finiteness test).
    fn within_limit(&self) -> bool;
}

impl Coordinates for Vec3 {
    fn within_limit(&self) -> bool {
        self.is_finite() & (self.abs().max_element() <= MAX_COORDINATE)
    }
}

impl Coordinates for DVec3 {
    fn within_limit(&self) -> bool {
        self.is_finite() & (self.abs().max_element() <= f64::from(MAX_COORDINATE))
    }
}

/// Per triangle of the BVH: flat in the sense of [`FLAT_RATIO`] (see `certify::is_flat`).
fn flat_triangles(bvh: &TriangleBvh) -> Vec<bool> {
    (0..bvh.triangle_count())
        .into_par_iter()
        .with_min_len(1024)
        .map(|t| bvh.corners(t).is_none_or(is_flat))
        .collect()
}

impl IncrementalDelaunay {
    /// A mesher for `rest` (the canonical template) and Gaussians whose canonical means (their
    /// world-space means with the template at rest) are `canonical_means`. Nothing is meshed
    /// until the first [`IncrementalDelaunay::update`].
    ///
    /// # Errors
    /// [`DelaunayError::NoTriangles`], [`DelaunayError::BadTriangle`],
    /// [`DelaunayError::InvalidOption`], [`DelaunayError::BadCoordinate`],
    /// [`DelaunayError::TooMany`].
    pub fn new(
        rest: &TriMesh,
        canonical_means: &[Vec3],
        options: DelaunayOptions,
    ) -> Result<Self, DelaunayError> {
        let o = &options;
        if !(o.hop_threshold.is_finite() && o.hop_threshold >= 0.0) {
            return Err(DelaunayError::InvalidOption {
                name: "hop_threshold",
            });
        }
        if !(o.interior_margin > 0.0 && o.interior_margin < 1.0 / 3.0) {
            return Err(DelaunayError::InvalidOption {
                name: "interior_margin",
            });
        }
        if !(o.degenerate_tol.is_finite() && o.degenerate_tol >= 0.0) {
            return Err(DelaunayError::InvalidOption {
                name: "degenerate_tol",
            });
        }
        let positions = rest.positions();
        let triangles = rest.triangles().to_vec();
        if triangles.is_empty() {
            return Err(DelaunayError::NoTriangles);
        }
        let vertex_count = positions.len();
        for (triangle, t) in triangles.iter().enumerate() {
            if let Some(&vertex) = t.iter().find(|&&v| v as usize >= vertex_count) {
                return Err(DelaunayError::BadTriangle {
                    triangle,
                    vertex,
                    vertex_count,
                });
            }
        }
        let count = vertex_count + canonical_means.len();
        if u32::try_from(count).is_err() || u32::try_from(triangles.len()).is_err() {
            return Err(DelaunayError::TooMany { count });
        }
        check_coordinates(positions, "template vertex")?;
        check_coordinates(canonical_means, "canonical mean")?;
        let rest_corners: Vec<[DVec3; 3]> = triangles
            .par_iter()
            .map(|t| t.map(|v| positions[v as usize]))
            .collect();
        let frames = rest_corners
            .par_iter()
            .map(|&v| ChartFrame::new(v, o.degenerate_tol))
            .collect();
        let rest_normals = rest_corners.par_iter().map(|&v| unit_normal(v)).collect();
        let edge_sum: f64 = rest_corners
            .iter()
            .map(|v| (v[1] - v[0]).length() + (v[2] - v[1]).length() + (v[0] - v[2]).length())
            .sum();
        let mean_edge = edge_sum / (3 * triangles.len()) as f64;
        let diagonal = rest.bounds().map_or(0.0, |b| b.diagonal());
        let rest_bvh = TriangleBvh::from_triangles(positions, &triangles)?;
        let canonical: Vec<DVec3> = canonical_means.iter().map(|p| p.as_dvec3()).collect();
        let rest_nearest = canonical
            .par_iter()
            .with_min_len(256)
            .map(|&q| {
                rest_bvh
                    .nearest_below(q, (f64::INFINITY, u32::MAX))
                    .map_or(0, |(_, t)| t)
            })
            .collect();
        Ok(Self {
            options,
            triangles,
            vertex_count,
            rest_corners,
            rest_normals,
            frames,
            canonical,
            rest_nearest,
            hop_distance: o.hop_threshold * mean_edge,
            diagonal,
            assigned: Vec::new(),
            anchors: Vec::new(),
            members: Vec::new(),
            charts: Vec::new(),
            previous: Vec::new(),
            bvh: None,
            flat: Vec::new(),
            vertices: Vec::new(),
            states: Vec::new(),
            certified: false,
            updates: 0,
            since_rebuild: 0,
            auto: AutoRebuild::default(),
        })
    }

    /// The options.
    #[must_use]
    pub fn options(&self) -> &DelaunayOptions {
        &self.options
    }

    /// Number of Gaussians.
    #[must_use]
    pub fn gaussian_count(&self) -> usize {
        self.canonical.len()
    }

    /// Number of charts (template triangles).
    #[must_use]
    pub fn chart_count(&self) -> usize {
        self.triangles.len()
    }

    /// The chart (template triangle) of each Gaussian after the last update (empty before).
    #[must_use]
    pub fn assignment(&self) -> &[u32] {
        &self.assigned
    }

    /// Vertex positions after the last update: deformed template vertices, then one vertex per
    /// Gaussian (empty before the first update).
    #[must_use]
    pub fn vertices(&self) -> &[DVec3] {
        &self.vertices
    }

    /// The mesh's triangles after the last update, chart by chart.
    #[must_use]
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let total = self.charts.iter().map(|c| c.triangles.len()).sum();
        let mut out = vec![[0u32; 3]; total];
        // One destination slice per chart, filled in parallel.
        let mut rest = out.as_mut_slice();
        let mut parts = Vec::with_capacity(self.charts.len());
        for c in &self.charts {
            let (head, tail) = rest.split_at_mut(c.triangles.len());
            parts.push(head);
            rest = tail;
        }
        parts
            .into_par_iter()
            .zip(self.charts.par_iter())
            .with_min_len(256)
            .for_each(|(dst, c)| dst.copy_from_slice(&c.triangles));
        out
    }

    /// The triangles of chart (template triangle) `t` after the last update; empty for a
    /// triangle that does not exist or before the first update.
    #[must_use]
    pub fn chart_triangles(&self, t: usize) -> &[[u32; 3]] {
        self.charts.get(t).map_or(&[], |c| c.triangles.as_slice())
    }

    /// The mesh after the last update (vertices and triangles as above).
    #[must_use]
    pub fn mesh(&self) -> TriMesh {
        // Vertices were checked finite and triangles index them.
        TriMesh::new_unchecked(self.vertices.clone(), self.triangles())
    }

    /// Triangulates every chart from scratch for the current assignment, without changing
    /// anything: the reference the incremental result must equal.
    #[must_use]
    pub fn triangulate_all(&self) -> Vec<[u32; 3]> {
        let members = self.members_from_assignment();
        let charts = self.triangulate_charts(
            &(0..self.triangles.len() as u32).collect::<Vec<_>>(),
            &members,
        );
        charts.into_iter().flat_map(|c| c.triangles).collect()
    }

    /// Moves to a new frame: `positions` are the deformed template vertices, `means` the
    /// deformed Gaussian means (e.g. from `trisplat_splat::Deformer::deform_geometry`). The first update, and
    /// every [`DelaunayOptions::rebuild_every`]-th, rebuilds from scratch; the others
    /// re-triangulate only the charts that Gaussians left or entered.
    ///
    /// # Errors
    /// [`DelaunayError::Count`] for arrays of the wrong length, [`DelaunayError::BadCoordinate`]
    /// for non-finite or huge coordinates; the state is unchanged then.
    pub fn update(
        &mut self,
        positions: &[DVec3],
        means: &[Vec3],
    ) -> Result<FrameStats, DelaunayError> {
        let start = Instant::now();
        self.check_frame(positions, means)?;
        let period = self.options.rebuild_every;
        let scheduled = self.bvh.is_none() || (period > 0 && self.since_rebuild >= period);
        let automatic = self.options.auto_rebuild && self.auto.rebuilds_left > 0;
        let mut stats = if scheduled || automatic {
            if automatic {
                self.auto.rebuilds_left -= 1;
            }
            let stats = self.rebuild_now(positions, means)?;
            self.auto.rebuild_ms = start.elapsed().as_secs_f64() * 1e3;
            stats
        } else {
            // Judged only when the Gaussians came with certificates (not right after a
            // rebuild, which leaves none).
            let judged = self.certified;
            let stats = self.step(positions, means)?;
            if self.options.auto_rebuild && judged {
                let costly = self.auto.costly(
                    &stats,
                    start.elapsed().as_secs_f64() * 1e3,
                    self.options.hop_threshold == 0.0,
                    self.canonical.len(),
                    self.triangles.len(),
                );
                self.auto.judge(costly);
            }
            stats
        };
        stats.frame = self.updates;
        self.updates += 1;
        stats.unmeshed = self.charts.iter().map(|c| c.unmeshed as usize).sum();
        stats.millis = start.elapsed().as_secs_f64() * 1e3;
        Ok(stats)
    }

    /// Rebuilds from scratch at this frame (as the first update does), whatever the period.
    ///
    /// # Errors
    /// As [`IncrementalDelaunay::update`].
    pub fn rebuild(
        &mut self,
        positions: &[DVec3],
        means: &[Vec3],
    ) -> Result<FrameStats, DelaunayError> {
        self.bvh = None;
        self.update(positions, means)
    }

    fn check_frame(&self, positions: &[DVec3], means: &[Vec3]) -> Result<(), DelaunayError> {
        if positions.len() != self.vertex_count {
            return Err(DelaunayError::Count {
                what: "deformed template",
                expected: self.vertex_count,
                got: positions.len(),
            });
        }
        if means.len() != self.canonical.len() {
            return Err(DelaunayError::Count {
                what: "deformed means",
                expected: self.canonical.len(),
                got: means.len(),
            });
        }
        check_coordinates(positions, "deformed vertex")?;
        check_coordinates(means, "deformed mean")
    }

    fn rebuild_now(
        &mut self,
        positions: &[DVec3],
        means: &[Vec3],
    ) -> Result<FrameStats, DelaunayError> {
        let bvh = TriangleBvh::from_triangles(positions, &self.triangles)?;
        self.flat = flat_triangles(&bvh);
        let seeds = &self.rest_nearest;
        self.assigned = means
            .par_iter()
            .zip(seeds.par_iter())
            .with_min_len(256)
            .map(|(m, &seed)| {
                let q = m.as_dvec3();
                let (d2, _) = bvh.distance_sq(q, seed);
                bvh.nearest_below(q, (d2, seed)).map_or(seed, |(_, t)| t)
            })
            .collect();
        self.anchors = (0..self.canonical.len())
            .into_par_iter()
            .with_min_len(256)
            .map(|i| self.anchor(i, self.assigned[i]))
            .collect();
        self.members = self.members_from_assignment();
        let all: Vec<u32> = (0..self.triangles.len() as u32).collect();
        self.charts = self.triangulate_charts(&all, &self.members);
        self.bvh = Some(bvh);
        // Certificates and cached chart meshes describe the previous state; the next update
        // makes new ones (and a run of rebuilds holds none).
        self.certified = false;
        self.states = Vec::new();
        self.previous = Vec::new();
        self.since_rebuild = 1;
        self.lift(positions, means);
        Ok(FrameStats {
            rebuilt: true,
            charts_redone: all.len(),
            searches: means.len(),
            ..FrameStats::default()
        })
    }

    fn step(&mut self, positions: &[DVec3], means: &[Vec3]) -> Result<FrameStats, DelaunayError> {
        let Some(mut bvh) = self.bvh.take() else {
            return self.rebuild_now(positions, means);
        };
        bvh.refit(positions)?;
        self.flat = flat_triangles(&bvh);
        if !self.certified {
            self.states = self
                .members
                .iter()
                .map(|list| ChartState::empty(list.len()))
                .collect();
            self.certified = true;
        }
        let mut states = std::mem::take(&mut self.states);
        let context = SearchContext {
            bvh: &bvh,
            positions,
            flat: self.flat.contains(&true).then_some(self.flat.as_slice()),
        };
        let outcome = self
            .members
            .par_chunks(CHART_BATCH)
            .zip(states.par_chunks_mut(CHART_BATCH))
            .enumerate()
            .fold(Outcome::default, |mut acc, (batch, (lists, states))| {
                SCRATCH.with_borrow_mut(|scratch| {
                    // The batch's means in one pass: the ids mostly follow the charts, so
                    // this streams through memory instead of missing the cache per chart.
                    let mut gathered = std::mem::take(&mut scratch.gathered);
                    gathered.clear();
                    for list in lists {
                        gathered.extend(list.iter().map(|&g| means[g as usize].as_dvec3()));
                    }
                    let mut start = 0;
                    for (j, (list, state)) in lists.iter().zip(states).enumerate() {
                        let a = (batch * CHART_BATCH + j) as u32;
                        let chart_means = &gathered[start..start + list.len()];
                        start += list.len();
                        self.hops_of_chart(
                            &context,
                            a,
                            list,
                            chart_means,
                            state,
                            scratch,
                            &mut acc,
                        );
                    }
                    scratch.gathered = gathered;
                });
                acc
            })
            .reduce(Outcome::default, Outcome::merge);
        self.bvh = Some(bvh);
        self.states = states;
        let searches = outcome.checked;
        let mut moves = outcome.moves;
        moves.sort_unstable();
        // The charts the moves touch, with the member lists their meshes were made from.
        let mut dirty: Vec<u32> = moves
            .iter()
            .flat_map(|&(g, c)| [self.assigned.get(g as usize).copied().unwrap_or(c), c])
            .collect();
        dirty.sort_unstable();
        dirty.dedup();
        let before: Vec<Vec<u32>> = dirty
            .iter()
            .map(|&t| self.members.get(t as usize).cloned().unwrap_or_default())
            .collect();
        let hopped = moves.len();
        for (g, c) in moves {
            let i = g as usize;
            let a = self.assigned[i];
            if let Some(list) = self.members.get_mut(a as usize)
                && let Ok(k) = list.binary_search(&g)
            {
                list.remove(k);
                if let Some(state) = self.states.get_mut(a as usize) {
                    state.remove(k);
                }
            }
            if let Some(list) = self.members.get_mut(c as usize)
                && let Err(k) = list.binary_search(&g)
            {
                list.insert(k, g);
                if let Some(state) = self.states.get_mut(c as usize) {
                    state.insert_empty(k);
                }
            }
            self.assigned[i] = c;
            self.anchors[i] = self.anchor(i, c);
        }
        self.remesh(&dirty, before);
        self.since_rebuild += 1;
        self.lift(positions, means);
        Ok(FrameStats {
            rebuilt: false,
            hopped,
            charts_redone: dirty.len(),
            searches,
            ..FrameStats::default()
        })
    }

    /// Hop targets of the Gaussians of chart `a` at this frame, new certificates, and the
    /// chart's new snapshot. Exactly the answer of a full BVH search per Gaussian (the nearest
    /// triangle, ties to the smallest id, under the hop threshold), found cheaper: a Gaussian
    /// whose motion certificate still holds cannot have hopped (module `certify`); the others
    /// are checked exactly against the triangles of one range query per chart, which also
    /// proves that no triangle from outside the chart's snapshot came near. A chart without a
    /// snapshot, or with a newcomer in its neighbourhood, checks all its Gaussians and takes a
    /// new snapshot.
    #[expect(
        clippy::too_many_arguments,
        reason = "one chart's step of the hop search, all inputs named"
    )]
    fn hops_of_chart(
        &self,
        cx: &SearchContext<'_>,
        a: u32,
        list: &[u32],
        means: &[DVec3],
        state: &mut ChartState,
        scratch: &mut Scratch,
        out: &mut Outcome,
    ) {
        if list.is_empty() {
            return;
        }
        let bvh = cx.bvh;
        let hop = self.hop_distance;
        let v = bvh.corners(a as usize).unwrap_or([DVec3::ZERO; 3]);
        let centre = (v[0] + v[1] + v[2]) / 3.0;
        let size = v.iter().map(|p| (*p - centre).length()).fold(0.0, f64::max);
        let margin = SNAPSHOT_MARGIN_REL * size;
        let slack = FILTER_MARGIN_REL * (self.diagonal + centre.abs().max_element() + size);
        let usable = |snap: &Snapshot| match cx.flat {
            None => true,
            Some(flat) => snap.triangles.iter().all(|&t| !flat[t as usize]),
        };
        let (moves_before, checked_close_before) = (out.moves.len(), out.checked_close);
        if let Some(snap) = state.snapshot.as_mut()
            && state.certificates.len() == list.len()
            && usable(snap)
            && let Some(fit) = snap.fit(v, cx.positions, &mut scratch.vertices)
        {
            // First the bounds of every member; the few they do not settle afterwards.
            let mut reach = 0.0f64;
            scratch.unsettled.clear();
            for (k, (c, &q)) in state.certificates.iter().zip(means).enumerate() {
                let from_centre = (q - centre).length();
                let bounds = c.bounds(&fit, q);
                if bounds.lower - (bounds.own - hop) > own_slack(slack, q, from_centre, bounds.own)
                {
                    // Every other triangle is certainly farther.
                    reach = reach.max(from_centre + (bounds.own - hop).max(0.0));
                } else {
                    scratch.unsettled.push(Unsettled {
                        k,
                        q,
                        from_centre,
                        bounds,
                    });
                }
            }
            scratch.pending.clear();
            scratch.exact.clear();
            // Move the snapshot to this frame (below) when the neighbourhood has drifted from
            // it; the certificates are then issued afresh from the bounds found here.
            let drift = fit.residual + (fit.sigma_hi - fit.sigma_lo) * size;
            let rebase = drift > REBASE_REL * size;
            for u in &scratch.unsettled {
                let (k, q, from_centre) = (u.k, u.q, u.from_centre);
                let g = list[k];
                let (d2, _) = bvh.distance_sq(q, a);
                let r = d2.sqrt() - hop;
                if state.certificates[k].is_some() {
                    let competitors = &state.competitors[k];
                    let other = competitors.other_bound(&fit, u.bounds.error);
                    let own_slack = own_slack(slack, q, from_centre, u.bounds.own);
                    if other - r > own_slack {
                        // The unlisted triangles by the bound against the exact own distance;
                        // the listed competitors likewise when their bound suffices, else
                        // exactly. Triangles outside the snapshot are excluded by the test
                        // below, whatever the outcome.
                        reach = reach.max(from_centre + r.max(0.0));
                        let mut near = competitors.near_bounds(&fit, u.bounds.error);
                        let mut close = competitors.close;
                        let mut any = false;
                        for (t, n) in close.iter_mut().zip(&near) {
                            if n - r > own_slack {
                                *t = u32::MAX;
                            }
                            any |= *t != u32::MAX;
                        }
                        if any {
                            // Only the listed competitors whose own bound is inconclusive.
                            if let Some(t) = self.close_check(bvh, q, a, d2, &close, &mut near) {
                                out.moves.push((g, t));
                            }
                            out.checked_close += 1;
                        }
                        if rebase {
                            scratch.exact.push((k, d2.sqrt(), near, other));
                        }
                        continue;
                    }
                }
                reach = reach.max(from_centre + r.max(0.0));
                scratch.pending.push((k, g, q, d2));
            }
            let pending = !scratch.pending.is_empty();
            let radius = reach + slack + if pending { 0.5 * margin } else { 0.0 };
            let inside =
                !bvh.any_within(&snap.frontier, centre, radius * radius, &mut scratch.stack);
            if inside {
                let fit = if rebase {
                    Self::rebase(v, cx.positions, means, state, scratch, &fit).unwrap_or(fit)
                } else {
                    fit
                };
                if pending {
                    // The snapshot's triangles, nearest first when it was taken: close to the
                    // order a sort would give now, without sorting (see `exact_check`).
                    scratch.candidates.clear();
                    if let Some(snap) = &state.snapshot {
                        for &t in snap.triangles.iter().filter(|&&t| t != a) {
                            let (lo, hi) = bvh.leaf_box(t);
                            scratch.candidates.push((t, lo, hi, 0.0));
                        }
                    }
                    for &(k, g, q, d2) in &scratch.pending {
                        let from_centre = (q - centre).length();
                        let cap = radius - from_centre;
                        let lead = from_centre + slack;
                        let candidates = &scratch.candidates;
                        match self.exact_check(bvh, q, a, d2, candidates, cap, size, lead) {
                            Ok((near, far)) => {
                                (state.certificates[k], state.competitors[k]) =
                                    Certificate::issue(&fit, q, d2.sqrt(), near, far);
                            }
                            Err(t) => out.moves.push((g, t)),
                        }
                    }
                }
                out.checked += scratch.pending.len();
                return;
            }
        }
        // Check every Gaussian and take a new snapshot; forget what this chart found above.
        out.moves.truncate(moves_before);
        out.checked_close = checked_close_before;
        out.refreshed += 1;
        scratch.pending.clear();
        let mut reach = 0.0f64;
        for (k, (&g, &q)) in list.iter().zip(means).enumerate() {
            let (d2, _) = bvh.distance_sq(q, a);
            reach = reach.max((q - centre).length() + (d2.sqrt() - hop).max(0.0));
            scratch.pending.push((k, g, q, d2));
        }
        state.clear(list.len());
        let radius = reach + slack + margin;
        scratch.found.clear();
        bvh.triangles_within(
            centre,
            radius * radius,
            &mut scratch.found,
            &mut scratch.stack,
        );
        let no_flat = cx
            .flat
            .is_none_or(|flat| scratch.found.iter().all(|&t| !flat[t as usize]));
        self.gather_candidates(bvh, a, centre, scratch);
        let snap = match LocalFrame::of(v) {
            Some(frame) if no_flat => {
                // The chart, then the others nearest first (the order later checks use).
                let mut triangles = Vec::with_capacity(scratch.candidates.len() + 1);
                triangles.push(a);
                triangles.extend(scratch.candidates.iter().map(|c| c.0));
                let token = scratch.next_token(bvh.node_count());
                bvh.frontier(&triangles, &mut scratch.marks, token, &mut scratch.frontier);
                let frontier = scratch.frontier.clone();
                Snapshot::new(&frame, triangles, frontier, &self.triangles, cx.positions)
            }
            _ => None,
        };
        let fit = snap
            .as_ref()
            .and_then(|s| s.fit(v, cx.positions, &mut scratch.vertices));
        for &(k, g, q, d2) in &scratch.pending {
            let from_centre = (q - centre).length();
            let cap = radius - from_centre;
            let lead = from_centre + slack;
            match self.exact_check(bvh, q, a, d2, &scratch.candidates, cap, size, lead) {
                Ok((near, far)) => {
                    if let Some(fit) = &fit {
                        (state.certificates[k], state.competitors[k]) =
                            Certificate::issue(fit, q, d2.sqrt(), near, far);
                    }
                }
                Err(t) => out.moves.push((g, t)),
            }
        }
        out.checked += list.len();
        state.snapshot = if fit.is_some() { snap } else { None };
    }

    /// Moves a chart's snapshot to this frame (the chart triangle's corners are `v`, its
    /// members' means `means`; `fit` maps the old snapshot here) and issues every member's
    /// certificate afresh from its
    /// current bounds: the exact ones found this frame (`scratch.exact`), else its old
    /// certificate's. Returns the new fit, or `None` (and nothing changed) when the chart
    /// triangle is flat or the new fit fails.
    fn rebase(
        v: [DVec3; 3],
        positions: &[DVec3],
        means: &[DVec3],
        state: &mut ChartState,
        scratch: &mut Scratch,
        fit: &Fit,
    ) -> Option<Fit> {
        let frame = LocalFrame::of(v)?;
        // Current bounds of every member, under the old fit.
        scratch.current.clear();
        let mut exact = scratch.exact.iter().peekable();
        for (k, (&q, (c, competitors))) in means
            .iter()
            .zip(state.certificates.iter().zip(&state.competitors))
            .enumerate()
        {
            let bounds = match exact.next_if(|e| e.0 == k) {
                Some(&(_, own, near, other)) => (own, near, other),
                None => {
                    let b = c.bounds(fit, q);
                    (
                        b.own,
                        competitors.near_bounds(fit, b.error),
                        competitors.other_bound(fit, b.error),
                    )
                }
            };
            scratch.current.push(bounds);
        }
        let snap = state.snapshot.as_mut()?;
        let new_fit = snap.rebase(
            &frame,
            v,
            positions,
            &mut scratch.saved,
            &mut scratch.vertices,
        )?;
        for (k, (&q, &(own, near, other))) in means.iter().zip(&scratch.current).enumerate() {
            let close = (near, state.competitors[k].close);
            (state.certificates[k], state.competitors[k]) =
                Certificate::issue(&new_fit, q, own, close, other);
        }
        Some(new_fit)
    }

    /// Fills `scratch.candidates` with the triangles of `scratch.found` other than `a`, with
    /// their padded boxes, nearest box to `centre` first.
    fn gather_candidates(&self, bvh: &TriangleBvh, a: u32, centre: DVec3, scratch: &mut Scratch) {
        scratch.candidates.clear();
        for &t in &scratch.found {
            if t != a {
                let (lo, hi) = bvh.leaf_box(t);
                let gap = (lo - centre).max(centre - hi).max(DVec3::ZERO);
                scratch.candidates.push((t, lo, hi, gap.length_squared()));
            }
        }
        scratch
            .candidates
            .sort_unstable_by(|x, y| x.3.total_cmp(&y.3).then(x.0.cmp(&y.0)));
    }

    /// Exact hop check of a Gaussian at `q` in chart `a` (own squared distance `d2`) against
    /// `candidates`, which hold every triangle nearer than `cap`: `Err(target)` when it hops
    /// (the nearest triangle, ties to the smallest id, under the hop threshold), else
    /// `Ok(((near, close), other))`: up to [`certify::MAX_CLOSE`] triangles `close` nearer
    /// than the own distance plus [`certify::CLOSE_GAP_REL`] times `size`, `near` their
    /// distances (`+∞` in empty slots), and `other ≤ d_U` for every other triangle `U ≠ a`
    /// (and `≤ cap`). Candidates sorted by their boxes' squared distances `gap2` from a point
    /// at most `lead` (plus rounding slack) from `q` end the search early: once a box is
    /// farther from that point than `lead` plus everything still needed, so are the rest.
    /// Candidates in any other order carry `gap2 = 0` and are each tested by their box.
    #[expect(
        clippy::too_many_arguments,
        reason = "one search step, all inputs named"
    )]
    fn exact_check(
        &self,
        bvh: &TriangleBvh,
        q: DVec3,
        a: u32,
        d2: f64,
        candidates: &[(u32, DVec3, DVec3, f64)],
        cap: f64,
        size: f64,
        lead: f64,
    ) -> Result<(Close, f64), u32> {
        let hop = self.hop_distance;
        let d = d2.sqrt();
        let r = d - hop;
        let can_hop = hop == 0.0 || r > 0.0;
        let near = d + CLOSE_GAP_REL * size;
        // Strictly nearer than r: with a hop threshold, (d², t) < (r², 0) means d² < r².
        let mut best = if hop > 0.0 { (r * r, 0u32) } else { (d2, a) };
        let mut found = false;
        let mut far = cap;
        // Close competitors by distance, ascending.
        let mut close = [(f64::INFINITY, u32::MAX); MAX_CLOSE];
        let mut count = 0;
        for &(t, lo, hi, gap2) in candidates {
            // Candidates come nearest box first: past this one, every remaining box is at
            // least `√gap2 - lead` from `q`, and each bound below only shrinks.
            let keep = if count == MAX_CLOSE {
                close[MAX_CLOSE - 1].0
            } else {
                near
            };
            let needed = far.max(keep).max(if can_hop { best.0.sqrt() } else { 0.0 });
            let reach = lead + needed;
            if gap2 > reach * reach {
                break;
            }
            let lower = (lo - q)
                .max(q - hi)
                .max(DVec3::ZERO)
                .length_squared()
                .sqrt();
            if (!can_hop || lower * lower > best.0) && lower >= far && lower >= keep {
                continue;
            }
            let (du2, _) = bvh.distance_sq(q, t);
            if can_hop && (du2, t) < best {
                best = (du2, t);
                found = true;
            }
            let du = du2.sqrt();
            if du < near {
                // Insert in order; the largest falls out to the far bound.
                let mut item = (du, t);
                for slot in &mut close {
                    if item.0 < slot.0 {
                        std::mem::swap(slot, &mut item);
                    }
                }
                if item.1 == u32::MAX {
                    count += 1;
                } else {
                    far = far.min(item.0);
                }
            } else {
                far = far.min(du);
            }
        }
        if found {
            Err(best.1)
        } else {
            Ok(((close.map(|c| c.0), close.map(|c| c.1)), far))
        }
    }

    /// Exact comparison of a Gaussian's own triangle `a` (squared distance `d2`) with its
    /// listed competitors (`u32::MAX`: an empty or skipped slot): the hop target when one of
    /// them wins (as [`Self::exact_check`]).
    fn close_check(
        &self,
        bvh: &TriangleBvh,
        q: DVec3,
        a: u32,
        d2: f64,
        close: &[u32; MAX_CLOSE],
        near: &mut [f64; MAX_CLOSE],
    ) -> Option<u32> {
        let hop = self.hop_distance;
        let r = d2.sqrt() - hop;
        if hop > 0.0 && r <= 0.0 {
            return None;
        }
        let mut best = if hop > 0.0 { (r * r, 0u32) } else { (d2, a) };
        let mut found = false;
        for (&t, n) in close.iter().zip(near.iter_mut()) {
            if t == u32::MAX {
                continue;
            }
            let (du2, _) = bvh.distance_sq(q, t);
            *n = du2.sqrt();
            if (du2, t) < best {
                best = (du2, t);
                found = true;
            }
        }
        found.then_some(best.1)
    }

    /// Canonical placement of Gaussian `i` in chart `t`: barycentric weights of its canonical
    /// mean projected onto the rest triangle's plane (negative outside the triangle) and its
    /// signed distance from that plane; for a degenerate rest triangle, the weights of the
    /// nearest point and no offset.
    fn anchor(&self, i: usize, t: u32) -> Anchor {
        let (Some(v), Some(p), Some(n)) = (
            self.rest_corners.get(t as usize),
            self.canonical.get(i),
            self.rest_normals.get(t as usize),
        ) else {
            return Anchor::default();
        };
        let degenerate = self.frames.get(t as usize).is_none_or(|f| f.degenerate);
        if !degenerate {
            let (e1, e2, d) = (v[1] - v[0], v[2] - v[0], *p - v[0]);
            let big_n = e1.cross(e2);
            let n2 = big_n.length_squared();
            let b1 = d.cross(e2).dot(big_n) / n2;
            let b2 = e1.cross(d).dot(big_n) / n2;
            let bary = [1.0 - b1 - b2, b1, b2];
            if bary.iter().all(|b| b.is_finite()) {
                return Anchor {
                    bary,
                    offset: d.dot(*n),
                };
            }
        }
        let (_, bary) = trisplat_geometry::spatial::closest_point_on_triangle(*p, v[0], v[1], v[2]);
        Anchor { bary, offset: 0.0 }
    }

    fn members_from_assignment(&self) -> Vec<Vec<u32>> {
        // Allocated in chart order with a little room for Gaussians hopping in: the lists
        // then lie in memory roughly in the order the hop search reads them.
        let mut counts = vec![0usize; self.triangles.len()];
        for &t in &self.assigned {
            if let Some(c) = counts.get_mut(t as usize) {
                *c += 1;
            }
        }
        let mut members: Vec<Vec<u32>> = counts
            .into_iter()
            .map(|c| Vec::with_capacity(c + SPARE_CAPACITY))
            .collect();
        for (i, &t) in self.assigned.iter().enumerate() {
            if let Some(list) = members.get_mut(t as usize) {
                list.push(i as u32);
            }
        }
        members
    }

    fn triangulate_charts(&self, charts: &[u32], members: &[Vec<u32>]) -> Vec<ChartMesh> {
        charts
            .par_iter()
            .with_min_len(16)
            .map(|&t| self.triangulate_chart(t as usize, &members[t as usize]))
            .collect()
    }

    /// Triangulates chart `t` holding the Gaussians `list`.
    fn triangulate_chart(&self, t: usize, list: &[u32]) -> ChartMesh {
        let offset = self.vertex_count as u32;
        let members: Vec<(u32, [f64; 3])> = list
            .iter()
            .map(|&g| (offset + g, self.anchors[g as usize].bary))
            .collect();
        let margin = self.options.interior_margin;
        triangulate(&self.frames[t], self.triangles[t], &members, margin)
    }

    /// New meshes for the charts `dirty`, whose meshes were made from the member lists
    /// `before`. A chart's mesh depends only on its member list (canonical coordinates depend
    /// only on the Gaussian and the chart), so a chart whose list is back to what it was
    /// before one of its last changes (most hops at hop threshold 0 are a Gaussian near a tie going
    /// back) takes that mesh again instead of being triangulated.
    fn remesh(&mut self, dirty: &[u32], before: Vec<Vec<u32>>) {
        self.previous.resize_with(self.charts.len(), Vec::new);
        let fresh: Vec<Result<usize, ChartMesh>> = dirty
            .par_iter()
            .with_min_len(16)
            .map(|&t| {
                let t = t as usize;
                let list = &self.members[t];
                match self.previous[t].iter().position(|p| p.members == *list) {
                    Some(slot) => Ok(slot),
                    None => Err(self.triangulate_chart(t, list)),
                }
            })
            .collect();
        for ((&t, members), fresh) in dirty.iter().zip(before).zip(fresh) {
            let t = t as usize;
            let cache = &mut self.previous[t];
            let mesh = match fresh {
                Ok(slot) => cache.remove(slot).mesh,
                Err(mesh) => mesh,
            };
            let old = std::mem::replace(&mut self.charts[t], mesh);
            // Most recent first; the oldest falls out.
            cache.insert(0, CachedChart { members, mesh: old });
            cache.truncate(CACHED_MESHES);
        }
    }

    fn lift(&mut self, positions: &[DVec3], means: &[Vec3]) {
        let nv = self.vertex_count;
        self.vertices.resize(nv + means.len(), DVec3::ZERO);
        let (template, gaussians) = self.vertices.split_at_mut(nv);
        template.copy_from_slice(positions);
        match self.options.lift {
            Lift::Means => gaussians
                .par_iter_mut()
                .zip(means.par_iter())
                .with_min_len(4096)
                .for_each(|(out, m)| *out = m.as_dvec3()),
            Lift::Surface => {
                let tris = &self.triangles;
                gaussians
                    .par_iter_mut()
                    .zip(self.assigned.par_iter().zip(self.anchors.par_iter()))
                    .with_min_len(1024)
                    .for_each(|(out, (&t, anchor))| {
                        let v = tris[t as usize].map(|k| positions[k as usize]);
                        let p = v[0] * anchor.bary[0]
                            + v[1] * anchor.bary[1]
                            + v[2] * anchor.bary[2]
                            + unit_normal(v) * anchor.offset;
                        *out = p;
                    });
            }
        }
    }
}

/// The margin by which a Gaussian at `q` (at `from_centre` from its chart's centroid, own
/// distance at most `own`) must be nearer its own triangle than any other to count as
/// certainly nearer: `slack` (the chart's) plus [`FILTER_MARGIN_REL`] of the magnitudes
/// involved, far above the rounding of the computed distances.
fn own_slack(slack: f64, q: DVec3, from_centre: f64, own: f64) -> f64 {
    slack + FILTER_MARGIN_REL * (q.abs().max_element() + from_centre + own)
}

/// Unit normal of a triangle (zero when it is degenerate).
fn unit_normal(v: [DVec3; 3]) -> DVec3 {
    (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero()
}
