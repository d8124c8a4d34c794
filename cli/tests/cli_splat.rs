//! `trisplat bind`, `deform`, `densify` and `prune`: success on fixtures, and the bad-input
//! contract (exit 1, one stderr line naming the file and the element, no output left).

mod common;
use common::{BIN, fresh_dir, listing};

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};
use trisplat_splat::glam::Vec3;
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};
use trisplat_splat::{GaussianParts, GaussianSet};

/// Positions written through f32 PLY files and deformed in f32, relative to the model size.
const POSITION_TOL: f32 = 1e-5;

/// Covariances of a translated frame against the untranslated one, relative: translating the
/// f32 vertices rounds them differently, which small triangles' frames amplify.
const COVARIANCE_TOL: f64 = 1e-4;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures/data")
        .join(name)
}

fn trisplat(args: &[&Path]) -> Output {
    Command::new(BIN).args(args).output().expect("run trisplat")
}

fn ok(args: &[&Path]) -> String {
    let out = trisplat(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{args:?}: {stderr}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs a failing command: exit 1, one `error:` line naming every string of `named`, and the
/// folder `dir` unchanged.
fn fails(args: &[&Path], dir: &Path, named: &[&str]) -> String {
    let before = listing(dir);
    let out = trisplat(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "one line on stderr: {stderr:?}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    for n in named {
        assert!(lines[0].contains(n), "`{n}` in: {stderr}");
    }
    let after: Vec<String> = listing(dir)
        .into_iter()
        .filter(|n| !before.contains(n))
        .collect();
    assert!(after.is_empty(), "left behind: {after:?}");
    lines[0].to_owned()
}

fn p(s: &str) -> &Path {
    Path::new(s)
}

/// Spot bound with one Gaussian per triangle, in `dir`.
fn bound_spot(dir: &Path) -> PathBuf {
    let g = dir.join("g.ply");
    ok(&[p("bind"), &fixture("spot_triangulated.obj"), p("-o"), &g]);
    g
}

#[test]
fn bind_initialises_and_attaches() {
    let dir = fresh_dir("bind");
    let mesh = fixture("spot_triangulated.obj");
    let spot = read_mesh(&mesh).expect("spot");
    let g = dir.join("g3.ply");
    ok(&[p("bind"), &mesh, p("-o"), &g, p("--per-triangle"), p("3")]);
    let set = read_gaussians(&g).expect("read");
    assert_eq!(set.len(), 3 * spot.triangle_count());
    let bytes = std::fs::read(&g).expect("bytes");
    assert!(String::from_utf8_lossy(&bytes[..600]).contains("property float binding_0"));
    let b = set.binding().expect("bound");
    assert_eq!(b.triangles[5].0, 1);
    assert!((set.opacity(0) - 0.1).abs() < 1e-6);
    // Attach world Gaussians (baked from the bound set) back: the same triangles.
    let out = dir.join("frames");
    ok(&[
        p("deform"),
        p("--template"),
        &mesh,
        p("--animation"),
        &mesh,
        p("--gaussians"),
        &g,
        p("-o"),
        &out,
    ]);
    let world = out.join("frame_000000.ply");
    assert!(read_gaussians(&world).expect("world").binding().is_none());
    let again = dir.join("again.ply");
    ok(&[p("bind"), &mesh, p("--gaussians"), &world, p("-o"), &again]);
    let again = read_gaussians(&again).expect("read");
    let diag = spot.bounds().expect("bounds").diagonal();
    for i in 0..set.len() {
        assert!((again.means()[i] - set.means()[i]).length() < 1e-3, "{i}");
        let _ = diag;
    }
}

/// Writes `mesh` moved by `offset` to `path`.
fn write_moved(mesh: &TriMesh, offset: Vec3, path: &Path) {
    let moved: Vec<_> = mesh
        .positions()
        .iter()
        .map(|q| *q + offset.as_dvec3())
        .collect();
    let m = TriMesh::new(moved, mesh.triangles().to_vec());
    write_mesh(path, &m, WriteOptions::default()).expect("write frame");
}

#[test]
fn deform_a_sequence_in_every_mode() {
    let dir = fresh_dir("sequence");
    let mesh_path = fixture("spot_triangulated.obj");
    let spot = read_mesh(&mesh_path).expect("spot");
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).expect("frames");
    let offsets = [
        Vec3::ZERO,
        Vec3::new(0.5, -1.0, 2.0),
        Vec3::new(0.0, 3.0, 0.0),
    ];
    for (i, o) in offsets.iter().enumerate() {
        write_moved(&spot, *o, &frames.join(format!("f{i}.obj")));
    }
    let diag = spot.bounds().expect("bounds").diagonal();
    for (mode, convention) in [("binding", "gaussianavatars"), ("jacobian", "surfhead")] {
        let g = dir.join(format!("g_{mode}.ply"));
        ok(&[
            p("bind"),
            &mesh_path,
            p("-o"),
            &g,
            p("--convention"),
            p(convention),
            p("--per-triangle"),
            p("2"),
        ]);
        let out = dir.join(format!("out_{mode}"));
        ok(&[
            p("deform"),
            p("--template"),
            &mesh_path,
            p("--animation"),
            &frames,
            p("--gaussians"),
            &g,
            p("-o"),
            &out,
            p("--mode"),
            p(mode),
            p("--frames"),
            p("1.."),
        ]);
        assert_eq!(listing(&out), ["frame_000001.ply", "frame_000002.ply"]);
        // A translated template translates the Gaussians and nothing else.
        let bound = read_gaussians(&g).expect("bound");
        let f1 = read_gaussians(&out.join("frame_000001.ply")).expect("f1");
        let f2 = read_gaussians(&out.join("frame_000002.ply")).expect("f2");
        assert_eq!(f1.len(), bound.len());
        let shift = offsets[2] - offsets[1];
        for i in 0..f1.len() {
            let d = f2.means()[i] - f1.means()[i] - shift;
            assert!(d.length() < POSITION_TOL * diag as f32, "{mode} {i}: {d}");
            // Same covariance (the rotation of equal scales is not unique in jacobian mode).
            let (c1, c2) = (f1.covariance(i), f2.covariance(i));
            let size = c1
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = (c1 - c2)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(diff < COVARIANCE_TOL * size, "{mode} {i}: {diff} vs {size}");
            let q1 = f1.rotations()[i];
            let n: f32 = q1.iter().map(|v| v * v).sum();
            assert!((n - 1.0).abs() < 1e-5 && q1[0] >= 0.0, "normalised, w >= 0");
            assert_eq!(f1.opacity_logits(), bound.opacity_logits());
        }
    }
}

#[test]
fn deform_lbs_and_blendshapes() {
    let dir = fresh_dir("lbs");
    let glb = fixture("gltf/RiggedSimple.glb");
    let g = dir.join("g.ply");
    ok(&[p("bind"), &glb, p("-o"), &g]);
    let out = dir.join("lbs");
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
        p("0..=3"),
        p("--fps"),
        p("10"),
    ]);
    assert_eq!(listing(&out).len(), 4);
    // Blendshapes: neutral = spot, one target moving every vertex up by 1, weights 0 and 0.5.
    let spot = read_mesh(&fixture("spot_triangulated.obj")).expect("spot");
    let targets = dir.join("targets");
    std::fs::create_dir_all(&targets).expect("targets");
    write_moved(
        &spot,
        Vec3::new(0.0, 1.0, 0.0),
        &targets.join("jawOpen.obj"),
    );
    let weights = dir.join("weights.json");
    std::fs::write(
        &weights,
        r#"{"names": ["jawOpen"], "frames": [{"weights": [0.0]}, {"weights": [0.5]}]}"#,
    )
    .expect("weights");
    let gs = bound_spot(&dir);
    let out = dir.join("blend");
    ok(&[
        p("deform"),
        p("--template"),
        &fixture("spot_triangulated.obj"),
        p("--animation"),
        &weights,
        p("--targets"),
        &targets,
        p("--gaussians"),
        &gs,
        p("-o"),
        &out,
    ]);
    let f0 = read_gaussians(&out.join("frame_000000.ply")).expect("f0");
    let f1 = read_gaussians(&out.join("frame_000001.ply")).expect("f1");
    for (a, b) in f0.means().iter().zip(f1.means()) {
        assert!((*b - *a - Vec3::new(0.0, 0.5, 0.0)).length() < 1e-5);
    }
}

#[test]
fn densify_and_prune_keep_every_triangle() {
    let dir = fresh_dir("densify");
    let mesh = fixture("spot_triangulated.obj");
    let tris = read_mesh(&mesh).expect("spot").triangle_count();
    let g = bound_spot(&dir);
    let mask = dir.join("mask.txt");
    let flags: Vec<&str> = (0..tris)
        .map(|i| if i % 2 == 0 { "1" } else { "0" })
        .collect();
    std::fs::write(&mask, flags.join("\n")).expect("mask");
    let d = dir.join("d.ply");
    let line = ok(&[
        p("densify"),
        &g,
        p("-o"),
        &d,
        p("--template"),
        &mesh,
        p("--mask"),
        &mask,
        p("--op"),
        p("clone"),
    ]);
    assert!(line.contains("cloned"), "{line}");
    let dense = read_gaussians(&d).expect("dense");
    assert_eq!(dense.len(), tris + tris.div_ceil(2));
    // Prune everything (opacity 0.1 < 0.5): no triangle is emptied.
    let pr = dir.join("p.ply");
    ok(&[
        p("prune"),
        &d,
        p("-o"),
        &pr,
        p("--template"),
        &mesh,
        p("--min-opacity"),
        p("0.5"),
    ]);
    let pruned = read_gaussians(&pr).expect("pruned");
    let mut seen = vec![false; tris];
    for t in &pruned.binding().expect("bound").triangles {
        seen[t.index()] = true;
    }
    assert!(seen.iter().all(|&s| s), "every triangle keeps a Gaussian");
    // Bound input without a template: an error, nothing written.
    fails(
        &[
            p("prune"),
            &d,
            p("-o"),
            &dir.join("x.ply"),
            p("--min-opacity"),
            p("0.5"),
        ],
        &dir,
        &["d.ply", "--template"],
    );
}

// ---------------------------------------------------------------------------------------------
// Bad input

#[test]
fn binding_index_out_of_range() {
    let dir = fresh_dir("range");
    // Bound to CesiumMan's 4.6k triangles, deformed with RiggedSimple's.
    let g = dir.join("g.ply");
    ok(&[p("bind"), &fixture("anim/CesiumMan.glb"), p("-o"), &g]);
    let small = fixture("gltf/RiggedSimple.glb");
    let out = dir.join("out");
    let line = fails(
        &[
            p("deform"),
            p("--template"),
            &small,
            p("--animation"),
            &small,
            p("--gaussians"),
            &g,
            p("-o"),
            &out,
        ],
        &dir,
        &["g.ply", "Gaussian", "triangle"],
    );
    assert!(
        line.contains("out of range") || line.contains("but the template has"),
        "{line}"
    );
}

#[test]
fn template_and_animation_counts_differ() {
    let dir = fresh_dir("counts");
    let g = bound_spot(&dir);
    let out = dir.join("out");
    fails(
        &[
            p("deform"),
            p("--template"),
            &fixture("spot_triangulated.obj"),
            p("--animation"),
            &fixture("anim/CesiumMan.glb"),
            p("--gaussians"),
            &g,
            p("-o"),
            &out,
        ],
        &dir,
        &["CesiumMan.glb", "vertices", "spot_triangulated.obj"],
    );
}

#[test]
fn a_bad_frame_removes_the_frames_already_written() {
    let dir = fresh_dir("badframe");
    let mesh_path = fixture("spot_triangulated.obj");
    let spot = read_mesh(&mesh_path).expect("spot");
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).expect("frames");
    write_moved(&spot, Vec3::ZERO, &frames.join("f0.obj"));
    write_moved(&spot, Vec3::X, &frames.join("f1.obj"));
    // Frame 2 has another topology.
    let cut = TriMesh::new(spot.positions()[..100].to_vec(), vec![[0, 1, 2]]);
    write_mesh(&frames.join("f2.obj"), &cut, WriteOptions::default()).expect("write");
    let g = bound_spot(&dir);
    let out = dir.join("out");
    std::fs::create_dir_all(&out).expect("out");
    fails(
        &[
            p("deform"),
            p("--template"),
            &mesh_path,
            p("--animation"),
            &frames,
            p("--gaussians"),
            &g,
            p("-o"),
            &out,
        ],
        &out,
        &["f2.obj"],
    );
    assert!(listing(&out).is_empty());
}

#[test]
fn animation_with_a_missing_accessor() {
    let dir = fresh_dir("accessor");
    let text = std::fs::read_to_string(fixture("gltf/SimpleSkin.gltf")).expect("gltf");
    let mut json: serde_json::Value = serde_json::from_str(&text).expect("json");
    json["animations"][0]["samplers"][0]["output"] = serde_json::json!(42);
    let bad = dir.join("missing.gltf");
    std::fs::write(&bad, serde_json::to_string(&json).expect("json")).expect("write");
    let g = dir.join("g.ply");
    ok(&[p("bind"), &fixture("gltf/SimpleSkin.gltf"), p("-o"), &g]);
    let out = dir.join("out");
    let line = fails(
        &[
            p("deform"),
            p("--template"),
            &fixture("gltf/SimpleSkin.gltf"),
            p("--animation"),
            &bad,
            p("--gaussians"),
            &g,
            p("-o"),
            &out,
        ],
        &dir,
        &["missing.gltf", "animations"],
    );
    assert_eq!(
        line.matches("out of bounds").count(),
        1,
        "the cause once: {line}"
    );
    // A missing animation file: the OS error once.
    let line = fails(
        &[
            p("deform"),
            p("--template"),
            &fixture("gltf/SimpleSkin.gltf"),
            p("--animation"),
            &dir.join("nope.glb"),
            p("--gaussians"),
            &g,
            p("-o"),
            &out,
        ],
        &dir,
        &["nope.glb"],
    );
    assert_eq!(
        line.matches("os error").count(),
        1,
        "the cause once: {line}"
    );
}

/// Writes spot's bound set with Gaussian 7's rotation replaced by `q` (unchecked).
fn with_rotation(dir: &Path, q: [f32; 4]) -> PathBuf {
    let g = bound_spot(dir);
    let mut parts: GaussianParts = read_gaussians(&g).expect("read").into_parts();
    parts.rotations[7] = q;
    let bad = dir.join("badq.ply");
    write_gaussians(
        &bad,
        &GaussianSet::new_unchecked(parts),
        &PlyWriteOptions::default(),
    )
    .expect("write");
    bad
}

fn deform_spot_fails(dir: &Path, g: &Path, named: &[&str]) -> String {
    let mesh = fixture("spot_triangulated.obj");
    fails(
        &[
            p("deform"),
            p("--template"),
            &mesh,
            p("--animation"),
            &mesh,
            p("--gaussians"),
            g,
            p("-o"),
            &dir.join("out"),
        ],
        dir,
        named,
    )
}

#[test]
fn nan_quaternion() {
    let dir = fresh_dir("nanq");
    let g = with_rotation(&dir, [f32::NAN, 0.0, 0.0, 1.0]);
    deform_spot_fails(&dir, &g, &["badq.ply", "Gaussian 7", "not finite"]);
}

#[test]
fn zero_quaternion() {
    let dir = fresh_dir("zeroq");
    let g = with_rotation(&dir, [0.0; 4]);
    deform_spot_fails(&dir, &g, &["badq.ply", "Gaussian 7", "zero"]);
    // bind --gaussians refuses it too.
    let mesh = fixture("spot_triangulated.obj");
    fails(
        &[
            p("bind"),
            &mesh,
            p("--gaussians"),
            &g,
            p("-o"),
            &dir.join("b.ply"),
        ],
        &dir,
        &["badq.ply", "Gaussian 7"],
    );
}

#[test]
fn lbs_needs_a_skin() {
    let dir = fresh_dir("noskin");
    let g = bound_spot(&dir);
    let mesh = fixture("spot_triangulated.obj");
    fails(
        &[
            p("deform"),
            p("--template"),
            &mesh,
            p("--animation"),
            &mesh,
            p("--gaussians"),
            &g,
            p("-o"),
            &dir.join("out"),
            p("--mode"),
            p("lbs"),
        ],
        &dir,
        &["spot_triangulated.obj", "lbs"],
    );
}

// ---------------------------------------------------------------------------------------------
// The real-template check (FLAME is not redistributable: run with
// `TRISPLAT_SHARED_DATA=$PWD/../shared/data cargo test -p trisplat-cli --test cli_splat -- --ignored`).

/// Agreement of `deform --mode binding` with the float64 GaussianAvatars formulas (issue 3).
const FLAME_REL_TOL: f64 = 1e-5;

/// The GaussianAvatars frame `(R row-major, centroid, k)` in plain f64 arrays (no shared code).
fn ga_frame(v: [[f64; 3]; 3]) -> ([[f64; 3]; 3], [f64; 3], f64) {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let unit = |a: [f64; 3]| {
        let l = dot(a, a).sqrt();
        [a[0] / l, a[1] / l, a[2] / l]
    };
    let (e1, e2) = (sub(v[1], v[0]), sub(v[2], v[0]));
    let a0 = unit(e1);
    let a1 = unit(cross(a0, e2));
    let a2 = unit(cross(a1, a0)).map(|x| -x);
    let k = (dot(e1, e1).sqrt() + dot(a2, e2).abs()) / 2.0;
    let c = [0, 1, 2].map(|i| (v[0][i] + v[1][i] + v[2][i]) / 3.0);
    ([0, 1, 2].map(|r| [a0[r], a1[r], a2[r]]), c, k)
}

fn quat_to_matrix(q: [f64; 4]) -> [[f64; 3]; 3] {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|v| v / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

#[test]
#[ignore = "needs the non-redistributable FLAME files: set TRISPLAT_SHARED_DATA"]
fn flame_binding_matches_float64_gaussian_avatars() {
    let Some(shared) = std::env::var_os("TRISPLAT_SHARED_DATA") else {
        panic!("set TRISPLAT_SHARED_DATA to the shared data folder");
    };
    let flame = PathBuf::from(shared).join("faces/flame");
    let (template, scan) = (
        flame.join("flame_template.ply"),
        flame.join("flame_registered_scan.ply"),
    );
    let t_mesh = read_mesh(&template).expect("template");
    let s_mesh = read_mesh(&scan).expect("scan");
    assert_eq!(t_mesh.triangles(), s_mesh.triangles(), "same topology");
    // Kept after the run for tests/reference/ref_deform_flame.py.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("flame_check");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    // Random local parameters, 3 per triangle, every 17th with a LAM-like log-scale of -29.
    let per = 3;
    let n = t_mesh.triangle_count() * per;
    let mut rng = trisplat_geometry::rng::Rng::new(21);
    let mut u = move || rng.uniform_f32() * 2.0 - 1.0;
    let mut parts = GaussianParts {
        means: (0..n).map(|_| Vec3::new(u(), u(), u()) * 0.5).collect(),
        log_scales: (0..n)
            .map(|i| {
                let tiny = if i % 17 == 0 { -29.0 } else { 0.0 };
                Vec3::new(u() - 1.0, u() - 1.0, u() - 1.0 + tiny)
            })
            .collect(),
        rotations: (0..n).map(|_| [u() + 1.5, u(), u(), u()]).collect(),
        opacity_logits: vec![0.3; n],
        sh: vec![0.1; 3 * n],
        binding: Some(trisplat_splat::Binding {
            triangles: (0..n)
                .map(|i| trisplat_geometry::TriId((i / per) as u32))
                .collect(),
            encoding: trisplat_splat::BindingEncoding::Float,
        }),
        space: trisplat_splat::ParameterSpace::Local,
        ..GaussianParts::default()
    };
    parts.sh_degree = 0;
    let g = dir.join("bound.ply");
    let set = GaussianSet::try_new(parts).expect("set");
    write_gaussians(&g, &set, &PlyWriteOptions::default()).expect("write");
    let out = dir.join("frames");
    ok(&[
        p("deform"),
        p("--template"),
        &template,
        p("--animation"),
        &scan,
        p("--gaussians"),
        &g,
        p("-o"),
        &out,
        p("--mode"),
        p("binding"),
    ]);
    let world = read_gaussians(&out.join("frame_000000.ply")).expect("frame");
    let diag = s_mesh.bounds().expect("bounds").diagonal();
    let (mut worst_mean, mut worst_rot, mut worst_scale) = (0.0f64, 0.0f64, 0.0f64);
    let binding = &set.binding().expect("bound").triangles;
    for (i, t) in binding.iter().enumerate() {
        let tri = s_mesh.triangles()[t.index()];
        let v = tri.map(|j| s_mesh.positions()[j as usize].to_array());
        let (r, c, k) = ga_frame(v);
        let ml = set.means()[i].as_dvec3().to_array();
        let want = [0, 1, 2].map(|a| k * (0..3).map(|b| r[a][b] * ml[b]).sum::<f64>() + c[a]);
        let got = world.means()[i].as_dvec3().to_array();
        let len = want
            .iter()
            .map(|x| x * x)
            .sum::<f64>()
            .sqrt()
            .max(1e-3 * diag);
        let err = (0..3)
            .map(|a| (got[a] - want[a]).powi(2))
            .sum::<f64>()
            .sqrt()
            / len;
        worst_mean = worst_mean.max(err);
        let rl = quat_to_matrix(set.rotations()[i].map(f64::from));
        let want_r: [[f64; 3]; 3] =
            [0, 1, 2].map(|a| [0, 1, 2].map(|b| (0..3).map(|m| r[a][m] * rl[m][b]).sum()));
        let got_r = quat_to_matrix(world.rotations()[i].map(f64::from));
        for a in 0..3 {
            for b in 0..3 {
                worst_rot = worst_rot.max((got_r[a][b] - want_r[a][b]).abs());
            }
        }
        for a in 0..3 {
            let want_s = k * f64::from(set.log_scales()[i][a]).exp();
            let got_s = f64::from(world.log_scales()[i][a]).exp();
            worst_scale = worst_scale.max((got_s - want_s).abs() / want_s);
        }
    }
    println!(
        "FLAME template -> registered scan, {n} Gaussians: means {worst_mean:.2e} (of |mu|), \
         rotations {worst_rot:.2e} (matrix entries), scales {worst_scale:.2e} (relative); \
         files in {}",
        dir.display()
    );
    assert!(worst_mean < FLAME_REL_TOL, "{worst_mean}");
    assert!(worst_rot < FLAME_REL_TOL, "{worst_rot}");
    assert!(worst_scale < FLAME_REL_TOL, "{worst_scale}");
}

/// `--gate seed` and `--gate stable` give the same files where both are defined (an unbound
/// set, so k = 1: W = √ε_w; the normal threshold C = 1 − ε_n), on both pairings.
#[test]
fn seed_and_stable_gates_write_the_same_files() {
    let dir = fresh_dir("gates");
    let g = fixture("render/random_deg3.ply");
    let run = |name: &str, extra: &[&str]| -> Vec<u8> {
        let out = dir.join(name);
        let mut args: Vec<&Path> = vec![p("densify"), &g, p("-o"), &out];
        args.extend(extra.iter().map(|s| p(s)));
        ok(&args);
        std::fs::read(&out).expect("output")
    };
    let eps = 0.012f64;
    let root = eps.sqrt().to_string();
    let seed = run("seed.ply", &["--gate", "seed"]);
    let stable = run(
        "stable.ply",
        &[
            "--gate",
            "stable",
            "--w2-threshold",
            &root,
            "--w2-to",
            "children",
        ],
    );
    assert!(seed == stable, "children: the gates differ");
    let ungated = run("all.ply", &[]);
    assert!(
        seed.len() < ungated.len(),
        "the seed gate held nothing back"
    );
    let seed = run(
        "seed_nn.ply",
        &[
            "--gate",
            "seed",
            "--w2-to",
            "nearest",
            "--w2-threshold",
            "0.0004",
        ],
    );
    let stable = run("stable_nn.ply", &["--w2-threshold", "0.02"]);
    assert!(seed == stable, "nearest: the gates differ");
    // Pruning: the seed's defaults against the same criteria in the stable form.
    let prune = |name: &str, extra: &[&str]| -> Vec<u8> {
        let out = dir.join(name);
        let mut args: Vec<&Path> = vec![p("prune"), &g, p("-o"), &out];
        args.extend(extra.iter().map(|s| p(s)));
        ok(&args);
        std::fs::read(&out).expect("output")
    };
    let seed = prune("p_seed.ply", &["--gate", "seed"]);
    let stable = prune(
        "p_stable.ply",
        &["--outlier-threshold", "0.015", "--normal-threshold", "0.7"],
    );
    assert!(seed == stable, "pruning: the gates differ");
    // --w2-to without a gate is a usage error (exit 2).
    let out = trisplat(&[
        p("densify"),
        &g,
        p("-o"),
        &dir.join("u.ply"),
        p("--w2-to"),
        p("children"),
    ]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
}

#[test]
fn refine_keeps_every_triangle_and_refuses_bad_input() {
    let dir = fresh_dir("refine");
    let mesh = fixture("spot_triangulated.obj");
    let tris = read_mesh(&mesh).expect("spot").triangle_count();
    let g = bound_spot(&dir);
    let r = dir.join("r.ply");
    let text = ok(&[
        p("refine"),
        &g,
        p("--template"),
        &mesh,
        p("-o"),
        &r,
        p("--rounds"),
        p("2"),
    ]);
    assert!(
        text.contains("round 1:") && text.contains("round 2:"),
        "{text}"
    );
    let refined = read_gaussians(&r).expect("refined");
    let mut seen = vec![false; tris];
    for t in &refined.binding().expect("bound").triangles {
        seen[t.index()] = true;
    }
    assert!(seen.iter().all(|&s| s), "every triangle keeps a Gaussian");
    assert!(refined.means().iter().all(|m| m.is_finite()));
    // Unbound input, a radius that leaves no surface, a bad option: exit 1, nothing written.
    let world = fixture("render/random_deg3.ply");
    fails(
        &[
            p("refine"),
            &world,
            p("--template"),
            &mesh,
            p("-o"),
            &dir.join("x.ply"),
        ],
        &dir,
        &["random_deg3.ply", "not bound"],
    );
    fails(
        &[
            p("refine"),
            &g,
            p("--template"),
            &mesh,
            p("-o"),
            &dir.join("x.ply"),
            p("--alpha"),
            p("1e-9"),
            p("--surfaces"),
            &dir.join("s"),
        ],
        &dir,
        &["g.ply", "round 1", "alpha"],
    );
    // A failure after the rounds (the output cannot be written) removes the surfaces they
    // wrote, and the folder made for them.
    fails(
        &[
            p("refine"),
            &g,
            p("--template"),
            &mesh,
            p("-o"),
            &dir.join("missing").join("x.ply"),
            p("--surfaces"),
            &dir.join("s"),
        ],
        &dir,
        &["missing"],
    );
    fails(
        &[
            p("refine"),
            &g,
            p("--template"),
            &mesh,
            p("-o"),
            &dir.join("x.ply"),
            p("--lambda"),
            p("nan"),
        ],
        &dir,
        &["g.ply", "round 1", "smooth"],
    );
    fails(
        &[p("refine"), &g, p("--template"), &mesh, p("-o"), &g],
        &dir,
        &["refusing to overwrite"],
    );
}
