//! What the LAM-fixture tests share: a track that opens the mouth, fresh folders, and the
//! fixture's run configuration. Each test binary uses some of them.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use trisplat_pipeline::avatar::AvatarFolder;
use trisplat_pipeline::config::{BindOptions, GaussianLayout, OutputOptions, OutputTarget};
use trisplat_pipeline::{ExtractConfig, ExtractOptions, Method};

/// A 10-frame weights track for the fixture's targets: the mouth closed in frames 0..7, the
/// jaw open and the tongue out in frames 7..10.
pub fn opening_mouth(dir: &Path) -> PathBuf {
    let frames: Vec<String> = (0..10)
        .map(|i| {
            let open = if i < 7 { 0 } else { 1 };
            format!(
                r#"{{"weights": [{open}, 0, 0, {open}], "time": {}, "rotation": []}}"#,
                f64::from(i) / 30.0
            )
        })
        .collect();
    let text = format!(
        r#"{{"names": ["jawOpen", "mouthSmileLeft", "eyeBlinkLeft", "tongueOut"], "frames": [{}]}}"#,
        frames.join(", ")
    );
    let path = dir.join("opening_mouth.json");
    std::fs::write(&path, text).expect("track");
    path
}

/// A fresh folder `group/name` under the target directory.
pub fn fresh_dir(group: &str, name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(group)
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    dir
}

/// The LAM fixture meshed by `methods` over `frames` of `track` into `out`: frame files and
/// the report, every other option at its default (the tests set what they are about).
pub fn lam_mini_config(
    track: &Path,
    methods: &[Method],
    frames: &str,
    out: &Path,
) -> ExtractConfig {
    let avatar = AvatarFolder::open(&trisplat_fixtures::path("lam_mini")).expect("fixture");
    ExtractConfig {
        template: avatar.template,
        animation: Some(track.display().to_string()),
        gaussians: Some(avatar.gaussians),
        methods: methods.to_vec(),
        output: out.to_path_buf(),
        frames: Some(frames.to_owned()),
        gt: None,
        options: ExtractOptions {
            bind: BindOptions {
                layout: GaussianLayout::Lam,
                ..BindOptions::default()
            },
            outputs: OutputOptions {
                targets: vec![OutputTarget::Meshes, OutputTarget::Report],
                ..OutputOptions::default()
            },
            ..ExtractOptions::default()
        },
    }
}
