//! The glTF and USD cache of a carried track made from the run's carried frames (module
//! `carried_frames`), not read back from frame files: byte-identical to the files assembled
//! from the frame files, with no frame file written when the `meshes` target is not asked,
//! and the same bytes after a resume (frames done by an earlier process placed again, a run
//! whose frames were all done replaying the keys at the end). On the LAM fixture driven by a
//! track whose mouth opens at frame 7 (a second key).

mod common;

use std::path::{Path, PathBuf};

use trisplat_geometry::io::{
    FrameFiles, GLB_PART_LIMIT, SequenceLayout, SequenceOptions, write_sequence_parts_with,
    write_usd_sequence,
};
use trisplat_pipeline::config::{OutputOptions, OutputTarget};
use trisplat_pipeline::{ExtractConfig, Method, Report, RunControl, Topology, run};

const METHODS: [Method; 3] = [Method::Tsdf, Method::Delaunay, Method::Alpha];

fn config(track: &Path, frames: &str, targets: &[OutputTarget], out: &Path) -> ExtractConfig {
    let mut config = common::lam_mini_config(track, &METHODS, frames, out);
    config.options.outputs.targets = targets.to_vec();
    config.options.metrics.consistency_views = 0;
    config.options.topology.topology = Topology::Adaptive;
    config
}

fn extract(
    track: &Path,
    frames: &str,
    targets: &[OutputTarget],
    out: &Path,
    resume: bool,
) -> Report {
    let control = RunControl {
        resume,
        ..RunControl::default()
    };
    run(&config(track, frames, targets, out), control, &mut |_| {}).expect("run")
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn frame_files(out: &Path, m: Method, frames: std::ops::Range<usize>) -> Vec<PathBuf> {
    frames
        .map(|f| out.join(m.name()).join(format!("frame_{f:06}.ply")))
        .collect()
}

fn ply_count(out: &Path, m: Method) -> usize {
    std::fs::read_dir(out.join(m.name()))
        .map(|d| {
            d.flatten()
                .filter(|e| e.file_name().to_string_lossy().ends_with(".ply"))
                .count()
        })
        .unwrap_or(0)
}

#[test]
fn carried_sequences_equal_those_assembled_from_frame_files_and_resume() {
    use OutputTarget::{Glb, Meshes, Report as Rep, Usd};
    let dir = common::fresh_dir("carried_frames", "sequences");
    let track = common::opening_mouth(&dir);
    let all = dir.join("all");
    let report = extract(&track, "0..10", &[Meshes, Glb, Usd, Rep], &all, false);
    assert!(
        METHODS
            .iter()
            .any(|m| report.methods[m.name()].mean.keys.iter().any(|&k| k > 0)),
        "a second key: {report:?}"
    );
    // The same sequences assembled from the frame files, as before (and `trisplat convert`).
    let options = SequenceOptions {
        layout: SequenceLayout::Auto,
        compression: OutputOptions::default().gltf_compression,
        morph_basis: OutputOptions::default().morph_basis(),
    };
    for m in METHODS {
        let files = frame_files(&all, m, 0..10);
        let glb = dir.join(format!("{}_files.glb", m.name()));
        write_sequence_parts_with(
            &glb,
            &FrameFiles(&files),
            &report.frame_times,
            &options,
            GLB_PART_LIMIT,
        )
        .expect("glb from files");
        let usda = dir.join(format!("{}_files.usda", m.name()));
        write_usd_sequence(&usda, &FrameFiles(&files), &report.frame_times).expect("usd");
        let name = m.name();
        assert!(
            bytes(&all.join(format!("{name}.glb"))) == bytes(&glb),
            "{name}.glb differs from the one assembled from the frame files"
        );
        assert!(
            bytes(&all.join(format!("{name}.usda"))) == bytes(&usda),
            "{name}.usda differs from the one assembled from the frame files"
        );
    }
    let same_glbs = |out: &Path, what: &str| {
        for m in METHODS {
            let name = format!("{}.glb", m.name());
            assert!(
                bytes(&out.join(&name)) == bytes(&all.join(&name)),
                "{what}: {name} differs"
            );
            assert_eq!(ply_count(out, m), 0, "{what}: {m} wrote frame files");
        }
    };
    // No frame file without `meshes`.
    let glb_only = dir.join("glb_only");
    extract(&track, "0..10", &[Glb, Rep], &glb_only, false);
    same_glbs(&glb_only, "glb,report");
    // Killed after frame 5 (the journal keeps frames 0..=5, nothing else was written): the
    // resumed run meshes frames 6..10 and places 0..=5 again.
    let cut_journal = |out: &Path, lines: usize| {
        let journal = bytes(&out.join("journal.jsonl"));
        let text = String::from_utf8(journal).expect("text");
        let cut: String = text.lines().take(lines).map(|l| format!("{l}\n")).collect();
        std::fs::write(out.join("journal.jsonl"), cut).expect("cut journal");
        for name in ["report.json", "tsdf.glb", "delaunay.glb", "alpha.glb"] {
            let _ = std::fs::remove_file(out.join(name));
        }
    };
    cut_journal(&glb_only, 7);
    extract(&track, "0..10", &[Glb, Rep], &glb_only, true);
    same_glbs(&glb_only, "resumed after frame 5");
    // Killed while the glTFs were written (every frame done): the keys are met again.
    cut_journal(&glb_only, 11);
    extract(&track, "0..10", &[Glb, Rep], &glb_only, true);
    same_glbs(&glb_only, "resumed with every frame done");
    // A run that starts after the first key (a shard) replays it.
    let part = dir.join("part");
    let part_report = extract(&track, "4..10", &[Meshes, Glb, Rep], &part, false);
    for m in METHODS {
        let files = frame_files(&part, m, 4..10);
        let glb = dir.join(format!("{}_part_files.glb", m.name()));
        write_sequence_parts_with(
            &glb,
            &FrameFiles(&files),
            &part_report.frame_times,
            &options,
            GLB_PART_LIMIT,
        )
        .expect("glb from files");
        assert!(
            bytes(&part.join(format!("{}.glb", m.name()))) == bytes(&glb),
            "frames 4..10: {m}.glb differs from the one assembled from the frame files"
        );
    }
}
