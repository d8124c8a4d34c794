//! The report of a run, made from its records and events only: report.json and report.md
//! (`model`, `markdown`, `table`), report.html (`html`), the plot (`plot`), the thumbnails of
//! one frame's meshes and the per-vertex error colours (`thumbnail`), and the names of these
//! files (`files`). `builder` assembles the model from the run's events.
//!
//! Nothing here runs a frame or measures a mesh: the metrics are in [`crate::metrics`], the
//! records they fill in [`crate::records`].

mod builder;
mod files;
pub mod html;
mod markdown;
pub(crate) mod model;
pub mod plot;
mod table;
pub mod thumbnail;

pub use builder::ReportBuilder;
pub use files::{
    GT_THUMBNAIL, PLOT_PNG, PLOT_SVG, REPORT_HTML, REPORT_JSON, REPORT_MD, THUMBNAIL_DIR,
    thumbnail_file,
};
pub use model::{DelaunayStats, GlbStorage, MethodReport, Report, RigRecord, Summary, Thumbnails};
pub use table::{Cell, Table};
