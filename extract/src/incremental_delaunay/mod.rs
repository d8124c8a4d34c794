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

mod auto_rebuild;
mod certify;
mod chart;
mod error;
mod mesher;
mod options;
mod rebuild;
mod state;
mod stats;
mod step;

pub use self::auto_rebuild::{AUTO_REBUILD_CHARTS, AUTO_REBUILD_CHECKED, AutoRebuild};
pub use self::certify::{CLOSE_GAP_REL, FLAT_RATIO, MAX_CLOSE, REBASE_REL, SNAPSHOT_MARGIN_REL};
pub use self::error::DelaunayError;
pub use self::options::{
    DEFAULT_DEGENERATE_TOL, DEFAULT_HOP_THRESHOLD, DEFAULT_INTERIOR_MARGIN, DelaunayOptions,
    FILTER_MARGIN_REL, Lift,
};
pub use self::state::IncrementalDelaunay;
pub use self::stats::FrameStats;
