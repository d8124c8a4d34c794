//! The command line's own surface: `--threads`, shell completions and manual pages generated
//! from the definition.

mod common;
use common::{fixture, one_error_line, run, run_ok};

#[test]
fn threads_do_not_change_results() {
    let obj = fixture("spot_triangulated.obj");
    let json = |threads: &str| {
        let out = run_ok(&[
            "--threads",
            threads,
            "eval",
            &obj,
            &obj,
            "--samples",
            "5000",
            "--json",
        ]);
        let mut v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        // The only field that may differ.
        v["seconds"] = serde_json::Value::Null;
        v
    };
    assert_eq!(json("1"), json("2"));
    // Anywhere on the line, as every global option.
    let out = run_ok(&[
        "eval",
        &obj,
        &obj,
        "--samples",
        "500",
        "--json",
        "--threads",
        "1",
    ]);
    assert!(!out.stdout.is_empty());
    for bad in ["0", "-1", "many"] {
        let out = run(&["--threads", bad, "eval", &obj, &obj]);
        assert_eq!(out.status.code(), Some(2), "--threads {bad}: {out:?}");
    }
}

#[test]
fn completions_cover_every_command() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let out = run_ok(&["completions", shell]);
        let text = String::from_utf8(out.stdout).expect("utf-8");
        for command in ["eval", "extract", "deform", "alpha-shape", "merge", "man"] {
            assert!(text.contains(command), "{shell}: {command} missing");
        }
    }
    let out = run(&["completions", "tcsh"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn manual_pages_for_trisplat_and_each_command() {
    let page = String::from_utf8(run_ok(&["man"]).stdout).expect("utf-8");
    assert!(page.contains(".TH trisplat 1"), "{page}");
    assert!(page.contains("extract"), "the commands are listed");
    let page = String::from_utf8(run_ok(&["man", "eval"]).stdout).expect("utf-8");
    assert!(page.contains(".TH trisplat-eval 1"), "{page}");
    assert!(
        page.contains("tau\\-fraction"),
        "the options are listed: {page}"
    );
    let out = run(&["man", "nope"]);
    assert_eq!(out.status.code(), Some(1));
    let line = one_error_line(&out);
    assert!(line.contains("nope") && line.contains("extract"), "{line}");
}
