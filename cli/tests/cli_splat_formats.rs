//! `trisplat convert` between Gaussian formats (INRIA PLY, SPZ, glTF with
//! KHR_gaussian_splatting) and `trisplat deform --format`: the files come out in the asked
//! format, readable by the library, with the values the formats keep; bad combinations are
//! refused with one line naming the file.

mod common;
use common::{BIN, fresh_dir, listing};

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use trisplat_splat::Axes;
use trisplat_splat::gltf_splat::read_gltf_gaussians;
use trisplat_splat::ply::read_gaussians;
use trisplat_splat::spz::{SpzReadOptions, read_spz};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures/data")
        .join(name)
}

fn trisplat(args: &[&Path]) -> Output {
    Command::new(BIN).args(args).output().expect("run trisplat")
}

fn ok(args: &[&Path]) {
    let out = trisplat(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn p(s: &str) -> &Path {
    Path::new(s)
}

#[test]
fn convert_between_ply_spz_and_gltf() {
    let dir = fresh_dir("splat_formats_convert");
    // LAM's Gaussians (world space, degree 0): PLY -> SPZ -> PLY, PLY -> GLB -> PLY.
    let ply = fixture("splat/lam_offset_subset.ply");
    let original = read_gaussians(&ply).expect("ply");
    let spz = dir.join("g.spz");
    ok(&[p("convert"), &ply, &spz]);
    let file = read_spz(&spz, &SpzReadOptions::default()).expect("spz");
    assert_eq!(file.version, 3);
    assert_eq!(file.gaussians.len(), original.len());
    for i in 0..original.len() {
        let d = (file.gaussians.means()[i] - original.means()[i])
            .abs()
            .max_element();
        assert!(d <= 0.5 / 4096.0, "Gaussian {i}: {d}");
    }
    // Stored RUB: with --axes none the reader sees y and z negated.
    let raw = read_spz(&spz, &SpzReadOptions { axes: None }).expect("spz");
    assert_eq!(raw.gaussians.means()[0].y, -file.gaussians.means()[0].y);
    // Back to PLY, and version 4 with other axes.
    let back = dir.join("back.ply");
    ok(&[p("convert"), &spz, &back]);
    assert_eq!(
        read_gaussians(&back).expect("back").means(),
        file.gaussians.means()
    );
    let v4 = dir.join("g4.spz");
    ok(&[
        p("convert"),
        &ply,
        &v4,
        p("--spz-version"),
        p("4"),
        p("--axes"),
        p("rub"),
    ]);
    let file4 = read_spz(
        &v4,
        &SpzReadOptions {
            axes: Some(Axes::Rub),
        },
    )
    .expect("v4");
    assert_eq!(file4.version, 4);
    assert!(
        (file4.gaussians.means()[0] - original.means()[0])
            .abs()
            .max_element()
            <= 0.5 / 4096.0
    );
    // glTF: means, rotations (unit) and SH exact.
    let glb = dir.join("g.glb");
    ok(&[p("convert"), &ply, &glb]);
    let splats = read_gltf_gaussians(&glb).expect("glb").gaussians;
    assert_eq!(splats.means(), original.means());
    assert_eq!(splats.sh(), original.sh());
    let from_glb = dir.join("from_glb.ply");
    ok(&[p("convert"), &glb, &from_glb]);
    assert_eq!(
        read_gaussians(&from_glb).expect("ply").means(),
        original.means()
    );
    let gltf = dir.join("from_spz.gltf");
    ok(&[p("convert"), &spz, &gltf]);
    assert_eq!(
        read_gltf_gaussians(&gltf).expect("gltf").gaussians.len(),
        original.len()
    );
    // A mesh glTF still converts as a mesh.
    let mesh = dir.join("mesh.ply");
    ok(&[p("convert"), &fixture("gltf/RiggedSimple.glb"), &mesh]);
    // Refusals: OBJ is no Gaussian format; bound Gaussians cannot go to SPZ.
    for (args, named) in [
        (
            vec![p("convert"), &spz, &dir.join("x.obj")],
            vec!["x.obj", ".spz, .glb or .gltf"],
        ),
        (
            vec![p("convert"), &spz, &dir.join("y.spz"), p("--axes"), p("up")],
            vec!["unknown axes"],
        ),
    ] {
        let out = trisplat(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_ne!(out.status.code(), Some(0), "{stderr}");
        for n in named {
            assert!(stderr.contains(n), "{n} in {stderr}");
        }
    }
    let bound = dir.join("bound.ply");
    ok(&[
        p("bind"),
        &fixture("spot_triangulated.obj"),
        p("-o"),
        &bound,
    ]);
    let out = trisplat(&[p("convert"), &bound, &dir.join("bound.spz")]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("bound.spz") && stderr.contains("bound Gaussians"),
        "{stderr}"
    );
    assert!(!dir.join("bound.spz").exists());
}

#[test]
fn deform_writes_frames_in_the_format_asked() {
    let dir = fresh_dir("splat_formats_deform");
    let glb = fixture("gltf/RiggedSimple.glb");
    let g = dir.join("g.ply");
    ok(&[p("bind"), &glb, p("-o"), &g]);
    let mut frames = Vec::new();
    for format in ["ply", "spz", "glb"] {
        let out = dir.join(format);
        ok(&[
            p("deform"),
            p("--template"),
            &glb,
            p("--animation"),
            &glb,
            p("--gaussians"),
            &g,
            p("-o"),
            &out,
            p("--mode"),
            p("lbs"),
            p("--frames"),
            p("2..4"),
            p("--format"),
            p(format),
            p("--axes"),
            p("rub"),
        ]);
        assert_eq!(
            listing(&out),
            [
                format!("frame_000002.{format}"),
                format!("frame_000003.{format}")
            ]
        );
        frames.push(out.join(format!("frame_000003.{format}")));
    }
    let ply = read_gaussians(&frames[0]).expect("ply");
    let spz = read_spz(
        &frames[1],
        &SpzReadOptions {
            axes: Some(Axes::Rub),
        },
    )
    .expect("spz");
    // --axes rub: stored as given (RiggedSimple is Y-up glTF).
    let stored = read_spz(&frames[1], &SpzReadOptions { axes: None }).expect("spz");
    assert_eq!(spz.gaussians.means(), stored.gaussians.means());
    let glb_frame = read_gltf_gaussians(&frames[2]).expect("glb").gaussians;
    assert_eq!(glb_frame.means(), ply.means());
    for i in 0..ply.len() {
        let d = (spz.gaussians.means()[i] - ply.means()[i])
            .abs()
            .max_element();
        assert!(d <= 0.5 / 4096.0, "{i}: {d}");
    }
}
