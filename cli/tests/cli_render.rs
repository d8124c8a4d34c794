//! `trisplat render` through the real binary: cameras.json and transforms.json, every mode, the
//! files of docs/conventions.md §10, and the refusals (bound Gaussians, bad lists, overwriting an input).

mod common;
use common::{fixture, fresh_dir, one_error_line, run, run_ok, s};

use trisplat_geometry::io::read_npy;

#[test]
fn renders_every_output_of_every_camera() {
    let dir = fresh_dir("all");
    let out = dir.join("out");
    let o = run(&[
        "render",
        &fixture("render/random_deg3.ply"),
        "--cameras",
        &fixture("render/random_cameras.json"),
        "-o",
        s(&out),
        "--outputs",
        "rgb,alpha,depth,median_depth,normal",
        "--background",
        "1,1,1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for cam in ["front", "side", "wide"] {
        for key in ["rgb", "alpha", "depth", "median_depth", "normal"] {
            assert!(
                out.join(format!("{cam}_{key}.png")).exists(),
                "{cam}_{key}.png"
            );
        }
        let rgb = read_npy(&out.join(format!("{cam}_rgb.npy"))).unwrap();
        assert_eq!(rgb.shape, vec![48, 64, 3]);
        let alpha = read_npy(&out.join(format!("{cam}_alpha.npy"))).unwrap();
        assert_eq!(alpha.shape, vec![48, 64]);
        // White background: uncovered pixels are white.
        let i = alpha
            .data
            .iter()
            .position(|&a| a == 0.0)
            .expect("an empty pixel");
        assert_eq!(&rgb.data[3 * i..3 * i + 3], &[1.0, 1.0, 1.0]);
    }
    // The other modes and the switches run on the same scene.
    for extra in [
        &["--mode", "2dgs"][..],
        &["--mode", "perspective"],
        &["--compat-3dgs"],
        &["--antialiased", "--normal-frame", "camera"],
        &["--ray-depth"],
    ] {
        let out = dir.join(extra.join("_"));
        let mut args = vec![
            "render".to_owned(),
            fixture("render/random_deg3.ply"),
            "--cameras".to_owned(),
            fixture("render/random_cameras.json"),
            "-o".to_owned(),
            s(&out).to_owned(),
            "--outputs".to_owned(),
            "alpha,depth,normal".to_owned(),
        ];
        args.extend(extra.iter().map(|a| (*a).to_owned()));
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&argv);
        assert!(
            o.status.success(),
            "{extra:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(out.join("front_depth.npy").exists());
        assert!(!out.join("front_rgb.npy").exists(), "only what is asked");
    }
    // Ray depth tilts each splat's depth over its footprint: the same coverage, other depths.
    let read = |dir: &std::path::Path, key: &str| {
        read_npy(&dir.join(format!("front_{key}.npy")))
            .unwrap()
            .data
    };
    let ray = dir.join("--ray-depth");
    assert_eq!(read(&out, "alpha"), read(&ray, "alpha"));
    let (mean_depth, ray_depth) = (read(&out, "depth"), read(&ray, "depth"));
    assert!(ray_depth.iter().all(|d| d.is_finite()));
    assert!(
        mean_depth
            .iter()
            .zip(&ray_depth)
            .any(|(a, b)| (a - b).abs() > 1e-4)
    );
}

#[test]
fn accepts_transforms_json_and_meshes() {
    let dir = fresh_dir("transforms");
    let transforms = dir.join("transforms.json");
    std::fs::write(
        &transforms,
        r#"{"camera_angle_x": 0.9, "w": 32, "h": 24,
            "frames": [{"file_path": "./r_0.png",
            "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#,
    )
    .unwrap();
    let out = dir.join("out");
    let o = run(&[
        "render",
        &fixture("render/random_deg3.ply"),
        "--cameras",
        s(&transforms),
        "-o",
        s(&out),
        "--outputs",
        "alpha",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let alpha = read_npy(&out.join("r_0_alpha.npy")).unwrap();
    assert_eq!(alpha.shape, vec![24, 32]);
    assert!(alpha.data.iter().any(|&a| a > 0.5));
    // A mesh: depth, normal and the hit mask as alpha.
    let mesh_out = dir.join("mesh");
    let o = run(&[
        "render",
        "--mesh",
        &fixture("spot_triangulated.obj"),
        "--cameras",
        s(&transforms),
        "-o",
        s(&mesh_out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for key in ["depth", "normal", "alpha"] {
        assert!(mesh_out.join(format!("r_0_{key}.npy")).exists(), "{key}");
    }
}

#[test]
fn refusals_are_one_line() {
    let dir = fresh_dir("refuse");
    // Bound (local) Gaussians must be baked first.
    let bound = dir.join("bound.ply");
    let o = run(&["bind", &fixture("spot_triangulated.obj"), "-o", s(&bound)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run(&[
        "render",
        s(&bound),
        "--cameras",
        &fixture("render/random_cameras.json"),
        "-o",
        s(&dir.join("out")),
    ]);
    let err = one_error_line(&o);
    assert!(err.contains("deform"), "{err}");
    // Unknown output name and bad background: usage errors.
    for bad in [&["--outputs", "rgb,colour"][..], &["--background", "1,2"]] {
        let mut args = vec![
            "render".to_owned(),
            fixture("render/random_deg3.ply"),
            "--cameras".to_owned(),
            fixture("render/random_cameras.json"),
            "-o".to_owned(),
            s(&dir.join("out2")).to_owned(),
        ];
        args.extend(bad.iter().map(|a| (*a).to_owned()));
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&argv);
        assert_eq!(o.status.code(), Some(2), "{bad:?}");
    }
    // The output folder may not be an input file.
    let copy = dir.join("scene.ply");
    std::fs::copy(fixture("render/random_deg3.ply"), &copy).unwrap();
    let before = std::fs::read(&copy).unwrap();
    let o = run(&[
        "render",
        s(&copy),
        "--cameras",
        &fixture("render/random_cameras.json"),
        "-o",
        s(&copy),
    ]);
    one_error_line(&o);
    assert_eq!(std::fs::read(&copy).unwrap(), before);
    // Missing cameras file: one line naming it.
    let o = run(&[
        "render",
        s(&copy),
        "--cameras",
        s(&dir.join("missing.json")),
        "-o",
        s(&dir.join("out3")),
    ]);
    assert!(one_error_line(&o).contains("missing.json"));
}

/// The bundled cameras.json (three cameras: front, side, wide), to edit.
fn fixture_cameras() -> serde_json::Value {
    serde_json::from_str(
        &std::fs::read_to_string(fixture("render/random_cameras.json")).expect("cameras"),
    )
    .expect("json")
}

#[test]
fn shared_camera_names_are_refused_and_a_failure_leaves_nothing_behind() {
    let dir = fresh_dir("names");
    let list = fixture_cameras()
        .as_array()
        .expect("a cameras.json list")
        .clone();
    // Two cameras named front (the second one renamed): refused before anything is written.
    let mut twice = list.clone();
    twice[1]["img_name"] = twice[0]["img_name"].clone();
    let twice_path = dir.join("twice.json");
    std::fs::write(&twice_path, serde_json::to_string(&twice).expect("json")).expect("write");
    let out = dir.join("out");
    let line = one_error_line(&run(&[
        "render",
        &fixture("render/random_deg3.ply"),
        "--cameras",
        s(&twice_path),
        "-o",
        s(&out),
    ]));
    assert!(
        line.contains("twice.json") && line.contains("cameras 0") && line.contains("own name"),
        "{line}"
    );
    assert!(!out.exists(), "nothing written");
    // The last camera's image cannot be written (a folder stands in its way): the images of
    // the cameras before it are removed, what was there before stays.
    let blocked = dir.join("blocked");
    let last = list.last().expect("a camera")["img_name"]
        .as_str()
        .expect("name")
        .to_owned();
    std::fs::create_dir_all(blocked.join(format!("{last}_alpha.npy"))).expect("obstacle");
    std::fs::write(blocked.join("keep.txt"), b"mine").expect("keep");
    let o = run(&[
        "render",
        &fixture("render/random_deg3.ply"),
        "--cameras",
        &fixture("render/random_cameras.json"),
        "-o",
        s(&blocked),
        "--outputs",
        "alpha",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let mut left: Vec<String> = std::fs::read_dir(&blocked)
        .expect("folder")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        vec!["keep.txt".to_owned(), format!("{last}_alpha.npy")]
    );
}

#[test]
fn images_past_the_pixel_limit_are_refused_before_anything_is_allocated() {
    let dir = fresh_dir("pixels");
    let mut cameras = fixture_cameras();
    cameras[1]["width"] = 200_000.into();
    cameras[1]["height"] = 200_000.into();
    let path = dir.join("huge.json");
    std::fs::write(&path, cameras.to_string()).expect("write");
    let out = dir.join("out");
    for input in [
        vec!["render", &fixture("render/random_deg3.ply")],
        vec!["render", "--mesh", &fixture("spot_triangulated.obj")],
    ] {
        let mut args = input.clone();
        args.extend(["--cameras", s(&path), "-o", s(&out)]);
        let line = one_error_line(&run(&args));
        assert!(
            line.contains("huge.json")
                && line.contains("camera 1")
                && line.contains("200000x200000"),
            "{line}"
        );
        assert!(!out.exists(), "nothing written");
    }
    // A lower --max-pixels refuses the fixture's own cameras; one above the renderer's
    // ceiling is a usage error.
    let (spot, random_cameras) = (
        fixture("spot_triangulated.obj"),
        fixture("render/random_cameras.json"),
    );
    let line = one_error_line(&run(&[
        "render",
        "--mesh",
        &spot,
        "--cameras",
        &random_cameras,
        "-o",
        s(&out),
        "--max-pixels",
        "100",
    ]));
    assert!(
        line.contains("over the limit of 100 pixels") && line.contains("--max-pixels"),
        "{line}"
    );
    assert!(!out.exists(), "nothing written");
    let tsdf_out = dir.join("t.ply");
    let res = run(&[
        "tsdf",
        "--cameras",
        &random_cameras,
        "--depth",
        s(&dir),
        "-o",
        s(&tsdf_out),
        "--max-pixels",
        "1000000000",
    ]);
    assert_eq!(res.status.code(), Some(2));
    // `cameras --views` is bounded by --max-views, which raises it.
    let cams = dir.join("c.json");
    let mesh = fixture("spot_triangulated.obj");
    let line = one_error_line(&run(&[
        "cameras",
        &mesh,
        "--views",
        "1000000000",
        "-o",
        s(&cams),
    ]));
    assert!(
        line.contains("over the limit of 100000 views") && line.contains("--max-views"),
        "{line}"
    );
    assert!(!cams.exists());
    run_ok(&[
        "cameras",
        &mesh,
        "--views",
        "12",
        "--max-views",
        "12",
        "-o",
        s(&cams),
    ]);
    assert!(cams.exists());
}
