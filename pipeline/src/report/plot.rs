//! The plot of a run, drawn with `plotters`: `error_vs_time.svg` (text left to the viewer's
//! sans-serif font) and `error_vs_time.png` (text drawn with the DejaVu Sans cut bundled in
//! `pipeline/assets/`, so no system font is needed).
//!
//! With a ground truth: Chamfer L1 (y) against milliseconds per frame (x), both on log axes
//! snapped to whole decades. Per method (its own colour and marker shape): a small
//! translucent mark per frame (every k-th frame past [`MAX_FRAME_MARKS`] frames, said in the
//! legend), a large outlined mark at the means over the frames, labelled with the method's
//! name, and bars from the smallest to the largest value over the frames in each direction. A
//! method whose scores are self-consistency (its meshes contain the ground truth's vertices)
//! is starred, with a footnote saying its scores are not accuracy. Without a ground truth:
//! milliseconds per frame (y, log axis) against the frame index (x), one line per method; the
//! title says there is no ground truth. The legend is a panel right of the chart.

use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use plotters::style::FontStyle;
use trisplat_geometry::io::{IoError, write_atomically};
use trisplat_geometry::metrics::Relation;

use super::model::Report;
use crate::config::Method;

/// Plot width in pixels (the PNG's; the SVG's view box).
pub const WIDTH: u32 = 960;
/// Plot height in pixels.
pub const HEIGHT: u32 = 560;
/// Width of the legend panel right of the chart.
const LEGEND: u32 = 230;
/// Past this many frames per method, only every k-th frame gets a mark (the means and bars
/// cover every frame): the SVG stays small.
pub const MAX_FRAME_MARKS: usize = 400;
/// The font family the plot asks for: the SVG names it (the viewer's sans-serif), the PNG
/// draws it with the bundled font.
const FAMILY: &str = "sans-serif";

/// DejaVu Sans, cut to Latin-1 and a few symbols (licence and recipe in
/// `pipeline/assets/DejaVuSans-LICENSE.txt`): lays out the text of both files and draws the
/// PNG's.
static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans-subset.ttf");

/// Registers [`FONT`] as plotters' sans-serif, once; false if the font does not parse.
fn font_ready() -> bool {
    static READY: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *READY.get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok())
}

/// The colour of a method's marks.
#[must_use]
pub fn color(method: Method) -> RGBColor {
    match method {
        Method::Tsdf => RGBColor(31, 119, 180),
        Method::Delaunay => RGBColor(230, 110, 0),
        Method::Alpha => RGBColor(44, 160, 44),
        Method::Opacity => RGBColor(148, 103, 189),
    }
}

/// The colour of a method as CSS (`#1f77b4`), for report.html.
#[must_use]
pub fn css_color(method: Method) -> String {
    let c = color(method);
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

/// Draws `method`'s marker (a circle for tsdf, a triangle for delaunay, a square for alpha, a
/// cross for opacity)
/// of `size` pixels (half-width) at each of `points` in `chart`'s coordinates.
fn chart_marks<DB, CT>(
    chart: &mut ChartContext<'_, DB, CT>,
    method: Method,
    points: &[CT::From],
    size: i32,
    style: ShapeStyle,
) -> DrawResult<DB::ErrorType>
where
    DB: DrawingBackend,
    CT: CoordTranslate,
    CT::From: Clone + 'static,
{
    let at = |p: &CT::From| EmptyElement::at(p.clone());
    match method {
        Method::Tsdf => chart.draw_series(
            points
                .iter()
                .map(|p| at(p) + Circle::new((0, 0), size, style)),
        ),
        Method::Delaunay => chart.draw_series(
            points
                .iter()
                .map(|p| at(p) + TriangleMarker::new((0, 0), size + size / 3, style)),
        ),
        Method::Alpha => chart.draw_series(
            points
                .iter()
                .map(|p| at(p) + Rectangle::new([(-size, -size), (size, size)], style)),
        ),
        Method::Opacity => chart.draw_series(
            points
                .iter()
                .map(|p| at(p) + Cross::new((0, 0), size + size / 3, style)),
        ),
    }
    .map(|_| ())
}

/// Draws `method`'s marker at pixel `at` of `area` (the legend).
fn legend_mark<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    method: Method,
    at: (i32, i32),
    size: i32,
    style: ShapeStyle,
) -> DrawResult<DB::ErrorType> {
    let base = EmptyElement::at(at);
    match method {
        Method::Tsdf => area.draw(&(base + Circle::new((0, 0), size, style))),
        Method::Delaunay => {
            area.draw(&(base + TriangleMarker::new((0, 0), size + size / 3, style)))
        }
        Method::Alpha => area.draw(&(base + Rectangle::new([(-size, -size), (size, size)], style))),
        Method::Opacity => area.draw(&(base + Cross::new((0, 0), size + size / 3, style))),
    }
}

/// A mean point `(x, y)` with the smallest and largest x and y over the frames.
type Mean = ((f64, f64), (f64, f64), (f64, f64));

/// One method's series.
struct Series {
    method: Method,
    /// (x, y) per frame.
    points: Vec<(f64, f64)>,
    /// The mean point, with the range over the frames in x and in y.
    mean: Option<Mean>,
    /// Its scores are self-consistency (starred).
    self_consistency: bool,
}

/// Smallest and largest of `v`.
fn span(v: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    v.fold(None, |acc, x| match acc {
        None => Some((x, x)),
        Some((lo, hi)) => Some((lo.min(x), hi.max(x))),
    })
}

/// The series of `report`: errors against time (with a ground truth), else times per frame.
fn series(report: &Report) -> Vec<Series> {
    let with_error = report.has_errors();
    report
        .ordered()
        .iter()
        .map(|m| {
            if with_error {
                let points: Vec<(f64, f64)> = m
                    .frames
                    .iter()
                    .filter_map(|r| r.metrics.map(|x| (r.ms, x.chamfer_l1)))
                    .collect();
                let mean = m.mean.chamfer_l1.and_then(|c| {
                    Some((
                        (m.mean.ms, c),
                        span(points.iter().map(|p| p.0))?,
                        span(points.iter().map(|p| p.1))?,
                    ))
                });
                Series {
                    method: m.method,
                    points,
                    mean,
                    self_consistency: m.relation == Some(Relation::SelfConsistency),
                }
            } else {
                Series {
                    method: m.method,
                    points: m.frames.iter().map(|r| (r.frame as f64, r.ms)).collect(),
                    mean: None,
                    self_consistency: false,
                }
            }
        })
        .collect()
}

/// A log axis over the positive values of `v`, snapped out to whole decades (at least one).
fn log_range(v: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = span(v.filter(|x| x.is_finite() && *x > 0.0)).unwrap_or((1.0, 10.0));
    let (a, b) = (lo.log10().floor(), hi.log10().ceil());
    let b = if b > a { b } else { a + 1.0 };
    10f64.powf(a)..10f64.powf(b)
}

/// A tick label: plain decimals from 0.001 to 99,999, else `2e-5`.
fn tick(v: f64) -> String {
    if v == 0.0 {
        return "0".to_owned();
    }
    if (1e-3..1e5).contains(&v.abs()) {
        // Up to 3 significant digits, no trailing zeros.
        let decimals = (2 - v.abs().log10().floor() as i32).max(0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_owned()
        } else {
            s
        }
    } else {
        let s = format!("{v:.0e}");
        s.replace("e-0", "e-")
    }
}

/// The title of the plot.
fn title(report: &Report) -> String {
    if report.has_errors() {
        format!(
            "Chamfer L1 against time per frame \u{2014} {} frames, ground truth: {}",
            report.frames.len(),
            report.ground_truth.as_deref().unwrap_or("-")
        )
    } else {
        format!(
            "Time per frame \u{2014} {} frames, no ground truth (no error to plot)",
            report.frames.len()
        )
    }
}

/// The note under the legend for a starred method.
pub const SELF_CONSISTENCY_NOTE: &str = "* scored against the mesh it was made from: \
     self-consistency, not accuracy";

type DrawResult<E> = Result<(), DrawingAreaErrorKind<E>>;

/// Draws the plot of `report` on `root` (see the module docs).
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    report: &Report,
) -> DrawResult<DB::ErrorType> {
    root.fill(&WHITE)?;
    let (chart_area, legend_area) = root.split_horizontally(WIDTH - LEGEND);
    let series = series(report);
    let every = series
        .iter()
        .map(|s| s.points.len().div_ceil(MAX_FRAME_MARKS).max(1))
        .max()
        .unwrap_or(1);
    let text = |size: f64| (FAMILY, size).into_font().color(&BLACK);
    if report.has_errors() {
        draw_errors(&chart_area, report, &series, every)?;
    } else {
        draw_times(&chart_area, report, &series, every)?;
    }
    // The legend.
    let mut y = 60;
    let x = 14;
    for s in &series {
        let c = color(s.method);
        legend_mark(&legend_area, s.method, (x + 7, y), 8, BLACK.filled())?;
        legend_mark(&legend_area, s.method, (x + 7, y), 6, c.filled())?;
        let star = if s.self_consistency { " *" } else { "" };
        legend_area.draw(&Text::new(
            format!("{}{star}", s.method.name()),
            (x + 20, y - 8),
            text(19.0),
        ))?;
        y += 26;
    }
    y += 8;
    let grey = RGBColor(90, 90, 90);
    let small = (FAMILY, 16.0).into_font().color(&grey);
    let mut notes: Vec<String> = Vec::new();
    if report.has_errors() {
        notes.push(
            "large mark: mean over the frames; bars: smallest to largest over the frames"
                .to_owned(),
        );
        notes.push(if every > 1 {
            format!("small marks: every {} frame", ordinal(every))
        } else {
            "small marks: one per frame".to_owned()
        });
    } else if every > 1 {
        notes.push(format!("marks: every {} frame", ordinal(every)));
    }
    notes.push(if report.serial_methods {
        "ms: each method alone (--serial-methods)".to_owned()
    } else {
        "ms: methods ran side by side, sharing the cores".to_owned()
    });
    if series.iter().any(|s| s.self_consistency) {
        notes.push(SELF_CONSISTENCY_NOTE.to_owned());
    }
    let width = LEGEND as i32 - 2 * x;
    for note in notes {
        for line in wrap(&legend_area, &note, &small, width) {
            legend_area.draw(&Text::new(line, (x, y), small.clone()))?;
            y += 17;
        }
        y += 8;
    }
    root.present()
}

/// `n` as an English ordinal: 2nd, 3rd, 11th, 21st.
fn ordinal(n: usize) -> String {
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

/// `text` broken into lines no wider than `width` pixels as drawn in `style`.
fn wrap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    style: &TextStyle<'_>,
    width: i32,
) -> Vec<String> {
    let fits = |s: &str| {
        area.estimate_text_size(s, style)
            .is_ok_and(|(w, _)| w as i32 <= width)
    };
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        let candidate = if line.is_empty() {
            word.to_owned()
        } else {
            format!("{line} {word}")
        };
        if line.is_empty() || fits(&candidate) {
            line = candidate;
        } else {
            lines.push(std::mem::replace(&mut line, word.to_owned()));
        }
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// Chamfer L1 against ms per frame, log-log.
fn draw_errors<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    report: &Report,
    series: &[Series],
    every: usize,
) -> DrawResult<DB::ErrorType> {
    let all = || series.iter().flat_map(|s| s.points.iter().copied());
    let xr = log_range(all().map(|p| p.0));
    let yr = log_range(all().map(|p| p.1));
    let (ylo, yhi) = (yr.start, yr.end);
    let mut chart = ChartBuilder::on(area)
        .caption(title(report), (FAMILY, 23))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(84)
        .build_cartesian_2d(xr.log_scale(), yr.log_scale())?;
    chart
        .configure_mesh()
        .x_desc("time per frame, ms (log scale)")
        .y_desc("Chamfer L1 to the ground truth, scene units (log scale)")
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .label_style((FAMILY, 17))
        .axis_desc_style((FAMILY, 18))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()?;
    let clamp = |y: f64| y.clamp(ylo, yhi);
    for s in series {
        let c = color(s.method);
        let points: Vec<(f64, f64)> = s
            .points
            .iter()
            .step_by(every)
            .map(|&(x, y)| (x, clamp(y)))
            .collect();
        chart_marks(&mut chart, s.method, &points, 3, c.mix(0.45).filled())?;
    }
    for s in series {
        let Some(((mx, my), (x0, x1), (y0, y1))) = s.mean else {
            continue;
        };
        let c = color(s.method);
        let bar = c.stroke_width(2);
        chart.draw_series([
            PathElement::new(vec![(x0, clamp(my)), (x1, clamp(my))], bar),
            PathElement::new(vec![(mx, clamp(y0)), (mx, clamp(y1))], bar),
        ])?;
        let at = [(mx, clamp(my))];
        // Outlined: a larger black mark under the coloured one (plotters fills triangles).
        chart_marks(&mut chart, s.method, &at, 10, BLACK.filled())?;
        chart_marks(&mut chart, s.method, &at, 8, c.filled())?;
        let star = if s.self_consistency { " *" } else { "" };
        chart.draw_series([EmptyElement::at((mx, clamp(my)))
            + Text::new(
                format!("{}{star}", s.method.name()),
                (12, -24),
                (FAMILY, 18).into_font().color(&BLACK),
            )])?;
    }
    Ok(())
}

/// ms per frame (log) against the frame index.
fn draw_times<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    report: &Report,
    series: &[Series],
    every: usize,
) -> DrawResult<DB::ErrorType> {
    let all = || series.iter().flat_map(|s| s.points.iter().copied());
    let (f0, f1) = span(all().map(|p| p.0)).unwrap_or((0.0, 1.0));
    let (f0, f1) = if f1 > f0 {
        (f0, f1)
    } else {
        (f0 - 0.5, f0 + 0.5)
    };
    let yr = log_range(all().map(|p| p.1));
    let (ylo, yhi) = (yr.start, yr.end);
    let mut chart = ChartBuilder::on(area)
        .caption(title(report), (FAMILY, 23))
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(84)
        .build_cartesian_2d(f0..f1, yr.log_scale())?;
    chart
        .configure_mesh()
        .x_desc("animation frame")
        .y_desc("time per frame, ms (log scale)")
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .label_style((FAMILY, 17))
        .axis_desc_style((FAMILY, 18))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()?;
    for s in series {
        let c = color(s.method);
        let points: Vec<(f64, f64)> = s
            .points
            .iter()
            .map(|&(x, y)| (x, y.clamp(ylo, yhi)))
            .collect();
        chart.draw_series(LineSeries::new(points.iter().copied(), c.stroke_width(2)))?;
        let marks: Vec<(f64, f64)> = points.iter().step_by(every).copied().collect();
        chart_marks(&mut chart, s.method, &marks, 4, c.filled())?;
    }
    Ok(())
}

/// Why the plot could not be drawn (a font that does not parse, a backend failure).
fn plot_error(path: &std::path::Path, what: impl std::fmt::Display) -> IoError {
    IoError::os(
        path,
        std::io::Error::other(format!("drawing the plot: {what}")),
    )
}

/// The plot of `report` as an SVG document (text in the viewer's sans-serif font).
///
/// # Errors
/// A message when plotters fails (it does not for a report `run` made).
pub fn svg(report: &Report) -> Result<String, String> {
    if !font_ready() {
        return Err("the bundled font does not parse".to_owned());
    }
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (WIDTH, HEIGHT)).into_drawing_area();
        draw(&root, report).map_err(|e| e.to_string())?;
    }
    Ok(out)
}

/// The plot of `report` as 8-bit RGB pixels, [`WIDTH`] x [`HEIGHT`], row-major.
///
/// # Errors
/// A message when plotters fails (it does not for a report `run` made).
pub fn pixels(report: &Report) -> Result<Vec<u8>, String> {
    if !font_ready() {
        return Err("the bundled font does not parse".to_owned());
    }
    let mut buf = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (WIDTH, HEIGHT)).into_drawing_area();
        draw(&root, report).map_err(|e| e.to_string())?;
    }
    Ok(buf)
}

/// Writes the plot of `report` as SVG to `path` (atomically); returns the SVG.
///
/// # Errors
/// [`IoError`] when it cannot be drawn or written.
pub fn write_svg(path: &std::path::Path, report: &Report) -> Result<String, IoError> {
    let text = svg(report).map_err(|e| plot_error(path, e))?;
    write_atomically(path, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| IoError::os(path, e))
    })?;
    Ok(text)
}

/// Writes the plot of `report` as PNG to `path` (atomically).
///
/// # Errors
/// [`IoError`] when it cannot be drawn or written.
pub fn write_png(path: &std::path::Path, report: &Report) -> Result<(), IoError> {
    let buf = pixels(report).map_err(|e| plot_error(path, e))?;
    write_atomically(path, |w| {
        PngEncoder::new(w)
            .write_image(&buf, WIDTH, HEIGHT, image::ExtendedColorType::Rgb8)
            .map_err(|e| IoError::os(path, std::io::Error::other(e.to_string())))
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn log_ranges_snap_to_decades_and_ticks_read_well() {
        assert_eq!(log_range([0.003, 0.02].into_iter()), 0.001..0.1);
        assert_eq!(log_range([5.0].into_iter()), 1.0..10.0);
        assert_eq!(log_range([f64::NAN, -1.0, 0.0].into_iter()), 1.0..10.0);
        assert_eq!(tick(0.001), "0.001");
        assert_eq!(tick(0.002), "0.002");
        assert_eq!(tick(0.0001), "1e-4");
        assert_eq!(tick(2e-5), "2e-5");
        assert_eq!(tick(100.0), "100");
        assert_eq!(tick(250.0), "250");
        assert_eq!(tick(1e6), "1e6");
        assert_eq!(tick(0.5), "0.5");
        assert_eq!(tick(0.0), "0");
        let ords: Vec<String> = [2, 3, 4, 11, 12, 13, 21, 22, 101].map(ordinal).into();
        assert_eq!(
            ords,
            [
                "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "101st"
            ]
        );
    }

    #[test]
    fn the_bundled_font_registers_and_lays_out_text() {
        assert!(font_ready());
        let mut s = String::new();
        let root = SVGBackend::with_string(&mut s, (100, 100)).into_drawing_area();
        let style: TextStyle<'_> = (FAMILY, 16).into_font().into();
        let (short, _) = root.estimate_text_size("ms", &style).expect("layout");
        let (long, _) = root
            .estimate_text_size("milliseconds", &style)
            .expect("layout");
        assert!(short > 0 && long > 3 * short, "{short} {long}");
        let lines = wrap(&root, SELF_CONSISTENCY_NOTE, &style, 180);
        assert!(lines.len() > 1 && lines.join(" ") == SELF_CONSISTENCY_NOTE);
    }

    /// A report of two methods with one measured frame each; delaunay's scores are
    /// self-consistency when `own`; without metrics when not `measured`.
    pub(crate) fn report(own: bool, measured: bool) -> Report {
        use crate::records::{FrameMetrics, FrameRecord, Resolved};
        use crate::report::{MethodReport, Summary};

        use std::collections::BTreeMap;
        let method = |m: Method, c: f64, relation: Relation| {
            let frames: Vec<FrameRecord> = (0..3)
                .map(|f| FrameRecord {
                    frame: f,
                    time: f as f64 / 3.0,
                    ms: 10.0 * c * (1.0 + f as f64),
                    render_ms: None,
                    vertices: 3,
                    faces: 1,
                    watertight: false,
                    metrics: measured.then_some(FrameMetrics {
                        chamfer_l1: c * (1.0 + 0.1 * f as f64),
                        chamfer_l2: c * c,
                        normal_consistency: None,
                        normal_angle_deg: None,
                        accuracy: c,
                        completeness: c,
                        precision: 1.0,
                        recall: 1.0,
                        fscore: 1.0,
                        tau: 0.01,
                        tau_fraction: Some(0.005),
                        gt_diagonal: 2.0,
                        gt_area: 1.0,
                        area_ratio: Some(1.0),
                        shared_vertex_fraction: Some(0.0),
                        relation,
                        structure: None,
                    }),
                    consistency: None,
                    topology: None,
                    simplify: None,
                })
                .collect();
            let mean = Summary::of(&frames);
            MethodReport {
                method: m,
                parameters: BTreeMap::new(),
                relation: mean.relation(),
                mean,
                frames,
                ply_dir: m.name().to_owned(),
                glb: format!("{}.glb", m.name()),
                glb_parts: Vec::new(),
                delaunay: None,
                rig: None,
            }
        };
        let relation = if own {
            Relation::SelfConsistency
        } else {
            Relation::Accuracy
        };
        Report {
            version: String::new(),
            template: "t.glb".to_owned(),
            template_vertices: 3,
            welded_vertices: 3,
            animation: "t.glb".to_owned(),
            unused_channels: Vec::new(),
            gaussians: String::new(),
            gaussian_count: 1,
            mode: "binding".to_owned(),
            frames: vec![0, 1, 2],
            frame_times: vec![0.0; 3],
            deform_ms: vec![0.0; 3],
            collapsed_triangles: vec![0; 3],
            failed_frames: Vec::new(),
            ground_truth: measured.then(|| "template".to_owned()),
            samples: 10,
            tau: None,
            tau_fraction: Some(0.005),
            resolved: Resolved {
                template_radius: 1.0,
                mean_spacing: 0.1,
                voxel: 0.01,
                alpha: 0.6,
            },
            gaussians_used: None,
            glb_storage: BTreeMap::new(),
            serial_methods: false,
            shard: None,
            methods: BTreeMap::from([
                (
                    "tsdf".to_owned(),
                    method(Method::Tsdf, 0.01, Relation::Accuracy),
                ),
                (
                    "delaunay".to_owned(),
                    method(Method::Delaunay, 0.001, relation),
                ),
            ]),
            thumbnails: None,
        }
    }

    #[test]
    fn the_svg_names_each_method_its_axes_and_the_self_consistency() {
        let plain = svg(&report(false, true)).expect("svg");
        assert!(plain.starts_with("<svg"), "{}", &plain[..60]);
        assert!(plain.trim_end().ends_with("</svg>"));
        for label in [
            ">\ntsdf\n</text>",
            ">\ndelaunay\n</text>",
            "time per frame, ms (log scale)",
            "Chamfer L1 to the ground truth, scene units (log scale)",
            "ground truth: template",
        ] {
            assert!(plain.contains(label), "{label} missing");
        }
        assert!(!plain.contains("self-consistency"));
        let starred = svg(&report(true, true)).expect("svg");
        assert!(starred.contains(">\ndelaunay *\n</text>"));
        assert!(starred.contains("self-consistency, not"), "the footnote");
        // Without metrics: time per frame against the frame.
        let times = svg(&report(false, false)).expect("svg");
        assert!(times.contains("animation frame") && times.contains("no ground truth"));
        assert!(!times.contains("Chamfer L1 to"));
    }

    #[test]
    fn the_png_has_text_and_each_method_colour() {
        let px = pixels(&report(true, true)).expect("pixels");
        assert_eq!(px.len(), (WIDTH * HEIGHT * 3) as usize);
        let has = |c: RGBColor| px.chunks_exact(3).any(|p| p == [c.0, c.1, c.2]);
        assert!(has(color(Method::Tsdf)) && has(color(Method::Delaunay)));
        assert!(!has(color(Method::Alpha)), "no alpha in this report");
        // Text in the legend panel: dark pixels right of the chart, where only the legend is.
        let dark = (0..HEIGHT as usize)
            .flat_map(|y| ((WIDTH - LEGEND) as usize + 30..WIDTH as usize).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let i = 3 * (y * WIDTH as usize + x);
                px[i] < 100 && px[i + 1] < 100 && px[i + 2] < 100
            })
            .count();
        assert!(dark > 300, "legend text drawn: {dark} dark pixels");
    }
}
