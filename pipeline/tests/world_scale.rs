//! The pipeline works at the scale of what it meshes: a skinned glTF whose mesh node scales it
//! by 0.01 while its joints scale it back (as LAM's `skin.glb`) is posed, bound and measured in
//! world space, so the scale-derived TSDF voxel and alpha follow the frames rather than the
//! node-transformed stored positions (100 times too small); and a template and animation at
//! different scales are refused.

use std::path::{Path, PathBuf};
use trisplat_pipeline::config::MetricOptions;

use glam::{DVec3, Vec3};
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};
use trisplat_pipeline::config::{
    COARSEST_VOXELS_PER_RADIUS, DEFAULT_ALPHA_FLOOR_SPACINGS, DEFAULT_VOXELS_PER_RADIUS,
};
use trisplat_pipeline::input::read_template;
use trisplat_pipeline::methods::default_voxel;
use trisplat_pipeline::{
    ExtractConfig, ExtractOptions, GroundTruth, Method, PipelineError, RunControl, run,
};

/// Scale of the mesh node (undone by the inverse bind matrix of its one joint).
const NODE_SCALE: f32 = 0.01;

/// Vertices and triangles of a unit octahedron (bounding radius 1 about its centre).
fn octahedron() -> (Vec<[f32; 3]>, Vec<[u16; 3]>) {
    let p = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let t = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    (p, t)
}

/// Writes `dir/skinned.gltf` + `skinned.bin`: root node scaled by [`NODE_SCALE`] holding the
/// skinned octahedron and its one joint; inverse bind matrix = 1 / [`NODE_SCALE`], so the
/// skinned (glTF) pose is the stored positions, radius 1, while the node transform alone
/// gives radius 0.01.
fn skinned_gltf(dir: &Path) -> PathBuf {
    let (p, t) = octahedron();
    let mut bin: Vec<u8> = Vec::new();
    for v in &p {
        for c in v {
            bin.extend(c.to_le_bytes());
        }
    }
    let joints_at = bin.len();
    bin.extend(std::iter::repeat_n(0u8, 4 * p.len()));
    let weights_at = bin.len();
    for _ in &p {
        for w in [1.0f32, 0.0, 0.0, 0.0] {
            bin.extend(w.to_le_bytes());
        }
    }
    let ibm_at = bin.len();
    let inv = 1.0 / NODE_SCALE;
    let ibm = [
        inv, 0.0, 0.0, 0.0, 0.0, inv, 0.0, 0.0, 0.0, 0.0, inv, 0.0, 0.0, 0.0, 0.0, 1.0,
    ];
    for c in ibm {
        bin.extend(c.to_le_bytes());
    }
    let index_at = bin.len();
    for tri in &t {
        for i in tri {
            bin.extend(i.to_le_bytes());
        }
    }
    let end = bin.len();
    let view = |offset: usize, len: usize| serde_json::json!({"buffer": 0, "byteOffset": offset, "byteLength": len});
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"children": [1, 2], "scale": [NODE_SCALE, NODE_SCALE, NODE_SCALE]},
            {"mesh": 0, "skin": 0},
            {"name": "joint"}
        ],
        "skins": [{"joints": [2], "inverseBindMatrices": 3}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "JOINTS_0": 1, "WEIGHTS_0": 2},
            "indices": 4
        }]}],
        "buffers": [{"uri": "skinned.bin", "byteLength": end}],
        "bufferViews": [
            view(0, joints_at),
            view(joints_at, weights_at - joints_at),
            view(weights_at, ibm_at - weights_at),
            view(ibm_at, index_at - ibm_at),
            view(index_at, end - index_at)
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": p.len(), "type": "VEC3",
             "min": [-1.0, -1.0, -1.0], "max": [1.0, 1.0, 1.0]},
            {"bufferView": 1, "componentType": 5121, "count": p.len(), "type": "VEC4"},
            {"bufferView": 2, "componentType": 5126, "count": p.len(), "type": "VEC4"},
            {"bufferView": 3, "componentType": 5126, "count": 1, "type": "MAT4"},
            {"bufferView": 4, "componentType": 5123, "count": 3 * t.len(), "type": "SCALAR"}
        ]
    });
    std::fs::write(dir.join("skinned.bin"), &bin).expect("write bin");
    let path = dir.join("skinned.gltf");
    std::fs::write(&path, serde_json::to_string(&doc).expect("json")).expect("write gltf");
    path
}

fn config(template: PathBuf, animation: Option<String>, output: PathBuf) -> ExtractConfig {
    ExtractConfig {
        template,
        animation,
        gaussians: None,
        methods: vec![Method::Delaunay, Method::Alpha],
        output,
        frames: None,
        gt: Some(GroundTruth::Template),
        options: ExtractOptions {
            metrics: MetricOptions {
                samples: 2000,
                ..Default::default()
            },
            ..ExtractOptions::default()
        },
    }
}

fn radius(vertices: &[DVec3]) -> f64 {
    trisplat_geometry::bounding_sphere(vertices, &[]).map_or(0.0, |(_, r)| r)
}

#[test]
fn skinned_template_with_a_scaled_node_is_meshed_in_world_space() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = skinned_gltf(dir.path());
    // The two readings of the file: the static one applies the node's scale, the posed one
    // (glTF's rule for skinned meshes) does not.
    let stored = read_mesh(&path).expect("static read");
    assert!((radius(stored.positions()) - f64::from(NODE_SCALE)).abs() < 1e-6);
    let world = read_template(&path).expect("posed read");
    assert!((radius(world.positions()) - 1.0).abs() < 1e-6);
    assert_eq!(world.triangles(), stored.triangles());

    let out = dir.path().join("out");
    let report = run(
        &config(path, None, out.clone()),
        RunControl::default(),
        &mut |_| {},
    )
    .expect("run");
    let r = report.resolved;
    // The scale-derived defaults follow the world-space size (radius 1), not the node
    // transform's (0.01).
    assert!((r.template_radius - 1.0).abs() < 1e-6, "{r:?}");
    assert_eq!(r.voxel, default_voxel(r.template_radius, r.mean_spacing));
    assert!(
        r.voxel >= r.template_radius / DEFAULT_VOXELS_PER_RADIUS,
        "{r:?}"
    );
    assert!(
        r.voxel <= r.template_radius / COARSEST_VOXELS_PER_RADIUS,
        "{r:?}"
    );
    // Four Gaussians per triangle of edge sqrt(2): spacing a sizeable part of an edge.
    assert!(r.mean_spacing > 0.1 && r.mean_spacing < 1.0, "{r:?}");
    // The alpha complex's search starts at its floor (the report's `alpha`).
    assert_eq!(r.alpha, DEFAULT_ALPHA_FLOOR_SPACINGS * r.mean_spacing);
    // The delaunay report keeps its update's statistics: one frame, rebuilt (the first).
    let d = report.methods["delaunay"]
        .delaunay
        .as_ref()
        .expect("delaunay stats");
    assert_eq!((d.charts, d.gaussians), (8, 32));
    assert_eq!(d.frames.len(), 1);
    assert!(d.frames[0].rebuilt && d.frames[0].charts_redone == 8);
    assert!(report.methods["alpha"].delaunay.is_none());
    // Both methods mesh the frame near the deformed template.
    for m in ["delaunay", "alpha"] {
        let a = &report.methods[m].mean;
        assert!(a.faces > 0.0, "{m}: empty mesh");
        let c = a.chamfer_l1.expect("measured");
        assert!(c < 0.05, "{m}: Chamfer {c}");
    }
}

#[test]
fn template_and_frames_at_different_scales_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (p, t) = octahedron();
    let positions: Vec<Vec3> = p.iter().map(|&v| Vec3::from(v)).collect();
    let triangles: Vec<[u32; 3]> = t.iter().map(|f| f.map(u32::from)).collect();
    let template = dir.path().join("template.ply");
    let mesh = TriMesh::new(positions.clone(), triangles.clone());
    write_mesh(&template, &mesh, WriteOptions::default()).expect("write template");
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).expect("frames dir");
    // Centimetres against metres: 100 times larger.
    for (i, scale) in [(0, 100.0f32), (1, 101.0)] {
        let moved: Vec<Vec3> = positions.iter().map(|&v| v * scale).collect();
        let frame = TriMesh::new(moved, triangles.clone());
        write_mesh(
            &frames.join(format!("f{i}.ply")),
            &frame,
            WriteOptions::default(),
        )
        .expect("write frame");
    }
    let out = dir.path().join("out");
    let anim = frames.display().to_string();
    let err = run(
        &config(template.clone(), Some(anim.clone()), out.clone()),
        RunControl::default(),
        &mut |_| {},
    )
    .expect_err("scale mismatch");
    assert!(
        matches!(err, PipelineError::ScaleMismatch { frame: 0, .. }),
        "{err}"
    );
    let text = err.to_string();
    assert!(text.starts_with(&format!("{anim}: frame 0 ")), "{text}");
    assert!(
        text.contains("template.ply") && text.contains("same scale"),
        "{text}"
    );
    assert!(!out.exists(), "nothing written");
    // The same frames at the template's scale run.
    for i in 0..2 {
        let f = frames.join(format!("f{i}.ply"));
        let frame = TriMesh::new(positions.clone(), triangles.clone());
        write_mesh(&f, &frame, WriteOptions::default()).expect("rewrite frame");
    }
    let report = run(
        &config(template, Some(anim), out),
        RunControl::default(),
        &mut |_| {},
    )
    .expect("same scale");
    assert_eq!(report.frames, vec![0, 1]);
}
