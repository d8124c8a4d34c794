//! Bad input at the library level: each case returns the right `IoError` naming the file and the
//! element at fault, never a panic; plus seeded byte-mutation fuzzing of every reader.

use std::path::{Path, PathBuf};

use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{self, IoError, ObjVertices, PlyEncoding, PlyExtras, gltf, obj, ply};
use trisplat_geometry::rng::Rng;

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).expect("write test input");
    p
}

/// The element and message of a `Malformed` error for `path`; fails the test otherwise.
fn malformed(result: Result<TriMesh, IoError>, path: &Path) -> (String, String) {
    match result {
        Err(IoError::Malformed {
            path: p,
            element,
            message,
        }) => {
            assert_eq!(p, path, "the error names the file");
            (element, message)
        }
        other => panic!("expected Malformed for {}, got {other:?}", path.display()),
    }
}

/// A binary little-endian PLY of a small mesh (the Spot fixture).
fn spot_ply_bytes(dir: &tempfile::TempDir) -> Vec<u8> {
    let mesh = trisplat_fixtures::spot().expect("spot");
    let p = dir.path().join("spot_source.ply");
    ply::write_ply_mesh(
        &p,
        &mesh,
        &PlyExtras::default(),
        PlyEncoding::BinaryLittleEndian,
    )
    .expect("write");
    std::fs::read(&p).expect("read back")
}

const ASCII_HEADER: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
    property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
    end_header\n";

#[test]
fn truncated_binary_ply() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bytes = spot_ply_bytes(&dir);
    let p = write(&dir, "cut.ply", &bytes[..bytes.len() - 1000]);
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert!(element.starts_with("face"), "{element}");
    assert!(message.contains("truncated"), "{message}");
}

#[test]
fn truncated_ascii_ply() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "cut.ply",
        format!("{ASCII_HEADER}0 0 0\n1 0 0\n").as_bytes(),
    );
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "vertex 2");
    assert!(message.contains("truncated"), "{message}");
}

#[test]
fn truncated_header() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "cut.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\n",
    );
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert!(element.starts_with("header line"), "{element}");
    assert!(message.contains("end_header"), "{message}");
}

#[test]
fn count_larger_than_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bytes = spot_ply_bytes(&dir);
    let text = String::from_utf8_lossy(&bytes[..200]).into_owned();
    let declared = text
        .lines()
        .find(|l| l.starts_with("element vertex"))
        .expect("vertex line")
        .to_owned();
    let huge = "element vertex 4000000000";
    let mut patched = Vec::new();
    let at = text.find(&declared).expect("found");
    patched.extend_from_slice(&bytes[..at]);
    patched.extend_from_slice(huge.as_bytes());
    patched.extend_from_slice(&bytes[at + declared.len()..]);
    let p = write(&dir, "huge.ply", &patched);
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "element vertex");
    assert!(message.contains("4000000000"), "{message}");
    assert!(message.contains("at most"), "{message}");
}

#[test]
fn count_larger_than_ascii_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = ASCII_HEADER.replace("element vertex 3", "element vertex 999999999999");
    let p = write(&dir, "huge.ply", format!("{text}0 0 0\n").as_bytes());
    let (element, _) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "element vertex");
}

#[test]
fn huge_list_length_is_truncation_not_allocation() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
        property float y\nproperty float z\nelement face 1\nproperty list uint int vertex_indices\n\
        end_header\n"
        .to_vec();
    b.extend_from_slice(&[0; 12]);
    b.extend_from_slice(&u32::MAX.to_le_bytes());
    let p = write(&dir, "list.ply", &b);
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "face 0");
    assert!(message.contains("truncated"), "{message}");
}

#[test]
fn nan_coordinate_in_ply() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "nan.ply",
        format!("{ASCII_HEADER}0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n").as_bytes(),
    );
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "vertex 1");
    assert!(message.contains("non-finite"), "{message}");
    // Point clouds are checked too.
    assert!(matches!(
        io::read_points(&p),
        Err(IoError::Malformed { element, .. }) if element == "vertex 1"
    ));
}

#[test]
fn nan_coordinate_in_binary_ply() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut b = ASCII_HEADER
        .replace("ascii", "binary_big_endian")
        .into_bytes();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, f32::INFINITY] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    b.push(3);
    for i in [0i32, 1, 2] {
        b.extend_from_slice(&i.to_be_bytes());
    }
    let p = write(&dir, "inf.ply", &b);
    let (element, _) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "vertex 2");
}

#[test]
fn out_of_range_index_in_ply() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "range.ply",
        format!("{ASCII_HEADER}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").as_bytes(),
    );
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "face 0");
    assert!(message.contains("vertex index 7"), "{message}");
    assert!(message.contains("out of range"), "{message}");
}

#[test]
fn negative_index_in_ply() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "neg.ply",
        format!("{ASCII_HEADER}0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n").as_bytes(),
    );
    let (element, _) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "face 0");
}

#[test]
fn non_utf8_obj() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "latin1.obj",
        b"v 0 0 0\nv 1 0 0\n# caf\xe9\nv 0 1 0\nf 1 2 3\n",
    );
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "line 3");
    assert!(message.contains("UTF-8"), "{message}");
}

#[test]
fn nan_coordinate_in_obj() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(&dir, "nan.obj", b"v 0 0 0\nv NaN 0 0\nv 0 1 0\nf 1 2 3\n");
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "vertex 1 (line 2)");
    assert!(message.contains("non-finite"), "{message}");
}

#[test]
fn out_of_range_index_in_obj() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "range.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n",
    );
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "face 1 (line 5)");
    assert!(message.contains("does not exist"), "{message}");
}

#[test]
fn missing_mtl_is_not_an_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "mtl.obj",
        b"mtllib nowhere.mtl\nusemtl skin\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    assert_eq!(io::read_mesh(&p).expect("reads").triangle_count(), 1);
}

fn gltf_with_buffer(uri: &str) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
          "min":[0,0,0],"max":[1,1,0]}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "buffers":[{{"byteLength":36,"uri":"{uri}"}}]}}"#
    )
}

#[test]
fn missing_external_bin() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "lonely.gltf",
        gltf_with_buffer("missing.bin").as_bytes(),
    );
    match io::read_mesh(&p) {
        Err(IoError::MissingReference {
            path, reference, ..
        }) => {
            assert_eq!(path, p);
            assert_eq!(reference, dir.path().join("missing.bin"));
        }
        other => panic!("expected MissingReference, got {other:?}"),
    }
}

#[test]
fn external_bin_too_short() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(&dir, "short.bin", &[0; 20]);
    let p = write(&dir, "short.gltf", gltf_with_buffer("short.bin").as_bytes());
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "buffer 0");
    assert!(message.contains("36"), "{message}");
}

#[test]
fn gltf_index_out_of_range() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u32, 1, 5] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    write(&dir, "mesh.bin", &bin);
    let text = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
        "meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
        "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
          "min":[0,0,0],"max":[1,1,0]},
          {"bufferView":1,"componentType":5125,"count":3,"type":"SCALAR"}],
        "bufferViews":[{"buffer":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":12}],
        "buffers":[{"byteLength":48,"uri":"mesh.bin"}]}"#;
    let p = write(&dir, "range.gltf", text.as_bytes());
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "mesh 0 primitive 0 index 2");
    assert!(message.contains("out of range"), "{message}");
}

#[test]
fn gltf_accessor_past_its_view() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(&dir, "mesh.bin", &[0; 36]);
    let text = gltf_with_buffer("mesh.bin").replace(r#""count":3"#, r#""count":4"#);
    let p = write(&dir, "past.gltf", text.as_bytes());
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "accessor 0");
    assert!(message.contains("do not fit"), "{message}");
}

/// Both glTF readers (static mesh and animation) read through one data module: an attribute
/// naming an accessor the file does not have is an error naming the primitive in both (the
/// animation reader used to panic in the `gltf` crate's validation), and so is an accessor
/// that runs past its buffer view.
#[test]
fn both_gltf_readers_refuse_bad_accessors_alike() {
    use trisplat_geometry::animation::{AnimationError, Clip, GltfTemplate};
    let dir = tempfile::tempdir().expect("tempdir");
    write(&dir, "mesh.bin", &[0; 36]);
    let bad_attribute = gltf_with_buffer("mesh.bin").replace(r#""POSITION":0"#, r#""POSITION":7"#);
    let p = write(&dir, "attribute.gltf", bad_attribute.as_bytes());
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "mesh 0 primitive 0");
    assert!(message.contains("accessor 7"), "{message}");
    match GltfTemplate::open(&p, &Clip::None) {
        Err(AnimationError::Primitive {
            path,
            mesh: 0,
            primitive: 0,
            message,
        }) => {
            assert_eq!(path, p);
            assert!(message.contains("accessor 7"), "{message}");
        }
        other => panic!("expected a primitive error, got {other:?}"),
    }
    let past = gltf_with_buffer("mesh.bin").replace(r#""count":3"#, r#""count":4"#);
    let p = write(&dir, "past.gltf", past.as_bytes());
    let (element, _) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "accessor 0");
    match GltfTemplate::open(&p, &Clip::None) {
        Err(AnimationError::Accessor {
            accessor: 0,
            message,
            ..
        }) => assert!(message.contains("do not fit"), "{message}"),
        other => panic!("expected an accessor error, got {other:?}"),
    }
}

#[test]
fn unknown_extension() {
    let p = Path::new("mesh.stl");
    assert!(matches!(
        io::read_mesh(p),
        Err(IoError::UnknownFormat { .. })
    ));
}

/// Flips, replaces, inserts and deletes a few bytes.
fn mutate(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let edits = 1 + rng.below(4);
    for _ in 0..edits {
        if b.is_empty() {
            b.push(0);
        }
        let len = u32::try_from(b.len()).unwrap_or(u32::MAX);
        let at = rng.below(len) as usize;
        match rng.below(5) {
            0 => b[at] ^= 1 << rng.below(8),
            1 => b[at] = u8::try_from(rng.below(256)).unwrap_or(0),
            2 => b.insert(at, b"0123456789 -\n"[rng.below(13) as usize]),
            3 => {
                b.remove(at);
            }
            _ => b.truncate(at),
        }
    }
    b
}

/// Runs `read` on `cases` mutations of `valid`; every outcome must be Ok or Err, never a panic.
fn fuzz(valid: &[u8], seed: u64, cases: usize, read: impl Fn(&[u8]) -> bool) -> usize {
    let mut rng = Rng::new(seed);
    let mut errors = 0;
    for _ in 0..cases {
        let input = mutate(&mut rng, valid);
        if !read(&input) {
            errors += 1;
        }
    }
    errors
}

const FUZZ_CASES: usize = 3000;

#[test]
fn fuzz_binary_ply_never_panics() {
    let valid = std::fs::read(trisplat_fixtures::path("io/quad_int_int_le.ply")).expect("fixture");
    let p = Path::new("fuzz.ply");
    let errors = fuzz(&valid, 1, FUZZ_CASES, |b| {
        ply::parse_ply(p, b)
            .and_then(|doc| ply::ply_to_mesh(p, &doc))
            .is_ok()
    });
    // The mutations must actually reach the error paths.
    assert!(errors > FUZZ_CASES / 10, "{errors} errors");
}

#[test]
fn fuzz_big_endian_and_ascii_ply_never_panics() {
    let p = Path::new("fuzz.ply");
    for (seed, name) in [
        (2, "io/quad_uchar_uint_be.ply"),
        (3, "io/unknown_props.ply"),
        (4, "io/tristrips.ply"),
    ] {
        let valid = std::fs::read(trisplat_fixtures::path(name)).expect("fixture");
        let errors = fuzz(&valid, seed, FUZZ_CASES / 3, |b| {
            ply::parse_ply(p, b)
                .and_then(|doc| ply::ply_to_mesh(p, &doc))
                .is_ok()
        });
        assert!(errors > 0, "{name}");
    }
}

#[test]
fn fuzz_obj_never_panics() {
    let valid = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n\
        usemtl a\nf 1/1/1 2/2/1 3/3/1 4/1/1\nf -1 -2 -3\n";
    let p = Path::new("fuzz.obj");
    for mode in [ObjVertices::Positions, ObjVertices::SplitSeams] {
        let errors = fuzz(valid, 5, FUZZ_CASES / 2, |b| {
            obj::parse_obj(p, b, mode).is_ok()
        });
        assert!(errors > 0);
    }
}

#[test]
fn fuzz_glb_never_panics() {
    let mesh = trisplat_fixtures::spot().expect("spot");
    let small = TriMesh::try_new(
        mesh.positions()[..50].to_vec(),
        mesh.triangles()
            .iter()
            .filter(|t| t.iter().all(|&v| v < 50))
            .copied()
            .collect(),
    )
    .expect("sub-mesh");
    let valid = gltf::glb_bytes(Path::new("x.glb"), &small).expect("glb");
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("fuzz.glb");
    let errors = fuzz(&valid, 6, FUZZ_CASES / 3, |b| {
        std::fs::write(&p, b).is_ok() && io::read_mesh(&p).is_ok()
    });
    assert!(errors > 0);
}

/// A glTF whose mesh hangs under a chain of 20,000 nested nodes: both glTF readers walk it
/// without recursion (the static reader overflowed the stack at depth 5,000) and agree.
#[test]
fn deep_node_chains_read_without_overflowing_the_stack() {
    use base64::Engine as _;
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("deep.gltf");
    let n = 20_000;
    let positions: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let mut nodes: Vec<serde_json::Value> = (1..n)
        .map(|i| serde_json::json!({"children": [i], "translation": [0.001, 0.0, 0.0]}))
        .collect();
    nodes.push(serde_json::json!({"mesh": 0}));
    let doc = serde_json::json!({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"byteLength": 36, "uri": format!("data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&positions))}],
    });
    std::fs::write(&path, doc.to_string()).expect("write");
    let stat = trisplat_geometry::io::read_mesh(&path).expect("static reader");
    let posed = trisplat_geometry::animation::GltfTemplate::open(
        &path,
        &trisplat_geometry::animation::Clip::None,
    )
    .expect("animation reader");
    use trisplat_geometry::animation::AnimatedTemplate as _;
    assert_eq!(stat.triangle_count(), 1);
    // 19,999 translations of 1 mm each.
    let x = stat.positions()[0].x;
    assert!((x - 19.999).abs() < 1e-3, "{x}");
    for (a, b) in stat.positions().iter().zip(posed.rest().positions()) {
        assert!(a.distance(*b) < 1e-4, "{a} vs {b}");
    }
}

/// Animations the `gltf` crate takes on trust (it panicked on them): a channel path that is
/// none of glTF's four, a channel node or sampler out of range, a sampler accessor out of
/// range. Each is refused naming the animation and channel.
#[test]
fn animation_references_out_of_range_are_refused() {
    let source = trisplat_fixtures::path("anim/SyntheticFeatures.gltf");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&source).expect("read")).expect("json");
    let dir = tempfile::tempdir().expect("tmp");
    for buffer in json["buffers"].as_array().expect("buffers") {
        if let Some(uri) = buffer["uri"].as_str().filter(|u| !u.starts_with("data:")) {
            std::fs::copy(source.with_file_name(uri), dir.path().join(uri)).expect("buffer");
        }
    }
    type Edit = fn(&mut serde_json::Value);
    let cases: [(&str, Edit, &str); 4] = [
        (
            "path",
            |g| g["animations"][0]["channels"][0]["target"]["path"] = "bogus".into(),
            "target path \"bogus\"",
        ),
        (
            "node",
            |g| g["animations"][0]["channels"][0]["target"]["node"] = 999.into(),
            "targets node 999",
        ),
        (
            "sampler",
            |g| g["animations"][0]["channels"][0]["sampler"] = 999.into(),
            "its sampler does not exist",
        ),
        (
            "accessor",
            |g| g["animations"][0]["samplers"][0]["output"] = 999.into(),
            "output accessor does not exist",
        ),
    ];
    for (name, edit, want) in cases {
        let mut g = json.clone();
        edit(&mut g);
        let path = dir.path().join(format!("{name}.gltf"));
        std::fs::write(&path, g.to_string()).expect("write");
        for clip in [
            trisplat_geometry::animation::Clip::None,
            trisplat_geometry::animation::Clip::Index(0),
        ] {
            let e = trisplat_geometry::animation::GltfTemplate::open(&path, &clip)
                .expect_err(name)
                .to_string();
            // The gltf crate's own validation catches some first ("animations[0]...").
            let named =
                (e.contains("animation 0") && e.contains(want)) || e.contains("animations[0]");
            assert!(e.contains(&format!("{name}.gltf")) && named, "{name}: {e}");
        }
    }
}

/// NaN or infinite PLY normals are refused naming the vertex (they were read and written
/// back as `vn NaN 0 1`).
#[test]
fn non_finite_ply_normals_are_refused() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("normals.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 inf 1\n3 0 1 2\n",
    )
    .expect("write");
    let e = io::read_mesh(&path).expect_err("inf normal").to_string();
    assert!(
        e.contains("vertex 2") && e.contains("non-finite normal"),
        "{e}"
    );
}

/// Found by AFL (`fuzz/regressions/gltf_animated/glb_header_length_0`): a GLB whose header gives
/// a total length shorter than the header made the `gltf` crate subtract with overflow (a panic
/// in builds with overflow checks, as fuzzing and `cargo test` use). Both readers refuse it.
#[test]
fn glb_header_length_shorter_than_the_header_is_refused() {
    use trisplat_geometry::animation::{AnimationError, Clip, GltfTemplate};
    let dir = tempfile::tempdir().expect("tempdir");
    for length in [0u8, 11] {
        let mut bytes = b"glTF\x02\x00\x00\x00".to_vec();
        bytes.extend_from_slice(&[length, 0, 0, 0]);
        let p = write(&dir, &format!("short_{length}.glb"), &bytes);
        let (element, message) = malformed(io::read_mesh(&p), &p);
        assert_eq!(element, "GLB header");
        assert!(
            message.contains(&format!("total length {length}")),
            "{message}"
        );
        match GltfTemplate::open(&p, &Clip::FirstIfAny) {
            Err(AnimationError::Mesh(IoError::Malformed { path, element, .. })) => {
                assert_eq!(path, p);
                assert_eq!(element, "GLB header");
            }
            other => panic!("expected a GLB header error, got {other:?}"),
        }
    }
    // Shorter than a header at all.
    let p = write(&dir, "tiny.glb", b"glTF\x02\x00");
    let (element, message) = malformed(io::read_mesh(&p), &p);
    assert_eq!(element, "GLB header");
    assert!(message.contains("6 bytes"), "{message}");
}

/// Found by AFL (`fuzz/regressions/gltf_animated/invalid_utf8_*`): invalid UTF-8 in a string the
/// `gltf` crate skips made the plain-JSON reference checks see no animations, and a channel with
/// an unknown path or node then panicked inside the crate. Such a document is refused.
#[test]
fn gltf_that_is_not_plain_json_is_refused() {
    use trisplat_geometry::animation::{AnimationError, Clip, GltfTemplate};
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions/gltf_animated");
    for name in [
        "invalid_utf8_hides_bad_channel_path.gltf",
        "invalid_utf8_hides_bad_channel_node.gltf",
    ] {
        let p = dir.join(name);
        match GltfTemplate::open(&p, &Clip::FirstIfAny) {
            Err(AnimationError::Gltf { path, error }) => {
                assert_eq!(path, p);
                assert!(error.to_string().contains("line 137"), "{error}");
            }
            other => panic!("expected a document error for {name}, got {other:?}"),
        }
        let (element, _) = malformed(io::read_mesh(&p), &p);
        assert_eq!(element, "document");
    }
}

/// Found by AFL (`fuzz/regressions/gltf/attribute_semantic_renamed_accessor_missing.gltf`): a
/// document without accessors whose primitive's `POSITION` names accessor 2 beside an unknown
/// semantic (`NOR:AL`) got past the accessor check and panicked in the `gltf` crate's
/// validation. Both readers now refuse it, naming the attribute.
#[test]
fn gltf_attribute_naming_a_missing_accessor_beside_an_odd_semantic_is_refused() {
    use trisplat_geometry::animation::{Clip, GltfTemplate};
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/regressions/gltf/attribute_semantic_renamed_accessor_missing.gltf");
    let e = io::read_mesh(&p).expect_err("missing accessor").to_string();
    assert!(e.contains("which does not exist"), "{e}");
    let e = GltfTemplate::open(&p, &Clip::FirstIfAny)
        .expect_err("missing accessor")
        .to_string();
    assert!(e.contains("which does not exist"), "{e}");
}

/// Found by AFL (`fuzz/regressions/gltf*/invalid_utf8_hides_missing_position_accessor.gltf`):
/// the same missing `POSITION` accessor, hidden from the accessor check by invalid UTF-8 in a
/// string the `gltf` crate skips (plain JSON failed, so the check passed it on to the crate's
/// validation, which panicked). The plain JSON is now read before the crate validates, so both
/// readers refuse it as a document error naming the line.
#[test]
fn gltf_not_plain_json_is_refused_before_the_crate_validates_it() {
    use trisplat_geometry::animation::{AnimationError, Clip, GltfTemplate};
    for target in ["gltf", "gltf_animated"] {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../fuzz/regressions")
            .join(target)
            .join("invalid_utf8_hides_missing_position_accessor.gltf");
        let (element, message) = malformed(io::read_mesh(&p), &p);
        assert_eq!(element, "document", "{message}");
        assert!(message.contains("line"), "{message}");
        match GltfTemplate::open(&p, &Clip::FirstIfAny) {
            Err(AnimationError::Gltf { path, .. }) => assert_eq!(path, p),
            other => panic!("expected a document error for {target}, got {other:?}"),
        }
    }
}
