//! Shared helpers for trisplat's cross-crate integration and reference tests (`tests/tests/`).

use std::path::Path;

/// Parses a JSON reference file written by `tests/reference/make_reference.py`.
///
/// # Panics
/// When the file is missing or not JSON (a broken fixture is a test failure).
#[must_use]
pub fn reference_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read reference {}: {e}", path.display()));
    serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("reference {} is not JSON: {e}", path.display()))
}

/// Relative difference `|a - b| / max(|b|, floor)`: `floor` keeps values near zero from
/// dividing by zero and is stated by each test.
#[must_use]
pub fn relative_error(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / b.abs().max(floor)
}

pub mod fuzz_harness;
