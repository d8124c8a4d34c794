//! One mesh carried through a track (`--topology fixed|adaptive`, docs/conventions.md §10):
//! the key mesh is the frame's own extraction, the other frames keep its triangles and follow
//! the Gaussians, and any split of the track (`--frames`, `--resume`) gives the same bytes,
//! because keys are decided from the track's first frame on. On the LAM fixture driven by a
//! track whose mouth is closed for seven frames and wide open for the last three.

mod common;

use std::path::Path;

use trisplat_geometry::io::read_mesh;
use trisplat_pipeline::{ExtractConfig, Method, Report, RunControl, Topology, run};

const METHODS: [Method; 3] = [Method::Tsdf, Method::Delaunay, Method::Alpha];

/// The LAM fixture meshed with `topology` over `frames` into `out` (frame files, report).
fn config(track: &Path, topology: Topology, frames: &str, out: &Path) -> ExtractConfig {
    let mut config = common::lam_mini_config(track, &METHODS, frames, out);
    config.options.metrics.consistency_views = 0;
    config.options.topology.topology = topology;
    config
}

fn extract(track: &Path, topology: Topology, frames: &str, out: &Path) -> Report {
    run(
        &config(track, topology, frames, out),
        RunControl::default(),
        &mut |_| {},
    )
    .expect("run")
}

fn frame_bytes(out: &Path, m: Method, f: usize) -> Vec<u8> {
    std::fs::read(out.join(m.name()).join(format!("frame_{f:06}.ply"))).expect("frame file")
}

#[test]
fn a_fixed_topology_carries_the_first_frame_through_the_track() {
    let dir = common::fresh_dir("topology", "fixed");
    let track = common::opening_mouth(&dir);
    let per_frame = extract(&track, Topology::PerFrame, "0..10", &dir.join("per_frame"));
    assert!(
        per_frame.methods.values().all(|m| m.mean.keys.is_empty()),
        "per frame: no keys"
    );
    let fixed_dir = dir.join("fixed");
    let fixed = extract(&track, Topology::Fixed, "0..10", &fixed_dir);
    for m in METHODS {
        let report = &fixed.methods[m.name()];
        assert_eq!(report.mean.keys, vec![0], "{m}");
        // The key is the frame's own extraction, byte for byte.
        assert!(
            frame_bytes(&fixed_dir, m, 0) == frame_bytes(&dir.join("per_frame"), m, 0),
            "{m}: key frame"
        );
        let key = read_mesh(&fixed_dir.join(m.name()).join("frame_000000.ply")).expect("key");
        for f in 1..10 {
            let record = &report.frames[f];
            let t = record.topology.expect("a carried frame's record");
            assert_eq!(t.key, 0, "{m} frame {f}");
            assert!((0.0..=1.0).contains(&t.hops) && (0.0..=1.0).contains(&t.stretched));
            let mesh = read_mesh(&fixed_dir.join(m.name()).join(format!("frame_{f:06}.ply")))
                .expect("frame");
            assert_eq!(mesh.triangles(), key.triangles(), "{m} frame {f}: topology");
            assert!(mesh.positions().iter().all(|p| p.is_finite()));
            // Closed-mouth frames barely move: the carried mesh stays where the frame's own
            // extraction is (its bounding box within a few millimetres).
            if f < 7 {
                let own = per_frame.methods[m.name()].frames[f].vertices;
                assert!(own > 0);
                let a = mesh.bounds().expect("bounds");
                let b = read_mesh(
                    &dir.join("per_frame")
                        .join(m.name())
                        .join(format!("frame_{f:06}.ply")),
                )
                .expect("own")
                .bounds()
                .expect("bounds");
                assert!(
                    (a.min - b.min).length() < 5e-3 && (a.max - b.max).length() < 5e-3,
                    "{m} frame {f}: {a:?} vs {b:?}"
                );
            }
        }
    }
}

#[test]
fn adaptive_keys_do_not_depend_on_where_a_run_starts() {
    let dir = common::fresh_dir("topology", "adaptive");
    let track = common::opening_mouth(&dir);
    let whole = dir.join("whole");
    let one = extract(&track, Topology::Adaptive, "0..10", &whole);
    // The mouth opening at frame 7 moves Gaussians off the closed mouth's mesh: a new key.
    let keys: Vec<usize> = METHODS
        .iter()
        .flat_map(|m| one.methods[m.name()].mean.keys.clone())
        .filter(|&k| k > 0)
        .collect();
    assert!(!keys.is_empty(), "no key after the first: {one:?}");
    for frames in ["4..10", "7..10", "9..10"] {
        let out = dir.join(frames.replace("..", "_"));
        let part = extract(&track, Topology::Adaptive, frames, &out);
        for m in METHODS {
            for (record, f) in part.methods[m.name()]
                .frames
                .iter()
                .zip(part.frames.clone())
            {
                assert_eq!(
                    record.topology.map(|t| t.key),
                    one.methods[m.name()].frames[f].topology.map(|t| t.key),
                    "{frames}: {m} frame {f}"
                );
                assert!(
                    frame_bytes(&out, m, f) == frame_bytes(&whole, m, f),
                    "{frames}: {m} frame {f} differs from one run"
                );
            }
        }
    }
    // Killed after frame 5: the journal keeps frames 0..=5, the rest is gone; the resumed run
    // replays the keys and writes the same bytes.
    let killed = dir.join("killed");
    extract(&track, Topology::Adaptive, "0..10", &killed);
    let journal = std::fs::read_to_string(killed.join("journal.jsonl")).expect("journal");
    let cut: String = journal.lines().take(7).map(|l| format!("{l}\n")).collect();
    std::fs::write(killed.join("journal.jsonl"), cut).expect("cut journal");
    for m in METHODS {
        for f in 6..10 {
            std::fs::remove_file(killed.join(m.name()).join(format!("frame_{f:06}.ply")))
                .expect("remove");
        }
    }
    let control = RunControl {
        resume: true,
        ..RunControl::default()
    };
    run(
        &config(&track, Topology::Adaptive, "0..10", &killed),
        control,
        &mut |_| {},
    )
    .expect("resume");
    for m in METHODS {
        for f in 0..10 {
            assert!(
                frame_bytes(&killed, m, f) == frame_bytes(&whole, m, f),
                "resumed: {m} frame {f} differs from one run"
            );
        }
    }
}

/// A carried mesh's metrics reuse its surface index (refitted) and structure from frame to
/// frame, and the ground truth's index is refitted too: every metric must equal a fresh
/// `measure_with` of the same mesh against the same ground truth, bit for bit.
#[test]
fn carried_scores_equal_fresh_scores_bit_for_bit() {
    use trisplat_pipeline::Session;
    use trisplat_pipeline::config::GroundTruth;
    use trisplat_pipeline::metrics::measure_with;

    let dir = common::fresh_dir("topology", "scores");
    let track = common::opening_mouth(&dir);
    let mut config = config(&track, Topology::Adaptive, "0..10", &dir.join("out"));
    config.gt = Some(GroundTruth::Gaussians);
    let (samples, tau) = (
        config.options.metrics.samples,
        config.options.metrics.threshold(),
    );
    let mut session = Session::open(&config).expect("session");
    let mut carried = 0;
    for f in session.frames() {
        let (result, compared) = session
            .frame_with(f, |result, gt| {
                let gt = gt.expect("ground truth");
                result
                    .methods
                    .iter()
                    .map(|m| {
                        let fresh = measure_with(&m.output.mesh, gt, samples, tau).expect("ok");
                        assert_eq!(m.metrics, fresh, "frame {f} {}", m.method.name());
                        assert!(fresh.is_some());
                    })
                    .count()
            })
            .expect("frame");
        assert_eq!(compared, METHODS.len());
        carried += result
            .methods
            .iter()
            .filter(|m| m.topology.as_ref().is_some_and(|t| t.key != f))
            .count();
    }
    assert!(carried >= 10, "carried method-frames: {carried}");
}
