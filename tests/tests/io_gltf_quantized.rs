//! Quantised and meshopt-compressed glTF sequences (`GltfCompression::Quantize` / `Meshopt`),
//! read back by an independent decoder: the `meshopt` crate's own decoders for the compressed
//! views (whose decoded bytes must equal the `Quantize` file's buffer exactly), and a small
//! glTF evaluator here (STEP channels, node transforms, `SHORT` positions plus morph deltas,
//! normalised `BYTE` normals) that must reproduce every frame within the documented bound,
//! `sqrt(3) / 2 / 16384` of the sequence's bounding-box diagonal. The real clients (the Khronos
//! validator, three.js) run in `tests/reference/gltf_clients`.

use std::path::Path;

use base64::Engine as _;
use glam::{DVec3, Vec3};
use serde_json::Value;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{
    GltfCompression, MorphBasis, SequenceLayout, SequenceOptions, write_sequence_with,
};

/// The documented position bound, as a fraction of the sequence's bounding-box diagonal.
const BOUND: f64 = 0.866_025_4 / 16384.0;

/// `n` frames of Spot moved by a smooth wave (one topology), with vertex normals.
fn wave(n: usize) -> Vec<TriMesh> {
    let base = trisplat_fixtures::spot().expect("spot fixture");
    (0..n)
        .map(|k| {
            let phase = 0.7 * k as f64;
            let p: Vec<DVec3> = base
                .positions()
                .iter()
                .map(|p| {
                    *p + 0.05
                        * DVec3::new(
                            (3.0 * p.y + phase).sin(),
                            (2.0 * p.z).cos() * phase.sin(),
                            0.0,
                        )
                })
                .collect();
            let mesh = TriMesh::new(p, base.triangles().to_vec());
            let normals = mesh.vertex_normals();
            mesh.with_normals(normals).expect("normals")
        })
        .collect()
}

/// Frames of three topologies: two waves of Spot, a strip, Spot moved (runs of 2, 1, 1).
fn mixed() -> Vec<TriMesh> {
    let mut frames = wave(2);
    let strip = TriMesh::new(
        vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.3)],
        vec![[0, 1, 2], [2, 1, 3]],
    );
    frames.push(strip);
    frames.push(wave(4).pop().expect("frame"));
    frames
}

/// A written file: its JSON and every buffer view's bytes as the accessors read them (meshopt
/// views decoded).
struct Decoded {
    json: Value,
    /// The data a client reads: buffer 0, or the fallback buffer rebuilt from the compressed
    /// views.
    data: Vec<u8>,
}

fn glb_chunks(bytes: &[u8]) -> (Value, Vec<u8>) {
    assert_eq!(&bytes[..4], b"glTF");
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().expect("len")) as usize;
    let json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).expect("json");
    let bin_start = 20 + json_len + 8;
    (json, bytes[bin_start..].to_vec())
}

fn decode(path: &Path) -> Decoded {
    let bytes = std::fs::read(path).expect("read");
    let (json, bin) = if path.extension().is_some_and(|e| e == "glb") {
        glb_chunks(&bytes)
    } else {
        let json: Value = serde_json::from_slice(&bytes).expect("json");
        let uri = json["buffers"][0]["uri"].as_str().expect("data uri");
        let b64 = uri.split_once(',').expect("comma").1;
        let bin = base64::engine::general_purpose::STANDARD
            .decode(b64)
            .expect("base64");
        (json, bin)
    };
    let used: Vec<&str> = json["extensionsUsed"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default();
    let required = json["extensionsRequired"].clone();
    assert_eq!(
        json["extensionsUsed"], required,
        "every extension used is required"
    );
    if !used.contains(&"EXT_meshopt_compression") {
        return Decoded { json, data: bin };
    }
    let fallback = &json["buffers"][1];
    assert!(fallback["uri"].is_null(), "the fallback buffer has no data");
    assert_eq!(
        fallback["extensions"]["EXT_meshopt_compression"]["fallback"],
        true
    );
    let mut data = vec![0u8; fallback["byteLength"].as_u64().expect("len") as usize];
    for (i, view) in json["bufferViews"]
        .as_array()
        .expect("views")
        .iter()
        .enumerate()
    {
        assert_eq!(view["buffer"], 1, "view {i} points at the fallback buffer");
        let ext = &view["extensions"]["EXT_meshopt_compression"];
        assert_eq!(ext["buffer"], 0);
        let at = |v: &Value| v.as_u64().expect("number") as usize;
        let (offset, len) = (at(&ext["byteOffset"]), at(&ext["byteLength"]));
        assert_eq!(offset % 4, 0, "view {i}: compressed data aligned");
        let (stride, count) = (at(&ext["byteStride"]), at(&ext["count"]));
        assert_eq!(
            stride * count,
            at(&view["byteLength"]),
            "view {i}: stride x count"
        );
        let encoded = &bin[offset..offset + len];
        let decoded: Vec<u8> = match ext["mode"].as_str() {
            Some("ATTRIBUTES") => {
                assert_eq!(encoded[0], 0xa0, "view {i}: vertex codec version 0");
                assert_eq!(stride % 4, 0);
                decode_attributes(encoded, count, stride)
            }
            Some("TRIANGLES") => {
                assert_eq!(encoded[0], 0xe1, "view {i}: index codec version 1");
                if stride == 2 {
                    meshopt::decode_index_buffer::<u16>(encoded, count)
                        .expect("indices")
                        .iter()
                        .flat_map(|x| x.to_le_bytes())
                        .collect()
                } else {
                    meshopt::decode_index_buffer::<u32>(encoded, count)
                        .expect("indices")
                        .iter()
                        .flat_map(|x| x.to_le_bytes())
                        .collect()
                }
            }
            other => panic!("view {i}: mode {other:?}"),
        };
        let start = at(&view["byteOffset"]);
        data[start..start + decoded.len()].copy_from_slice(&decoded);
    }
    Decoded { json, data }
}

fn decode_attributes(encoded: &[u8], count: usize, stride: usize) -> Vec<u8> {
    macro_rules! typed {
        ($n:literal) => {
            meshopt::decode_vertex_buffer::<[u8; $n]>(encoded, count)
                .expect("attributes")
                .concat()
        };
    }
    match stride {
        4 => typed!(4),
        8 => typed!(8),
        12 => typed!(12),
        16 => typed!(16),
        s => panic!("stride {s}"),
    }
}

impl Decoded {
    /// A copy with every triangle's indices rotated to start at its smallest (meshopt's index
    /// codec keeps the triangles and their winding, not always their first corner).
    fn canonical(&self) -> Self {
        let mut data = self.data.clone();
        for acc in self.json["accessors"].as_array().expect("accessors") {
            let view =
                &self.json["bufferViews"][acc["bufferView"].as_u64().expect("view") as usize];
            if view["target"] != 34963 {
                continue;
            }
            let size = if acc["componentType"] == 5123 { 2 } else { 4 };
            let start = view["byteOffset"].as_u64().unwrap_or(0) as usize;
            let len = view["byteLength"].as_u64().expect("len") as usize;
            for tri in data[start..start + len].chunks_exact_mut(3 * size) {
                let read = |c: usize| {
                    let mut b = [0u8; 4];
                    b[..size].copy_from_slice(&tri[c * size..(c + 1) * size]);
                    u32::from_le_bytes(b)
                };
                let t = [read(0), read(1), read(2)];
                let first = (0..3).min_by_key(|&c| t[c]).expect("corner");
                for c in 0..3 {
                    let v = t[(first + c) % 3].to_le_bytes();
                    tri[c * size..(c + 1) * size].copy_from_slice(&v[..size]);
                }
            }
        }
        Self {
            json: self.json.clone(),
            data,
        }
    }

    /// Accessor `a`'s elements as f64 (normalised integers mapped as glTF says).
    fn accessor(&self, a: &Value) -> Vec<Vec<f64>> {
        let acc = &self.json["accessors"][a.as_u64().expect("index") as usize];
        let view = &self.json["bufferViews"][acc["bufferView"].as_u64().expect("view") as usize];
        let width = match acc["type"].as_str() {
            Some("SCALAR") => 1,
            Some("VEC2") => 2,
            Some("VEC3") => 3,
            _ => 4,
        };
        let (size, normalized) = (
            match acc["componentType"].as_u64() {
                Some(5120 | 5121) => 1,
                Some(5122 | 5123) => 2,
                _ => 4,
            },
            acc["normalized"].as_bool().unwrap_or(false),
        );
        let stride = view["byteStride"]
            .as_u64()
            .map_or(size * width, |s| s as usize);
        let base = view["byteOffset"].as_u64().unwrap_or(0) as usize;
        let count = acc["count"].as_u64().expect("count") as usize;
        (0..count)
            .map(|e| {
                (0..width)
                    .map(|c| {
                        let o = base + e * stride + c * size;
                        let b = &self.data[o..o + size];
                        match acc["componentType"].as_u64() {
                            Some(5120) => {
                                let x = f64::from(i8::from_le_bytes([b[0]]));
                                if normalized { (x / 127.0).max(-1.0) } else { x }
                            }
                            Some(5122) => {
                                let x = f64::from(i16::from_le_bytes([b[0], b[1]]));
                                assert!(!normalized);
                                x
                            }
                            Some(5123) => f64::from(u16::from_le_bytes([b[0], b[1]])),
                            Some(5125) => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                            _ => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// The value of animation channel targets `(node, path)` at time `t` (STEP), if animated.
    fn animated(&self, node: usize, path: &str, t: f64) -> Option<Vec<f64>> {
        let anim = &self.json["animations"][0];
        let channel = anim["channels"].as_array()?.iter().find(|c| {
            c["target"]["node"].as_u64() == Some(node as u64) && c["target"]["path"] == path
        })?;
        let sampler = &anim["samplers"][channel["sampler"].as_u64()? as usize];
        assert_eq!(sampler["interpolation"], "STEP");
        let times = self.accessor(&sampler["input"]);
        let values: Vec<f64> = self.accessor(&sampler["output"]).concat();
        let k = times.iter().rposition(|x| x[0] <= t).unwrap_or(0);
        let per_key = values.len() / times.len();
        Some(values[k * per_key..(k + 1) * per_key].to_vec())
    }

    /// The world positions and normals of the visible mesh at time `t`.
    fn visible(&self, t: f64) -> (Vec<DVec3>, Option<Vec<Vec3>>) {
        let nodes = self.json["nodes"].as_array().expect("nodes");
        let mut found = Vec::new();
        // Depth-first from the root with (translation, uniform scale) so far.
        let mut stack = vec![(0usize, DVec3::ZERO, 1.0f64)];
        while let Some((n, offset, scale)) = stack.pop() {
            let node = &nodes[n];
            let s = self.animated(n, "scale", t).map_or_else(
                || {
                    node["scale"]
                        .as_array()
                        .map_or(1.0, |s| s[0].as_f64().expect("s"))
                },
                |v| v[0],
            );
            let tr = node["translation"].as_array().map_or(DVec3::ZERO, |v| {
                DVec3::new(
                    v[0].as_f64().expect("x"),
                    v[1].as_f64().expect("y"),
                    v[2].as_f64().expect("z"),
                )
            });
            let (offset, scale) = (offset + scale * tr, scale * s);
            if scale == 0.0 {
                continue;
            }
            if let Some(m) = node["mesh"].as_u64() {
                found.push((n, m as usize, offset, scale));
            }
            for c in node["children"].as_array().into_iter().flatten() {
                stack.push((c.as_u64().expect("child") as usize, offset, scale));
            }
        }
        assert_eq!(found.len(), 1, "one visible mesh at {t} s");
        let (n, m, offset, scale) = found[0];
        let primitive = &self.json["meshes"][m]["primitives"][0];
        let mut p = self.accessor(&primitive["attributes"]["POSITION"]);
        let mut normals = primitive["attributes"]
            .get("NORMAL")
            .map(|a| self.accessor(a));
        if let Some(weights) = self.animated(n, "weights", t) {
            for (j, w) in weights.iter().enumerate().filter(|(_, w)| **w != 0.0) {
                let target = &primitive["targets"][j];
                for (v, d) in p.iter_mut().zip(self.accessor(&target["POSITION"])) {
                    (0..3).for_each(|c| v[c] += w * d[c]);
                }
                if let (Some(ns), Some(a)) = (normals.as_mut(), target.get("NORMAL")) {
                    for (v, d) in ns.iter_mut().zip(self.accessor(a)) {
                        (0..3).for_each(|c| v[c] += w * d[c]);
                    }
                }
            }
        }
        let positions = p
            .iter()
            .map(|v| offset + scale * DVec3::new(v[0], v[1], v[2]))
            .collect();
        let normals = normals.map(|ns| {
            ns.iter()
                .map(|v| Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32).normalize_or_zero())
                .collect()
        });
        (positions, normals)
    }
}

/// The diagonal of the bounding box of every vertex of `frames`.
fn diagonal(frames: &[TriMesh]) -> f64 {
    let (lo, hi) = frames
        .iter()
        .flat_map(|f| f.positions())
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    (hi - lo).length()
}

/// Every frame at its time: positions within the bound (and not exact: quantised), normals
/// within a few degrees.
fn check_frames(file: &Decoded, frames: &[TriMesh], times: &[f64]) {
    check_frames_of(file, frames, times, diagonal(frames));
}

/// [`check_frames`] for `frames` of a sequence whose diagonal is `diag`.
fn check_frames_of(file: &Decoded, frames: &[TriMesh], times: &[f64], diag: f64) {
    let mut worst = 0.0f64;
    for (k, frame) in frames.iter().enumerate() {
        let (got, normals) = file.visible(times[k]);
        assert_eq!(got.len(), frame.vertex_count(), "frame {k}: vertex count");
        for (a, b) in got.iter().zip(frame.positions()) {
            worst = worst.max((*a - *b).length() / diag);
        }
        if let (Some(got), Some(want)) = (normals, frame.normals()) {
            for (v, (a, b)) in got.iter().zip(want).enumerate() {
                let cos = a.dot(b.normalize());
                assert!(cos > 0.99, "frame {k} vertex {v}: normal {a} for {b}");
            }
        }
    }
    assert!(
        worst <= BOUND * 1.001,
        "a vertex is {worst:e} of the diagonal off, bound {BOUND:e}"
    );
    assert!(
        worst > BOUND / 100.0,
        "quantised positions should not be exact ({worst:e})"
    );
}

fn write(
    dir: &Path,
    name: &str,
    frames: &[TriMesh],
    times: &[f64],
    layout: SequenceLayout,
    compression: GltfCompression,
) -> std::path::PathBuf {
    let path = dir.join(name);
    write_sequence_with(
        &path,
        &frames,
        times,
        &SequenceOptions {
            layout,
            compression,
            morph_basis: MorphBasis::OFF,
        },
    )
    .expect("write");
    path
}

#[test]
fn meshopt_decodes_to_the_quantized_buffer_and_reproduces_every_frame() {
    let dir = tempfile::tempdir().expect("folder");
    for (frames, layout) in [
        (wave(5), SequenceLayout::Auto),
        (wave(3), SequenceLayout::NodePerFrame),
        (mixed(), SequenceLayout::Auto),
    ] {
        let times: Vec<f64> = (0..frames.len()).map(|k| k as f64 / 30.0).collect();
        let plain = decode(&write(
            dir.path(),
            "q.glb",
            &frames,
            &times,
            layout,
            GltfCompression::Quantize,
        ));
        assert_eq!(
            plain.json["extensionsRequired"],
            serde_json::json!(["KHR_mesh_quantization"])
        );
        check_frames(&plain, &frames, &times);
        for name in ["m.glb", "m.gltf"] {
            let packed_path = write(
                dir.path(),
                name,
                &frames,
                &times,
                layout,
                GltfCompression::Meshopt,
            );
            let packed = decode(&packed_path);
            assert_eq!(
                packed.json["extensionsRequired"],
                serde_json::json!(["EXT_meshopt_compression", "KHR_mesh_quantization"])
            );
            let (packed, plain) = (packed.canonical(), plain.canonical());
            let first = packed
                .data
                .iter()
                .zip(&plain.data)
                .position(|(a, b)| a != b);
            assert!(
                packed.data == plain.data,
                "{layout:?} {name}: decoded views differ from the quantised buffer \
                 ({} and {} bytes, first difference at {first:?})",
                packed.data.len(),
                plain.data.len()
            );
            check_frames(&packed, &frames, &times);
            check_frames(&plain, &frames, &times);
        }
        let packed = std::fs::metadata(dir.path().join("m.glb"))
            .expect("size")
            .len();
        let quantized = std::fs::metadata(dir.path().join("q.glb"))
            .expect("size")
            .len();
        assert!(
            packed < quantized,
            "{layout:?}: compressed {packed} >= quantised {quantized}"
        );
    }
}

#[test]
fn small_meshes_index_with_u16_and_spot_positions_as_short() {
    let dir = tempfile::tempdir().expect("folder");
    let frames = wave(2);
    let file = decode(&write(
        dir.path(),
        "s.glb",
        &frames,
        &[0.0, 1.0],
        SequenceLayout::Auto,
        GltfCompression::Meshopt,
    ));
    let primitive = &file.json["meshes"][0]["primitives"][0];
    let accessor = |a: &Value| &file.json["accessors"][a.as_u64().expect("index") as usize];
    assert_eq!(accessor(&primitive["indices"])["componentType"], 5123);
    assert_eq!(
        accessor(&primitive["attributes"]["POSITION"])["componentType"],
        5122
    );
    assert_eq!(
        accessor(&primitive["attributes"]["NORMAL"])["componentType"],
        5120
    );
    assert_eq!(
        accessor(&primitive["attributes"]["NORMAL"])["normalized"],
        true
    );
    assert_eq!(
        accessor(&primitive["targets"][0]["POSITION"])["componentType"],
        5122
    );
    // The mesh is on a leaf whose uniform scale is the grid step.
    let leaf = &file.json["nodes"][1];
    let s = leaf["scale"][0].as_f64().expect("scale");
    assert!(
        (s * 16384.0 / diagonal(&frames) - 1.0).abs() < 1e-6,
        "step {s}"
    );
}

/// Compressed, a sequence whose plain size needs parts is first tried as one file: kept when its
/// compressed buffer fits, else cut into parts by the plain sizes, each a complete file.
#[test]
fn compressed_parts_only_when_the_compressed_buffer_does_not_fit() {
    use trisplat_geometry::io::write_sequence_parts_with;
    let dir = tempfile::tempdir().expect("folder");
    let frames = wave(24);
    let times: Vec<f64> = (0..frames.len()).map(|k| k as f64 / 30.0).collect();
    let options = SequenceOptions {
        layout: SequenceLayout::Auto,
        compression: GltfCompression::Meshopt,
        morph_basis: MorphBasis::OFF,
    };
    // One frame's plain bound: positions, normals (24 bytes a vertex), indices, keys.
    let frame_bytes = (24 * frames[0].vertex_count() + 12 * frames[0].triangle_count() + 64) as u64;
    let path = dir.path().join("one.glb");
    let written = write_sequence_parts_with(
        &path,
        &frames.as_slice(),
        &times,
        &options,
        30 * frame_bytes,
    )
    .expect("one file");
    assert_eq!(
        written,
        std::slice::from_ref(&path),
        "the compressed sequence fits in one file"
    );
    check_frames(&decode(&path), &frames, &times);
    let compressed = std::fs::metadata(&path).expect("size").len();
    assert!(compressed < 30 * frame_bytes);
    // A limit below the compressed size but above one frame: parts of the plain cut.
    let limit = frame_bytes + frame_bytes / 2;
    assert!(
        compressed > limit,
        "the test needs a sequence that compresses to over {limit}"
    );
    let path = dir.path().join("cut.glb");
    let parts = write_sequence_parts_with(&path, &frames.as_slice(), &times, &options, limit)
        .expect("parts");
    assert!(parts.len() > 1, "{} parts under {limit} bytes", parts.len());
    assert!(!path.exists(), "no whole file when it does not fit");
    let mut first = 0;
    for part in &parts {
        let file = decode(part);
        let count = file.json["animations"][0]["samplers"][0]["input"]
            .as_u64()
            .map(|a| {
                file.json["accessors"][a as usize]["count"]
                    .as_u64()
                    .expect("count")
            })
            .expect("keys") as usize;
        let run = first..first + count;
        check_frames_of(&file, &frames[run.clone()], &times[run], diagonal(&frames));
        first += count;
    }
    assert_eq!(first, frames.len(), "the parts hold every frame once");
}

/// Frames that change between the survey and the writing (a frame file rewritten meanwhile).
struct Changing {
    frames: Vec<TriMesh>,
    reads: std::sync::atomic::AtomicUsize,
}

impl trisplat_geometry::io::FrameSource for Changing {
    fn frame_count(&self) -> usize {
        self.frames.len()
    }

    fn frame(
        &self,
        k: usize,
    ) -> Result<std::borrow::Cow<'_, TriMesh>, trisplat_geometry::io::IoError> {
        let reads = self.reads.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        // After the survey's reading of every frame, frame 1 loses its last vertex.
        if k == 1 && reads >= self.frames.len() {
            let f = &self.frames[1];
            let n = f.vertex_count() - 1;
            let triangles: Vec<[u32; 3]> = f
                .triangles()
                .iter()
                .filter(|t| t.iter().all(|&v| (v as usize) < n))
                .copied()
                .collect();
            return Ok(std::borrow::Cow::Owned(TriMesh::new(
                f.positions()[..n].to_vec(),
                triangles,
            )));
        }
        Ok(std::borrow::Cow::Borrowed(&self.frames[k]))
    }
}

#[test]
fn a_frame_changed_while_writing_is_an_error_and_nothing_is_left() {
    let dir = tempfile::tempdir().expect("folder");
    for compression in [GltfCompression::Quantize, GltfCompression::Meshopt] {
        let source = Changing {
            frames: wave(3),
            reads: 0.into(),
        };
        let path = dir.path().join("changed.glb");
        let options = SequenceOptions {
            layout: SequenceLayout::Auto,
            compression,
            morph_basis: MorphBasis::OFF,
        };
        let err = write_sequence_with(&path, &source, &[0.0, 1.0, 2.0], &options)
            .expect_err("a changed frame");
        let message = err.to_string();
        assert!(
            message.contains("changed.glb") && message.contains("frame 1"),
            "{compression:?}: {message}"
        );
        let left: Vec<_> = std::fs::read_dir(dir.path()).expect("list").collect();
        assert!(
            left.is_empty(),
            "{compression:?}: {} files left",
            left.len()
        );
    }
}

/// `wave(n)` without normals (a morph basis is fitted only then), and each frame's own
/// bounding-box diagonal.
fn wave_points(n: usize) -> Vec<TriMesh> {
    wave(n)
        .into_iter()
        .map(|f| TriMesh::new(f.positions().to_vec(), f.triangles().to_vec()))
        .collect()
}

/// The largest distance of a vertex of any frame from its place, as a fraction of that
/// frame's own bounding-box diagonal (what the glTF clients check), evaluated independently.
fn worst_relative(file: &Decoded, frames: &[TriMesh], times: &[f64]) -> f64 {
    let mut worst = 0.0f64;
    for (k, frame) in frames.iter().enumerate() {
        let (got, _) = file.visible(times[k]);
        assert_eq!(got.len(), frame.vertex_count(), "frame {k}: vertex count");
        let diag = diagonal(std::slice::from_ref(frame));
        for (a, b) in got.iter().zip(frame.positions()) {
            worst = worst.max((*a - *b).length() / diag);
        }
    }
    worst
}

/// Writes `frames` as one glb within the part limit and returns the writer's summary.
fn write_summarised(
    path: &std::path::Path,
    frames: &[TriMesh],
    times: &[f64],
    options: &SequenceOptions,
) -> trisplat_geometry::io::SequenceSummary {
    use trisplat_geometry::io::{GLB_PART_LIMIT, write_sequence_parts_summarised};
    write_sequence_parts_summarised(path, &frames, times, options, GLB_PART_LIMIT).expect("write")
}

#[test]
fn a_morph_basis_reproduces_every_frame_within_its_tolerance() {
    let dir = tempfile::tempdir().expect("folder");
    // The wave spans three shapes (x: sin and cos of 3y, y: cos 2z) over 40 frames; two hold
    // it within the tolerance.
    let frames = wave_points(40);
    let times: Vec<f64> = (0..frames.len()).map(|k| k as f64 / 30.0).collect();
    let options = SequenceOptions::default();
    assert!(options.morph_basis.enabled(), "the basis is the default");
    let path = dir.path().join("basis.glb");
    let summary = write_summarised(&path, &frames, &times, &options);
    let file = decode(&path);
    let targets = file.json["meshes"][0]["primitives"][0]["targets"]
        .as_array()
        .expect("targets")
        .len();
    assert!((2..=6).contains(&targets), "{targets} basis vectors");
    assert_eq!(
        file.json["meshes"][0]["extras"]["targetNames"][0],
        "basis_000"
    );
    assert_eq!(summary.segments.len(), 1);
    let run = &summary.segments[0];
    assert_eq!(run.basis, Some(targets));
    assert_eq!(run.frame_errors.len(), frames.len());
    let tolerance = options.morph_basis.tolerance;
    let worst = worst_relative(&file, &frames, &times);
    assert!(
        worst <= tolerance,
        "{worst:e} over the tolerance {tolerance:e}"
    );
    // The writer's own measure is what an independent evaluator finds (f32 arithmetic apart).
    let reported = run.max_error / run.diagonal;
    assert!(
        (reported - worst).abs() <= 1e-3 * tolerance + 0.02 * worst,
        "reported {reported:e}, evaluated {worst:e}"
    );
    // Smaller than one target per frame, and byte-identical when written again.
    let per_frame = dir.path().join("per_frame.glb");
    let off = SequenceOptions {
        morph_basis: MorphBasis::OFF,
        ..SequenceOptions::default()
    };
    write_sequence_with(&per_frame, &frames.as_slice(), &times, &off).expect("write");
    let (a, b) = (
        std::fs::metadata(&path).expect("basis").len(),
        std::fs::metadata(&per_frame).expect("per frame").len(),
    );
    assert!(a < b, "basis {a} bytes, per-frame targets {b}");
    let again = dir.path().join("again.glb");
    write_sequence_with(&again, &frames.as_slice(), &times, &options).expect("write");
    assert_eq!(std::fs::read(&path).ok(), std::fs::read(&again).ok());
}

#[test]
fn frames_a_basis_cannot_hold_keep_one_target_per_frame() {
    let dir = tempfile::tempdir().expect("folder");
    // Every frame moves each vertex its own way (no shared shape): a basis needs a vector per
    // frame, so the writer keeps one target per frame.
    let base = wave_points(1).pop().expect("frame");
    let frames: Vec<TriMesh> = (0..6u64)
        .map(|k| {
            let mut rng = trisplat_geometry::rng::Rng::new(k + 1);
            let p = base
                .positions()
                .iter()
                .map(|p| {
                    *p + 0.02
                        * DVec3::new(
                            rng.uniform_f64() - 0.5,
                            rng.uniform_f64() - 0.5,
                            rng.uniform_f64(),
                        )
                })
                .collect();
            TriMesh::new(p, base.triangles().to_vec())
        })
        .collect();
    let times: Vec<f64> = (0..frames.len()).map(|k| k as f64).collect();
    let path = dir.path().join("noise.glb");
    let summary = write_summarised(&path, &frames, &times, &SequenceOptions::default());
    assert_eq!(summary.segments[0].basis, None);
    let file = decode(&path);
    assert_eq!(
        file.json["meshes"][0]["extras"]["targetNames"][0],
        "frame_000001"
    );
    check_frames(&file, &frames, &times);
}

#[test]
fn the_basis_is_fitted_only_for_a_file_over_its_payload_threshold() {
    let dir = tempfile::tempdir().expect("folder");
    let frames = wave_points(40);
    let times: Vec<f64> = (0..frames.len()).map(|k| k as f64 / 30.0).collect();
    // One target per frame after the first: 8 bytes per vertex and frame.
    let payload = 8 * (frames.len() as u64 - 1) * frames[0].vertex_count() as u64;
    let write = |name: &str, min_payload: u64| {
        let options = SequenceOptions {
            morph_basis: MorphBasis {
                min_payload,
                ..MorphBasis::default()
            },
            ..SequenceOptions::default()
        };
        let path = dir.path().join(name);
        let summary = write_summarised(&path, &frames, &times, &options);
        assert_eq!(summary.target_payload, payload, "{name}");
        assert_eq!(
            options.morph_basis.applies_to(payload),
            payload > min_payload
        );
        (
            summary.segments[0].basis,
            std::fs::read(&path).expect("glb"),
        )
    };
    let (over, basis_bytes) = write("over.glb", payload - 1);
    assert!(over.is_some(), "a payload over the threshold gets a basis");
    let (at, at_bytes) = write("at.glb", payload);
    assert_eq!(
        at, None,
        "a payload at the threshold keeps one target per frame"
    );
    let off = dir.path().join("off.glb");
    let plain = SequenceOptions {
        morph_basis: MorphBasis::OFF,
        ..SequenceOptions::default()
    };
    write_sequence_with(&off, &frames.as_slice(), &times, &plain).expect("write");
    assert_eq!(
        Some(at_bytes),
        std::fs::read(&off).ok(),
        "as with the basis off"
    );
    assert_ne!(basis_bytes, std::fs::read(&off).expect("off"));
}
