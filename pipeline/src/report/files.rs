//! The names of the report's files in the output folder.

/// File name of the JSON report in the output folder.
pub const REPORT_JSON: &str = "report.json";
/// File name of the Markdown report.
pub const REPORT_MD: &str = "report.md";
/// File name of the plot as PNG.
pub const PLOT_PNG: &str = "error_vs_time.png";
/// File name of the plot as SVG.
pub const PLOT_SVG: &str = "error_vs_time.svg";
/// File name of the HTML report.
pub const REPORT_HTML: &str = "report.html";
/// Folder of the thumbnails in the output folder.
pub const THUMBNAIL_DIR: &str = "thumbnails";
/// The name of the ground truth's thumbnail (beside the methods' names).
pub const GT_THUMBNAIL: &str = "ground_truth";

/// The file of `name`'s thumbnail of animation frame `frame`, relative to the output folder
/// (`thumbnails/tsdf_frame_000003.png`; `name` is a method's or [`GT_THUMBNAIL`]).
#[must_use]
pub fn thumbnail_file(name: &str, frame: usize) -> String {
    format!("{THUMBNAIL_DIR}/{name}_frame_{frame:06}.png")
}
