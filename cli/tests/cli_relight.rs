//! `trisplat render --env` through the real binary: relit images and material maps written
//! under the render contract, material edits visible in the maps, and bad environment maps or
//! edits refused with one error line naming the file and nothing written.

mod common;
use common::{fixture, fresh_dir, listing, one_error_line, run, run_ok, s};

use trisplat_geometry::io::read_npy;

fn map() -> String {
    fixture("relight/esplanade_64x32.hdr")
}

fn render_args<'a>(g: &'a str, cams: &'a str, out: &'a str, env: &'a str) -> Vec<&'a str> {
    vec![
        "render",
        g,
        "--cameras",
        cams,
        "-o",
        out,
        "-q",
        "--env",
        env,
    ]
}

#[test]
fn relit_render_writes_images_and_material_maps() {
    let dir = fresh_dir("relight_ok");
    let out = dir.join("r");
    let (g, cams, env) = (
        fixture("render/random_deg3.ply"),
        fixture("render/random_cameras.json"),
        map(),
    );
    let mut args = render_args(&g, &cams, s(&out), &env);
    args.extend([
        "--outputs",
        "rgb,alpha,normal",
        "--material-maps",
        "all",
        "--roughness",
        "0.3",
        "--env-rotation",
        "-45",
        "--env-intensity",
        "2",
    ]);
    run_ok(&args);
    let files = listing(&out);
    for kind in ["rgb", "alpha", "normal", "albedo", "roughness", "specular"] {
        assert!(
            files.iter().any(|f| f.ends_with(&format!("_{kind}.npy"))),
            "{kind}: {files:?}"
        );
        assert!(files.iter().any(|f| f.ends_with(&format!("_{kind}.png"))));
    }
    let first = files
        .iter()
        .find(|f| f.ends_with("_roughness.npy"))
        .unwrap()
        .trim_end_matches("_roughness.npy")
        .to_string();
    let rough = read_npy(&out.join(format!("{first}_roughness.npy"))).unwrap();
    let alpha = read_npy(&out.join(format!("{first}_alpha.npy"))).unwrap();
    let rgb = read_npy(&out.join(format!("{first}_rgb.npy"))).unwrap();
    assert_eq!(rough.shape.len(), 2);
    assert!(rgb.data.iter().all(|v| v.is_finite() && *v >= 0.0));
    // The roughness map is Σ w r with r = 0.3 everywhere: 0.3 alpha.
    let worst = rough
        .data
        .iter()
        .zip(&alpha.data)
        .map(|(r, a)| (r - 0.3 * a).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "{worst}");
    assert!(alpha.data.iter().any(|a| *a > 0.1), "something is in view");
}

#[test]
fn bad_maps_and_edits_fail_with_nothing_written() {
    let dir = fresh_dir("relight_bad");
    let (g, cams) = (
        fixture("render/random_deg3.ply"),
        fixture("render/random_cameras.json"),
    );
    let not_hdr = dir.join("not_a_map.hdr");
    std::fs::write(&not_hdr, b"P6\n2 1\n255\n\0\0\0\0\0\0").unwrap();
    let square = dir.join("square.hdr");
    let mut bytes = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X 4\n".to_vec();
    bytes.extend([128u8; 64]);
    std::fs::write(&square, bytes).unwrap();
    for (bad, words) in [(&not_hdr, "not a Radiance HDR"), (&square, "2:1")] {
        let out_dir = dir.join(format!(
            "out_{}",
            bad.file_stem().unwrap().to_string_lossy()
        ));
        let out = run(&render_args(&g, &cams, s(&out_dir), s(bad)));
        let line = one_error_line(&out);
        assert!(line.contains(s(bad)) && line.contains(words), "{line}");
        assert!(
            !out_dir.exists() || listing(&out_dir).is_empty(),
            "nothing written"
        );
    }
    // Out-of-range edits are usage errors (exit 2); --env-rotation without --env too.
    let out_dir = dir.join("out_edit");
    let env = map();
    let mut args = render_args(&g, &cams, s(&out_dir), &env);
    args.extend(["--f0", "1.5"]);
    assert_eq!(run(&args).status.code(), Some(2));
    let out = run(&[
        "render",
        &g,
        "--cameras",
        &cams,
        "-o",
        s(&out_dir),
        "--env-rotation",
        "10",
    ]);
    assert_eq!(out.status.code(), Some(2));
}
