//! Helpers shared by the CLI integration tests: run the real binary, fresh output folders,
//! fixture paths and the one-line error contract of docs/conventions.md §10.
// Each test file uses a different subset of these helpers.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The `trisplat` binary built for these tests.
pub const BIN: &str = env!("CARGO_BIN_EXE_trisplat");

/// Runs `trisplat args...` and returns its output, whatever the exit code.
pub fn run(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().expect("run trisplat")
}

/// Runs `trisplat args...` and asserts that it succeeded (stderr in the message).
pub fn run_ok(args: &[&str]) -> Output {
    let out = run(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A fresh, empty folder under cargo's temporary folder, unique per process and call.
pub fn fresh_dir(name: &str) -> PathBuf {
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "{}_{}_{n}_{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test folder");
    dir
}

/// Sorted file names in `dir`.
pub fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("read folder")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// `fixtures/data/<name>` as a string argument.
pub fn fixture(name: &str) -> String {
    trisplat_fixtures::path(name).to_string_lossy().into_owned()
}

/// A path as a string argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Asserts the failure contract (exit 1, exactly one `error: ` line on stderr) and returns
/// that line.
pub fn one_error_line(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr:?}");
    assert!(stderr.starts_with("error: "), "{stderr}");
    stderr
}

/// The `report.json` an `extract` run wrote into `out`; asserts it holds no NaN.
pub fn report(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    assert!(!text.contains("NaN"), "{text}");
    serde_json::from_str(&text).expect("report.json parses")
}
