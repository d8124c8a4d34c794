//! Tests of the input readers.
use std::path::Path;

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::VertexSkinning;
use trisplat_splat::Deformer;

use super::*;
use crate::config::{BIND_NORMAL_SCALE, BIND_OPACITY, BIND_TANGENT_SCALE, Mode};
use crate::error::PipelineError;

fn square() -> TriMesh {
    let p = vec![
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
        DVec3::new(0.0, 1.0, 0.0),
    ];
    TriMesh::new(p, vec![[0, 1, 2], [0, 2, 3]])
}

#[test]
fn self_bound_gaussians_are_flat_along_the_normal() {
    let mesh = square();
    for mode in [Mode::Binding, Mode::Jacobian] {
        let set = bind_here(&mesh, Path::new("square"), mode, 4).expect("bound");
        let world = Deformer::new(&mesh, deform_mode(mode))
            .deform(&set, mesh.positions())
            .expect("deformed");
        for i in 0..world.len() {
            let c = world.covariance(i);
            let normal = c * glam::DVec3::Z;
            let in_plane = c * glam::DVec3::X;
            let (n, t) = (glam::DVec3::Z.dot(normal), glam::DVec3::X.dot(in_plane));
            let ratio = f64::from(BIND_NORMAL_SCALE / BIND_TANGENT_SCALE).powi(2);
            assert!(
                (n / t - ratio).abs() < 1e-3 * ratio.max(1e-3),
                "{mode:?} {i}: {n} {t}"
            );
            assert!((world.opacity(i) - BIND_OPACITY).abs() < 1e-6);
        }
    }
}

#[test]
fn welded_template_remaps_frames_and_skinning() {
    // The square with its diagonal's vertices duplicated (a UV seam).
    let p = vec![
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(1.0, 1.0, 0.0),
        DVec3::new(0.0, 1.0, 0.0),
    ];
    let stored = TriMesh::new(p.clone(), vec![[0, 1, 2], [3, 4, 5]]);
    let w = WeldedTemplate::new(&stored);
    assert!(w.merged());
    assert_eq!(w.first, vec![0, 1, 2, 5]);
    assert_eq!(w.mesh.triangles(), &[[0, 1, 2], [0, 2, 3]]);
    // A frame where the copies moved apart: the first copy wins.
    let mut frame = p.clone();
    frame[3] = DVec3::splat(9.0);
    let moved = w.positions(frame).expect("six vertices");
    assert_eq!(moved, vec![p[0], p[1], p[2], p[5]]);
    assert!(w.positions(vec![DVec3::ZERO; 5]).is_none());
    // Skin rows of the first copies (vertex v: one influence, palette entry v).
    let skinning = VertexSkinning {
        offsets: (0..=6).collect(),
        entries: (0..6).collect(),
        weights: vec![1.0; 6],
        palette_len: 6,
        base_positions: p.clone(),
    };
    let s = w.skinning(&skinning).expect("six rows");
    assert_eq!(s.offsets, vec![0, 1, 2, 3, 4]);
    assert_eq!(s.entries, vec![0, 1, 2, 5]);
    assert_eq!(s.palette_len, 6);
    assert_eq!(s.base_positions.len(), 4);
    let short = VertexSkinning {
        offsets: vec![0, 1],
        ..skinning
    };
    assert!(w.skinning(&short).is_none());
    // Nothing to weld: frames pass through.
    let single = TriMesh::new(p[..3].to_vec(), vec![[0, 1, 2]]);
    let w = WeldedTemplate::new(&single);
    assert!(!w.merged());
    assert_eq!(
        w.positions(p[..3].to_vec()).expect("three"),
        p[..3].to_vec()
    );
}

#[test]
fn scale_mismatch_is_refused_either_way() {
    let t = square();
    let path = Path::new("t.ply");
    let scaled = |k: f64| -> Vec<DVec3> { t.positions().iter().map(|&p| p * k).collect() };
    for k in [1.0, 0.5, 2.0, 9.9, 1.0 / 9.9] {
        check_scale(&t, path, &scaled(k), 0, "a").expect("same scale");
    }
    for k in [10.5, 100.0, 1.0 / 10.5, 0.01] {
        let e = check_scale(&t, path, &scaled(k), 3, "anim").expect_err("mismatch");
        let PipelineError::ScaleMismatch { frame, ratio, .. } = &e else {
            panic!("{e}");
        };
        assert_eq!(*frame, 3);
        assert!((ratio / k - 1.0).abs() < 1e-5, "{ratio} {k}");
        let text = e.to_string();
        assert!(
            text.starts_with("anim: frame 3 ") && text.contains("t.ply"),
            "{text}"
        );
    }
    // A frame without finite vertices is an error, not a pass.
    let bad = vec![DVec3::NAN; 4];
    assert!(check_scale(&t, path, &bad, 0, "a").is_err());
}

#[test]
fn frame_ranges() {
    assert_eq!(parse_frames(None, 5).expect("all"), 0..5);
    assert_eq!(parse_frames(Some("1..3"), 5).expect("ok"), 1..3);
    assert_eq!(parse_frames(Some("1..=3"), 5).expect("ok"), 1..4);
    assert_eq!(parse_frames(Some("2.."), 5).expect("ok"), 2..5);
    assert_eq!(parse_frames(Some("..2"), 5).expect("ok"), 0..2);
    assert_eq!(parse_frames(Some("4"), 5).expect("ok"), 4..5);
    for bad in ["3..3", "0..9", "x..2", "7", "5.."] {
        let e = parse_frames(Some(bad), 5).expect_err(bad).to_string();
        assert!(e.starts_with(&format!("--frames {bad}: ")), "{e}");
    }
}
