//! Mesh sequences written as one animated glTF (`geometry::io::write_mesh_sequence`): read
//! back with `GltfTemplate` and evaluated at every frame time and between frames, for both
//! layouts and both containers; a structural check of the rules the Khronos glTF-Validator
//! enforces (it needs node, which CI does not have); bad input.

use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{DVec3, Vec3};
use serde_json::Value;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate};
use trisplat_geometry::io::{
    FrameFiles, IoError, SequenceLayout, WriteOptions, read_mesh, write_mesh, write_mesh_sequence,
    write_sequence,
};

/// Largest allowed difference between an evaluated and an input coordinate (metre-sized
/// meshes; positions are f32 and the morph deltas f32, so a few 1e-7 are expected).
const POSITION_TOLERANCE: f64 = 1e-6;

/// How far from unit length a written normal may be (the validator's own threshold is 5e-4).
const UNIT_TOLERANCE: f64 = 1e-5;

fn spot() -> TriMesh {
    trisplat_fixtures::spot().expect("spot fixture")
}

/// `n` frames of Spot, each vertex moved by a smooth per-frame wave (same topology).
fn wave_frames(n: usize, normals: bool) -> Vec<TriMesh> {
    let base = spot();
    (0..n)
        .map(|k| {
            let phase = 0.7 * k as f64;
            let positions: Vec<DVec3> = base
                .positions()
                .iter()
                .map(|p| {
                    *p + 0.05
                        * DVec3::new(
                            (3.0 * p.y + phase).sin(),
                            (2.0 * p.z - phase).cos(),
                            (4.0 * p.x + 0.5 * phase).sin(),
                        )
                })
                .collect();
            let mesh = TriMesh::new(positions, base.triangles().to_vec());
            if normals {
                let vn = mesh.vertex_normals();
                mesh.with_normals(vn).expect("normals")
            } else {
                mesh
            }
        })
        .collect()
}

/// A strip of `columns` quads at height `k` (a different topology per column count).
fn strip(columns: usize, k: usize) -> TriMesh {
    let mut positions = Vec::new();
    for c in 0..=columns {
        for r in 0..2 {
            positions.push(Vec3::new(c as f32 * 0.1, r as f32 * 0.1, 0.2 * k as f32));
        }
    }
    let mut triangles = Vec::new();
    for c in 0..columns as u32 {
        let (a, b, d, e) = (2 * c, 2 * c + 1, 2 * c + 2, 2 * c + 3);
        triangles.push([a, d, b]);
        triangles.push([b, d, e]);
    }
    TriMesh::new(positions, triangles)
}

/// Frames of different topologies: Spot, strips of growing length, Spot moved.
fn mixed_frames() -> Vec<TriMesh> {
    let moved = {
        let s = spot();
        let p: Vec<DVec3> = s.positions().iter().map(|p| *p + DVec3::X).collect();
        TriMesh::new(p, s.triangles().to_vec())
    };
    vec![spot(), strip(3, 1), strip(5, 2), moved, strip(1, 4)]
}

fn out_dir() -> tempfile::TempDir {
    tempfile::tempdir().expect("temporary folder")
}

fn max_difference(a: &[DVec3], b: &[DVec3]) -> f64 {
    assert_eq!(a.len(), b.len(), "vertex counts");
    a.iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).abs().max_element())
        .fold(0.0, f64::max)
}

/// Times at which frame `k` must be shown: its own time, the middle of its interval (or a
/// bit after the last), and before the first time for frame 0.
fn probe_times(times: &[f64], k: usize) -> Vec<f64> {
    let mut t = vec![times[k]];
    match times.get(k + 1) {
        Some(next) => t.push(0.5 * (times[k] + next)),
        None => t.push(times[k] + 1.0),
    }
    if k == 0 && times[0] > 0.0 {
        t.push(0.5 * times[0]);
    }
    t
}

/// Morph layout: the template's vertices are those of frame `k` at its times.
fn check_morph_roundtrip(path: &Path, frames: &[TriMesh], times: &[f64]) {
    let template = GltfTemplate::open(path, &Clip::Index(0)).expect("template opens");
    assert_eq!(template.rest().triangles(), frames[0].triangles());
    assert_eq!(template.clip(), Some((0, Some("sequence"))));
    assert!((template.duration() - times[times.len() - 1]).abs() < 1e-6);
    for (k, frame) in frames.iter().enumerate() {
        for t in probe_times(times, k) {
            let got = template.evaluate_at(t).expect("evaluates");
            let d = max_difference(&got, frame.positions());
            assert!(d <= POSITION_TOLERANCE, "frame {k} at {t} s: off by {d}");
        }
    }
}

/// Node-per-frame layout: at frame `k`'s times its block of vertices equals the frame and
/// every other block is collapsed to the origin (scale 0).
fn check_node_roundtrip(path: &Path, frames: &[TriMesh], times: &[f64]) {
    let template = GltfTemplate::open(path, &Clip::Index(0)).expect("template opens");
    let mut starts = vec![0];
    let mut triangles = Vec::new();
    for f in frames {
        let base = *starts.last().expect("start") as u32;
        triangles.extend(f.triangles().iter().map(|t| t.map(|v| v + base)));
        starts.push(starts.last().expect("start") + f.vertex_count());
    }
    assert_eq!(template.rest().triangles(), triangles.as_slice());
    for k in 0..frames.len() {
        for t in probe_times(times, k) {
            let got = template.evaluate_at(t).expect("evaluates");
            assert_eq!(got.len(), starts[frames.len()]);
            for (j, frame) in frames.iter().enumerate() {
                let block = &got[starts[j]..starts[j + 1]];
                if j == k {
                    let d = max_difference(block, frame.positions());
                    assert!(d <= POSITION_TOLERANCE, "frame {k} at {t} s: off by {d}");
                } else {
                    assert!(
                        block.iter().all(|p| *p == DVec3::ZERO),
                        "frame {j} visible at {t} s (frame {k}'s time)"
                    );
                }
            }
        }
    }
}

/// The JSON document and binary buffer of a written `.glb` or `.gltf`, with the GLB framing
/// checked (magic, version, total length, chunk alignment).
fn load(path: &Path) -> (Value, Vec<u8>) {
    let bytes = std::fs::read(path).expect("read output");
    if path.extension().is_some_and(|e| e == "glb") {
        let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().expect("4 bytes"));
        assert_eq!(&bytes[0..4], b"glTF");
        assert_eq!(u32_at(4), 2);
        assert_eq!(u32_at(8) as usize, bytes.len());
        let json_len = u32_at(12) as usize;
        assert_eq!(&bytes[16..20], b"JSON");
        assert_eq!(json_len % 4, 0);
        let doc: Value = serde_json::from_slice(&bytes[20..20 + json_len]).expect("json");
        let at = 20 + json_len;
        let bin_len = u32_at(at) as usize;
        assert_eq!(&bytes[at + 4..at + 8], b"BIN\0");
        assert_eq!(bin_len % 4, 0);
        assert_eq!(at + 8 + bin_len, bytes.len());
        (doc, bytes[at + 8..].to_vec())
    } else {
        let doc: Value = serde_json::from_slice(&bytes).expect("json");
        let uri = doc["buffers"][0]["uri"].as_str().expect("data uri");
        let payload = uri
            .strip_prefix("data:application/octet-stream;base64,")
            .expect("base64 data uri");
        let bin = base64::engine::general_purpose::STANDARD
            .decode(payload)
            .expect("base64");
        (doc, bin)
    }
}

fn usize_of(v: &Value) -> usize {
    v.as_u64().expect("unsigned integer") as usize
}

fn width(kind: &str) -> usize {
    match kind {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" => 4,
        other => panic!("unexpected accessor type {other}"),
    }
}

/// Accessor `a` decoded (float or u32 components) as f64, flat.
fn accessor(doc: &Value, bin: &[u8], a: usize) -> Vec<f64> {
    let acc = &doc["accessors"][a];
    let view = &doc["bufferViews"][usize_of(&acc["bufferView"])];
    let offset = usize_of(&view["byteOffset"]) + acc["byteOffset"].as_u64().unwrap_or(0) as usize;
    let n = usize_of(&acc["count"]) * width(acc["type"].as_str().expect("type"));
    (0..n)
        .map(|i| {
            let b: [u8; 4] = bin[offset + 4 * i..offset + 4 * i + 4]
                .try_into()
                .expect("4");
            match usize_of(&acc["componentType"]) {
                5126 => f64::from(f32::from_le_bytes(b)),
                5125 => f64::from(u32::from_le_bytes(b)),
                other => panic!("unexpected component type {other}"),
            }
        })
        .collect()
}

/// Checks `min`/`max` of accessor `a` exist and equal its values' bounds.
fn check_bounds(doc: &Value, bin: &[u8], a: usize) {
    let acc = &doc["accessors"][a];
    let w = width(acc["type"].as_str().expect("type"));
    let values = accessor(doc, bin, a);
    for c in 0..w {
        let column = values.iter().skip(c).step_by(w);
        let lo = column.clone().fold(f64::INFINITY, |m, &x| m.min(x));
        let hi = column.fold(f64::NEG_INFINITY, |m, &x| m.max(x));
        // The JSON number read back and rounded to f32 must be the f32 bound itself.
        let min = acc["min"][c].as_f64().expect("accessor min");
        let max = acc["max"][c].as_f64().expect("accessor max");
        assert_eq!(f64::from(min as f32), lo, "accessor {a} min[{c}]");
        assert_eq!(f64::from(max as f32), hi, "accessor {a} max[{c}]");
    }
}

/// The structural rules of the glTF 2.0 specification that the Khronos validator checks and
/// that these files could break: views inside the buffer and 4-byte aligned, accessors inside
/// their views, `min`/`max` where required and exact, view targets, index ranges, unit normals,
/// morph target counts, node hierarchy, animation keys and output sizes. Returns the document.
fn check_structure(path: &Path) -> Value {
    let (doc, bin) = load(path);
    assert_eq!(doc["asset"]["version"], "2.0");
    let buffers = doc["buffers"].as_array().expect("buffers");
    assert_eq!(buffers.len(), 1);
    let buffer_len = usize_of(&buffers[0]["byteLength"]);
    assert!(buffer_len <= bin.len() && bin.len() <= buffer_len + 3);
    let views = doc["bufferViews"].as_array().expect("views");
    for (i, v) in views.iter().enumerate() {
        let (o, l) = (usize_of(&v["byteOffset"]), usize_of(&v["byteLength"]));
        assert_eq!(o % 4, 0, "view {i} alignment");
        assert!(l > 0 && o + l <= buffer_len, "view {i} inside the buffer");
    }
    let accessors = doc["accessors"].as_array().expect("accessors");
    let mut used_as = vec![""; accessors.len()];
    for (a, acc) in accessors.iter().enumerate() {
        let view = &views[usize_of(&acc["bufferView"])];
        let count = usize_of(&acc["count"]);
        let elem = 4 * width(acc["type"].as_str().expect("type"));
        assert!(count >= 1, "accessor {a} count");
        assert!(
            count * elem <= usize_of(&view["byteLength"]),
            "accessor {a} size"
        );
    }
    let mut mark = |a: &Value, what: &'static str, target: Option<u64>| {
        let a = usize_of(a);
        let view = &views[usize_of(&accessors[a]["bufferView"])];
        assert_eq!(
            view["target"].as_u64(),
            target,
            "accessor {a} ({what}) view target"
        );
        used_as[a] = what;
        a
    };
    for mesh in doc["meshes"].as_array().into_iter().flatten() {
        let weights = mesh["weights"].as_array().map_or(0, Vec::len);
        for prim in mesh["primitives"].as_array().expect("primitives") {
            assert_eq!(prim["mode"], 4);
            let attrs = &prim["attributes"];
            let pos = mark(&attrs["POSITION"], "position", Some(34962));
            check_bounds(&doc, &bin, pos);
            let n = usize_of(&accessors[pos]["count"]);
            if !attrs["NORMAL"].is_null() {
                let a = mark(&attrs["NORMAL"], "normal", Some(34962));
                for v in accessor(&doc, &bin, a).chunks_exact(3) {
                    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                    assert!((len - 1.0).abs() < UNIT_TOLERANCE, "normal length {len}");
                }
            }
            let idx = mark(&prim["indices"], "indices", Some(34963));
            let indices = accessor(&doc, &bin, idx);
            assert_eq!(indices.len() % 3, 0);
            assert!(indices.iter().all(|&i| (i as usize) < n), "index range");
            let targets = prim["targets"].as_array().map_or(&[][..], Vec::as_slice);
            assert_eq!(targets.len(), weights, "mesh weights per morph target");
            for t in targets {
                let a = mark(&t["POSITION"], "target position", Some(34962));
                check_bounds(&doc, &bin, a);
                assert_eq!(usize_of(&accessors[a]["count"]), n);
                if !t["NORMAL"].is_null() {
                    let a = mark(&t["NORMAL"], "target normal", Some(34962));
                    assert_eq!(usize_of(&accessors[a]["count"]), n);
                    assert!(!attrs["NORMAL"].is_null(), "NORMAL target without NORMAL");
                }
            }
        }
    }
    // Node tree: every child exists and has one parent; the scene's roots have none.
    let nodes = doc["nodes"].as_array().expect("nodes");
    let mut parent = vec![None; nodes.len()];
    for (i, node) in nodes.iter().enumerate() {
        for c in node["children"].as_array().into_iter().flatten() {
            let c = usize_of(c);
            assert!(c < nodes.len() && parent[c].is_none(), "node {c} parent");
            parent[c] = Some(i);
        }
        if let Some(m) = node.get("mesh") {
            assert!(usize_of(m) < doc["meshes"].as_array().expect("meshes").len());
        }
    }
    for root in doc["scenes"][usize_of(&doc["scene"])]["nodes"]
        .as_array()
        .expect("scene nodes")
    {
        assert!(parent[usize_of(root)].is_none(), "scene root has a parent");
    }
    // One animation; STEP samplers with strictly increasing, non-negative key times.
    let animations = doc["animations"].as_array().expect("animations");
    assert_eq!(animations.len(), 1);
    let anim = &animations[0];
    let samplers = anim["samplers"].as_array().expect("samplers");
    for ch in anim["channels"].as_array().expect("channels") {
        let s = &samplers[usize_of(&ch["sampler"])];
        assert_eq!(s["interpolation"], "STEP");
        let input = mark(&s["input"], "animation input", None);
        let output = mark(&s["output"], "animation output", None);
        check_bounds(&doc, &bin, input);
        let times = accessor(&doc, &bin, input);
        assert!(times[0] >= 0.0 && times.windows(2).all(|w| w[0] < w[1]));
        let node = &nodes[usize_of(&ch["target"]["node"])];
        let per_key = match ch["target"]["path"].as_str().expect("path") {
            "scale" => 3,
            "weights" => {
                let mesh = &doc["meshes"][usize_of(&node["mesh"])];
                mesh["weights"].as_array().expect("weights").len()
            }
            other => panic!("unexpected channel path {other}"),
        };
        assert_eq!(accessor(&doc, &bin, output).len(), times.len() * per_key);
    }
    assert!(
        used_as.iter().all(|u| !u.is_empty()),
        "every accessor is used: {used_as:?}"
    );
    doc
}

fn times_at(fps: f64, n: usize) -> Vec<f64> {
    (0..n).map(|k| k as f64 / fps).collect()
}

#[test]
fn morph_targets_roundtrip_glb_and_gltf() {
    let dir = out_dir();
    let frames = wave_frames(6, false);
    // Irregular times that are not exact in f32, starting after 0.
    let times = [0.1, 0.2, 0.35, 1.0 / 3.0 + 0.1, 0.9, 1.7];
    for name in ["seq.glb", "seq.gltf"] {
        let path = dir.path().join(name);
        write_mesh_sequence(&path, &frames, &times, SequenceLayout::Auto).expect("write");
        let doc = check_structure(&path);
        assert_eq!(doc["meshes"].as_array().expect("meshes").len(), 1);
        let targets = doc["meshes"][0]["primitives"][0]["targets"].as_array();
        assert_eq!(targets.expect("targets").len(), 5);
        assert_eq!(doc["meshes"][0]["extras"]["targetNames"][4], "frame_000005");
        check_morph_roundtrip(&path, &frames, &times);
        // The static reader sees frame 0.
        let rest = read_mesh(&path).expect("static read");
        assert!(max_difference(rest.positions(), frames[0].positions()) <= POSITION_TOLERANCE);
    }
}

#[test]
fn morph_targets_carry_normal_deltas() {
    let dir = out_dir();
    let frames = wave_frames(4, true);
    let times = times_at(30.0, 4);
    let path = dir.path().join("normals.glb");
    write_mesh_sequence(&path, &frames, &times, SequenceLayout::MorphTargets).expect("write");
    let doc = check_structure(&path);
    check_morph_roundtrip(&path, &frames, &times);
    let (_, bin) = load(&path);
    let prim = &doc["meshes"][0]["primitives"][0];
    let base = accessor(&doc, &bin, usize_of(&prim["attributes"]["NORMAL"]));
    for (j, target) in prim["targets"]
        .as_array()
        .expect("targets")
        .iter()
        .enumerate()
    {
        let delta = accessor(&doc, &bin, usize_of(&target["NORMAL"]));
        let want = frames[j + 1].normals().expect("normals");
        for (v, n) in want.iter().enumerate() {
            let n = n.normalize();
            for c in 0..3 {
                let got = base[3 * v + c] + delta[3 * v + c];
                assert!(
                    (got - f64::from(n[c])).abs() < 1e-6,
                    "frame {} vertex {v}",
                    j + 1
                );
            }
        }
    }
}

#[test]
fn node_per_frame_roundtrip_glb_and_gltf() {
    let dir = out_dir();
    let frames = mixed_frames();
    let times = times_at(24.0, frames.len());
    for name in ["nodes.glb", "nodes.gltf"] {
        let path = dir.path().join(name);
        // Auto falls back to one node per frame for mixed topologies.
        write_mesh_sequence(&path, &frames, &times, SequenceLayout::Auto).expect("write");
        let doc = check_structure(&path);
        assert_eq!(
            doc["meshes"].as_array().expect("meshes").len(),
            frames.len()
        );
        assert_eq!(
            doc["nodes"][0]["children"]
                .as_array()
                .expect("children")
                .len(),
            5
        );
        check_node_roundtrip(&path, &frames, &times);
    }
}

#[test]
fn node_per_frame_on_request_for_a_fixed_topology() {
    let dir = out_dir();
    let frames = wave_frames(3, true);
    let times = [0.5, 0.75, 2.0];
    let path = dir.path().join("forced.gltf");
    write_mesh_sequence(&path, &frames, &times, SequenceLayout::NodePerFrame).expect("write");
    let doc = check_structure(&path);
    assert!(doc["meshes"][0]["primitives"][0]["targets"].is_null());
    // Same triangles in every frame: one index accessor for all.
    let indices: Vec<&Value> = (0..3)
        .map(|m| &doc["meshes"][m]["primitives"][0]["indices"])
        .collect();
    assert!(indices.iter().all(|i| *i == indices[0]), "{indices:?}");
    check_node_roundtrip(&path, &frames, &times);
}

/// Runs of frames with one topology (a carried mesh between keys) become one node each,
/// animated by morph targets within the run and shown by a scale track for its frames.
#[test]
fn runs_of_one_topology_share_a_node_with_morph_targets() {
    let dir = out_dir();
    let wave = wave_frames(4, true);
    let moved = |m: &TriMesh, dz: f64| {
        let p: Vec<DVec3> = m.positions().iter().map(|p| *p + DVec3::Z * dz).collect();
        TriMesh::new(p, m.triangles().to_vec())
    };
    // Runs: wave 0..3 | strip 3..5 | empty 5 | strip 6 | wave 7..9.
    let empty = TriMesh::new(Vec::<DVec3>::new(), Vec::new());
    let frames = vec![
        wave[0].clone(),
        wave[1].clone(),
        wave[2].clone(),
        strip(3, 1),
        moved(&strip(3, 1), 0.5),
        empty,
        strip(2, 3),
        wave[3].clone(),
        moved(&wave[3], 0.25),
    ];
    let times = times_at(10.0, frames.len());
    for ext in ["glb", "gltf"] {
        let path = dir.path().join(format!("runs.{ext}"));
        write_mesh_sequence(&path, &frames, &times, SequenceLayout::Auto).expect("write");
        let doc = check_structure(&path);
        let children = doc["nodes"][0]["children"].as_array().expect("children");
        assert_eq!(children.len(), 5, "one node per run");
        let names: Vec<&str> = (1..=5)
            .map(|n| doc["nodes"][n]["name"].as_str().expect("name"))
            .collect();
        assert_eq!(
            names,
            [
                "frame_000000",
                "frame_000003",
                "frame_000005",
                "frame_000006",
                "frame_000007"
            ]
        );
        let targets = |n: usize| {
            let mesh = doc["nodes"][n]["mesh"].as_u64().expect("mesh") as usize;
            doc["meshes"][mesh]["primitives"][0]["targets"]
                .as_array()
                .map_or(0, Vec::len)
        };
        assert_eq!(
            [targets(1), targets(2), targets(4), targets(5)],
            [2, 1, 0, 1]
        );
        assert!(
            doc["nodes"][3]["mesh"].is_null(),
            "the empty frame has no mesh"
        );
        // Every frame's time shows that frame and only it.
        let template = GltfTemplate::open(&path, &Clip::Index(0)).expect("template opens");
        let runs = [0..3, 3..5, 5..6, 6..7, 7..9];
        let mut starts = vec![0];
        for r in &runs {
            starts.push(starts.last().expect("start") + frames[r.start].vertex_count());
        }
        for (k, frame) in frames.iter().enumerate() {
            let run = runs.iter().position(|r| r.contains(&k)).expect("run");
            for t in probe_times(&times, k) {
                let got = template.evaluate_at(t).expect("evaluates");
                for (j, _) in runs.iter().enumerate() {
                    let block = &got[starts[j]..starts[j + 1]];
                    if j == run {
                        let d = max_difference(block, frame.positions());
                        assert!(d <= POSITION_TOLERANCE, "frame {k} at {t} s: off by {d}");
                    } else {
                        assert!(
                            block.iter().all(|p| *p == DVec3::ZERO),
                            "run {j} visible at {t} s (frame {k}'s time)"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn one_frame_and_empty_frames() {
    let dir = out_dir();
    let one = wave_frames(1, false);
    for layout in [SequenceLayout::MorphTargets, SequenceLayout::NodePerFrame] {
        let path = dir.path().join(format!("one_{layout:?}.glb"));
        write_mesh_sequence(&path, &one, &[0.0], layout).expect("write");
        check_structure(&path);
        let template = GltfTemplate::open(&path, &Clip::Index(0)).expect("opens");
        let got = template.evaluate_at(0.0).expect("evaluates");
        assert!(max_difference(&got, one[0].positions()) <= POSITION_TOLERANCE);
    }
    // A frame without triangles (an extraction that found nothing) is a node without a mesh.
    let frames = vec![strip(2, 0), TriMesh::default(), strip(3, 2)];
    let times = times_at(30.0, 3);
    let path = dir.path().join("gap.glb");
    write_mesh_sequence(&path, &frames, &times, SequenceLayout::Auto).expect("write");
    let doc = check_structure(&path);
    assert!(doc["nodes"][2].get("mesh").is_none());
    check_node_roundtrip(&path, &frames, &times);
}

/// 100 frames of 20,000 vertices: both layouts write, stay near the expected size and read
/// back (fast in `--release`).
#[test]
fn hundred_frames_of_twenty_thousand_vertices() {
    let (cols, rows) = (200usize, 100usize);
    let grid = |k: usize| {
        let positions: Vec<Vec3> = (0..rows * cols)
            .map(|i| {
                let (x, y) = ((i % cols) as f32 * 0.01, (i / cols) as f32 * 0.01);
                Vec3::new(x, y, 0.1 * (x * 7.0 + 0.1 * k as f32).sin())
            })
            .collect();
        let mut triangles = Vec::new();
        for r in 0..rows as u32 - 1 {
            for c in 0..cols as u32 - 1 {
                let i = r * cols as u32 + c;
                triangles.push([i, i + 1, i + cols as u32]);
                triangles.push([i + 1, i + cols as u32 + 1, i + cols as u32]);
            }
        }
        TriMesh::new(positions, triangles)
    };
    let frames: Vec<TriMesh> = (0..100).map(grid).collect();
    let times = times_at(30.0, 100);
    let dir = out_dir();
    let vertex_bytes = 100 * rows * cols * 12;
    let index_bytes = frames[0].triangle_count() * 12;
    for (layout, name, expected) in [
        (
            SequenceLayout::Auto,
            "big_morph.glb",
            vertex_bytes + index_bytes,
        ),
        (
            SequenceLayout::NodePerFrame,
            "big_nodes.glb",
            // Consecutive frames with the same triangles share one index accessor.
            vertex_bytes + index_bytes,
        ),
    ] {
        let path: PathBuf = dir.path().join(name);
        write_mesh_sequence(&path, &frames, &times, layout).expect("write");
        let size = std::fs::metadata(&path).expect("metadata").len() as usize;
        assert!(
            size >= expected && size < expected + expected / 100 + 100_000,
            "{name}: {size} bytes, expected about {expected}"
        );
        let template = GltfTemplate::open(&path, &Clip::Index(0)).expect("opens");
        let got = template.evaluate_at(times[57]).expect("evaluates");
        let start = if layout == SequenceLayout::Auto {
            0
        } else {
            57 * rows * cols
        };
        let d = max_difference(&got[start..start + rows * cols], frames[57].positions());
        assert!(d <= POSITION_TOLERANCE, "{name}: off by {d}");
    }
}

fn expect_error(result: Result<(), IoError>, path: &Path, element: &str) {
    let message = result.expect_err("must fail").to_string();
    assert!(message.contains(&path.display().to_string()), "{message}");
    assert!(message.contains(element), "{message} should name {element}");
    assert!(!path.exists(), "nothing is written on error");
}

#[test]
fn bad_sequences_are_errors_naming_the_element() {
    let dir = out_dir();
    let path = dir.path().join("bad.glb");
    let frames = wave_frames(3, false);
    let auto = SequenceLayout::Auto;
    expect_error(write_mesh_sequence(&path, &[], &[], auto), &path, "frames");
    expect_error(
        write_mesh_sequence(&path, &frames, &[0.0, 1.0], auto),
        &path,
        "frame times",
    );
    expect_error(
        write_mesh_sequence(&path, &frames, &[0.0, 1.0, 1.0], auto),
        &path,
        "frame time 2",
    );
    expect_error(
        write_mesh_sequence(&path, &frames, &[0.0, f64::NAN, 2.0], auto),
        &path,
        "frame time 1",
    );
    expect_error(
        write_mesh_sequence(&path, &frames, &[-1.0, 0.0, 1.0], auto),
        &path,
        "frame time 0",
    );
    // Distinct in f64, one f32 key time.
    expect_error(
        write_mesh_sequence(&path, &frames, &[0.0, 1e6, 1e6 + 1e-6], auto),
        &path,
        "frame time 2",
    );
    let mut mixed = wave_frames(3, false);
    mixed[2] = strip(2, 0);
    expect_error(
        write_mesh_sequence(
            &path,
            &mixed,
            &[0.0, 1.0, 2.0],
            SequenceLayout::MorphTargets,
        ),
        &path,
        "frame 2",
    );
    let mut nan = wave_frames(2, false);
    let mut p = nan[1].positions().to_vec();
    p[7] = DVec3::new(0.0, f64::NAN, 0.0);
    nan[1] = TriMesh::new_unchecked(p, nan[1].triangles().to_vec());
    expect_error(
        write_mesh_sequence(&path, &nan, &[0.0, 1.0], auto),
        &path,
        "frame 1 vertex 7",
    );
    let ply = dir.path().join("bad.ply");
    expect_error(
        write_mesh_sequence(&ply, &frames, &[0.0, 1.0, 2.0], auto),
        &ply,
        ".glb",
    );
}

/// An edit that breaks a valid document.
type Breakage = Box<dyn Fn(&mut Value)>;

/// The structural check is not vacuous: a wrong `min`, a misaligned view and a decreasing key
/// time each make it fail.
#[test]
fn structure_check_catches_broken_files() {
    let dir = out_dir();
    let path = dir.path().join("good.gltf");
    let frames = wave_frames(3, false);
    write_mesh_sequence(&path, &frames, &[0.0, 0.5, 1.0], SequenceLayout::Auto).expect("write");
    check_structure(&path);
    let doc: Value = serde_json::from_slice(&std::fs::read(&path).expect("read")).expect("json");
    let input = usize_of(&doc["animations"][0]["samplers"][0]["input"]);
    let breakages: [(&str, Breakage); 3] = [
        (
            "min",
            Box::new(|d| d["accessors"][0]["min"][0] = (-1e3).into()),
        ),
        (
            "alignment",
            Box::new(|d| d["bufferViews"][1]["byteOffset"] = 2.into()),
        ),
        (
            "key times",
            Box::new(move |d| d["accessors"][input]["max"][0] = (-1.0).into()),
        ),
    ];
    for (what, breaking) in breakages {
        let mut broken = doc.clone();
        breaking(&mut broken);
        let bad = dir
            .path()
            .join(format!("bad_{}.gltf", what.replace(' ', "_")));
        std::fs::write(&bad, serde_json::to_vec(&broken).expect("json")).expect("write");
        let caught = std::panic::catch_unwind(|| check_structure(&bad));
        assert!(caught.is_err(), "{what}: the check passed a broken file");
    }
}

/// Frames read one at a time from files (how the main job assembles its `.glb` without holding
/// the frames) give the same bytes as the frames in memory, for both layouts and containers;
/// a frame file that goes missing is an error naming it, and nothing is written.
#[test]
fn frames_from_files_write_the_same_bytes_as_frames_in_memory() {
    let dir = out_dir();
    for (name, frames) in [("wave", wave_frames(5, true)), ("mixed", mixed_frames())] {
        let files: Vec<PathBuf> = frames
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let path = dir.path().join(format!("{name}_{k:03}.ply"));
                write_mesh(&path, f, WriteOptions::default()).expect("write frame");
                path
            })
            .collect();
        let times = times_at(24.0, frames.len());
        for ext in ["glb", "gltf"] {
            for layout in [SequenceLayout::Auto, SequenceLayout::NodePerFrame] {
                let from_memory = dir.path().join(format!("{name}_memory.{ext}"));
                let from_files = dir.path().join(format!("{name}_files.{ext}"));
                write_mesh_sequence(&from_memory, &frames, &times, layout).expect("memory");
                write_sequence(&from_files, &FrameFiles(&files), &times, layout).expect("files");
                let (a, b) = (
                    std::fs::read(&from_memory).expect("read"),
                    std::fs::read(&from_files).expect("read"),
                );
                assert!(a == b, "{name} {ext} {layout:?}: bytes differ");
                check_structure(&from_files);
            }
        }
        let missing = dir.path().join(format!("{name}_gone.glb"));
        let mut gone = files.clone();
        gone[1] = dir.path().join("no_such_frame.ply");
        let err = write_sequence(&missing, &FrameFiles(&gone), &times, SequenceLayout::Auto)
            .expect_err("missing frame");
        assert!(err.to_string().contains("no_such_frame.ply"), "{err}");
        assert!(!missing.exists());
    }
}

/// A sequence over the part size is split into consecutive `.glb` parts, each complete and
/// keeping its frames' own times; under it, one file at the path asked for.
#[test]
fn long_sequences_split_into_parts() {
    use trisplat_geometry::io::write_sequence_parts;
    let dir = out_dir();
    for (name, frames) in [("wave", wave_frames(5, true)), ("mixed", mixed_frames())] {
        let times = times_at(30.0, frames.len());
        let path = dir.path().join(format!("{name}.glb"));
        let one = write_sequence_parts(
            &path,
            &frames.as_slice(),
            &times,
            SequenceLayout::Auto,
            u64::MAX,
        )
        .expect("one file");
        assert_eq!(one, std::slice::from_ref(&path));
        // About two frames per part.
        let frame_bytes = std::fs::metadata(&path).expect("size").len() / frames.len() as u64;
        let parts = write_sequence_parts(
            &path,
            &frames.as_slice(),
            &times,
            SequenceLayout::Auto,
            frame_bytes * 5 / 2,
        )
        .expect("parts");
        assert!(parts.len() >= 2, "{name}: {parts:?}");
        let mut first = 0;
        for (i, part) in parts.iter().enumerate() {
            assert_eq!(
                part.file_name().and_then(|n| n.to_str()),
                Some(format!("{name}_part{:03}.glb", i + 1).as_str())
            );
            let doc = check_structure(part);
            let count = match doc["meshes"][0]["primitives"][0]["targets"].as_array() {
                Some(targets) if name == "wave" => targets.len() + 1,
                _ => doc["nodes"][0]["children"].as_array().map_or(1, Vec::len),
            };
            let run = first..first + count;
            if name == "wave" {
                check_morph_roundtrip(part, &frames[run.clone()], &times[run.clone()]);
            } else {
                check_node_roundtrip(part, &frames[run.clone()], &times[run.clone()]);
            }
            first += count;
        }
        assert_eq!(
            first,
            frames.len(),
            "{name}: every frame in exactly one part"
        );
    }
}

/// The parts writer writes `.glb` only and refuses a frame larger than a part; a source whose
/// frame changes between the writer's readings is an error, and nothing is written.
#[test]
fn sequence_writer_error_paths() {
    use std::cell::Cell;
    use trisplat_geometry::io::{FrameSource, write_sequence_parts};
    let dir = out_dir();
    let frames = wave_frames(3, false);
    let times = times_at(30.0, 3);
    let gltf = dir.path().join("seq.gltf");
    let err = write_sequence_parts(
        &gltf,
        &frames.as_slice(),
        &times,
        SequenceLayout::Auto,
        1 << 30,
    )
    .expect_err("parts are .glb");
    assert!(matches!(err, IoError::Unsupported { .. }), "{err}");
    let glb = dir.path().join("seq.glb");
    let err = write_sequence_parts(&glb, &frames.as_slice(), &times, SequenceLayout::Auto, 1000)
        .expect_err("a frame over the part size");
    assert!(err.to_string().contains("frame 0 alone needs"), "{err}");
    assert!(!glb.exists());

    /// Frame 1 gains a vertex on every reading after the first.
    struct Shifting {
        frames: Vec<TriMesh>,
        reads: Cell<usize>,
    }
    impl FrameSource for Shifting {
        fn frame_count(&self) -> usize {
            self.frames.len()
        }
        fn frame(&self, k: usize) -> Result<std::borrow::Cow<'_, TriMesh>, IoError> {
            if k != 1 {
                return Ok(std::borrow::Cow::Borrowed(&self.frames[k]));
            }
            self.reads.set(self.reads.get() + 1);
            let f = &self.frames[1];
            let mut positions = f.positions().to_vec();
            positions.extend(std::iter::repeat_n(DVec3::ZERO, self.reads.get()));
            Ok(std::borrow::Cow::Owned(TriMesh::new(
                positions,
                f.triangles().to_vec(),
            )))
        }
    }
    let shifting = Shifting {
        frames: mixed_frames(),
        reads: Cell::new(0),
    };
    let times = times_at(30.0, shifting.frames.len());
    let err = write_sequence(&glb, &shifting, &times, SequenceLayout::NodePerFrame)
        .expect_err("frame changed");
    assert!(
        err.to_string()
            .contains("a frame changed while the sequence was written"),
        "{err}"
    );
    assert!(!glb.exists(), "nothing written");
}
