//! `pipeline::fit`: mesh targets (vertex colours interpolated at the hit, the normal colour
//! otherwise, depth and camera-frame normals) and the fit's option checks.

use glam::DVec3;
use trisplat_geometry::{Camera, TriMesh};
use trisplat_pipeline::fit::{
    DensifyOptions, FitError, FitOptions, TargetColor, fit, mesh_targets,
};
use trisplat_splat::fit::bound::{BoundParams, to_set};
use trisplat_splat::render::RenderMode;
use trisplat_splat::{BindOptions, init_bound};

/// A square in the plane z = 0 seen head-on from z = -2, colours red at x = -1 and blue at
/// x = +1.
fn square() -> (TriMesh, Camera) {
    let p = vec![
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(1.0, -1.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
        DVec3::new(-1.0, 1.0, 0.0),
    ];
    let mesh = TriMesh::try_new(p, vec![[0, 1, 2], [0, 2, 3]])
        .unwrap()
        .with_colors(vec![
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [1.0, 0.0, 0.0, 1.0],
        ])
        .unwrap();
    let camera = Camera::look_at(
        "front",
        DVec3::new(0.0, 0.0, -2.0),
        DVec3::ZERO,
        DVec3::NEG_Y,
        (32, 32),
        30.0,
    )
    .unwrap();
    (mesh, camera)
}

/// Mesh targets of `mesh` at its rest positions from `cameras`, on black.
fn at_rest(
    mesh: &TriMesh,
    cameras: &[Camera],
    color: TargetColor,
) -> Result<Vec<trisplat_pipeline::fit::Target>, FitError> {
    mesh_targets(mesh, mesh.positions(), cameras, color, [0.0; 3])
}

#[test]
fn mesh_targets_interpolate_vertex_colours() {
    let (mesh, camera) = square();
    let t = &at_rest(&mesh, std::slice::from_ref(&camera), TargetColor::Auto).unwrap()[0];
    let w = 32;
    for (p, &a) in t.alpha.as_ref().unwrap().iter().enumerate() {
        if a == 0.0 {
            continue;
        }
        // World x of the hit from the pixel: the colour is linear in x across the square.
        let (i, j) = (p / w, p % w);
        let d = f64::from(t.depth.as_ref().unwrap()[p]);
        let ray = camera.unproject(j as f64 + 0.5, i as f64 + 0.5);
        let x = (camera.position() + camera.rotation() * ray * d).x;
        let s = (x + 1.0) / 2.0;
        assert!(
            (f64::from(t.rgb[3 * p]) - (1.0 - s)).abs() < 1e-4,
            "red at {p}"
        );
        assert!(
            (f64::from(t.rgb[3 * p + 2]) - s).abs() < 1e-4,
            "blue at {p}"
        );
        assert!((d - 2.0).abs() < 1e-5);
        // Facing the camera: (0, 0, -1) in the camera frame.
        let n = &t.normal.as_ref().unwrap()[3 * p..3 * p + 3];
        assert!((n[2] + 1.0).abs() < 1e-5, "{n:?}");
    }
    let normal = &at_rest(&mesh, std::slice::from_ref(&camera), TargetColor::Normal).unwrap()[0];
    let hit = normal
        .alpha
        .as_ref()
        .unwrap()
        .iter()
        .position(|&a| a > 0.0)
        .unwrap();
    // The world normal facing the camera is (0, 0, -1): colour (0.5, 0.5, 0).
    assert_eq!(&normal.rgb[3 * hit..3 * hit + 3], &[0.5, 0.5, 0.0]);
}

#[test]
fn fit_modes_and_their_terms() {
    let (mesh, camera) = square();
    let set = init_bound(&mesh, &BindOptions::default()).unwrap();
    let targets = at_rest(&mesh, &[camera], TargetColor::Auto).unwrap();
    let frames = [trisplat_pipeline::fit::FitFrame {
        frame: 0,
        positions: mesh.positions().to_vec(),
        targets,
    }];
    let mut options = FitOptions {
        iterations: 3,
        ..FitOptions::default()
    };
    options.render.mode = RenderMode::Perspective;
    let e = fit(&set, &mesh, &frames, &[], &options, |_| {}).unwrap_err();
    assert!(matches!(e, FitError::BadOption(_)) && e.to_string().contains("perspective"));
    // The 2DGS terms need 2DGS mode.
    options.render.mode = RenderMode::Gaussian3d;
    options.normal_weight = 0.1;
    let e = fit(&set, &mesh, &frames, &[], &options, |_| {}).unwrap_err();
    assert!(e.to_string().contains("--mode 2dgs"), "{e}");
    // In 2DGS mode they run, with finite losses.
    options.render.mode = RenderMode::Surfel2d;
    options.distortion_weight = 10.0;
    let fitted = fit(&set, &mesh, &frames, &[], &options, |_| {}).unwrap();
    assert!(
        fitted
            .checkpoints
            .iter()
            .skip(1)
            .all(|c| c.loss.is_some_and(f64::is_finite))
    );
    options.normal_weight = 0.0;
    options.distortion_weight = 0.0;
    options.render.mode = RenderMode::Gaussian3d;
    let fitted = fit(&set, &mesh, &frames, &[], &options, |_| {}).unwrap();
    assert_eq!(fitted.set.len(), set.len());
    assert_eq!(fitted.checkpoints.last().unwrap().iteration, 3);
    assert_eq!((fitted.iterations, fitted.out_of_time), (3, false));
    // A time budget stops the fit after the iteration that spends it, with a checkpoint there.
    let timed = FitOptions {
        iterations: 1000,
        time_budget: Some(1e-9),
        ..options.clone()
    };
    let fitted = fit(&set, &mesh, &frames, &[], &timed, |_| {}).unwrap();
    assert_eq!((fitted.iterations, fitted.out_of_time), (1, true));
    assert_eq!(fitted.checkpoints.last().unwrap().iteration, 1);
    for bad in [0.0, -1.0, f64::NAN] {
        let e = fit(
            &set,
            &mesh,
            &frames,
            &[],
            &FitOptions {
                time_budget: Some(bad),
                ..timed.clone()
            },
            |_| {},
        )
        .unwrap_err();
        assert!(e.to_string().contains("--time-budget"), "{e}");
    }
    // The depth and alpha terms with mesh targets (which carry both).
    let with_terms = FitOptions {
        depth_weight: 0.5,
        alpha_weight: 0.5,
        ..options.clone()
    };
    let fitted = fit(&set, &mesh, &frames, &[], &with_terms, |_| {}).unwrap();
    assert!(fitted.checkpoints.last().unwrap().loss.unwrap() > 0.0);
    // Needing a target image that is not there is refused, naming the view.
    let mut bare = frames.clone();
    bare[0].targets[0].depth = None;
    let e = fit(&set, &mesh, &bare, &[], &with_terms, |_| {}).unwrap_err();
    assert!(
        e.to_string().contains("'front'") && e.to_string().contains("depth"),
        "{e}"
    );
}

/// The square seen from `n` cameras on a cone around its normal (z < 0 side), 32 × 32.
fn cone_cameras(n: usize, tilt: f64, phase: f64, prefix: &str) -> Vec<Camera> {
    (0..n)
        .map(|i| {
            let a = phase + std::f64::consts::TAU * i as f64 / n as f64;
            let eye = DVec3::new(tilt * a.cos(), tilt * a.sin(), -2.5);
            Camera::look_at(
                format!("{prefix}{i}"),
                eye,
                DVec3::ZERO,
                DVec3::NEG_Y,
                (32, 32),
                40.0,
            )
            .unwrap()
        })
        .collect()
}

#[test]
fn densification_adds_gaussians_without_losing_held_out_psnr() {
    // Two triangles, one Gaussian each, cannot draw a red-to-blue gradient: the screen-space
    // gradients are large, so densification clones and splits; children keep the binding.
    let (mesh, _) = square();
    let set = init_bound(&mesh, &BindOptions::default()).unwrap();
    let frame = |cams: &[Camera]| trisplat_pipeline::fit::FitFrame {
        frame: 0,
        positions: mesh.positions().to_vec(),
        targets: at_rest(&mesh, cams, TargetColor::Auto).unwrap(),
    };
    let train = [frame(&cone_cameras(6, 0.8, 0.0, "train"))];
    let held_out = [frame(&cone_cameras(3, 0.5, 0.5, "eval"))];
    let base = FitOptions {
        iterations: 300,
        eval_every: 300,
        ..FitOptions::default()
    };
    let densify = DensifyOptions {
        from: 50,
        every: 50,
        until: 250,
        opacity_reset_every: None,
        ..DensifyOptions::default()
    };
    let with = FitOptions {
        densify: Some(densify),
        ..base.clone()
    };
    let plain = fit(&set, &mesh, &train, &held_out, &base, |_| {}).unwrap();
    let dense = fit(&set, &mesh, &train, &held_out, &with, |_| {}).unwrap();
    assert!(plain.densify.is_empty() && plain.set.len() == set.len());
    // After 100, 150, 200: above `from`, below `until`.
    assert_eq!(
        dense
            .densify
            .iter()
            .map(|e| e.iteration)
            .collect::<Vec<_>>(),
        [100, 150, 200]
    );
    let last = dense.densify.last().unwrap();
    assert_eq!(dense.set.len(), last.gaussians);
    assert!(dense.set.len() > set.len(), "{:?}", dense.densify);
    assert!(
        dense
            .set
            .binding()
            .unwrap()
            .triangles
            .iter()
            .all(|t| t.index() < 2)
    );
    let psnr =
        |f: &trisplat_pipeline::fit::Fitted| f.checkpoints.last().unwrap().eval_psnr.unwrap();
    assert!(
        psnr(&dense) > psnr(&plain) - 0.5,
        "held-out PSNR {} with densification, {} without",
        psnr(&dense),
        psnr(&plain)
    );
    assert_eq!(dense.checkpoints.last().unwrap().gaussians, dense.set.len());
    // Reproducible.
    let again = fit(&set, &mesh, &train, &held_out, &with, |_| {}).unwrap();
    assert_eq!(again.set, dense.set);
    // Bad values are refused by name.
    let bad = FitOptions {
        densify: Some(DensifyOptions {
            every: 0,
            ..densify
        }),
        ..base.clone()
    };
    let e = fit(&set, &mesh, &train, &held_out, &bad, |_| {}).unwrap_err();
    assert!(e.to_string().contains("--densify-every"), "{e}");
    let bad = FitOptions {
        sh_up_every: Some(0),
        ..base
    };
    let e = fit(&set, &mesh, &train, &held_out, &bad, |_| {}).unwrap_err();
    assert!(e.to_string().contains("--sh-up-every"), "{e}");
}

#[test]
fn sh_schedule_leaves_inactive_bands_untouched_in_the_fit() {
    // The square's set widened to SH degree 3 (bands 1-3 non-zero): with a degree raised every
    // 100 iterations, 150 iterations train bands 0 and 1 only; bands 2 and 3 come out as they
    // went in, bit for bit.
    let (mesh, camera) = square();
    let set = init_bound(&mesh, &BindOptions::default()).unwrap();
    let mut bound = BoundParams::from_set(&set, mesh.triangle_count()).unwrap();
    let n = bound.len();
    bound.local.sh_degree = 3;
    bound.local.sh = (0..n * 48)
        .map(|x| 0.05 * ((x % 48) as f64).cos())
        .collect();
    let set = to_set(&bound);
    let frames = [trisplat_pipeline::fit::FitFrame {
        frame: 0,
        positions: mesh.positions().to_vec(),
        targets: at_rest(&mesh, &[camera], TargetColor::Auto).unwrap(),
    }];
    let options = FitOptions {
        iterations: 150,
        eval_every: 50,
        sh_up_every: Some(100),
        ..FitOptions::default()
    };
    let fitted = fit(&set, &mesh, &frames, &frames, &options, |_| {}).unwrap();
    let degrees: Vec<u8> = fitted.checkpoints.iter().map(|c| c.sh_degree).collect();
    assert_eq!(degrees, [0, 0, 1, 1]);
    let (before, after) = (set.sh(), fitted.set.sh());
    // File order: DC 0..3, then per channel 15 rest coefficients (band 1: the first 3).
    let band = |j: usize| {
        if j < 3 {
            0
        } else {
            match (j - 3) % 15 {
                0..3 => 1,
                3..8 => 2,
                _ => 3,
            }
        }
    };
    let mut moved = [false; 4];
    for x in 0..n * 48 {
        let b = band(x % 48);
        if before[x] != after[x] {
            moved[b] = true;
        }
        if b >= 2 {
            assert_eq!(before[x], after[x], "coefficient {x} (band {b})");
        }
    }
    assert_eq!(moved, [true, true, false, false]);
    // Without the schedule every band trains.
    let all = FitOptions {
        sh_up_every: None,
        ..options
    };
    let fitted = fit(&set, &mesh, &frames, &frames, &all, |_| {}).unwrap();
    assert!(fitted.checkpoints.iter().all(|c| c.sh_degree == 3));
    assert!((0..n * 48).any(|x| band(x % 48) == 3 && set.sh()[x] != fitted.set.sh()[x]));
}

/// A 4 x 4 PNG: texel (i, j) has red i / 3 and green j / 3 (exact in 8 bits), blue 51 / 255.
fn ramp_png() -> Vec<u8> {
    let img = image::RgbImage::from_fn(4, 4, |i, j| {
        image::Rgb([(85 * i) as u8, (85 * j) as u8, 51])
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// The square of [`square`] as a glTF file: uv = ((x + 1) / 2, (y + 1) / 2), material 0
/// textured with [`ramp_png`] (in a buffer view), CLAMP_TO_EDGE, LINEAR.
fn textured_square(path: &std::path::Path) -> TriMesh {
    use serde_json::json;
    let (mesh, _) = square();
    let mut bin = Vec::new();
    for p in mesh.positions() {
        for c in p.to_array() {
            bin.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    for p in mesh.positions() {
        for c in [(p.x + 1.0) / 2.0, (p.y + 1.0) / 2.0] {
            bin.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    for i in mesh.triangles().iter().flatten() {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let png = ramp_png();
    let png_offset = bin.len();
    bin.extend_from_slice(&png);
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0
        }]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"wrapS": 33071, "wrapT": 33071, "magFilter": 9729}],
        "images": [{"bufferView": 3, "mimeType": "image/png"}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-1.0, -1.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5125, "count": 6, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
            {"buffer": 0, "byteOffset": 80, "byteLength": 24},
            {"buffer": 0, "byteOffset": png_offset, "byteLength": png.len()}
        ],
        "buffers": [{"byteLength": bin.len()}],
    });
    std::fs::write(
        path,
        trisplat_geometry::io::gltf::gltf_text_from_parts(doc, &bin),
    )
    .unwrap();
    let base = trisplat_geometry::io::read_gltf_base_color(path).unwrap();
    trisplat_geometry::io::read_mesh(path)
        .unwrap()
        .with_base_color(std::sync::Arc::new(base))
        .unwrap()
}

#[test]
fn mesh_targets_sample_the_base_colour_texture() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = textured_square(&dir.path().join("square.gltf"));
    let (_, camera) = square();
    let render = |color| {
        at_rest(&mesh, std::slice::from_ref(&camera), color)
            .unwrap()
            .remove(0)
    };
    let t = render(TargetColor::Texture);
    assert_eq!(
        render(TargetColor::Auto).rgb,
        t.rgb,
        "auto takes the texture"
    );
    let w = 32;
    let mut hits = 0;
    for (p, &a) in t.alpha.as_ref().unwrap().iter().enumerate() {
        if a == 0.0 {
            continue;
        }
        hits += 1;
        let (i, j) = (p / w, p % w);
        let d = f64::from(t.depth.as_ref().unwrap()[p]);
        let ray = camera.unproject(j as f64 + 0.5, i as f64 + 0.5);
        let x = camera.position() + camera.rotation() * ray * d;
        let (u, v) = ((x.x + 1.0) / 2.0, (x.y + 1.0) / 2.0);
        // Bilinear between texel centres of a ramp is the ramp: (4u - 1/2) / 3, clamped to
        // the edge texels beyond the outer centres; v runs down the image's rows.
        let ramp = |s: f64| ((4.0 * s - 0.5) / 3.0).clamp(0.0, 1.0);
        let got = &t.rgb[3 * p..3 * p + 3];
        assert!(
            (f64::from(got[0]) - ramp(u)).abs() < 1e-4,
            "red at {p}: {got:?}"
        );
        assert!(
            (f64::from(got[1]) - ramp(v)).abs() < 1e-4,
            "green at {p}: {got:?}"
        );
        assert!((got[2] - 0.2).abs() < 1e-6, "blue at {p}: {got:?}");
    }
    assert!(hits > 100, "{hits}");
    // The normal colour ignores the texture; no texture, no texture colour.
    let normal = render(TargetColor::Normal);
    assert_ne!(normal.rgb, t.rgb);
    let (plain, _) = square();
    let e = at_rest(&plain, std::slice::from_ref(&camera), TargetColor::Texture).unwrap_err();
    assert!(matches!(e, FitError::Target(_)) && e.to_string().contains("base-colour texture"));
}

/// CesiumMan's rest pose as `trisplat fit` reads it (the animated template), with its base
/// colour, and 8 cameras around it of `size` pixels.
fn cesium_man(size: u32) -> (TriMesh, Vec<Camera>) {
    use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate};
    let path = trisplat_fixtures::path("anim/CesiumMan.glb");
    let template = GltfTemplate::open(&path, &Clip::None)
        .unwrap()
        .rest()
        .clone();
    let base = trisplat_geometry::io::read_gltf_base_color(&path).unwrap();
    let mesh = template.with_base_color(std::sync::Arc::new(base)).unwrap();
    // An orbit about the box's longest axis (the figure's height).
    let b = mesh.bounds().unwrap();
    let extent = (b.max - b.min).to_array();
    let up = (0..3)
        .max_by(|&i, &j| extent[i].total_cmp(&extent[j]))
        .unwrap();
    let (h1, h2) = ((up + 1) % 3, (up + 2) % 3);
    let axis = |i: usize| DVec3::from_array(std::array::from_fn(|k| f64::from(u8::from(k == i))));
    let cameras = (0..8)
        .map(|k| {
            let a = f64::from(k) * std::f64::consts::TAU / 8.0;
            let dir = a.cos() * axis(h1) + a.sin() * axis(h2) + 0.3 * axis(up);
            let eye = b.center() + 1.2 * b.diagonal() * dir;
            Camera::look_at(
                format!("v{k}"),
                eye,
                b.center(),
                axis(up),
                (size, size),
                40.0,
            )
            .unwrap()
        })
        .collect();
    (mesh, cameras)
}

#[test]
fn cesium_man_texture_targets_are_sane() {
    let (mesh, cameras) = cesium_man(48);
    let textured = at_rest(&mesh, &cameras, TargetColor::Auto).unwrap();
    let normal = at_rest(&mesh, &cameras, TargetColor::Normal).unwrap();
    let mut hits = 0usize;
    let mut sum = [0.0f64; 3];
    for (t, n) in textured.iter().zip(&normal) {
        assert_eq!(t.alpha, n.alpha, "the texture changes rgb only");
        for (p, &a) in t.alpha.as_ref().unwrap().iter().enumerate() {
            let c = &t.rgb[3 * p..3 * p + 3];
            assert!(c.iter().all(|x| (0.0..=1.0).contains(x)), "{c:?}");
            if a > 0.0 {
                hits += 1;
                for ch in 0..3 {
                    sum[ch] += f64::from(c[ch]);
                }
            } else {
                assert_eq!(c, [0.0; 3], "background");
            }
        }
    }
    assert!(hits > 1000, "{hits}");
    // The surface's area-weighted mean colour (the base colour at the triangles' centroids)
    // matches the one computed outside: trimesh 5.2.0's uvs (its v flipped back to glTF's)
    // on Pillow 13.0.0's decode, nearest texel: (0.820, 0.886, 0.873); with v the other way
    // up it would be (0.849, 0.902, 0.882), the texture's own mean is (0.869, 0.917, 0.907).
    // The mean over the hit pixels is near it, and it is not the normal colour.
    let mean = sum.map(|s| s / hits as f64);
    let base = mesh.base_color().unwrap();
    let areas = mesh.triangle_areas();
    let mut surface = [0.0f64; 3];
    for (t, a) in areas.iter().enumerate() {
        let c = base.rgb_at(t, [1.0 / 3.0; 3]);
        for ch in 0..3 {
            surface[ch] += a * f64::from(c[ch]);
        }
    }
    let total: f64 = areas.iter().sum();
    let surface = surface.map(|s| s / total);
    println!("{hits} hits, mean rgb {mean:?}; area-weighted surface mean {surface:?}");
    for ch in 0..3 {
        assert!(
            (surface[ch] - [0.820, 0.886, 0.873][ch]).abs() < 0.01,
            "{surface:?}"
        );
        assert!(
            (mean[ch] - surface[ch]).abs() < 0.05,
            "{mean:?} vs {surface:?}"
        );
    }
    assert!(textured.iter().zip(&normal).any(|(t, n)| t.rgb != n.rgb));
}

/// Timing (run with `--release -- --ignored --nocapture`): decoding CesiumMan's texture and
/// making 8 textured 256 x 256 targets.
#[test]
#[ignore = "a timing, not a check"]
fn time_cesium_man_texture_targets() {
    let path = trisplat_fixtures::path("anim/CesiumMan.glb");
    let start = std::time::Instant::now();
    let runs = 5;
    for _ in 0..runs {
        trisplat_geometry::io::read_gltf_base_color(&path).unwrap();
    }
    let read = start.elapsed().as_secs_f64() / f64::from(runs);
    let (mesh, cameras) = cesium_man(256);
    let mut times = Vec::new();
    for color in [TargetColor::Texture, TargetColor::Normal] {
        let start = std::time::Instant::now();
        for _ in 0..runs {
            at_rest(&mesh, &cameras, color).unwrap();
        }
        times.push(start.elapsed().as_secs_f64() / f64::from(runs));
    }
    println!(
        "read_gltf_base_color (JSON, buffers, JPEG decode, corners): {:.1} ms; 8 targets \
         256x256 on {} threads: texture {:.1} ms, normal {:.1} ms",
        read * 1e3,
        rayon::current_num_threads(),
        times[0] * 1e3,
        times[1] * 1e3
    );
}
