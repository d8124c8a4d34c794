//! Shards merged equal one run, byte for byte (docs/shards.md): whatever a run decides once
//! (here which Gaussians delaunay and alpha mesh) is a function of the whole track, not of
//! the shard's frames. On the LAM fixture driven by a track whose mouth is closed for seven
//! frames and wide open for the last three (exposing Gaussians the closed mouth hides), over
//! several splits.

mod common;

use std::path::{Path, PathBuf};

use trisplat_geometry::io::GltfCompression;
use trisplat_pipeline::config::OutputTarget;
use trisplat_pipeline::{
    ExtractConfig, MergeOutputs, Method, PipelineError, Report, RunControl, Shard, ShardOptions,
    ShardSpec, merge, merge_with, run,
};

/// The LAM fixture driven by `track` (10 frames), meshed by `methods` over `frames` into
/// `out`: frame files and report only.
fn config(track: &Path, methods: &[Method], frames: &str, out: &Path) -> ExtractConfig {
    common::lam_mini_config(track, methods, frames, out)
}

fn extract(track: &Path, methods: &[Method], frames: &str, out: &Path) -> Report {
    let config = config(track, methods, frames, out);
    run(&config, RunControl::default(), &mut |_| {}).expect("run")
}

#[test]
fn any_split_of_the_track_merges_to_one_run() {
    let methods = [Method::Delaunay, Method::Alpha];
    let dir = common::fresh_dir("shards", "lam");
    let track = common::opening_mouth(&dir);
    let whole = dir.join("whole");
    let one = extract(&track, &methods, "0..10", &whole);
    assert_eq!(one.frames, (0..10).collect::<Vec<_>>());
    let used = one.gaussians_used.expect("point methods ran");
    assert!(used.hidden > 0, "the fixture hides Gaussians: {used:?}");
    for split in [
        &["0..5", "5..10"][..],
        &["0..1", "1..4", "4..10"],
        &["0..9", "9..10"],
    ] {
        let name = split.join("_");
        let shards: Vec<PathBuf> = split
            .iter()
            .enumerate()
            .map(|(i, frames)| {
                let out = dir.join(format!("{name}_{i}"));
                let shard = extract(&track, &methods, frames, &out);
                assert_eq!(shard.gaussians_used, one.gaussians_used, "shard {frames}");
                out
            })
            .collect();
        let merged_dir = dir.join(format!("{name}_merged"));
        let merged = merge(&shards, &merged_dir, false).expect("merge");
        assert_eq!(merged.frames, one.frames, "{name}");
        for m in methods {
            for f in 0..10 {
                let file = format!("{}/frame_{f:06}.ply", m.name());
                let a = std::fs::read(whole.join(&file)).expect("one run's frame");
                let b = std::fs::read(merged_dir.join(&file)).expect("merged frame");
                assert!(a == b, "split {name}: {file} differs from one run");
            }
        }
    }
}

/// `report` as JSON with what a shard may not reproduce blanked: wall times, and the
/// incremental Delaunay's statistics (each shard starts with a rebuild).
fn without_timings(report: &Report) -> serde_json::Value {
    let mut r = report.clone();
    r.deform_ms.iter_mut().for_each(|t| *t = 0.0);
    r.thumbnails = None;
    for m in r.methods.values_mut() {
        for f in &mut m.frames {
            f.ms = 0.0;
            f.render_ms = f.render_ms.map(|_| 0.0);
        }
        m.mean = trisplat_pipeline::report::Summary::of(&m.frames);
        m.relation = None;
        m.delaunay = None;
    }
    serde_json::to_value(&r).expect("json")
}

#[test]
fn shard_flags_split_the_track_and_merge_refuses_an_incomplete_split() {
    let methods = [Method::Tsdf, Method::Delaunay, Method::Alpha];
    let dir = common::fresh_dir("shards", "shard_flag");
    let track = common::opening_mouth(&dir);
    let whole = dir.join("whole");
    let mut one = config(&track, &methods, "0..10", &whole);
    one.frames = None;
    one.options.outputs.targets.push(OutputTarget::Glb);
    let one = run(&one, RunControl::default(), &mut |_| {}).expect("one run");
    // Render consistency is measured by default, on every frame and method.
    for m in one.methods.values() {
        assert!(
            m.frames.iter().all(|f| f.consistency.is_some()),
            "{}",
            m.method
        );
        let iou = m.mean.render_iou.expect("mean render IoU");
        // The fixture's 952 Gaussians are sparse: its tsdf mesh covers a quarter of their
        // silhouette (IoU 0.25), delaunay and alpha about 0.65.
        assert!(iou > 0.2 && iou <= 1.0, "{}: {iou}", m.method);
    }
    let shards: Vec<PathBuf> = (0..3)
        .map(|index| {
            let out = dir.join(format!("shard_{index}"));
            let mut c = config(&track, &methods, "0..10", &out);
            c.frames = None;
            c.options.outputs.targets.push(OutputTarget::Glb);
            c.options.shard = ShardOptions {
                shard: Some(ShardSpec::Given(Shard::new(index, 3).expect("shard"))),
                shard_count: None,
            };
            let r = run(&c, RunControl::default(), &mut |_| {}).expect("shard run");
            let expected = [0..3, 3..6, 6..10][index].clone().collect::<Vec<_>>();
            assert_eq!(r.frames, expected, "shard {index}/3");
            out
        })
        .collect();
    // Two of three shards: the missing one is named, and nothing is written.
    let refused_dir = dir.join("incomplete");
    let e = merge(&shards[..2], &refused_dir, false).expect_err("incomplete");
    assert!(
        matches!(&e, PipelineError::Merge { problem, .. } if problem.contains("missing: 2/3")),
        "{e}"
    );
    assert!(
        !refused_dir.exists(),
        "a refused merge wrote its output folder"
    );
    let merged_dir = dir.join("merged");
    let merged = merge(&shards, &merged_dir, false).expect("merge");
    assert_eq!(without_timings(&merged), without_timings(&one));
    for m in methods {
        for f in 0..10 {
            let file = format!("{}/frame_{f:06}.ply", m.name());
            let a = std::fs::read(whole.join(&file)).expect("one run's frame");
            let b = std::fs::read(merged_dir.join(&file)).expect("merged frame");
            assert!(a == b, "{file} differs from one run");
        }
        let glb = format!("{}.glb", m.name());
        let a = std::fs::read(whole.join(&glb)).expect("one run's glb");
        let b = std::fs::read(merged_dir.join(&glb)).expect("merged glb");
        assert!(a == b, "{glb} differs from one run");
    }
    // The job's outputs given to the merge: plain glTF and a USD cache, no frame files.
    let outputs = MergeOutputs {
        targets: vec![OutputTarget::Glb, OutputTarget::Usd],
        gltf_compression: GltfCompression::None,
        gltf_morph_tolerance: 0.0,
        gltf_morph_above: 0.0,
    };
    let plain_dir = dir.join("merged_plain");
    merge_with(&shards, &plain_dir, false, &outputs).expect("merge with outputs");
    for m in methods {
        let glb = std::fs::read(plain_dir.join(format!("{}.glb", m.name()))).expect("glb");
        let json_length = u32::from_le_bytes(glb[12..16].try_into().expect("4 bytes")) as usize;
        let json = String::from_utf8_lossy(&glb[20..20 + json_length]);
        assert!(
            !json.contains("EXT_meshopt_compression"),
            "{}: {json}",
            m.name()
        );
        let meshopt = std::fs::read(merged_dir.join(format!("{}.glb", m.name()))).expect("glb");
        assert!(
            glb.len() > meshopt.len(),
            "{}: plain is not larger",
            m.name()
        );
        let usda =
            std::fs::read_to_string(plain_dir.join(format!("{}.usda", m.name()))).expect("usda");
        assert!(usda.contains("endTimeCode = 9\n"), "{}", m.name());
        assert!(
            !plain_dir.join(m.name()).join("frame_000000.ply").exists(),
            "{}: frame files kept without the meshes target",
            m.name()
        );
    }
    assert!(
        !plain_dir.join("report.json").exists(),
        "report without the report target"
    );
    assert!(
        !plain_dir.join("thumbnails").exists(),
        "thumbnails without the report target"
    );
}
