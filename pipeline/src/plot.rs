//! error_vs_time.png: a small scatter plot drawn with our own rasteriser and the embedded
//! bitmap font, written as an 8-bit RGB PNG.
//!
//! With a ground truth: Chamfer L1 (y) against milliseconds per frame (x), both on log axes,
//! one small dot per frame and one large dot (black outline) for each method's mean; a method
//! whose scores are self-consistency (its meshes contain the ground truth's vertices) is
//! starred in the legend, with a footnote saying its scores are not accuracy. Without:
//! milliseconds per frame (y, log axis) against the frame index (x, linear), one line per
//! method; the title says there is no ground truth.

use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use trisplat_geometry::io::{IoError, write_atomically};

use crate::config::Method;
use crate::font;
use crate::report::Report;
use trisplat_geometry::metrics::Relation;

/// Plot width in pixels.
pub const WIDTH: usize = 900;
/// Plot height in pixels.
pub const HEIGHT: usize = 600;
/// Text is drawn at this many pixels per font pixel.
const TEXT_SCALE: usize = 2;
const LEFT: usize = 110;
const RIGHT: usize = 200;
const TOP: usize = 50;
const BOTTOM: usize = 70;

type Rgb = [u8; 3];
const WHITE: Rgb = [255, 255, 255];
const BLACK: Rgb = [0, 0, 0];
const GRID: Rgb = [225, 225, 225];

/// The colour of a method's marks.
#[must_use]
pub fn color(method: Method) -> Rgb {
    match method {
        Method::Tsdf => [31, 119, 180],
        Method::Delaunay => [255, 127, 14],
        Method::Alpha => [44, 160, 44],
    }
}

/// An RGB raster.
#[derive(Clone, Debug)]
pub struct Canvas {
    width: usize,
    height: usize,
    data: Vec<u8>,
}

impl Canvas {
    /// A white canvas.
    #[must_use]
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            data: vec![255; width * height * 3],
        }
    }

    /// The pixels, row-major RGB.
    #[must_use]
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// The colour at `(x, y)`, `None` outside.
    #[must_use]
    pub fn pixel(&self, x: usize, y: usize) -> Option<Rgb> {
        (x < self.width && y < self.height).then(|| {
            let i = (y * self.width + x) * 3;
            [self.data[i], self.data[i + 1], self.data[i + 2]]
        })
    }

    fn set(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let i = (y as usize * self.width + x as usize) * 3;
            self.data[i..i + 3].copy_from_slice(&c);
        }
    }

    fn rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb) {
        for y in y0.min(y1)..=y0.max(y1) {
            for x in x0.min(x1)..=x0.max(x1) {
                self.set(x, y, c);
            }
        }
    }

    /// A line (Bresenham), `thick` pixels wide.
    fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: Rgb, thick: i64) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        let half = thick / 2;
        loop {
            self.rect(
                x - half,
                y - half,
                x - half + thick - 1,
                y - half + thick - 1,
                c,
            );
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    fn disc(&mut self, cx: i64, cy: i64, r: i64, c: Rgb) {
        for y in -r..=r {
            for x in -r..=r {
                if x * x + y * y <= r * r {
                    self.set(cx + x, cy + y, c);
                }
            }
        }
    }

    /// Text with its top-left corner at `(x, y)`; `vertical` turns it 90° counter-clockwise
    /// (reading upward, `(x, y)` then is its bottom-left corner).
    fn text(&mut self, x: i64, y: i64, s: &str, c: Rgb, vertical: bool) {
        let k = TEXT_SCALE as i64;
        for (n, ch) in s.chars().enumerate() {
            let g = font::glyph(ch);
            let advance = n as i64 * (font::WIDTH as i64 + 1) * k;
            for (row, bits) in g.iter().enumerate() {
                for (col, b) in bits.bytes().enumerate() {
                    if b != b'#' {
                        continue;
                    }
                    let (u, v) = (advance + col as i64 * k, row as i64 * k);
                    for a in 0..k {
                        for b in 0..k {
                            if vertical {
                                self.set(x + v + b, y - u - a, c);
                            } else {
                                self.set(x + u + a, y + v + b, c);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Width of `s` in pixels as drawn.
fn text_width(s: &str) -> i64 {
    (s.chars().count() * (font::WIDTH + 1) * TEXT_SCALE) as i64
}

/// An axis mapping data to pixels, log10 or linear.
#[derive(Clone, Copy, Debug)]
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
}

impl Axis {
    /// Covers `values` (finite; positive for log axes); log axes snap to whole decades.
    fn new(values: &[f64], log: bool) -> Self {
        let v: Vec<f64> = values
            .iter()
            .copied()
            .filter(|v| v.is_finite() && (!log || *v > 0.0))
            .map(|v| if log { v.log10() } else { v })
            .collect();
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
        let (lo, hi) = if log {
            let (a, b) = (lo.floor(), hi.ceil());
            (a, if b > a { b } else { a + 1.0 })
        } else if hi > lo {
            (lo, hi)
        } else {
            (lo - 0.5, lo + 0.5)
        };
        Self { lo, hi, log }
    }

    /// Position in `[0, 1]` of `v`.
    fn unit(&self, v: f64) -> f64 {
        let v = if self.log {
            v.max(f64::MIN_POSITIVE).log10()
        } else {
            v
        };
        ((v - self.lo) / (self.hi - self.lo)).clamp(0.0, 1.0)
    }

    /// Major ticks: (value, label).
    fn ticks(&self) -> Vec<(f64, String)> {
        if self.log {
            let (a, b) = (self.lo as i32, self.hi as i32);
            return (a..=b).map(|e| (10f64.powi(e), decade_label(e))).collect();
        }
        let span = self.hi - self.lo;
        let step = nice_step(span / 6.0);
        let first = (self.lo / step).ceil() as i64;
        let last = (self.hi / step).floor() as i64;
        (first..=last)
            .map(|i| {
                let v = i as f64 * step;
                (v, format!("{}", (v * 1e6).round() / 1e6))
            })
            .collect()
    }

    /// Minor ticks (2..9 times each decade) of a log axis.
    fn minor(&self) -> Vec<f64> {
        if !self.log {
            return Vec::new();
        }
        (self.lo as i32..self.hi as i32)
            .flat_map(|e| (2..10).map(move |k| f64::from(k) * 10f64.powi(e)))
            .collect()
    }
}

/// `10^e` as a short label: plain for 1e-2..1e4, else `1e-5`.
fn decade_label(e: i32) -> String {
    if (-2..=4).contains(&e) {
        let v = 10f64.powi(e);
        format!("{}", (v * 100.0).round() / 100.0)
    } else {
        format!("1e{e}")
    }
}

/// 1, 2 or 5 times a power of ten, at least `raw`.
fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|k| k * p)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * p)
}

/// One series: a method's points and its mean point.
struct Series {
    method: Method,
    points: Vec<(f64, f64)>,
    mean: Option<(f64, f64)>,
    /// Its scores are self-consistency (starred in the legend).
    self_consistency: bool,
}

/// Draws the plot of `report` (see the module docs).
#[must_use]
pub fn draw(report: &Report) -> Canvas {
    let with_error = report.ground_truth.is_some()
        && report.ordered().iter().any(|m| m.mean.chamfer_l1.is_some());
    let series: Vec<Series> = report
        .ordered()
        .iter()
        .map(|m| {
            if with_error {
                Series {
                    method: m.method,
                    points: m
                        .frames
                        .iter()
                        .filter_map(|r| r.metrics.map(|x| (r.ms, x.chamfer_l1)))
                        .collect(),
                    mean: m.mean.chamfer_l1.map(|c| (m.mean.ms, c)),
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
        .collect();
    let xs: Vec<f64> = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0))
        .collect();
    let ys: Vec<f64> = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .collect();
    let x_axis = Axis::new(&xs, with_error);
    let y_axis = Axis::new(&ys, true);
    let (title, x_label, y_label) = if with_error {
        (
            format!(
                "Chamfer L1 vs time per frame ({} frames, gt: {})",
                report.frames.len(),
                report.ground_truth.as_deref().unwrap_or("-")
            ),
            "ms per frame (log)",
            "Chamfer L1 (log)",
        )
    } else {
        (
            format!(
                "Time per frame - no ground truth, no error ({} frames)",
                report.frames.len()
            ),
            "frame",
            "ms per frame (log)",
        )
    };

    let mut c = Canvas::new(WIDTH, HEIGHT);
    let (x0, x1) = (LEFT as i64, (WIDTH - RIGHT) as i64);
    let (y0, y1) = (TOP as i64, (HEIGHT - BOTTOM) as i64);
    let px = |v: f64| x0 + (x_axis.unit(v) * (x1 - x0) as f64).round() as i64;
    let py = |v: f64| y1 - (y_axis.unit(v) * (y1 - y0) as f64).round() as i64;

    // Grid and ticks.
    for v in x_axis.minor() {
        c.line((px(v), y0), (px(v), y1), GRID, 1);
    }
    for v in y_axis.minor() {
        c.line((x0, py(v)), (x1, py(v)), GRID, 1);
    }
    for (v, label) in x_axis.ticks() {
        let x = px(v);
        c.line((x, y0), (x, y1), GRID, 1);
        c.line((x, y1), (x, y1 + 6), BLACK, 1);
        c.text(x - text_width(&label) / 2, y1 + 10, &label, BLACK, false);
    }
    for (v, label) in y_axis.ticks() {
        let y = py(v);
        c.line((x0, y), (x1, y), GRID, 1);
        c.line((x0 - 6, y), (x0, y), BLACK, 1);
        c.text(x0 - 10 - text_width(&label), y - 7, &label, BLACK, false);
    }
    // Frame.
    c.line((x0, y0), (x1, y0), BLACK, 1);
    c.line((x0, y1), (x1, y1), BLACK, 1);
    c.line((x0, y0), (x0, y1), BLACK, 1);
    c.line((x1, y0), (x1, y1), BLACK, 1);
    // Labels.
    c.text(
        (WIDTH as i64 - text_width(&title)) / 2,
        14,
        &title,
        BLACK,
        false,
    );
    c.text(
        (x0 + x1 - text_width(x_label)) / 2,
        y1 + 40,
        x_label,
        BLACK,
        false,
    );
    c.text(
        14,
        (y0 + y1 + text_width(y_label)) / 2,
        y_label,
        BLACK,
        true,
    );
    // Data.
    for s in &series {
        let col = color(s.method);
        if !with_error {
            for w in s.points.windows(2) {
                c.line((px(w[0].0), py(w[0].1)), (px(w[1].0), py(w[1].1)), col, 2);
            }
        }
        for &(x, y) in &s.points {
            c.disc(px(x), py(y), 3, col);
        }
        if let Some((x, y)) = s.mean {
            c.disc(px(x), py(y), 8, BLACK);
            c.disc(px(x), py(y), 6, col);
        }
    }
    // Legend; a method scored against the mesh it contains is starred and the star explained.
    let lx = x1 + 20;
    let mut starred = false;
    for (i, s) in series.iter().enumerate() {
        let y = y0 + 10 + i as i64 * 28;
        c.disc(lx + 8, y + 7, 6, color(s.method));
        let label = if with_error && s.self_consistency {
            starred = true;
            format!("{} *", s.method.name())
        } else {
            s.method.name().to_owned()
        };
        c.text(lx + 22, y, &label, BLACK, false);
    }
    if with_error {
        let y = y0 + 10 + series.len() as i64 * 28 + 10;
        c.disc(lx + 8, y + 7, 8, BLACK);
        c.disc(lx + 8, y + 7, 6, WHITE);
        c.text(lx + 22, y, "mean", BLACK, false);
        if starred {
            for (k, line) in SELF_CONSISTENCY_NOTE.iter().enumerate() {
                c.text(lx, y + 40 + k as i64 * 20, line, BLACK, false);
            }
        }
    }
    c
}

/// The legend's footnote for a starred method (lines fit the 200-pixel margin).
pub const SELF_CONSISTENCY_NOTE: [&str; 4] = [
    "* scored on",
    "its own input:",
    "self-consist.,",
    "not accuracy",
];

/// Draws the plot of `report` and writes it to `path` (PNG, atomically).
///
/// # Errors
/// [`IoError`] when the file cannot be written.
pub fn write_plot(path: &std::path::Path, report: &Report) -> Result<(), IoError> {
    let canvas = draw(report);
    write_atomically(path, |w| {
        PngEncoder::new(w)
            .write_image(
                canvas.data(),
                WIDTH as u32,
                HEIGHT as u32,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| IoError::os(path, std::io::Error::other(e.to_string())))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axis_snaps_to_decades() {
        let a = Axis::new(&[0.003, 0.02], true);
        assert_eq!((a.lo, a.hi), (-3.0, -1.0));
        assert_eq!(a.ticks().len(), 3);
        assert!((a.unit(0.01) - 0.5).abs() < 1e-12);
        // One value: one decade around it; no values: a default range; never NaN.
        let one = Axis::new(&[5.0], true);
        assert_eq!((one.lo, one.hi), (0.0, 1.0));
        let none = Axis::new(&[f64::NAN, -1.0], true);
        assert!(none.unit(3.0).is_finite());
    }

    #[test]
    fn linear_ticks_are_nice() {
        let a = Axis::new(&[0.0, 9.0], false);
        let t: Vec<f64> = a.ticks().into_iter().map(|t| t.0).collect();
        assert_eq!(t, vec![0.0, 2.0, 4.0, 6.0, 8.0]);
        assert_eq!(nice_step(0.13), 0.2);
        assert_eq!(decade_label(-3), "1e-3");
        assert_eq!(decade_label(2), "100");
        assert_eq!(decade_label(-1), "0.1");
    }

    /// A report of two methods with one measured frame each; delaunay's scores are
    /// self-consistency when `own`.
    fn report(own: bool) -> Report {
        use crate::config::Method;
        use crate::methods::Resolved;
        use crate::report::{FrameMetrics, FrameRecord, MethodReport, Summary};
        use std::collections::BTreeMap;
        let method = |m: Method, c: f64, relation: Relation| {
            let frames = vec![FrameRecord {
                frame: 0,
                time: 0.0,
                ms: 10.0 * c,
                render_ms: None,
                vertices: 3,
                faces: 1,
                watertight: false,
                metrics: Some(FrameMetrics {
                    chamfer_l1: c,
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
            }];
            let mean = Summary::of(&frames);
            MethodReport {
                method: m,
                parameters: BTreeMap::new(),
                relation: mean.relation(),
                mean,
                frames,
                ply_dir: String::new(),
                glb: String::new(),
                glb_parts: Vec::new(),
                delaunay: None,
            }
        };
        let relation = if own {
            Relation::SelfConsistency
        } else {
            Relation::Accuracy
        };
        Report {
            version: String::new(),
            template: String::new(),
            template_vertices: 3,
            welded_vertices: 3,
            animation: String::new(),
            unused_channels: Vec::new(),
            gaussians: String::new(),
            gaussian_count: 1,
            mode: String::new(),
            frames: vec![0],
            frame_times: vec![0.0],
            deform_ms: vec![0.0],
            failed_frames: Vec::new(),
            ground_truth: Some("template".to_owned()),
            samples: 10,
            tau: None,
            tau_fraction: Some(0.005),
            resolved: Resolved {
                template_radius: 1.0,
                mean_spacing: 0.1,
                voxel: 0.01,
                alpha: 0.6,
            },
            serial_methods: false,
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
        }
    }

    #[test]
    fn self_consistency_is_starred_and_explained_in_the_legend() {
        let ink = |c: &Canvas| {
            let mut n = 0;
            for y in 0..HEIGHT {
                for x in WIDTH - RIGHT..WIDTH {
                    n += usize::from(c.pixel(x, y) == Some(BLACK));
                }
            }
            n
        };
        let plain = draw(&report(false));
        let starred = draw(&report(true));
        let note: usize = SELF_CONSISTENCY_NOTE
            .iter()
            .map(|l| text_width(l) as usize)
            .sum();
        assert!(
            ink(&starred) > ink(&plain) + note,
            "the star and the note add ink"
        );
        let margin = (RIGHT - 20) as i64;
        assert!(
            SELF_CONSISTENCY_NOTE
                .iter()
                .all(|l| text_width(l) <= margin)
        );
    }

    #[test]
    fn text_and_lines_leave_ink() {
        let mut c = Canvas::new(60, 30);
        c.text(1, 1, "A1", BLACK, false);
        assert_eq!(c.pixel(1, 3), Some(BLACK)); // left stroke of A
        c.line((0, 29), (59, 29), [1, 2, 3], 1);
        assert_eq!(c.pixel(30, 29), Some([1, 2, 3]));
        assert_eq!(c.pixel(60, 0), None);
    }
}
