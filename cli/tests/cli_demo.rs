//! `trisplat demo` runs anywhere: from an empty folder, with nothing but the binary (the avatar
//! is embedded; the cli crate does not depend on the fixtures crate at run time).

mod common;

use std::process::Command;

use common::{BIN, fresh_dir, listing};

#[test]
fn demo_runs_in_an_empty_folder_from_the_embedded_avatar() {
    let dir = fresh_dir("demo_anywhere");
    let out = Command::new(BIN)
        .args(["demo", "-o", "out"])
        .current_dir(&dir)
        .output()
        .expect("run trisplat demo");
    assert!(
        out.status.success(),
        "demo failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out_dir = dir.join("out");
    let names = listing(&out_dir);
    for name in [
        "CesiumMan.glb",
        "CesiumMan_LICENSE.txt",
        "report.json",
        "report.md",
        "report.html",
        "error_vs_time.svg",
        "error_vs_time.png",
        "thumbnails",
        "tsdf.glb",
        "delaunay.glb",
        "alpha.glb",
    ] {
        assert!(names.iter().any(|n| n == name), "{name} missing: {names:?}");
    }
    // The avatar written out is the fixture, byte for byte, with its attribution beside it.
    let written = std::fs::read(out_dir.join("CesiumMan.glb")).expect("avatar");
    let fixture = std::fs::read(trisplat_fixtures::path("anim/CesiumMan.glb")).expect("fixture");
    assert!(
        written == fixture,
        "the embedded avatar differs from the fixture"
    );
    let licence = std::fs::read_to_string(out_dir.join("CesiumMan_LICENSE.txt")).expect("licence");
    assert!(licence.contains("CC BY 4.0") && licence.contains("Cesium"));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("report.json")).expect("report"))
            .expect("report parses");
    assert_eq!(report["frames"].as_array().map(Vec::len), Some(7));
}
