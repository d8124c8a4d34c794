//! LAM avatars (`fixtures/data/lam_mini`, a cut-down export of LAM's p2-1 avatar, MIT): what
//! LAM's files mean, pinned from the data, and the errors of a folder that does not fit.

use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{
    AnimatedTemplate, Clip, GltfMorphAnimation, GltfTemplate, WeightsTrack,
};
use trisplat_pipeline::PipelineError;
use trisplat_pipeline::avatar::{
    AvatarFolder, LAM_VERTEX_ORDER, bind_lam, read_lam_gaussians, silhouette_iou,
};
use trisplat_pipeline::input::read_template;
use trisplat_splat::Convention;
use trisplat_splat::SH_C0;
use trisplat_splat::ply::read_gaussians;
use trisplat_splat::{DeformMode, Deformer};

fn folder() -> PathBuf {
    trisplat_fixtures::path("lam_mini")
}

fn template() -> TriMesh {
    read_template(&folder().join("skin.glb")).expect("fixture template")
}

fn identity(n: usize) -> Vec<u32> {
    (0..n as u32).collect()
}

/// Mean distance between the offsets of the two ends of every mesh edge, rows of
/// `offset.ply` taken for vertices through `row_of_vertex`.
fn offset_roughness(mesh: &TriMesh, offsets: &[glam::Vec3], row_of_vertex: &[usize]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
            sum += f64::from(offsets[row_of_vertex[a]].distance(offsets[row_of_vertex[b]]));
            n += 1;
        }
    }
    sum / n as f64
}

#[test]
fn offset_rows_follow_the_glb_vertex_order_not_vertex_order_json() {
    // Which row of offset.ply belongs to which vertex, established from the data: LAM's
    // offsets vary smoothly over the head, so the right map makes neighbouring vertices'
    // offsets close. Row i for vertex i does; mapping through vertex_order.json, either way,
    // scatters them as much as a random map would.
    let mesh = template();
    let offsets = read_gaussians(&folder().join("offset.ply"))
        .expect("offsets")
        .means()
        .to_vec();
    let n = mesh.vertex_count();
    assert_eq!(offsets.len(), n);
    let order: Vec<usize> = serde_json::from_str(
        &std::fs::read_to_string(folder().join(LAM_VERTEX_ORDER)).expect("vertex order"),
    )
    .expect("json");
    let mut inverse = vec![0; n];
    for (k, &v) in order.iter().enumerate() {
        inverse[v] = k;
    }
    let same = offset_roughness(&mesh, &offsets, &(0..n).collect::<Vec<_>>());
    let through = offset_roughness(&mesh, &offsets, &order);
    let back = offset_roughness(&mesh, &offsets, &inverse);
    assert!(
        same * 2.0 < through && same * 2.0 < back,
        "row i for vertex i: {same:.5}; through vertex_order: {through:.5}, its inverse {back:.5}"
    );
}

#[test]
fn bound_lam_avatar_at_rest_is_vertex_plus_offset_with_rgb_colours() {
    let dir = folder();
    let mesh = template();
    let raw = read_gaussians(&dir.join("offset.ply")).expect("offsets");
    let n = mesh.vertex_count();
    let bound = bind_lam(
        &dir.join("offset.ply"),
        &mesh,
        &mesh,
        &identity(n),
        &dir.join("skin.glb"),
        Convention::GaussianAvatars,
    )
    .expect("bind");
    // Every Gaussian is bound to a triangle around its own vertex.
    let binding = bound.binding().expect("bound");
    for (v, t) in binding.triangles.iter().enumerate() {
        assert!(
            mesh.triangles()[t.0 as usize].contains(&(v as u32)),
            "vertex {v}"
        );
    }
    let rest = Deformer::new(&mesh, DeformMode::Binding)
        .deform(&bound, mesh.positions())
        .expect("rest");
    let diagonal = mesh.bounds().expect("bounds").diagonal();
    for v in 0..n {
        let want = mesh.positions()[v] + raw.means()[v].as_dvec3();
        let got = rest.means()[v].as_dvec3();
        assert!(
            got.distance(want) <= 1e-6 * diagonal,
            "vertex {v}: {got} vs {want}"
        );
        // LAM's f_dc is the colour itself: the SH DC coefficient gives it back.
        for c in 0..3 {
            let rgb = 0.5 + SH_C0 * f64::from(rest.sh()[v * 3 + c]);
            assert!(
                (rgb - f64::from(raw.sh()[v * 3 + c])).abs() < 1e-5,
                "vertex {v}"
            );
        }
        // Rotations and scales are those of the file (LAM keeps them in the rest frame).
        let (q, r) = (rest.rotations()[v], raw.rotations()[v]);
        let dot: f32 = (0..4).map(|k| q[k] * r[k]).sum::<f32>().abs()
            / (0..4).map(|k| r[k] * r[k]).sum::<f32>();
        assert!(dot > 1.0 - 1e-5, "vertex {v}: rotation {q:?} vs {r:?}");
        let ds = (rest.log_scales()[v] - raw.log_scales()[v])
            .abs()
            .max_element();
        assert!(ds < 1e-4, "vertex {v}: log-scales differ by {ds}");
    }
    // Rendered at rest the Gaussians cover most of the mesh's outline; LAM's offsets of up
    // to 10 cm (lips pushed out, the mouth's inside) keep the IoU of this patch well below 1,
    // as on the whole avatar (docs/benchmarks.md).
    let views = silhouette_iou(&rest, &mesh, 4, 128, &dir).expect("silhouettes");
    assert_eq!(views.len(), 4);
    for s in &views {
        assert!(s.iou > 0.3 && s.covered > 0.6, "{s:?}");
    }
}

fn copy_folder(to: &Path) {
    for f in ["skin.glb", "offset.ply", "vertex_order.json"] {
        std::fs::copy(folder().join(f), to.join(f)).expect("copy");
    }
}

fn message(e: &PipelineError) -> String {
    e.to_string()
}

#[test]
fn folders_and_files_that_do_not_fit_are_refused_naming_them() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    // Not a folder, a folder without the files.
    let e = AvatarFolder::open(&d.join("none")).expect_err("not a folder");
    assert!(message(&e).contains("not a folder"), "{e}");
    let e = AvatarFolder::open(d).expect_err("empty");
    assert!(message(&e).contains("no skin.glb and offset.ply"), "{e}");
    assert!(!AvatarFolder::is_avatar(d));
    copy_folder(d);
    assert!(AvatarFolder::is_avatar(d));
    let mesh = template();
    let skin = d.join("skin.glb");

    // vertex_order.json: a duplicate, a vertex out of range, the wrong length, not JSON.
    let n = mesh.vertex_count();
    for (text, expect) in [
        (
            format!("[0, 0{}]", ", 1".repeat(n - 2)),
            "entry 1: vertex 0 appears twice",
        ),
        (format!("[{n}{}]", ", 0".repeat(n - 1)), "out of range"),
        ("[0, 1]".to_owned(), "2 entries"),
        ("{".to_owned(), "not a JSON array"),
    ] {
        std::fs::write(d.join(LAM_VERTEX_ORDER), text).expect("write");
        let e = read_lam_gaussians(&d.join("offset.ply"), &mesh, &skin).expect_err(expect);
        let m = message(&e);
        assert!(
            m.contains(LAM_VERTEX_ORDER) && m.contains(expect),
            "{m} (want {expect})"
        );
    }
    std::fs::remove_file(d.join(LAM_VERTEX_ORDER)).expect("rm");
    // Without vertex_order.json the offsets still read (it is checked, not needed).
    read_lam_gaussians(&d.join("offset.ply"), &mesh, &skin).expect("no vertex order");

    // Another template's vertex count: named with both numbers.
    let set = read_gaussians(&d.join("offset.ply")).expect("read");
    let fewer = set.select(&(0..n - 1).collect::<Vec<_>>());
    let short = d.join("short.ply");
    trisplat_splat::ply::write_gaussians(&short, &fewer, &Default::default()).expect("write");
    let e = read_lam_gaussians(&short, &mesh, &skin).expect_err("row count");
    let m = message(&e);
    assert!(
        m.contains("short.ply") && m.contains(&format!("{} Gaussians", n - 1)),
        "{m}"
    );
    assert!(m.contains(&format!("{n} vertices")), "{m}");

    // A bound file is not LAM's layout.
    let bound = bind_lam(
        &d.join("offset.ply"),
        &mesh,
        &mesh,
        &identity(n),
        &skin,
        Convention::GaussianAvatars,
    )
    .expect("bind");
    let bound_path = d.join("bound.ply");
    trisplat_splat::ply::write_gaussians(&bound_path, &bound, &Default::default()).expect("write");
    let e = read_lam_gaussians(&bound_path, &mesh, &skin).expect_err("bound");
    assert!(message(&e).contains("already bound"), "{e}");
}

/// The weights track of the fixture's targets, all at zero, with these head poses.
fn head_track(poses: &[[f64; 3]]) -> WeightsTrack {
    let frames: Vec<String> = (0..poses.len())
        .map(|i| format!(r#"{{"weights": [0, 0, 0], "time": {}}}"#, i as f64 / 30.0))
        .collect();
    let poses: Vec<String> = poses
        .iter()
        .map(|p| format!("[{}, {}, {}]", p[0], p[1], p[2]))
        .collect();
    let text = format!(
        r#"{{"names": ["jawOpen", "mouthSmileLeft", "eyeBlinkLeft"], "frames": [{}],
            "head_pose": [{}]}}"#,
        frames.join(", "),
        poses.join(", ")
    );
    WeightsTrack::parse(&text, Path::new("head.json")).expect("track")
}

/// Vertices skinned by one matrix only, the one that skins the most of them (the head joint).
fn head_only_vertices(template: &GltfTemplate) -> Vec<usize> {
    let skinning = template.skinning();
    let single: Vec<(usize, usize)> = (0..template.rest().vertex_count())
        .filter_map(|v| {
            let influences: Vec<(usize, f64)> = skinning.influences(v).collect();
            (influences.len() == 1).then(|| (v, influences[0].0))
        })
        .collect();
    let mut counts = std::collections::HashMap::new();
    for (_, m) in &single {
        *counts.entry(*m).or_insert(0usize) += 1;
    }
    let head = counts
        .into_iter()
        .max_by_key(|(_, c)| *c)
        .expect("skinned")
        .0;
    single
        .into_iter()
        .filter(|(_, m)| *m == head)
        .map(|(v, _)| v)
        .collect()
}

/// Largest `|(a1 - b1) - R (a0 - b0)|` over pairs of `vertices` between two frames.
fn rigid_residual(vertices: &[usize], before: &[DVec3], after: &[DVec3], r: DQuat) -> f64 {
    let a = vertices[0];
    vertices
        .iter()
        .map(|&b| {
            let d0 = before[b] - before[a];
            let d1 = after[b] - after[a];
            (d1 - r * d0).length()
        })
        .fold(0.0, f64::max)
}

#[test]
fn head_pose_turns_the_head_joint_by_an_axis_angle_vector_in_radians() {
    // LAM's track (test_expression_1s.json) gives `head_pose` as 973 triples up to 0.065 in
    // size, and LAM's FLAME tracking poses the head with an axis-angle vector (Rodrigues) in
    // radians. Degrees would make 0.065 an invisible 0.001 rad; read as Euler XYZ angles the
    // track would differ by at most 0.002 rad. A large pose tells the readings apart: the
    // vertices the head joint alone skins must turn rigidly by exp([v]x) in world axes.
    let template = GltfTemplate::open(&folder().join("skin.glb"), &Clip::None).expect("skin.glb");
    let pose = [0.3, -0.5, 0.2];
    let anim = GltfMorphAnimation::new(template.clone(), head_track(&[[0.0; 3], pose]))
        .expect("animation");
    assert!(
        anim.unused_channels().is_empty(),
        "{:?}",
        anim.unused_channels()
    );
    let (rest, turned) = (
        anim.frame(0).expect("frame 0"),
        anim.frame(1).expect("frame 1"),
    );
    let head = head_only_vertices(&template);
    assert!(head.len() > 100, "{} head-only vertices", head.len());
    let axis_angle = DQuat::from_scaled_axis(DVec3::from_array(pose));
    let size = template.rest().bounds().expect("bounds").diagonal();
    let residual = rigid_residual(&head, &rest, &turned, axis_angle);
    assert!(residual < 1e-5 * size, "axis-angle residual {residual}");
    for (name, other) in [
        (
            "Euler XYZ",
            DQuat::from_euler(glam::EulerRot::XYZ, pose[0], pose[1], pose[2]),
        ),
        (
            "degrees",
            DQuat::from_scaled_axis(DVec3::from_array(pose) * std::f64::consts::PI / 180.0),
        ),
        ("inverse", DQuat::from_scaled_axis(-DVec3::from_array(pose))),
    ] {
        let r = rigid_residual(&head, &rest, &turned, other);
        assert!(r > 100.0 * residual.max(1e-9), "{name}: {r} vs {residual}");
    }
    // Frame 0 (no turn) is the rest pose itself.
    for (a, b) in rest.iter().zip(template.rest().positions()) {
        assert!(a.distance(*b) < 1e-6, "{a} vs {b}");
    }

    // Without a joint named `head` the pose drives nothing: listed as unused.
    let morph_only = GltfTemplate::open(
        &trisplat_fixtures::path("anim/SyntheticFeatures.gltf"),
        &Clip::None,
    )
    .expect("synthetic");
    let names = morph_only.morph_target_names().concat();
    let text = format!(
        r#"{{"names": ["{}"], "frames": [{{"weights": [0.5]}}], "head_pose": [[0.1, 0, 0]]}}"#,
        names[0]
    );
    let track = WeightsTrack::parse(&text, Path::new("h.json")).expect("track");
    let anim = GltfMorphAnimation::new(morph_only, track).expect("anim");
    assert_eq!(anim.unused_channels(), ["head_pose"]);

    // A head pose that does not fit its frames is refused, naming the entry.
    for (text, want) in [
        (
            r#""head_pose": [[0, 0, 0]]"#,
            "has 1 rotations for 2 frames",
        ),
        (r#""head_pose": [[0, 0], [0, 0, 0]]"#, "head_pose[0]"),
        (r#""head_pose": [[0, 0, 0], [0, null, 0]]"#, "head_pose[1]"),
        (r#""head_pose": 3"#, "expected a list"),
    ] {
        let json = format!(
            r#"{{"names": ["jawOpen"], "frames": [{{"weights": [0]}}, {{"weights": [1]}}], {text}}}"#
        );
        let e = WeightsTrack::parse(&json, Path::new("h.json")).expect_err(want);
        assert!(e.to_string().contains(want), "{e} (want {want})");
    }
}
