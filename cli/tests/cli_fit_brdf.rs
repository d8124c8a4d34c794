//! `trisplat fit --appearance brdf`: a short material fit of Spot under the CC0 fixture map
//! writes a PLY with materials in range and raises the held-out PSNR; a missing `--env`, `--env`
//! with another appearance, an SH-only option and a file that is not a Radiance map are refused
//! with nothing written; `--env-fit` writes the estimated map beside the PLY and refuses a
//! bad width.

mod common;
use common::{fixture, fresh_dir, listing, run, run_ok, s};
use serde_json::Value;
use trisplat_splat::ply::read_gaussians;

#[test]
fn fit_brdf_writes_materials_and_refuses_bad_input() {
    let dir = fresh_dir("fit_brdf");
    let mesh = fixture("spot_triangulated.obj");
    let env = fixture("relight/esplanade_64x32.hdr");
    let g = dir.join("g.ply");
    run_ok(&["bind", &mesh, "-o", s(&g), "--per-triangle", "1"]);
    let (train, eval) = (dir.join("train.json"), dir.join("eval.json"));
    run_ok(&[
        "cameras",
        &mesh,
        "-o",
        s(&train),
        "--views",
        "6",
        "--size",
        "32x32",
    ]);
    run_ok(&[
        "cameras",
        &mesh,
        "-o",
        s(&eval),
        "--rig",
        "orbit",
        "--views",
        "2",
        "--size",
        "32x32",
    ]);
    let out = dir.join("fitted.ply");
    let base = [
        "fit",
        s(&g),
        "--template",
        &mesh,
        "--cameras",
        s(&train),
        "--eval-cameras",
        s(&eval),
        "-o",
        s(&out),
        "--iterations",
        "40",
        "--eval-every",
        "40",
    ];
    let fit = |extra: &[&str]| run(&[&base[..], extra].concat());
    let before = listing(&dir);
    // No --env.
    let r = fit(&["--appearance", "brdf"]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("--env"));
    // --env with the SH fit.
    let r = fit(&["--env", &env]);
    assert_eq!(r.status.code(), Some(2));
    // An SH-only option.
    let r = fit(&["--appearance", "brdf", "--env", &env, "--densify"]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("--densify"));
    // Not a Radiance file.
    let bad = dir.join("bad.hdr");
    std::fs::write(&bad, b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 3\n").unwrap();
    let mut before_bad = before.clone();
    before_bad.push("bad.hdr".into());
    before_bad.sort();
    let r = fit(&["--appearance", "brdf", "--env", s(&bad)]);
    let stderr = String::from_utf8_lossy(&r.stderr).to_string();
    assert_eq!(r.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("bad.hdr"), "{stderr}");
    let mut now = listing(&dir);
    now.sort();
    assert_eq!(now, before_bad);
    // A fit.
    let done = fit(&[
        "--appearance",
        "brdf",
        "--env",
        &env,
        "--env-rotation",
        "30",
        "--fit-normals",
        "--json",
    ]);
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let v: Value = serde_json::from_slice(&done.stdout).unwrap();
    assert_eq!(v["appearance"], "brdf");
    let cps = v["checkpoints"].as_array().unwrap();
    let p0 = cps[0]["eval_psnr"].as_f64().unwrap();
    let p1 = cps.last().unwrap()["eval_psnr"].as_f64().unwrap();
    assert!(p1 > p0, "held-out PSNR {p0:.2} -> {p1:.2} dB");
    let set = read_gaussians(&out).unwrap();
    let m = set.material().expect("materials written");
    assert_eq!(m.albedo.len(), set.len());
    assert!(m.first_out_of_range().is_none());
    assert!(set.binding().is_some());
    // --env-fit: an odd or too wide map, or another appearance, refused with nothing written.
    let listed = listing(&dir);
    for (extra, what) in [
        (
            &["--appearance", "brdf", "--env-fit", "--env-fit-width", "7"][..],
            "--env-fit-width",
        ),
        (
            &[
                "--appearance",
                "brdf",
                "--env-fit",
                "--env-fit-width",
                "256",
            ][..],
            "--env-fit-width",
        ),
        (&["--env-fit"][..], "--env-fit"),
    ] {
        let r = fit(extra);
        let stderr = String::from_utf8_lossy(&r.stderr).to_string();
        assert_eq!(r.status.code(), Some(2), "{extra:?}: {stderr}");
        assert!(stderr.contains(what), "{stderr}");
        assert_eq!(listing(&dir), listed);
    }
    // The environment estimated from a grey start, written beside the PLY.
    let done = fit(&[
        "--appearance",
        "brdf",
        "--env-fit",
        "--env-fit-width",
        "16",
        "--json",
    ]);
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let v: Value = serde_json::from_slice(&done.stdout).unwrap();
    let map_path = dir.join("fitted.env.hdr");
    assert_eq!(v["env_fit"].as_str(), Some(s(&map_path)));
    let map = trisplat_geometry::envmap::EnvMap::read(&map_path).unwrap();
    assert_eq!((map.width(), map.height()), (16, 8));
    assert!(
        map.texels()
            .iter()
            .flatten()
            .all(|v| v.is_finite() && *v > 0.0)
    );
}
