//! The report's tables as one model, printed as Markdown here and as HTML by `html`; the
//! number formats their cells use.

use std::fmt::Write as _;

use trisplat_geometry::metrics::Relation;

/// The "scored as" cell: what a method's or frame's scores measure (self-consistency in
/// bold).
pub(super) fn scored_as(relation: Option<Relation>) -> Cell {
    match relation {
        Some(Relation::Accuracy) => Cell::plain("accuracy".to_owned()),
        Some(Relation::SelfConsistency) => Cell {
            text: "self-consistency".to_owned(),
            strong: true,
        },
        None => Cell::plain("-".to_owned()),
    }
}

/// `v` in scientific notation with `digits` decimals, `-` when absent.
pub(super) fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{x:.digits$e}"))
}

/// `v` with 4 decimals, `-` when absent.
pub(super) fn optf(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{x:.4}"))
}

/// `v` with `digits` decimals, `-` when absent.
pub(super) fn fixed(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{x:.digits$}"))
}

/// The fraction `v` as a percentage with 2 decimals, `-` when absent.
pub(super) fn pct(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_owned(), |x| format!("{:.2}%", 100.0 * x))
}

/// `v` with at most 6 significant digits, without trailing zeros (`24`, `0.00603532`; the
/// exact value is in report.json).
pub(super) fn significant(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let decimals = (5 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    }
}

/// One cell of a report table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cell {
    /// Its text (plain, not escaped).
    pub text: String,
    /// Shown in bold (report.md `**…**`, report.html `<strong>`).
    pub strong: bool,
}

impl Cell {
    /// A cell in normal weight.
    #[must_use]
    pub fn plain(text: String) -> Self {
        Self {
            text,
            strong: false,
        }
    }
}

/// A table of the report, as report.md and report.html print it (the same cells in both).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Table {
    /// Column titles.
    pub header: Vec<String>,
    /// Per column: aligned right (numbers) rather than left.
    pub right: Vec<bool>,
    /// The rows, each with one cell per column.
    pub rows: Vec<Vec<Cell>>,
}

impl Table {
    /// An empty table with these columns (title, aligned right).
    pub(super) fn new(columns: &[(&str, bool)]) -> Self {
        Self {
            header: columns.iter().map(|c| c.0.to_owned()).collect(),
            right: columns.iter().map(|c| c.1).collect(),
            rows: Vec::new(),
        }
    }

    /// The table in Markdown (GitHub's pipe tables), one line per row.
    #[must_use]
    pub fn markdown(&self) -> String {
        let mut s = format!("| {} |\n|", self.header.join(" | "));
        for &right in &self.right {
            s.push_str(if right { "---:|" } else { "---|" });
        }
        s.push('\n');
        for row in &self.rows {
            let cells: Vec<String> = row
                .iter()
                .map(|c| {
                    if c.strong {
                        format!("**{}**", c.text)
                    } else {
                        c.text.clone()
                    }
                })
                .collect();
            let _ = writeln!(s, "| {} |", cells.join(" | "));
        }
        s
    }
}
