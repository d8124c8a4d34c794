//! Mesh sequences written as a USD mesh cache (`geometry::io::write_usd_sequence`): what the
//! summary and the layer say for carried and re-meshed frames, values written so that they read
//! back exactly, and bad input refused with nothing left behind. USD itself reads the files in
//! CI (`.ci/usd-cache`, Pixar's `usd-core`: validators, and every frame's points and triangles
//! against its PLY).

use std::path::{Path, PathBuf};

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{IoError, write_usd_sequence};

fn dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("io_usd_sequence")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("dir");
    d
}

/// A square of two triangles moved up by `lift`.
fn square(lift: f64) -> TriMesh {
    TriMesh::new(
        vec![
            DVec3::new(0.0, lift, 0.0),
            DVec3::new(1.0, lift, 0.0),
            DVec3::new(1.0, lift, 1.0),
            DVec3::new(0.0, lift, 1.0),
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

/// A triangle (another topology).
fn triangle() -> TriMesh {
    TriMesh::new(
        vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(0.1, 0.0, 0.0),
            DVec3::new(0.0, 0.1, 0.0),
        ],
        vec![[0, 1, 2]],
    )
}

/// The lines of the `timeSamples` block of `attribute` in `text`.
fn samples<'a>(text: &'a str, attribute: &str) -> Vec<&'a str> {
    let start = text
        .find(&format!("{attribute}.timeSamples = {{"))
        .unwrap_or_else(|| panic!("no {attribute} samples in\n{text}"));
    text[start..]
        .lines()
        .skip(1)
        .take_while(|l| l.trim() != "}")
        .collect()
}

fn no_temporaries(d: &Path) {
    let left: Vec<_> = std::fs::read_dir(d)
        .expect("listing")
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn points_every_frame_topology_where_it_changes() {
    let d = dir("keys");
    let path = d.join("cache.usda");
    // Frames 0-2 carry one square, frame 3 is a triangle, frame 4 the square again.
    let frames = vec![
        square(0.0),
        square(0.25),
        square(0.5),
        triangle(),
        square(1.0),
    ];
    let times: Vec<f64> = (0..5).map(|k| f64::from(k) / 30.0).collect();
    let summary = write_usd_sequence(&path, &frames.as_slice(), &times).expect("written");
    assert_eq!(summary.samples, 5);
    assert_eq!(summary.topology_keys, vec![0, 3, 4]);
    assert_eq!(summary.time_codes_per_second, 30.0);
    assert!(!summary.normals);
    let text = std::fs::read_to_string(&path).expect("read");
    assert!(text.starts_with("#usda 1.0\n"), "{text}");
    assert!(text.contains("timeCodesPerSecond = 30\n"), "{text}");
    assert!(text.contains("startTimeCode = 0\n") && text.contains("endTimeCode = 4\n"));
    let points = samples(&text, "point3f[] points");
    assert_eq!(points.len(), 5);
    assert_eq!(
        points[1].trim(),
        "1: [(0, 0.25, 0), (1, 0.25, 0), (1, 0.25, 1), (0, 0.25, 1)],"
    );
    assert_eq!(
        points[3].trim(),
        "3: [(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0)],"
    );
    let indices = samples(&text, "int[] faceVertexIndices");
    assert_eq!(
        indices,
        vec![
            "            0: [0, 1, 2, 0, 2, 3],",
            "            3: [0, 1, 2],",
            "            4: [0, 1, 2, 0, 2, 3],"
        ]
    );
    let counts = samples(&text, "int[] faceVertexCounts");
    assert_eq!(counts[1].trim(), "3: [3],");
    let extent = samples(&text, "float3[] extent");
    assert_eq!(extent[4].trim(), "4: [(0, 1, 0), (1, 1, 1)],");
    assert!(!text.contains("normals"));
}

#[test]
fn values_read_back_as_the_same_f32_and_normals_when_every_frame_has_them() {
    let d = dir("values");
    let path = d.join("cache.usda");
    let awkward = [0.1_f64, 1.0 / 3.0, -2.5e-8, 123_456.789, 1e-30];
    let mesh = TriMesh::new(
        vec![
            DVec3::new(awkward[0], awkward[1], awkward[2]),
            DVec3::new(awkward[3], awkward[4], 0.0),
            DVec3::new(0.0, 0.0, 1.0),
        ],
        vec![[0, 1, 2]],
    )
    .with_normals(vec![glam::Vec3::Z; 3])
    .expect("normals");
    // Irregular times: time codes in milliseconds.
    let frames = [mesh.clone(), mesh.clone(), mesh];
    let summary = write_usd_sequence(&path, &frames.as_slice(), &[0.0, 0.0125, 0.03]).expect("ok");
    assert_eq!(summary.time_codes_per_second, 1000.0);
    assert!(summary.normals);
    let text = std::fs::read_to_string(&path).expect("read");
    let first = samples(&text, "point3f[] points")[0];
    let values: Vec<f32> = first
        .split(['[', ']', '(', ')', ','])
        .skip(1)
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let expected: Vec<f32> = [
        awkward[0], awkward[1], awkward[2], awkward[3], awkward[4], 0.0, 0.0, 0.0, 1.0,
    ]
    .iter()
    .map(|&v| v as f32)
    .collect();
    assert_eq!(values, expected);
    assert!(samples(&text, "normal3f[] normals")[1].starts_with("            12.5: [(0, 0, 1)"));
    assert!(text.contains("interpolation = \"vertex\""));
}

#[test]
fn bad_input_is_refused_naming_the_element_and_leaves_nothing() {
    let d = dir("bad");
    let frames = vec![square(0.0), square(1.0)];
    let err = write_usd_sequence(&d.join("cache.usdc"), &frames.as_slice(), &[0.0, 0.1])
        .expect_err("usdc");
    assert!(matches!(err, IoError::Unsupported { .. }), "{err}");
    assert!(err.to_string().contains("usdcat"), "{err}");
    let path = d.join("cache.usda");
    let err = write_usd_sequence(&path, &frames.as_slice(), &[0.1, 0.1]).expect_err("equal times");
    assert!(err.to_string().contains("frame time 1"), "{err}");
    let err = write_usd_sequence(&path, &frames.as_slice(), &[0.0]).expect_err("one time");
    assert!(err.to_string().contains("1 times for 2 frames"), "{err}");
    let err = write_usd_sequence(&path, &[].as_slice(), &[]).expect_err("no frames");
    assert!(err.to_string().contains("no frames"), "{err}");
    let huge = TriMesh::new(
        vec![DVec3::ZERO, DVec3::new(1e300, 0.0, 0.0), DVec3::Y],
        vec![[0, 1, 2]],
    );
    let err = write_usd_sequence(&path, &[square(0.0), huge].as_slice(), &[0.0, 0.1])
        .expect_err("not finite as f32");
    let message = err.to_string();
    assert!(message.contains("frame 1, vertex 1"), "{message}");
    no_temporaries(&d);
}
