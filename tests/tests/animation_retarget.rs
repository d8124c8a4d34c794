//! Clips retargeted by joint name (`GltfTemplate::retarget`, `extract --clip-from`): a file's
//! own clip retargeted onto itself plays exactly as the clip does; joints without a namesake
//! are dropped and listed; a source without a clip or without one matching joint is refused.

use std::path::{Path, PathBuf};

use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate};

fn synthetic() -> PathBuf {
    trisplat_fixtures::path("anim/SyntheticFeatures.gltf")
}

/// A copy of SyntheticFeatures (with its buffers) in `dir`, each node named `rename(name)`.
fn renamed(dir: &Path, rename: &dyn Fn(&str) -> String) -> PathBuf {
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(synthetic()).expect("read")).expect("json");
    for node in json["nodes"].as_array_mut().expect("nodes") {
        if let Some(name) = node["name"].as_str() {
            node["name"] = serde_json::Value::String(rename(name));
        }
    }
    // Buffers are embedded or sit beside the file: copy what it refers to.
    for buffer in json["buffers"].as_array().expect("buffers") {
        if let Some(uri) = buffer["uri"].as_str()
            && !uri.starts_with("data:")
        {
            std::fs::copy(synthetic().with_file_name(uri), dir.join(uri)).expect("buffer");
        }
    }
    let path = dir.join("renamed.gltf");
    std::fs::write(&path, json.to_string()).expect("write");
    path
}

#[test]
fn own_clip_retargeted_plays_as_the_clip() {
    let played = GltfTemplate::open(&synthetic(), &Clip::Index(0)).expect("clip");
    let still = GltfTemplate::open(&synthetic(), &Clip::None).expect("still");
    let retargeted = still.retarget(&played).expect("retarget");
    assert!(retargeted.unused_channels().is_empty());
    assert_eq!(retargeted.frame_count(), played.frame_count());
    assert!(played.frame_count() > 2);
    for f in 0..played.frame_count() {
        assert_eq!(
            retargeted.frame(f).expect("retargeted"),
            played.frame(f).expect("played"),
            "frame {f}"
        );
    }
    // Past the clip's end a retargeted clip loops (an idle loop under a long track).
    let end = played.duration();
    assert!((retargeted.clip_time(end * 2.5) - end * 0.5).abs() < 1e-12);
    assert_eq!(played.clip_time(end * 2.5), end * 2.5);
}

#[test]
fn joints_without_a_namesake_are_dropped_and_listed() {
    let dir = tempfile::tempdir().expect("tmp");
    let source = renamed(dir.path(), &|n| {
        if n == "joint2" {
            "jointX".to_owned()
        } else {
            n.to_owned()
        }
    });
    let motion = GltfTemplate::open(&source, &Clip::Index(0)).expect("source");
    let played = GltfTemplate::open(&synthetic(), &Clip::Index(0)).expect("clip");
    let retargeted = GltfTemplate::open(&synthetic(), &Clip::None)
        .expect("still")
        .retarget(&motion)
        .expect("retarget");
    assert_eq!(retargeted.unused_channels(), ["joint:jointX"]);
    // joint2's scale channel is gone: some frame differs from the full clip.
    let differs = (0..played.frame_count())
        .any(|f| retargeted.frame(f).expect("frame") != played.frame(f).expect("frame"));
    assert!(differs);

    // No joint in common, or no clip at all: refused, naming the source.
    let strangers = renamed(dir.path(), &|n| format!("other_{n}"));
    let motion = GltfTemplate::open(&strangers, &Clip::Index(0)).expect("source");
    let e = GltfTemplate::open(&synthetic(), &Clip::None)
        .expect("still")
        .retarget(&motion)
        .expect_err("no namesake");
    assert!(
        e.to_string().contains("renamed.gltf") && e.to_string().contains("named like"),
        "{e}"
    );
    let clipless = GltfTemplate::open(&synthetic(), &Clip::None).expect("still");
    let e = clipless.clone().retarget(&clipless).expect_err("no clip");
    assert!(e.to_string().contains("no animation clip"), "{e}");
}
