//! `trisplat fit`: a short fit of Spot bound one Gaussian per triangle to mesh renders raises
//! the held-out PSNR and keeps the binding (with and without refine rounds interleaved); user
//! images with a mask; bad inputs are one `error:` line with exit 1 (2 for usage) and no output.

mod common;
use common::{fixture, fresh_dir, listing, run, run_ok, s};
use serde_json::Value;
use std::path::Path;
use trisplat_splat::ply::read_gaussians;

fn json(args: &[&str]) -> Value {
    let mut all = args.to_vec();
    all.push("--json");
    let out = run_ok(&all);
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

/// Exit `code`, one `error:` line naming each of `named`, nothing new in `dir`.
fn fails(args: &[&str], code: i32, dir: &Path, named: &[&str]) {
    let before = listing(dir);
    let out = run(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
    if code == 1 {
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{stderr}");
        assert!(lines[0].starts_with("error: "), "{stderr}");
    }
    for n in named {
        assert!(stderr.contains(n), "`{n}` in: {stderr}");
    }
    assert_eq!(listing(dir), before, "{args:?} left files");
}

/// Spot bound, training and held-out cameras (small images) in `dir`.
fn setup(dir: &Path) -> (String, String, String, String) {
    setup_for(dir, "spot_triangulated.obj", &["--per-triangle", "1"], "40")
}

/// The fixture `mesh` bound (with `bind_extra`), 8 training cameras on a sphere and 3 held-out
/// ones on an orbit at `elevation`°, 40 × 40, in `dir`: `(template, gaussians, training
/// cameras, held-out cameras)`.
fn setup_for(
    dir: &Path,
    mesh: &str,
    bind_extra: &[&str],
    elevation: &str,
) -> (String, String, String, String) {
    let mesh = fixture(mesh);
    let g = dir.join("g.ply");
    run_ok(&[&["bind", &mesh, "-o", s(&g)], bind_extra].concat());
    let train = dir.join("train.json");
    let eval = dir.join("eval.json");
    let size = ["--size", "40x40"];
    run_ok(
        &[
            &["cameras", &mesh, "-o", s(&train), "--views", "8"][..],
            &size,
        ]
        .concat(),
    );
    run_ok(
        &[
            &[
                "cameras",
                &mesh,
                "-o",
                s(&eval),
                "--rig",
                "orbit",
                "--views",
                "3",
            ][..],
            &["--elevation", elevation],
            &size,
        ]
        .concat(),
    );
    (
        mesh,
        s(&g).to_owned(),
        s(&train).to_owned(),
        s(&eval).to_owned(),
    )
}

/// `fit` of `(gaussians, template, training cameras, held-out cameras)` for 40 iterations
/// (held-out checkpoints every 20) on 2 threads, with `extra` options; its `--json` object.
fn fit_with_held_out(inputs: (&str, &str, &str, &str), out: &Path, extra: &[&str]) -> Value {
    let (g, spot, train, eval) = inputs;
    let mut args = vec![
        "fit",
        g,
        "--template",
        spot,
        "--cameras",
        train,
        "--eval-cameras",
        eval,
        "-o",
        s(out),
        "--iterations",
        "40",
        "--eval-every",
        "20",
        "--threads",
        "2",
    ];
    args.extend_from_slice(extra);
    json(&args)
}

#[test]
fn surfels_fit_with_the_2dgs_terms() {
    // --mode 2dgs with depth-normal consistency and depth distortion: the held-out PSNR rises
    // and every term's loss is finite.
    let dir = fresh_dir("fit_2dgs");
    let (spot, g, train, eval) = setup(&dir);
    let out = dir.join("fitted.ply");
    let r = fit_with_held_out(
        (&g, &spot, &train, &eval),
        &out,
        &[
            "--mode",
            "2dgs",
            "--normal-weight",
            "0.05",
            "--distortion-weight",
            "100",
        ],
    );
    let cps = r["checkpoints"].as_array().expect("checkpoints");
    let first = cps[0]["eval_psnr"].as_f64().expect("psnr");
    let last = cps[2]["eval_psnr"].as_f64().expect("psnr");
    assert!(last > first + 0.5, "held-out PSNR {first} -> {last}");
    assert!(
        cps[1..]
            .iter()
            .all(|c| c["loss"].as_f64().is_some_and(f64::is_finite))
    );
    // The mesh targets' depth and normals score the geometry too.
    for c in cps {
        let depth = c["eval_depth_l1"].as_f64().expect("depth error");
        let angle = c["eval_normal_deg"].as_f64().expect("normal error");
        assert!(depth.is_finite() && depth >= 0.0, "{c}");
        assert!((0.0..90.0).contains(&angle), "{c}");
    }
    assert_eq!(
        read_gaussians(&out).expect("fitted").len() as u64,
        r["gaussians"].as_u64().expect("count")
    );
}

#[test]
fn fit_raises_held_out_psnr_and_keeps_the_binding() {
    let dir = fresh_dir("fit");
    let (spot, g, train, eval) = setup(&dir);
    let tris = trisplat_geometry::io::read_mesh(Path::new(&spot))
        .expect("spot")
        .triangle_count();
    for refine in [None, Some("15")] {
        let out = dir.join("fitted.ply");
        let refine_args = refine.map(|n| ["--refine-every", n]);
        let r = fit_with_held_out(
            (&g, &spot, &train, &eval),
            &out,
            refine_args.as_ref().map_or(&[][..], |a| &a[..]),
        );
        let cps = r["checkpoints"].as_array().expect("checkpoints");
        assert_eq!(cps.len(), 3, "{r}");
        let first = cps[0]["eval_psnr"].as_f64().expect("psnr");
        let last = cps[2]["eval_psnr"].as_f64().expect("psnr");
        assert!(last > first + 0.5, "held-out PSNR {first} -> {last}");
        assert!(
            cps[2]["eval_ssim"].as_f64().expect("ssim")
                > cps[0]["eval_ssim"].as_f64().expect("ssim")
        );
        let fitted = read_gaussians(&out).expect("fitted");
        assert_eq!(fitted.len() as u64, r["gaussians"].as_u64().expect("count"));
        let binding = fitted.binding().expect("still bound");
        assert!(binding.triangles.iter().all(|t| t.index() < tris));
        assert_eq!(
            r["refines"].as_array().map(Vec::len),
            Some(usize::from(refine.is_some()) * 2)
        );
    }
}

#[test]
fn fit_densifies_with_its_flags_and_reports_each_step() {
    let dir = fresh_dir("fit_densify");
    let (spot, g, train, eval) = setup(&dir);
    let tris = trisplat_geometry::io::read_mesh(Path::new(&spot))
        .expect("spot")
        .triangle_count();
    let out = dir.join("fitted.ply");
    let r = fit_with_held_out(
        (&g, &spot, &train, &eval),
        &out,
        &[
            "--densify",
            "--densify-from",
            "5",
            "--densify-every",
            "10",
            "--densify-until",
            "35",
            "--densify-grad",
            "1e-7",
            "--percent-dense",
            "0.01",
            "--prune-opacity",
            "0.005",
            "--opacity-reset-every",
            "20",
            "--max-world-size",
            "0.1",
            "--sh-up-every",
            "10",
        ],
    );
    // Densify after 10, 20, 30; opacities reset after 20.
    let events = r["densify"].as_array().expect("densify events");
    let at: Vec<u64> = events
        .iter()
        .map(|e| e["iteration"].as_u64().unwrap())
        .collect();
    assert_eq!(at, [10, 20, 30], "{r}");
    for e in events {
        for key in ["cloned", "split", "pruned", "spared", "gaussians", "ms"] {
            assert!(e[key].is_number(), "{key} in {e}");
        }
    }
    assert!(events[0]["cloned"].as_u64().unwrap() + events[0]["split"].as_u64().unwrap() > 0);
    assert_eq!(r["opacity_resets"], serde_json::json!([20]), "{r}");
    let count = events.last().unwrap()["gaussians"].as_u64().unwrap();
    assert_eq!(r["gaussians"].as_u64(), Some(count));
    assert!(count > r["before"].as_u64().unwrap(), "{r}");
    let cps = r["checkpoints"].as_array().expect("checkpoints");
    assert_eq!(cps.last().unwrap()["gaussians"].as_u64(), Some(count));
    assert!(cps.iter().all(|c| c["sh_degree"].is_number()), "{r}");
    let fitted = read_gaussians(&out).expect("fitted");
    assert_eq!(fitted.len() as u64, count);
    let binding = fitted.binding().expect("still bound");
    assert!(binding.triangles.iter().all(|t| t.index() < tris));
    // Every triangle keeps at least one Gaussian.
    let mut seen = vec![false; tris];
    for t in &binding.triangles {
        seen[t.index()] = true;
    }
    assert!(seen.iter().all(|&b| b));
    // Interleaved with refine rounds (after 15 and 30; at 30 the densify step comes first):
    // both run, and the counts stay consistent.
    let out3 = dir.join("fitted3.ply");
    let r = fit_with_held_out(
        (&g, &spot, &train, &eval),
        &out3,
        &[
            "--densify",
            "--densify-from",
            "5",
            "--densify-every",
            "10",
            "--densify-grad",
            "1e-7",
            "--refine-every",
            "15",
        ],
    );
    let refines = r["refines"].as_array().expect("refines");
    let events = r["densify"].as_array().expect("densify");
    assert_eq!((refines.len(), events.len()), (2, 3), "{r}");
    assert_eq!(
        refines[1]["before"].as_u64(),
        events[2]["gaussians"].as_u64(),
        "{r}"
    );
    assert_eq!(
        read_gaussians(&out3).expect("fitted").len() as u64,
        r["gaussians"].as_u64().expect("count")
    );
    // The text output names the steps.
    let out2 = dir.join("fitted2.ply");
    let (gs, spots, trains) = (g.as_str(), spot.as_str(), train.as_str());
    let text = run_ok(&[
        "fit",
        gs,
        "--template",
        spots,
        "--cameras",
        trains,
        "-o",
        s(&out2),
        "--iterations",
        "12",
        "--densify",
        "--densify-from",
        "5",
        "--densify-every",
        "10",
        "--densify-grad",
        "1e-7",
        "--threads",
        "2",
    ]);
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(stdout.contains("densify after iteration 10:"), "{stdout}");
}

#[test]
fn fit_reads_user_images_and_masks() {
    let dir = fresh_dir("fit_images");
    let (spot, g, train, _) = setup(&dir);
    let cams = trisplat_geometry::read_cameras_json(Path::new(&train)).expect("cameras");
    let images = dir.join("images");
    std::fs::create_dir_all(&images).expect("mkdir");
    for c in &cams {
        // A flat orange picture, its mask a centred square.
        let img = image::RgbImage::from_pixel(c.width, c.height, image::Rgb([230, 120, 20]));
        img.save(images.join(format!("{}.png", c.name)))
            .expect("png");
        let mask = image::GrayImage::from_fn(c.width, c.height, |x, y| {
            let inside = (10..30).contains(&x) && (10..30).contains(&y);
            image::Luma([if inside { 255 } else { 0 }])
        });
        mask.save(images.join(format!("{}_mask.png", c.name)))
            .expect("png");
    }
    let out = dir.join("fitted.ply");
    let out2 = dir.join("x.ply");
    // `fit` on the images, the output path and the options to follow.
    let base = [
        "fit",
        &g,
        "--template",
        &spot,
        "--cameras",
        &train,
        "--images",
        s(&images),
        "-o",
    ];
    let r = json(
        &[
            &base[..],
            &[s(&out), "--iterations", "10", "--alpha-weight", "0.5"],
        ]
        .concat(),
    );
    assert_eq!(r["target"], "images", "{r}");
    assert_eq!(r["views"], 8, "{r}");
    assert!(
        r["checkpoints"][0]["eval_depth_l1"].is_null(),
        "no depth yet: {r}"
    );
    // RGB-D: depth maps beside the images (here the mesh's own, as `render --mesh` writes
    // them) are read, fitted with --depth-weight and scored on the held-out views.
    run_ok(&[
        "render",
        "--mesh",
        &spot,
        "--cameras",
        &train,
        "-o",
        s(&images),
        "--outputs",
        "depth",
    ]);
    let r = json(
        &[
            &base[..],
            &[
                s(&out),
                "--eval-cameras",
                &train,
                "--eval-images",
                s(&images),
            ],
            &["--iterations", "10", "--depth-weight", "0.5"],
        ]
        .concat(),
    );
    let depth = r["checkpoints"][0]["eval_depth_l1"]
        .as_f64()
        .expect("depth scored");
    assert!(depth.is_finite() && depth > 0.0, "{r}");
    // A depth map that cannot be read is refused, naming it.
    let broken = images.join(format!("{}_depth.npy", cams[1].name));
    std::fs::write(&broken, b"not an npy").expect("write");
    fails(&[&base[..], &[s(&out2)]].concat(), 1, &dir, &[s(&broken)]);
    std::fs::remove_file(&broken).expect("rm");
    // A picture of the wrong size is refused, naming the file.
    let bad = images.join(format!("{}.png", cams[0].name));
    image::RgbImage::new(7, 5).save(&bad).expect("png");
    fails(
        &[&base[..], &[s(&out2)]].concat(),
        1,
        &dir,
        &[s(&bad), "7x5"],
    );
}

#[test]
fn fit_refuses_bad_input() {
    let dir = fresh_dir("fit_bad");
    let (spot, g, train, _) = setup(&dir);
    let out = dir.join("x.ply");
    let o = s(&out);
    let base = [
        "fit",
        g.as_str(),
        "--template",
        spot.as_str(),
        "--cameras",
        train.as_str(),
        "-o",
        o,
    ];
    let with = |extra: &[&str]| {
        let mut a: Vec<String> = base.iter().map(|v| (*v).to_owned()).collect();
        a.extend(extra.iter().map(|v| (*v).to_owned()));
        a
    };
    let call = |a: &Vec<String>, code: i32, named: &[&str]| {
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        fails(&refs, code, &dir, named);
    };
    call(&with(&["--normal-weight", "0.1"]), 1, &["--mode 2dgs"]);
    call(&with(&["--distortion-weight", "0.1"]), 1, &["--mode 2dgs"]);
    call(&with(&["--mode", "perspective"]), 2, &[]);
    call(&with(&["--iterations", "0"]), 2, &[]);
    call(&with(&["--lambda-dssim", "2"]), 1, &["lambda-dssim"]);
    // Densification and the SH schedule: bad values are one error line naming the option;
    // densification options without --densify are usage errors.
    call(
        &with(&["--densify", "--densify-every", "0"]),
        1,
        &["--densify-every"],
    );
    call(
        &with(&[
            "--densify",
            "--densify-from",
            "900",
            "--densify-until",
            "800",
        ]),
        1,
        &["--densify-from 900", "--densify-until 800"],
    );
    call(
        &with(&["--densify", "--prune-opacity", "1.5"]),
        1,
        &["--prune-opacity"],
    );
    call(
        &with(&["--densify", "--densify-grad=-1"]),
        1,
        &["--densify-grad"],
    );
    call(
        &with(&["--densify", "--percent-dense", "0"]),
        1,
        &["--percent-dense"],
    );
    call(&with(&["--sh-up-every", "0"]), 1, &["--sh-up-every"]);
    call(&with(&["--percent-dense", "0.1"]), 2, &["--densify"]);
    call(
        &with(&["--max-views", "3"]),
        1,
        &["--max-views", "8 target views"],
    );
    call(
        &with(&["--max-pixels", "100"]),
        1,
        &["--max-pixels", "train.json"],
    );
    // An unbound set, a broken cameras file, a missing image folder.
    let world = fixture("render/random_deg3.ply");
    fails(
        &[
            "fit",
            &world,
            "--template",
            &spot,
            "--cameras",
            &train,
            "-o",
            o,
        ],
        1,
        &dir,
        &["random_deg3.ply"],
    );
    let broken = dir.join("broken.json");
    std::fs::write(&broken, "[{\"width\": 3}]").expect("write");
    fails(
        &[
            "fit",
            &g,
            "--template",
            &spot,
            "--cameras",
            s(&broken),
            "-o",
            o,
        ],
        1,
        &dir,
        &["broken.json"],
    );
    std::fs::remove_file(&broken).expect("rm");
    fails(
        &[
            "fit",
            &g,
            "--template",
            &spot,
            "--cameras",
            &train,
            "--images",
            "/nonexistent",
            "-o",
            o,
        ],
        1,
        &dir,
        &["/nonexistent"],
    );
    // Never over an input.
    fails(
        &[
            "fit",
            &g,
            "--template",
            &spot,
            "--cameras",
            &train,
            "-o",
            &g,
        ],
        1,
        &dir,
        &["overwrite"],
    );
}

#[test]
fn fit_follows_an_animation_frame_by_frame() {
    let dir = fresh_dir("fit_anim");
    let man = fixture("anim/CesiumMan.glb");
    let g = dir.join("g.ply");
    run_ok(&["bind", &man, "-o", s(&g)]);
    let cams = dir.join("cams.json");
    run_ok(&[
        "cameras",
        &man,
        "-o",
        s(&cams),
        "--views",
        "3",
        "--size",
        "24x24",
    ]);
    let out = dir.join("fitted.ply");
    let r = json(&[
        "fit",
        s(&g),
        "--template",
        &man,
        "--cameras",
        s(&cams),
        "-o",
        s(&out),
        "--animation",
        &man,
        "--frames",
        "0..2",
        "--fps",
        "3",
        "--iterations",
        "6",
        "--eval-every",
        "3",
    ]);
    assert_eq!(r["frames"], serde_json::json!([0, 1]), "{r}");
    assert_eq!(r["views"], 6, "{r}");
    assert_eq!(read_gaussians(&out).expect("fitted").len(), 4672);
    // The frame range needs an animation.
    fails(
        &[
            "fit",
            s(&g),
            "--template",
            &man,
            "--cameras",
            s(&cams),
            "-o",
            s(&out),
            "--frames",
            "0..2",
        ],
        2,
        &dir,
        &["--animation"],
    );
}

#[test]
fn fit_to_cesium_man_texture_targets() {
    // `--color texture`: targets coloured from CesiumMan's JPEG base-colour texture; a short
    // fit raises the held-out PSNR, and the scores differ from those of the normal colour.
    let dir = fresh_dir("fit_texture");
    let (man, g, train, eval) = setup_for(&dir, "anim/CesiumMan.glb", &[], "30");
    let out = dir.join("fitted.ply");
    let inputs = (g.as_str(), man.as_str(), train.as_str(), eval.as_str());
    let textured = fit_with_held_out(inputs, &out, &["--color", "texture"]);
    let cps = textured["checkpoints"].as_array().expect("checkpoints");
    assert_eq!(cps.len(), 3, "{textured}");
    let psnr = |c: &Value| c["eval_psnr"].as_f64().expect("psnr");
    let (first, last) = (psnr(&cps[0]), psnr(&cps[2]));
    println!("texture targets: held-out PSNR {first:.2} -> {last:.2} dB");
    assert!(first.is_finite() && (5.0..60.0).contains(&first), "{first}");
    assert!(last > first + 0.3, "held-out PSNR {first} -> {last}");
    assert_eq!(
        read_gaussians(&out).expect("fitted").len() as u64,
        textured["gaussians"].as_u64().expect("count")
    );
    // auto picks the texture (same targets, same seeded run); normal does not.
    let auto = fit_with_held_out(inputs, &out, &[]);
    assert_eq!(auto["checkpoints"][0]["eval_psnr"], cps[0]["eval_psnr"]);
    let normal = fit_with_held_out(inputs, &out, &["--color", "normal"]);
    assert_ne!(normal["checkpoints"][0]["eval_psnr"], cps[0]["eval_psnr"]);
    // --color texture on a template without a texture: one error line, nothing written.
    let spot_dir = dir.join("spot");
    std::fs::create_dir_all(&spot_dir).expect("mkdir");
    let (spot, spot_g, spot_train, _) = setup(&spot_dir);
    let refused = spot_dir.join("refused.ply");
    fails(
        &[
            "fit",
            &spot_g,
            "--template",
            &spot,
            "--cameras",
            &spot_train,
            "-o",
            s(&refused),
            "--color",
            "texture",
        ],
        1,
        &spot_dir,
        &["--color texture", "spot_triangulated.obj"],
    );
}
