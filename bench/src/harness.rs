//! Shared benchmark plumbing: timing, running the Python side, printing ratios.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};

/// Best-of-`repeats` wall time of `f` in seconds, and its last result.
pub fn time_best<T>(repeats: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..repeats.max(1) {
        let start = Instant::now();
        let value = f();
        best = best.min(start.elapsed().as_secs_f64());
        last = Some(value);
    }
    (best, last.unwrap_or_else(|| unreachable!("repeats >= 1")))
}

/// Runs `python script args...`; the script prints one JSON object on its last stdout line
/// with at least a `seconds` key (its own timing of the measured work, load excluded).
///
/// # Errors
/// When the interpreter cannot start, the script fails, or prints no JSON.
pub fn run_python(python: &str, script: &Path, args: &[&str]) -> anyhow::Result<serde_json::Value> {
    let output = Command::new(python)
        .arg(script)
        .args(args)
        .output()
        .with_context(|| format!("cannot start {python}"))?;
    if !output.status.success() {
        bail!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().last().unwrap_or_default();
    serde_json::from_str(line).with_context(|| format!("{}: no JSON result", script.display()))
}

/// Path of a benchmark's Python companion script in `bench/python/`.
#[must_use]
pub fn python_script(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("python")
        .join(name)
}

/// Prints one result row: our time, theirs, and the speed-up ratio.
pub fn report(name: &str, ours_s: f64, theirs: Option<(&str, f64)>) {
    match theirs {
        Some((tool, t)) => println!(
            "{name:<40} trisplat {ours_s:>9.3} s   {tool} {t:>9.3} s   speed-up x{:.2}",
            t / ours_s
        ),
        None => println!("{name:<40} trisplat {ours_s:>9.3} s"),
    }
}
