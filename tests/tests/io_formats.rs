//! Round trips of every mesh format and the PLY/OBJ feature matrix.

use std::path::{Path, PathBuf};

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
    let cloud = PointCloud::try_new(m.positions().to_vec())
        .and_then(|c| c.with_normals(m.vertex_normals()))
        .expect("cloud");
    let p = tmp(&dir, "points.ply");
    io::write_points(&p, &cloud, WriteOptions { ascii: true }).expect("write");
    let back = io::read_points(&p).expect("read");
    assert_eq!(back, cloud);
    let _ = Path::new("x");
    let _ = write_bytes;
}
