//! LAM avatars (`fixtures/data/lam_mini`, a cut-down export of LAM's p2-1 avatar, MIT): what
//! LAM's files mean, pinned from the data, and the errors of a folder that does not fit.

use std::path::{Path, PathBuf};

use trisplat_geometry::TriMesh;
use trisplat_pipeline::avatar::{
    AvatarFolder, LAM_VERTEX_ORDER, bind_lam, read_lam_gaussians, silhouette_iou,
};
use trisplat_pipeline::error::PipelineError;
use trisplat_pipeline::input::read_template;
use trisplat_splat::deform::{DeformMode, Deformer};
use trisplat_splat::frames::Convention;
use trisplat_splat::ply::read_gaussians;
use trisplat_splat::sh::SH_C0;

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
    let diagonal = f64::from(mesh.bounds().expect("bounds").diagonal());
    for v in 0..n {
        let want = mesh.positions()[v].as_dvec3() + raw.means()[v].as_dvec3();
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
