//! OBJ/PLY frame sequences: natural order, printf and glob patterns, topology checks.

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{AnimatedTemplate, AnimationError, MeshSequence};
use trisplat_geometry::io::{WriteOptions, write_mesh};

/// A small strip: 6 vertices, 4 triangles, moved along z by `k` (the frame's signature).
fn frame_mesh(k: usize) -> TriMesh {
    let positions = (0..6)
        .map(|i| {
            Vec3::new(
                (i / 2) as f32,
                (i % 2) as f32,
                0.25 * k as f32 + 0.01 * i as f32,
            )
        })
        .collect();
    TriMesh::new(positions, vec![[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4]])
}

fn write(dir: &Path, name: &str, mesh: &TriMesh) -> PathBuf {
    let p = dir.join(name);
    write_mesh(&p, mesh, WriteOptions::default()).expect("write frame");
    p
}

/// The frame index encoded in a frame's z offset.
fn signature(positions: &[DVec3]) -> usize {
    (positions[0].z / 0.25).round() as usize
}

#[test]
fn directory_in_natural_order() {
    let dir = tempfile::tempdir().expect("tmp");
    for k in [1, 2, 10, 3] {
        write(dir.path(), &format!("f{k}.ply"), &frame_mesh(k));
    }
    std::fs::write(dir.path().join("notes.txt"), "not a frame").expect("write");
    let seq = MeshSequence::from_dir(dir.path()).expect("sequence");
    assert_eq!(seq.frame_count(), 4);
    let order: Vec<usize> = (0..4)
        .map(|i| signature(&seq.frame(i).expect("frame")))
        .collect();
    assert_eq!(order, [1, 2, 3, 10]);
    assert_eq!(seq.topology(), frame_mesh(0).triangles());
    assert_eq!(seq.rest().positions(), frame_mesh(1).positions());
    assert_eq!(seq.frame(2).expect("frame"), frame_mesh(3).positions());
    assert_eq!(seq.frame_time(1), Some(1.0 / 30.0));
    assert_eq!(seq.frame_time(4), None);
    assert!(matches!(
        seq.frame(4),
        Err(AnimationError::FrameOutOfRange { frame: 4, count: 4 })
    ));
    seq.validate_all().expect("all frames share the topology");
    let seq = seq.with_fps(25.0);
    assert_eq!(seq.frame_time(2), Some(2.0 / 25.0));
    assert_eq!(
        seq.frame_mesh(3).expect("mesh").positions(),
        frame_mesh(10).positions()
    );
}

#[test]
fn printf_and_glob_patterns() {
    let dir = tempfile::tempdir().expect("tmp");
    for k in [0, 1, 2, 12] {
        write(dir.path(), &format!("frame_{k:03}.obj"), &frame_mesh(k));
    }
    // Not matched by %03d: too few digits; a different prefix.
    write(dir.path(), "frame_7.obj", &frame_mesh(7));
    write(dir.path(), "other_004.obj", &frame_mesh(4));
    let base = dir.path().display().to_string();
    let seq = MeshSequence::from_pattern(&format!("{base}/frame_%03d.obj")).expect("printf");
    let order: Vec<usize> = (0..seq.frame_count())
        .map(|i| signature(&seq.frame(i).expect("frame")))
        .collect();
    assert_eq!(order, [0, 1, 2, 12]);
    // %d takes any number of digits.
    let seq = MeshSequence::from_pattern(&format!("{base}/frame_%d.obj")).expect("printf");
    assert_eq!(seq.frame_count(), 5);
    // Glob: natural order.
    let seq = MeshSequence::from_pattern(&format!("{base}/frame_*.obj")).expect("glob");
    let order: Vec<usize> = (0..seq.frame_count())
        .map(|i| signature(&seq.frame(i).expect("frame")))
        .collect();
    assert_eq!(order, [0, 1, 2, 7, 12]);
    // A directory given as the pattern.
    let seq = MeshSequence::from_pattern(&base).expect("dir");
    assert_eq!(seq.frame_count(), 6);
    // Nothing matches.
    let err = MeshSequence::from_pattern(&format!("{base}/none_*.obj")).expect_err("empty");
    assert!(matches!(err, AnimationError::NoFrames { .. }), "{err}");
}

#[test]
fn topology_mismatch_names_the_frame_file() {
    let dir = tempfile::tempdir().expect("tmp");
    write(dir.path(), "f0.ply", &frame_mesh(0));
    write(dir.path(), "f1.ply", &frame_mesh(1));
    // Same vertex count, one triangle flipped.
    let m = frame_mesh(2);
    let mut tris = m.triangles().to_vec();
    tris[2] = [2, 5, 3];
    let bad = write(
        dir.path(),
        "f2.ply",
        &TriMesh::new(m.positions().to_vec(), tris),
    );
    // One vertex fewer.
    let short = write(
        dir.path(),
        "f3.ply",
        &TriMesh::new(frame_mesh(3).positions()[..5].to_vec(), vec![[0, 1, 3]]),
    );
    let seq = MeshSequence::from_dir(dir.path()).expect("sequence");
    assert!(seq.frame(1).is_ok());
    let err = seq.frame(2).expect_err("flipped triangle");
    let text = err.to_string();
    assert!(
        matches!(&err, AnimationError::TopologyMismatch { path, .. } if *path == bad),
        "{text}"
    );
    assert!(
        text.contains("f2.ply") && text.contains("triangle 2"),
        "{text}"
    );
    let err = seq.frame(3).expect_err("short");
    assert!(
        matches!(&err, AnimationError::TopologyMismatch { path, .. } if *path == short),
        "{err}"
    );
    assert!(err.to_string().contains("5 vertices instead of 6"), "{err}");
    assert!(seq.validate_all().is_err());
}

#[test]
fn unreadable_frames_and_empty_directories() {
    let dir = tempfile::tempdir().expect("tmp");
    let err = MeshSequence::from_dir(dir.path()).expect_err("empty");
    assert!(matches!(err, AnimationError::NoFrames { .. }), "{err}");
    assert!(matches!(
        MeshSequence::from_dir(&dir.path().join("absent")),
        Err(AnimationError::Os { .. })
    ));
    write(dir.path(), "a1.obj", &frame_mesh(0));
    std::fs::write(dir.path().join("a2.obj"), "v 0 0 0\nf 1 2 3\n").expect("write");
    let seq = MeshSequence::from_dir(dir.path()).expect("sequence");
    let err = seq.frame(1).expect_err("bad obj");
    assert!(err.to_string().contains("a2.obj"), "{err}");
    assert!(matches!(
        MeshSequence::from_files(Vec::new(), "nothing"),
        Err(AnimationError::NoFrames { .. })
    ));
}
