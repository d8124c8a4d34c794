//! Decimation and vertex colours of the main job's meshes (`--faces`, `--simplify-error`,
//! `--vertex-colors`; docs/conventions.md §10) on the LAM fixture: a carried key is decimated
//! before it is bound, so every carried frame is the decimated key deformed (its vertices
//! where the undecimated key's same vertices are carried, its colours the key's); per frame,
//! every frame is decimated and the report says what it cost.

mod common;

use std::collections::HashMap;
use std::path::Path;

use trisplat_geometry::TriMesh;
use trisplat_geometry::io::read_mesh;
use trisplat_pipeline::config::{FinishOptions, VertexColors};
use trisplat_pipeline::{Method, Report, RunControl, Topology, run};

const METHODS: [Method; 2] = [Method::Delaunay, Method::Alpha];
const FACES: usize = 400;

fn extract(track: &Path, topology: Topology, finish: FinishOptions, out: &Path) -> Report {
    let mut config = common::lam_mini_config(track, &METHODS, "5..9", out);
    config.options.metrics.consistency_views = 0;
    config.options.topology.topology = topology;
    config.options.finish = finish;
    run(&config, RunControl::default(), &mut |_| {}).expect("run")
}

fn frame(out: &Path, m: Method, f: usize) -> TriMesh {
    read_mesh(&out.join(m.name()).join(format!("frame_{f:06}.ply"))).expect("frame file")
}

/// Position bits, to find a vertex by where it is.
fn key(p: glam::DVec3) -> [u64; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

#[test]
fn a_decimated_key_is_carried_with_its_colours() {
    let dir = common::fresh_dir("decimate", "fixed");
    let track = common::opening_mouth(&dir);
    let (full_dir, small_dir) = (dir.join("full"), dir.join("small"));
    let plain = FinishOptions {
        vertex_colors: VertexColors::Off,
        ..FinishOptions::default()
    };
    let full = extract(&track, Topology::Fixed, plain, &full_dir);
    let decimated = FinishOptions {
        faces: Some(FACES),
        ..FinishOptions::default()
    };
    let small = extract(&track, Topology::Fixed, decimated, &small_dir);
    for m in METHODS {
        let frames = &small.methods[m.name()].frames;
        // The key (the run replays the track's first frame as its key): what it cost is in
        // the record of the frames carried from it only where it was made; here none.
        assert!(
            frames
                .iter()
                .all(|r| r.topology.is_some_and(|t| t.key == 0))
        );
        assert!(frames.iter().all(|r| r.faces <= FACES), "{m}");
        let undecimated = full.methods[m.name()].frames[0].faces;
        assert!(undecimated > FACES, "{m}: {undecimated} faces");
        let first = frame(&small_dir, m, 5);
        let colors = first.colors().expect("coloured by default").to_vec();
        assert!(
            colors
                .iter()
                .all(|c| c.iter().all(|x| (0.0..=1.0).contains(x)))
        );
        for f in 5..9 {
            let (s, u) = (frame(&small_dir, m, f), frame(&full_dir, m, f));
            assert!(u.colors().is_none(), "--vertex-colors off");
            assert_eq!(s.triangles(), first.triangles(), "{m} frame {f}");
            assert_eq!(
                s.colors(),
                Some(&colors[..]),
                "{m} frame {f}: the key's colours"
            );
            // Each vertex of the decimated frame is where the undecimated run carries the same
            // key vertex: the vertices at frame 5 name them.
            let at: HashMap<[u64; 3], usize> = frame(&full_dir, m, 5)
                .positions()
                .iter()
                .enumerate()
                .map(|(i, &p)| (key(p), i))
                .collect();
            for (i, p) in first.positions().iter().enumerate() {
                let j = at[&key(*p)];
                assert_eq!(
                    s.positions()[i],
                    u.positions()[j],
                    "{m} frame {f} vertex {i}"
                );
            }
        }
    }
}

#[test]
fn per_frame_every_mesh_is_decimated_and_the_report_says_what_it_cost() {
    let dir = common::fresh_dir("decimate", "per_frame");
    let track = common::opening_mouth(&dir);
    let finish = FinishOptions {
        simplify_error: Some(0.01),
        ..FinishOptions::default()
    };
    let report = extract(&track, Topology::PerFrame, finish, &dir.join("out"));
    for m in METHODS {
        let method = &report.methods[m.name()];
        assert_eq!(method.parameters.get("simplify_error"), Some(&0.01));
        for r in &method.frames {
            let s = r.simplify.expect("every frame decimated");
            assert_eq!(s.faces_after, r.faces);
            assert!(s.faces_after < s.faces_before, "{m} frame {}", r.frame);
            // Within 1% of the extent by meshoptimizer's estimate (a LAM head: about 3 mm).
            assert!(s.meshopt_error >= 0.0 && s.meshopt_error < 0.01, "{s:?}");
            assert!(
                s.mean_distance <= s.hausdorff && s.hausdorff.is_finite(),
                "{s:?}"
            );
        }
    }
    let md = std::fs::read_to_string(dir.join("out").join("report.md")).expect("report.md");
    assert!(
        md.contains("decimated 4 mesh(es)") && md.contains("Hausdorff"),
        "{md}"
    );
}
