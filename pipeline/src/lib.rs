//! The main job of trisplat (`trisplat extract`, `trisplat demo`): an animated template and
//! Gaussians bound to its triangles in, one mesh per frame and method out, with timings,
//! metrics against a ground truth, a report and a plot.
//!
//! # Stages (docs/conventions.md §1)
//! A run does only the stages its arguments need; [`Plan`] lists them with the reason each
//! runs or is skipped (`--explain` prints it). One [`Session`] per run reads the inputs once
//! and asks the same plan before every stage, then meshes frame by frame ([`Session::frame`]);
//! [`run()`] writes what each frame returns and tells what happens as [`Event`]s, which the
//! report ([`report::ReportBuilder`]), the command line's progress and any other caller read:
//!
//! 1. **animate**: read the template T and open the animation A: a glTF clip (`--clip`,
//!    sampled at `--fps`), a folder or pattern of OBJ/PLY frames, or a LAM/ARKit weights
//!    JSON driving a glTF template's morph targets. Without A, a glTF template plays its own
//!    first clip; any other template is one still frame.
//!    The template is read in world space as its animation poses it
//!    ([`input::read_template`]: a glTF's node transforms, skins and default morph weights
//!    applied), and the first frame meshed must be at its scale
//!    ([`input::check_scale`], within [`input::SCALE_MISMATCH`]).
//!    Vertices the file splits at UV/normal seams are welded by position
//!    ([`input::WeldedTemplate`]): every later stage sees the welded template, so the meshes
//!    are watertight wherever the surface is.
//! 2. **bind** (only without `--gaussians`): `--per-triangle` Gaussians per triangle
//!    (default [`config::DEFAULT_PER_TRIANGLE`]), spread evenly, opacity
//!    [`config::BIND_OPACITY`], flattened along the triangle normal to
//!    [`config::BIND_NORMAL_SCALE`] of their in-plane size: opaque surface discs, since
//!    untrained GaussianAvatars-style blobs (opacity 0.1, isotropic) render no surface.
//! 3. **deform**: every frame, `binding`, `jacobian` or `lbs` (as `trisplat deform`).
//! 4. **render** (only for `tsdf`): median depth (`--tsdf-depth`; the depth where the
//!    accumulated alpha reaches ½) of every Gaussian of the frame from a sphere rig around it.
//! 5. **mesh**: `tsdf`, `delaunay` and/or `alpha` (module [`methods`] for their defaults);
//!    each mesh (each key mesh when carried) decimated with `--faces` / `--simplify-error`
//!    (geometry's `simplify`) and coloured from the Gaussians near its vertices unless
//!    `--vertex-colors off`.
//! 6. **metrics** (only with a ground truth): docs/conventions.md §8 in surface mode against each frame's
//!    deformed template (`--gt template`) or one static mesh (`--gt FILE`).
//! 7. **write**: `DIR/<method>/frame_NNNNNN.ply` (NNNNNN = animation frame index) and
//!    `DIR/<method>.glb`, the animated sequence.
//! 8. **report**: `DIR/report.json`, `DIR/report.md`, `DIR/report.html` (with the
//!    thumbnails in `DIR/thumbnails/`), `DIR/error_vs_time.svg` and `DIR/error_vs_time.png`.
//!
//! # Defaults, derived from the (world-space) template so that any scale works
//! - TSDF voxel: the rest-pose Gaussians' mean nearest-neighbour spacing, clamped to template
//!   bounding radius / [`config::DEFAULT_VOXELS_PER_RADIUS`] ..=
//!   / [`config::COARSEST_VOXELS_PER_RADIUS`] ([`methods::default_voxel`]); truncation
//!   5 voxels; [`config::DEFAULT_VIEWS`] views of [`config::DEFAULT_RESOLUTION`]² pixels,
//!   40° field of view, framing each frame's bounding sphere with a 10% margin.
//! - Alpha: the boundary of the solid the alpha complex (singular triangles kept) encloses
//!   (`--alpha-rule solid`; `complex` the whole complex) at the smallest α from
//!   [`config::DEFAULT_ALPHA_FLOOR_SPACINGS`] to [`config::DEFAULT_ALPHA_CEILING_SPACINGS`] × the
//!   mean nearest-neighbour spacing of the rest-pose Gaussian means whose mesh has at most
//!   `--alpha-pieces` (default 10) pieces, per frame; `--alpha-rule open3d`:
//!   [`config::DEFAULT_ALPHA_SPACINGS`] spacings.
//! - Delaunay: incremental (`--hop-threshold`, default 0: each frame equals a from-scratch
//!   triangulation; above 0 fewer charts are redone and frames may differ from one);
//!   `--rebuild-every N` rebuilds every N frames, 1 on every frame. The report keeps what each
//!   update did (Gaussians hopped, charts redone, rebuilt).
//! - Metrics: [`config::DEFAULT_SAMPLES`] samples per mesh, F-score at
//!   [`config::DEFAULT_TAU`] (input units).
//!
//! # Timing
//! Each method's milliseconds per frame cover its own work only: rendering plus fusion for
//! tsdf, the update plus mesh assembly for delaunay, the tetrahedralisation and boundary for
//! alpha. Reading the frame, deforming (reported once as `deform_ms`), metrics and file
//! writes are not included. The methods of a frame run side by side, so each method's time
//! includes waiting for the cores the others hold; `--serial-methods` runs them one after
//! the other, each timed alone (the meshes are the same either way).
//!
//! # Errors
//! One [`PipelineError`] naming the file, frame, method or option at fault; files the run
//! created are removed again. Outputs are written atomically and never over an input.

// Modules whose items callers address by path (options and their defaults, the stages'
// building blocks, the report's model); the rest are private, their public items re-exported
// below.
pub mod anchor;
pub mod avatar;
pub mod config;
pub mod consistency;
pub mod eval;
pub mod fit;
pub mod input;
pub mod methods;
pub mod metrics;
pub mod opacity;
pub mod output;
pub mod records;
pub mod refine;
pub mod report;

mod carried_frames;
mod carry;
mod deform;
mod error;
mod event;
mod finish;
mod journal;
mod lock;
mod memory;
mod merge;
mod option_checks;
mod plan;
mod rig;
mod rig_output;
mod run;
mod session;
mod topology;
mod vertex_colors;
mod visibility;

pub use config::{
    ExtractConfig, ExtractOptions, GroundTruth, Method, Mode, OutputTarget, RunControl, Shard,
    ShardOptions, ShardSpec, Topology, TopologyOptions,
};
pub use error::PipelineError;
pub use event::Event;
pub use journal::JOURNAL;
pub use lock::FolderLock;
pub use merge::{MergeOutputs, merge, merge_with};
pub use plan::{Plan, Stage, StagePlan};
pub use report::Report;
pub use run::run;
pub use session::{FrameResult, MethodFrame, Session, SessionOptions};
pub use visibility::{Visibility, VisibilityError};
