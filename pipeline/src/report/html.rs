//! report.html: the run on one page, self-contained (inline CSS and the plot as inline SVG; the
//! thumbnails are PNG files beside it in `thumbnails/`, linked relatively, so the folder can
//! be moved or served as it is).
//!
//! In order: the run's facts (as report.md's list), the plot, the means over the frames (the
//! cells of report.md's table, [`Report::summary_table`]), the thumbnails of one frame (each
//! method's mesh and the ground truth from one camera, coloured by distance to the ground
//! truth, with the colour scale), per method its notes and per-frame table (the first
//! [`MAX_FRAME_ROWS`] frames, folded away past [`OPEN_FRAME_ROWS`]; every frame is in
//! report.json and report.md), and the files of the run.

use std::fmt::Write as _;
use std::path::Path;

use trisplat_geometry::io::{IoError, write_atomically};

use super::files::{PLOT_PNG, PLOT_SVG, REPORT_JSON, REPORT_MD};
use super::model::{Report, Thumbnails};
use super::plot;
use super::table::{Cell, Table};
use super::thumbnail::viridis;
use crate::config::Method;

/// Per-frame rows shown per method; the rest are in report.json and report.md.
pub const MAX_FRAME_ROWS: usize = 100;
/// Per-frame tables with at most this many rows are shown unfolded.
pub const OPEN_FRAME_ROWS: usize = 30;

/// `s` with `&`, `<`, `>` and `"` escaped for HTML text and attribute values.
#[must_use]
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            _ => out.push(ch),
        }
    }
    out
}

/// The report's Markdown inline marks as HTML: `` `code` `` and `**strong**` (the rest
/// escaped).
fn inline(markdown: &str) -> String {
    let mut out = String::new();
    let (mut code, mut strong) = (false, false);
    let mut rest = markdown;
    while let Some(ch) = rest.chars().next() {
        if rest.starts_with("**") && !code {
            out.push_str(if strong { "</strong>" } else { "<strong>" });
            strong = !strong;
            rest = &rest[2..];
            continue;
        }
        if ch == '`' {
            out.push_str(if code { "</code>" } else { "<code>" });
            code = !code;
        } else {
            out.push_str(&escape(&ch.to_string()));
        }
        rest = &rest[ch.len_utf8()..];
    }
    if code {
        out.push_str("</code>");
    }
    if strong {
        out.push_str("</strong>");
    }
    out
}

/// The per-frame columns report.html shows (all of them are in report.md and report.json):
/// the table stays readable without scrolling sideways.
pub const FRAME_COLUMNS: [&str; 15] = [
    "frame",
    "ms",
    "faces",
    "watertight",
    "components",
    "boundary edges",
    "area ratio",
    "scored as",
    "Chamfer L1",
    "normal consistency",
    "recall",
    "F-score",
    "hopped",
    "charts redone",
    "rebuilt",
];

/// A method's name with its plot colour as a dot.
fn method_label(m: Method) -> String {
    format!(
        "<span class=\"dot\" style=\"background:{}\"></span>{}",
        plot::css_color(m),
        escape(m.name())
    )
}

/// A column title as HTML: escaped, breaking only between words, never at a hyphen nor
/// before a short last word ("Chamfer L1", "normal angle °").
fn header_html(title: &str) -> String {
    let mut words: Vec<String> = title
        .split(' ')
        .map(|w| escape(w).replace('-', "&#8209;"))
        .collect();
    if words.len() > 1 && words.last().is_some_and(|w| w.chars().count() <= 2) {
        let last = words.pop().unwrap_or_default();
        if let Some(prev) = words.last_mut() {
            prev.push_str("&nbsp;");
            prev.push_str(&last);
        }
    }
    words.join(" ")
}

/// `cell` as HTML: escaped, self-consistency in bold.
fn cell_html(cell: &Cell) -> String {
    if cell.strong {
        format!("<strong class=\"sc\">{}</strong>", escape(&cell.text))
    } else {
        escape(&cell.text)
    }
}

/// The columns of `table` whose titles are in `keep`, in the table's order.
fn select(table: &Table, keep: &[&str]) -> Table {
    let columns: Vec<usize> = (0..table.header.len())
        .filter(|&k| keep.contains(&table.header[k].as_str()))
        .collect();
    Table {
        header: columns.iter().map(|&k| table.header[k].clone()).collect(),
        right: columns.iter().map(|&k| table.right[k]).collect(),
        rows: table
            .rows
            .iter()
            .map(|row| columns.iter().map(|&k| row[k].clone()).collect())
            .collect(),
    }
}

/// `table` turned a quarter: one column per row of it (headed by its first cell, rendered by
/// `head`), one row per column (for the means: the methods side by side).
fn transposed_html(table: &Table, head: &dyn Fn(&Cell) -> String) -> String {
    let mut s = String::from("<div class=\"scroll narrow\"><table>\n<thead><tr>");
    let _ = write!(
        s,
        "<th>{}</th>",
        escape(table.header.first().map_or("", String::as_str))
    );
    for row in &table.rows {
        let _ = write!(
            s,
            "<th class=\"num\">{}</th>",
            row.first().map_or_else(String::new, head)
        );
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for k in 1..table.header.len() {
        let _ = write!(
            s,
            "<tr><th scope=\"row\">{}</th>",
            header_html(&table.header[k])
        );
        for row in &table.rows {
            let _ = write!(
                s,
                "<td class=\"num\">{}</td>",
                row.get(k).map_or_else(String::new, cell_html)
            );
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody></table></div>\n");
    s
}

/// `table` as HTML, the first `max_rows` rows; `first_cell` renders the first column's cells
/// (e.g. a method's name with its colour).
fn table_html(table: &Table, max_rows: usize, first_cell: &dyn Fn(&Cell) -> String) -> String {
    let mut s = String::from("<div class=\"scroll\"><table>\n<thead><tr>");
    for (h, &right) in table.header.iter().zip(&table.right) {
        let _ = write!(
            s,
            "<th{}>{}</th>",
            if right { " class=\"num\"" } else { "" },
            header_html(h)
        );
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for row in table.rows.iter().take(max_rows) {
        s.push_str("<tr>");
        for (k, (cell, &right)) in row.iter().zip(&table.right).enumerate() {
            let text = if k == 0 {
                first_cell(cell)
            } else {
                cell_html(cell)
            };
            let _ = write!(
                s,
                "<td{}>{text}</td>",
                if right { " class=\"num\"" } else { "" }
            );
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody></table></div>\n");
    s
}

const STYLE: &str = "
:root { color-scheme: light; }
body { font: 15px/1.45 system-ui, -apple-system, 'Segoe UI', Roboto, 'DejaVu Sans', sans-serif;
  color: #1d1d1f; background: #fff; margin: 0 auto; max-width: 1240px; padding: 20px 28px 60px; }
h1 { font-size: 26px; margin: 8px 0 2px; }
h2 { font-size: 20px; margin: 34px 0 8px; padding-top: 8px; border-top: 1px solid #e3e3e3; }
h3 { font-size: 17px; margin: 22px 0 6px; }
.sub { color: #555; margin: 0 0 12px; }
nav { font-size: 14px; margin: 6px 0 0; }
nav a { margin-right: 14px; }
a { color: #0b62b5; }
ul.facts { margin: 8px 0; padding-left: 20px; color: #333; font-size: 14px; }
ul.facts li { margin: 2px 0; }
code { font: 13px/1.3 ui-monospace, 'DejaVu Sans Mono', monospace; background: #f3f3f3;
  padding: 0 3px; border-radius: 3px; overflow-wrap: anywhere; }
figure { margin: 0; }
figure.plot svg { width: 100%; height: auto; max-width: 960px; display: block; }
.scroll { overflow-x: auto; border: 1px solid #e3e3e3; border-radius: 4px; }
.scroll.narrow { display: inline-block; max-width: 100%; }
table { border-collapse: collapse; font-size: 13px; font-variant-numeric: tabular-nums;
  white-space: nowrap; }
th, td { padding: 4px 9px; text-align: left; }
th { background: #f5f5f7; font-weight: 600; border-bottom: 1px solid #ddd; white-space: normal;
  vertical-align: bottom; }
tbody th { background: none; border-bottom: none; font-weight: 500; white-space: nowrap; }
td.num, th.num { text-align: right; }
tbody tr:nth-child(even) { background: #fafafa; }
.dot { display: inline-block; width: 10px; height: 10px; border-radius: 50%; margin-right: 6px;
  vertical-align: 0; }
strong.sc { color: #a34700; }
p.note { font-size: 14px; color: #333; max-width: 900px; }
.thumbs { display: flex; flex-wrap: wrap; gap: 14px; align-items: stretch; }
.thumbs figure { border: 1px solid #e3e3e3; border-radius: 4px; padding: 6px; background: #fff;
  width: min-content; }
.thumbs img { display: block; }
.thumbs figcaption { font-size: 13px; margin-top: 4px; min-width: 150px; }
.scale { display: flex; align-items: center; gap: 10px; font-size: 13px; margin: 6px 0 14px; }
.bar { width: 380px; height: 14px; border: 1px solid #bbb; border-radius: 2px; }
.ticks { position: relative; width: 382px; height: 16px; font-size: 12px; color: #444; }
.ticks span { position: absolute; top: 0; white-space: nowrap; }
.ticks .lo { left: 0; }
.ticks .mid { left: 50%; transform: translateX(-50%); }
.ticks .hi { right: 0; }
details { margin: 10px 0; }
summary { cursor: pointer; font-weight: 600; }
.more { font-size: 13px; color: #555; margin: 4px 0 0; }
";

/// The page of `report`, with `svg` (the plot) inline.
#[must_use]
pub fn html(report: &Report, svg: &str) -> String {
    let mut s = String::new();
    let name = Path::new(&report.template).file_name().map_or_else(
        || report.template.clone(),
        |n| n.to_string_lossy().into_owned(),
    );
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>trisplat report: {}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n",
        escape(&name)
    );
    let gt = report.ground_truth.as_deref().map_or_else(
        || "no ground truth".to_owned(),
        |g| format!("ground truth: {g}"),
    );
    let methods: Vec<&str> = report.ordered().iter().map(|m| m.method.name()).collect();
    let _ = write!(
        s,
        "<h1>trisplat extract report</h1>\n<p class=\"sub\">{} &middot; {} frames &middot; {} \
         &middot; {}</p>\n",
        escape(&name),
        report.frames.len(),
        escape(&methods.join(", ")),
        escape(&gt)
    );
    let thumbs = report.thumbnails.as_ref();
    let _ = writeln!(
        s,
        "<nav><a href=\"#plot\">Plot</a><a href=\"#means\">Means</a>{}<a \
         href=\"#frames\">Per frame</a><a href=\"#files\">Files</a></nav>",
        if thumbs.is_some() {
            "<a href=\"#thumbnails\">Meshes</a>"
        } else {
            ""
        }
    );
    s.push_str("<ul class=\"facts\">\n");
    for fact in report.facts() {
        // A fact may hold a nested list (failed frames): one line each.
        let mut lines = fact.lines();
        let head = lines.next().unwrap_or_default();
        let _ = write!(s, "<li>{}", inline(head));
        let rest: Vec<&str> = lines.collect();
        if !rest.is_empty() {
            s.push_str("<ul>");
            for line in rest {
                let _ = write!(
                    s,
                    "<li>{}</li>",
                    inline(line.trim_start().trim_start_matches("- "))
                );
            }
            s.push_str("</ul>");
        }
        s.push_str("</li>\n");
    }
    s.push_str("</ul>\n");

    // The plot.
    let _ = write!(
        s,
        "<h2 id=\"plot\">{}</h2>\n<figure class=\"plot\">\n{}\n</figure>\n<p class=\"more\">The \
         plot as files: <a href=\"{PLOT_SVG}\">{PLOT_SVG}</a>, <a \
         href=\"{PLOT_PNG}\">{PLOT_PNG}</a>.</p>\n",
        if report.has_errors() {
            "Error against time per frame"
        } else {
            "Time per frame"
        },
        svg.trim()
    );

    // The means.
    let _ = writeln!(s, "<h2 id=\"means\">Means over frames</h2>");
    let label = |c: &Cell| {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == c.text)
            .map_or_else(|| escape(&c.text), method_label)
    };
    s.push_str(&transposed_html(&report.summary_table(), &label));
    for note in report.self_consistency_notes() {
        let _ = writeln!(s, "<p class=\"note\">{}</p>", inline(&note));
    }

    if let Some(t) = thumbs {
        s.push_str(&thumbnails_html(report, t));
    }

    // Per frame.
    let _ = writeln!(s, "<h2 id=\"frames\">Per frame</h2>");
    for m in report.ordered() {
        let table = select(&Report::frame_table(m), &FRAME_COLUMNS);
        let n = table.rows.len();
        let shown = n.min(MAX_FRAME_ROWS);
        let _ = write!(
            s,
            "<details{}>\n<summary>{} &middot; {n} frames{}</summary>\n",
            if n <= OPEN_FRAME_ROWS { " open" } else { "" },
            method_label(m.method),
            if shown < n {
                format!(" (the first {shown} shown)")
            } else {
                String::new()
            }
        );
        for note in Report::method_notes(m) {
            let _ = writeln!(s, "<p class=\"note\">{}</p>", inline(&note));
        }
        s.push_str(&table_html(&table, MAX_FRAME_ROWS, &|c| escape(&c.text)));
        let _ = writeln!(
            s,
            "<p class=\"more\">{}Every frame with every column (time, vertices, largest piece, \
             Chamfer L2, normal angle, tau, precision in report.json) is in <a \
             href=\"{REPORT_MD}\">{REPORT_MD}</a> and <a href=\"{REPORT_JSON}\">{REPORT_JSON}</a>.</p>",
            if shown < n {
                format!("{} more frames not shown. ", n - shown)
            } else {
                String::new()
            }
        );
        s.push_str("</details>\n");
    }

    // Files.
    let _ = writeln!(s, "<h2 id=\"files\">Files</h2>\n<ul class=\"facts\">");
    let _ = writeln!(
        s,
        "<li><a href=\"{REPORT_JSON}\">{REPORT_JSON}</a>: every number of the run; <a \
         href=\"{REPORT_MD}\">{REPORT_MD}</a>: the same as tables</li>"
    );
    for m in report.ordered() {
        let glbs: Vec<String> = if m.glb_parts.is_empty() {
            vec![m.glb.clone()]
        } else {
            m.glb_parts.clone()
        };
        let links: Vec<String> = glbs
            .iter()
            .map(|g| format!("<a href=\"{0}\">{0}</a>", escape(g)))
            .collect();
        let _ = writeln!(
            s,
            "<li>{}: <a href=\"{1}/\">{1}/</a> (one PLY per frame), {2} (the animated \
             sequence)</li>",
            method_label(m.method),
            escape(&m.ply_dir),
            links.join(", ")
        );
    }
    let _ = writeln!(
        s,
        "</ul>\n<p class=\"more\">Written by trisplat {}.</p>\n</body>\n</html>",
        escape(&report.version)
    );
    s
}

/// The thumbnails section.
fn thumbnails_html(report: &Report, t: &Thumbnails) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<h2 id=\"thumbnails\">The meshes of frame {}</h2>",
        t.frame
    );
    let frame_metrics = |m: &super::model::MethodReport| {
        m.frames
            .iter()
            .find(|r| r.frame == t.frame)
            .and_then(|r| r.metrics)
    };
    match t.scale {
        Some(scale) => {
            let tau = scale / 2.0;
            let stops: Vec<String> = (0..=8)
                .map(|k| {
                    let [r, g, b] = viridis(f64::from(k) / 8.0);
                    format!("rgb({r},{g},{b})")
                })
                .collect();
            let _ = writeln!(
                s,
                "<p class=\"note\">Each mesh seen from the same camera; the colour of a point is \
                 its distance to the ground truth's surface ({}), from 0 to 2&tau;, \
                 twice the F-score threshold (points farther than 2&tau; are yellow too); \
                 shading follows the surface's angle to the camera. The ground truth is grey.</p>",
                escape(&gt_words(report.ground_truth.as_deref().unwrap_or("-")))
            );
            let _ = writeln!(
                s,
                "<div class=\"scale\"><span>distance to the ground truth, scene units</span><div>\
                 <div class=\"bar\" style=\"background:linear-gradient(to right,{})\"></div>\
                 <div class=\"ticks\"><span class=\"lo\">0</span><span class=\"mid\">&tau; = {}</span>\
                 <span class=\"hi\">&ge; 2&tau; = {}</span></div></div></div>",
                stops.join(","),
                format_distance(tau),
                format_distance(scale)
            );
        }
        None => {
            let _ = writeln!(
                s,
                "<p class=\"note\">Each mesh seen from the same camera, shaded by the surface's \
                 angle to the camera (no ground truth: no distances to colour).</p>"
            );
        }
    }
    s.push_str("<div class=\"thumbs\">\n");
    if let Some(file) = &t.ground_truth {
        let _ = writeln!(
            s,
            "<figure><img src=\"{0}\" alt=\"ground truth, frame {1}\"><figcaption><strong>ground \
             truth</strong><br>{2}</figcaption></figure>",
            escape(file),
            t.frame,
            escape(&gt_words(report.ground_truth.as_deref().unwrap_or("-")))
        );
    }
    for m in report.ordered() {
        let Some(file) = t.methods.get(m.method.name()) else {
            continue;
        };
        let caption = match frame_metrics(m) {
            Some(x) => {
                let sc = if x.relation == trisplat_geometry::metrics::Relation::SelfConsistency {
                    " <strong class=\"sc\">(self-consistency)</strong>"
                } else {
                    ""
                };
                format!(
                    "Chamfer L1 {} at this frame{sc}",
                    format_distance(x.chamfer_l1)
                )
            }
            None => "not measured".to_owned(),
        };
        let _ = writeln!(
            s,
            "<figure><img src=\"{0}\" alt=\"{1}, frame {2}\"><figcaption><strong>{3}</strong><br>{caption}</figcaption></figure>",
            escape(file),
            escape(m.method.name()),
            t.frame,
            method_label(m.method),
        );
    }
    s.push_str("</div>\n");
    s
}

/// The ground truth as words: `template` and `gaussians` said out, a file or sequence as
/// given.
fn gt_words(label: &str) -> String {
    match label {
        "template" => "the frame's deformed template".to_owned(),
        "gaussians" => "the frame's surface of the Gaussians' centres".to_owned(),
        other => other.to_owned(),
    }
}

/// A distance with 3 significant digits (`0.00852`, `1.23e-5`).
fn format_distance(d: f64) -> String {
    if d != 0.0 && (d.abs() < 1e-3 || d.abs() >= 1e5) {
        format!("{d:.2e}")
    } else {
        let digits = if d == 0.0 {
            0
        } else {
            (2 - d.abs().log10().floor() as i32).max(0) as usize
        };
        format!("{d:.digits$}")
    }
}

/// Writes report.html atomically.
///
/// # Errors
/// [`IoError`] when the file cannot be written.
pub fn write_html(path: &Path, report: &Report, svg: &str) -> Result<(), IoError> {
    let text = html(report, svg);
    write_atomically(path, |w| {
        w.write_all(text.as_bytes())
            .map_err(|e| IoError::os(path, e))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inline_marks_become_tags_and_text_is_escaped() {
        assert_eq!(
            inline("**a** `x<y` & b"),
            "<strong>a</strong> <code>x&lt;y</code> &amp; b"
        );
        assert_eq!(escape("\"<&>\""), "&quot;&lt;&amp;&gt;&quot;");
        assert_eq!(header_html("Chamfer L1"), "Chamfer&nbsp;L1");
        assert_eq!(header_html("F-score"), "F&#8209;score");
        assert_eq!(header_html("boundary edges"), "boundary edges");
        assert_eq!(format_distance(0.008_523), "0.00852");
        assert_eq!(format_distance(1.234e-5), "1.23e-5");
        assert_eq!(format_distance(0.0), "0");
        assert_eq!(format_distance(12.5), "12.5");
    }
}
