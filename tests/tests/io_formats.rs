//! Round trips of every mesh format and the PLY/OBJ feature matrix.

use std::path::PathBuf;

use glam::{DVec3, Vec2, Vec3};

use trisplat_geometry::io::{
    self, ObjVertices, PlyEncoding, PlyExtras, ReadOptions, WriteOptions, ply,
};
use trisplat_geometry::{PointCloud, TriMesh};

fn spot() -> TriMesh {
    io::read_mesh(&trisplat_fixtures::path("spot_triangulated.obj")).expect("spot reads")
}

fn tmp(dir: &tempfile::TempDir, name: &str) -> PathBuf {
    dir.path().join(name)
}

fn write_bytes(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let p = tmp(dir, name);
    std::fs::write(&p, bytes).expect("write fixture");
    p
}

fn assert_same_mesh(a: &TriMesh, b: &TriMesh) {
    assert_eq!(a.positions(), b.positions());
    assert_eq!(a.triangles(), b.triangles());
    assert_eq!(a.normals(), b.normals());
    assert_eq!(a.uvs(), b.uvs());
    assert_eq!(quantized(a.colors()), quantized(b.colors()));
}

/// Colours are stored as 8-bit values: compare them at that precision.
fn quantized(c: Option<&[[f32; 4]]>) -> Option<Vec<[u8; 4]>> {
    c.map(|c| {
        c.iter()
            .map(|c| c.map(|x| (x * 255.0).round() as u8))
            .collect()
    })
}

#[test]
fn spot_reads_with_file_order() {
    let m = spot();
    assert_eq!(m.vertex_count(), 2930);
    assert_eq!(m.triangle_count(), 5856);
    // Spot's uvs are indexed differently from its positions (seams): dropped in this mode.
    assert!(m.uvs().is_none());
}

#[test]
fn spot_split_seams_keeps_uvs() {
    let m = io::read_mesh_with(
        &trisplat_fixtures::path("spot_triangulated.obj"),
        ReadOptions {
            obj_vertices: ObjVertices::SplitSeams,
        },
    )
    .expect("spot reads");
    assert_eq!(m.triangle_count(), 5856);
    assert!(m.vertex_count() > 2930);
    assert_eq!(m.uvs().map(<[_]>::len), Some(m.vertex_count()));
}

fn ply_round_trip(encoding: PlyEncoding) {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = spot();
    let n = m.vertex_count();
    let colors = (0..n)
        .map(|i| {
            let x = (i % 256) as f32 / 255.0;
            [x, 1.0 - x, 0.0, 1.0]
        })
        .collect();
    let m = m
        .with_normals(spot().vertex_normals())
        .and_then(|m| m.with_colors(colors))
        .expect("attributes");
    let p = tmp(&dir, "spot.ply");
    io::ply::write_ply_mesh(&p, &m, &PlyExtras::default(), encoding).expect("write");
    let back = io::read_mesh(&p).expect("read back");
    assert_same_mesh(&m, &back);
    assert_eq!(ply::read_ply_document(&p).expect("doc").encoding, encoding);
}

#[test]
fn ply_binary_le_round_trip() {
    ply_round_trip(PlyEncoding::BinaryLittleEndian);
}

#[test]
fn ply_binary_be_round_trip() {
    ply_round_trip(PlyEncoding::BinaryBigEndian);
}

#[test]
fn ply_ascii_round_trip() {
    ply_round_trip(PlyEncoding::Ascii);
}

#[test]
fn obj_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = io::read_mesh_with(
        &trisplat_fixtures::path("spot_triangulated.obj"),
        ReadOptions {
            obj_vertices: ObjVertices::SplitSeams,
        },
    )
    .expect("spot");
    let m = m.clone().with_normals(m.vertex_normals()).expect("normals");
    let p = tmp(&dir, "spot.obj");
    io::write_mesh(&p, &m, WriteOptions::default()).expect("write");
    let back = io::read_mesh(&p).expect("read back");
    assert_same_mesh(&m, &back);
}

#[test]
fn points_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = spot();
    let cloud = PointCloud::try_new(m.positions_f32())
        .and_then(|c| c.with_normals(m.vertex_normals()))
        .expect("cloud");
    let p = tmp(&dir, "points.ply");
    io::write_points(&p, &cloud, WriteOptions { ascii: true }).expect("write");
    let back = io::read_points(&p).expect("read");
    assert_eq!(back, cloud);
}

const QUAD_POSITIONS: [[f32; 3]; 5] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [1.0, 1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.5, 1.5, 0.0],
];

fn check_quad_fixture(name: &str) {
    let m = io::read_mesh(&trisplat_fixtures::path(name)).expect(name);
    let expected: Vec<Vec3> = QUAD_POSITIONS.iter().map(|&p| Vec3::from(p)).collect();
    assert_eq!(m.positions_f32(), expected, "{name}");
    // The quad is fan-triangulated, then the triangle follows.
    assert_eq!(m.triangles(), &[[0, 1, 2], [0, 2, 3], [3, 2, 4]], "{name}");
}

#[test]
fn ply_face_list_uchar_int_ascii() {
    check_quad_fixture("io/quad_uchar_int_ascii.ply");
}

#[test]
fn ply_face_list_int_int_binary_le() {
    check_quad_fixture("io/quad_int_int_le.ply");
}

#[test]
fn ply_face_list_uchar_uint_binary_be_vertex_index() {
    check_quad_fixture("io/quad_uchar_uint_be.ply");
}

#[test]
fn ply_tristrips_with_restarts() {
    let m = io::read_mesh(&trisplat_fixtures::path("io/tristrips.ply")).expect("tristrips");
    // Strip 0 1 3 2: (0 1 3), odd (3 1 2); restart; strip 3 2 4 4: (3 2 4), the degenerate
    // (2 4 4) dropped. All counter-clockwise seen from +z.
    assert_eq!(m.triangles(), &[[0, 1, 3], [3, 1, 2], [3, 2, 4]]);
    assert!(m.face_normals().iter().all(|n| n.z > 0.99));
}

#[test]
fn ply_point_cloud_normals_and_uchar_rgba() {
    let c =
        io::read_points(&trisplat_fixtures::path("io/points_normals_rgba.ply")).expect("points");
    assert_eq!(c.len(), 3);
    assert_eq!(c.positions()[1], Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(c.normals().expect("normals")[2], Vec3::X);
    let colors = c.colors().expect("colors");
    assert_eq!(colors[0], [1.0, 0.0, 0.0, 1.0]);
    assert_eq!(colors[1], [0.0, 1.0, 0.0, 128.0 / 255.0]);
    assert_eq!(colors[2], [0.0, 0.0, 1.0, 0.0]);
}

#[test]
fn ply_point_cloud_float_rgb() {
    let c =
        io::read_points(&trisplat_fixtures::path("io/points_float_rgb_le.ply")).expect("points");
    assert!(c.normals().is_none());
    assert_eq!(c.colors().expect("colors")[2], [0.25, 0.25, 1.0, 1.0]);
}

#[test]
fn read_points_of_a_mesh_has_vertex_normals() {
    let c = io::read_points(&trisplat_fixtures::path("spot_triangulated.obj")).expect("points");
    let m = spot();
    assert_eq!(c.positions(), m.positions_f32());
    assert_eq!(c.normals().expect("normals"), m.vertex_normals().as_slice());
}

#[test]
fn ply_unknown_properties_survive_a_round_trip() {
    let src = trisplat_fixtures::path("io/unknown_props.ply");
    let (mesh, extras) = ply::read_ply_mesh(&src).expect("read");
    assert_eq!(mesh.triangle_count(), 2);
    let names = |p: &[ply::PlyProperty]| p.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&extras.vertex_properties), ["quality", "label"]);
    assert_eq!(names(&extras.face_properties), ["intensity"]);
    assert_eq!(extras.other_elements.len(), 1);
    assert_eq!(extras.other_elements[0].name, "material");
    assert_eq!(extras.comments, ["with extra properties"]);
    assert_eq!(extras.obj_info, ["made by hand"]);
    let dir = tempfile::tempdir().expect("tempdir");
    for encoding in [
        PlyEncoding::Ascii,
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
    ] {
        let p = tmp(&dir, "extras.ply");
        ply::write_ply_mesh(&p, &mesh, &extras, encoding).expect("write");
        let (mesh2, extras2) = ply::read_ply_mesh(&p).expect("read back");
        assert_same_mesh(&mesh, &mesh2);
        assert_eq!(extras, extras2, "{encoding:?}");
    }
    // Values are kept with their types.
    let quality = extras.vertex_properties[0].data.clone();
    assert_eq!(
        quality,
        ply::PropertyData::Scalar(ply::ScalarColumn::F32(vec![0.5, 0.25, 0.125, 1.0]))
    );
}

#[test]
fn ply_polygon_faces_drop_face_properties() {
    // Face properties are kept only when faces map one to one onto triangles.
    let dir = tempfile::tempdir().expect("tempdir");
    let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
        property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
        property float intensity\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 0.5\n";
    let p = write_bytes(&dir, "poly.ply", text.as_bytes());
    let (mesh, extras) = ply::read_ply_mesh(&p).expect("read");
    assert_eq!(mesh.triangle_count(), 2);
    assert!(extras.face_properties.is_empty());
}

/// The counts (and bounds) trimesh 5.2.0 reports, from `tests/reference/ref_io.py`.
#[test]
fn counts_match_trimesh() {
    const BOUNDS_TOLERANCE: f64 = 1e-6;
    let path = trisplat_fixtures::path("reference/io/trimesh_counts.json");
    let text = std::fs::read_to_string(&path).expect("reference file");
    let reference: serde_json::Value = serde_json::from_str(&text).expect("json");
    let files = reference["files"].as_object().expect("files");
    let mut compared = 0;
    for (name, want) in files {
        let Some(n_v) = want["vertices"].as_u64() else {
            continue; // trimesh could not read it (recorded as `trimesh_error`)
        };
        let options = ReadOptions {
            obj_vertices: ObjVertices::SplitSeams,
        };
        let m = io::read_mesh_with(&trisplat_fixtures::path(name), options).expect(name);
        assert_eq!(m.vertex_count() as u64, n_v, "{name} vertices");
        assert_eq!(
            m.triangle_count() as u64,
            want["faces"].as_u64().expect("faces"),
            "{name} faces"
        );
        let b = m.bounds().expect("bounds");
        let scale = b.diagonal().max(1.0);
        for (k, corner) in [b.min, b.max].iter().enumerate() {
            for axis in 0..3 {
                let w = want["bounds"][k][axis].as_f64().expect("bound");
                let got = corner[axis];
                assert!(
                    (got - w).abs() <= BOUNDS_TOLERANCE * scale,
                    "{name} bounds[{k}][{axis}]: {got} vs {w}"
                );
            }
        }
        compared += 1;
    }
    assert!(compared >= 8, "{compared}");
}

fn round_trip_gltf(name: &str) {
    let dir = tempfile::tempdir().expect("tempdir");
    let m = io::read_mesh_with(
        &trisplat_fixtures::path("spot_triangulated.obj"),
        ReadOptions {
            obj_vertices: ObjVertices::SplitSeams,
        },
    )
    .expect("spot");
    let n = m.vertex_count();
    let colors = (0..n)
        .map(|i| [(i % 7) as f32 / 7.0, 0.5, 0.25, 1.0])
        .collect();
    let m = m
        .clone()
        .with_normals(m.vertex_normals())
        .and_then(|m| m.with_colors(colors))
        .expect("attributes");
    let p = tmp(&dir, name);
    io::write_mesh(&p, &m, WriteOptions::default()).expect("write");
    let back = io::read_mesh(&p).expect("read back");
    // glTF stores f32 positions: the round trip is exact at f32.
    assert_eq!(back.positions_f32(), m.positions_f32());
    assert_eq!(back.triangles(), m.triangles());
    assert_eq!(back.uvs(), m.uvs());
    assert_eq!(back.colors(), m.colors());
    const NORMAL_TOLERANCE: f32 = 1e-6;
    for (a, b) in back
        .normals()
        .expect("normals")
        .iter()
        .zip(m.normals().expect("n"))
    {
        assert!((*a - *b).length() <= NORMAL_TOLERANCE);
    }
}

#[test]
fn gltf_round_trip() {
    round_trip_gltf("spot.gltf");
}

#[test]
fn glb_round_trip() {
    round_trip_gltf("spot.glb");
}

#[test]
fn khronos_fixtures_read() {
    for (name, v, t) in [
        ("gltf/SimpleSkin.gltf", 10, 8),
        ("gltf/RiggedSimple.glb", 96, 188),
        ("gltf/SimpleMorph/SimpleMorph.gltf", 3, 1),
        ("gltf/AnimatedMorphCube/AnimatedMorphCube.gltf", 24, 12),
        ("gltf/MorphPrimitivesTest/MorphPrimitivesTest.gltf", 30, 32),
    ] {
        let m = io::read_mesh(&trisplat_fixtures::path(name)).expect(name);
        assert_eq!((m.vertex_count(), m.triangle_count()), (v, t), "{name}");
        let report = m.report();
        assert!(
            report.out_of_range_triangles.is_empty() && report.non_finite_vertices.is_empty(),
            "{name}"
        );
    }
}

/// A glTF with the given primitive modes over one buffer of 4 positions, one node per
/// primitive with its own transform.
fn synthetic_gltf(nodes: &str, meshes: &str, scene: &str) -> String {
    use base64::Engine as _;
    let mut bin = Vec::new();
    for v in [
        0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0,
    ] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let uri = base64::engine::general_purpose::STANDARD.encode(&bin);
    format!(
        r#"{{"asset":{{"version":"2.0"}},{scene}"nodes":{nodes},"meshes":{meshes},
        "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3",
          "min":[0,0,0],"max":[1,1,0]}}],
        "bufferViews":[{{"buffer":0,"byteLength":48}}],
        "buffers":[{{"byteLength":48,"uri":"data:application/octet-stream;base64,{uri}"}}]}}"#
    )
}

#[test]
fn gltf_strips_fans_and_node_transforms() {
    let dir = tempfile::tempdir().expect("tempdir");
    // mesh 0: strip, mesh 1: fan; node 0 translates by x+10 and has node 1 (scale -1 in x: a
    // mirror, so the winding flips) as its child.
    let meshes = r#"[{"primitives":[{"attributes":{"POSITION":0},"mode":5}]},
        {"primitives":[{"attributes":{"POSITION":0},"mode":6}]}]"#;
    let nodes = r#"[{"mesh":0,"translation":[10,0,0],"children":[1]},
        {"mesh":1,"scale":[-1,1,1]}]"#;
    let text = synthetic_gltf(nodes, meshes, r#""scene":0,"scenes":[{"nodes":[0]}],"#);
    let p = write_bytes(&dir, "modes.gltf", text.as_bytes());
    let m = io::read_mesh(&p).expect("read");
    assert_eq!(m.vertex_count(), 8);
    // Strip 0 1 2 3: (0 1 2), then the odd triangle (1 2 3) written as (2 1 3) to keep the
    // winding.
    // Fan 0 1 2 3: (1 2 0), (2 3 0); mirrored: winding swapped.
    assert_eq!(m.triangles(), &[[0, 1, 2], [2, 1, 3], [5, 4, 6], [6, 4, 7]]);
    assert_eq!(m.positions()[1], DVec3::new(11.0, 0.0, 0.0));
    // Child: local scale -1 then the parent's translation.
    assert_eq!(m.positions()[5], DVec3::new(9.0, 0.0, 0.0));
    // The strip keeps facing +z; the first fan triangle (1 2 0) faces +z before the mirror
    // and still does after it, thanks to the winding fix (the second fan triangle of this
    // non-convex fan faces -z either way).
    let normals = m.face_normals();
    assert!(normals[..3].iter().all(|n| n.z > 0.99), "{normals:?}");
}

#[test]
fn gltf_without_scenes_uses_root_nodes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let meshes = r#"[{"primitives":[{"attributes":{"POSITION":0}}]}]"#;
    // Node 1 is a child of node 0: only node 0 is a root; node 2 is another root.
    let nodes = r#"[{"children":[1]},{"mesh":0},{"mesh":0,"translation":[0,0,5]}]"#;
    let text = synthetic_gltf(nodes, meshes, "").replace(r#""count":4"#, r#""count":3"#);
    let p = write_bytes(&dir, "roots.gltf", text.as_bytes());
    let m = io::read_mesh(&p).expect("read");
    assert_eq!((m.vertex_count(), m.triangle_count()), (6, 2));
    assert_eq!(m.positions()[3].z, 5.0);
}

#[test]
fn empty_mesh_writes_and_reads() {
    let dir = tempfile::tempdir().expect("tempdir");
    for name in ["e.ply", "e.obj", "e.gltf", "e.glb"] {
        let p = tmp(&dir, name);
        io::write_mesh(&p, &TriMesh::default(), WriteOptions::default()).expect(name);
        let m = io::read_mesh(&p).expect(name);
        assert_eq!(m.vertex_count(), 0, "{name}");
    }
}

#[test]
fn obj_modes() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Two quads sharing an edge, the second with its own uvs on the shared vertices (a seam),
    // and an unreferenced vertex 7.
    let text = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nv 9 9 9\n\
        vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0\nvt 0.5 1\n\
        f 1/1 2/2 3/3 4/4\nf 2/5 5/2 6/3 3/6\n";
    let p = write_bytes(&dir, "seam.obj", text);
    let pos = io::read_mesh(&p).expect("positions");
    assert_eq!((pos.vertex_count(), pos.triangle_count()), (7, 4));
    assert!(
        pos.uvs().is_none(),
        "uvs are inconsistent per vertex: dropped"
    );
    let split = io::read_mesh_with(
        &p,
        ReadOptions {
            obj_vertices: ObjVertices::SplitSeams,
        },
    )
    .expect("split");
    // 4 + 4 corners, none shared (the shared positions have different uvs).
    assert_eq!((split.vertex_count(), split.triangle_count()), (8, 4));
    assert_eq!(split.uvs().expect("uvs")[4], Vec2::new(0.5, 0.0));
    let auto = io::read_mesh_with(
        &p,
        ReadOptions {
            obj_vertices: ObjVertices::Auto,
        },
    )
    .expect("auto");
    assert_eq!(auto, split);
    // Consistent uvs are kept in Positions mode, negative indices resolve.
    let text = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf -3/-3 -2/-2 -1/-1\n";
    let p = write_bytes(&dir, "rel.obj", text);
    let m = io::read_mesh(&p).expect("rel");
    assert_eq!(m.triangles(), &[[0, 1, 2]]);
    assert_eq!(m.uvs().expect("uvs")[1], Vec2::new(1.0, 0.0));
}

/// VOCA exports write `f v/vt/vn` corners in files with no `vt` or `vn` lines at all: the
/// references are dropped (as trimesh does). A reference made before such lines exist, in a
/// file that has them later, is still an error naming the face and line.
#[test]
fn obj_faces_naming_attributes_the_file_lacks() {
    let dir = tempfile::tempdir().unwrap();
    for text in [
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1/1/1 2/2/2 3/3/3\nf 2/2/2 4/4/4 3/3/3\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1//1 2//2 3//3\nf 2//2 4//4 3//3\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nf 1/1/1 2/2/2 3/3/3\nf 2/2/2 4/4/4 3/3/3\n",
    ] {
        let path = write_bytes(&dir, "voca.obj", text.as_bytes());
        let mesh = io::read_mesh(&path).unwrap();
        assert_eq!(mesh.vertex_count(), 4, "{text}");
        assert_eq!(mesh.triangles(), &[[0, 1, 2], [1, 3, 2]], "{text}");
        assert!(mesh.normals().is_none(), "{text}");
    }
    let late = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\nvn 0 0 1\n";
    let path = write_bytes(&dir, "late.obj", late.as_bytes());
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(err.contains("face 0 (line 4)"), "{err}");
    assert!(err.contains("`1//1`"), "{err}");
    let beyond = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//2 3//1\n";
    let path = write_bytes(&dir, "beyond.obj", beyond.as_bytes());
    let err = io::read_mesh(&path).unwrap_err().to_string();
    assert!(
        err.contains("face 0 (line 5)") && err.contains("`2//2`"),
        "{err}"
    );
}
