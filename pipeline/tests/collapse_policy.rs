//! The degenerate-triangle policy in the main job (docs/numerics.md): a template triangle that
//! collapses to zero area keeps its last valid frame, is counted in the frame's result, and a
//! run that starts at the collapse (a shard, `--resume`) gives what a run through every frame
//! gives.

use std::path::Path;
use trisplat_pipeline::config::{AnimationOptions, BindOptions};

use trisplat_pipeline::{ExtractConfig, ExtractOptions, Method, Mode, Session};
use trisplat_splat::GaussianSet;

/// Two triangles sharing the edge 1-2; vertex 0 belongs to triangle 0 only.
const TRIANGLES: [[u32; 3]; 2] = [[0, 1, 2], [1, 3, 2]];

/// Vertex 0 of each frame: frames 2 and 3 put it on the segment 1-2 (triangle 0 has zero
/// area), the others lift it off the plane by different amounts.
const VERTEX_0: [[f64; 3]; 6] = [
    [0.0, 0.0, 0.0],
    [0.1, 0.2, 0.1],
    [0.5, 0.5, 0.0],
    [0.5, 0.5, 0.0],
    [0.3, 0.2, 0.2],
    [0.1, 0.0, -0.1],
];

fn write_obj(path: &Path, v0: [f64; 3]) {
    let mut text = format!("v {} {} {}\n", v0[0], v0[1], v0[2]);
    text.push_str("v 1 0 0\nv 0 1 0\nv 1 1 0.25\n");
    for t in TRIANGLES {
        text.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    std::fs::write(path, text).expect("write OBJ");
}

/// The template and its six frames in a temporary folder.
fn scene() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    write_obj(&dir.path().join("template.obj"), VERTEX_0[0]);
    std::fs::create_dir(dir.path().join("frames")).expect("frames dir");
    for (i, v0) in VERTEX_0.iter().enumerate() {
        write_obj(&dir.path().join(format!("frames/f{i:03}.obj")), *v0);
    }
    dir
}

fn config(dir: &Path, frames: &str, mode: Mode) -> ExtractConfig {
    ExtractConfig {
        template: dir.join("template.obj"),
        animation: Some(dir.join("frames").display().to_string()),
        gaussians: None,
        methods: Vec::new(),
        output: dir.join("unused"),
        frames: Some(frames.to_owned()),
        gt: None,
        options: ExtractOptions {
            animation: AnimationOptions {
                mode,
                ..Default::default()
            },
            bind: BindOptions {
                per_triangle: 3,
                ..Default::default()
            },
            ..ExtractOptions::default()
        },
    }
}

fn worlds(session: &mut Session, frames: std::ops::Range<usize>) -> Vec<GaussianSet> {
    frames.map(|f| session.world(f).expect("world")).collect()
}

#[test]
fn a_collapsed_triangle_keeps_its_last_valid_frame_wherever_the_run_starts() {
    let dir = scene();
    for mode in [Mode::Binding, Mode::Jacobian] {
        let mut whole = Session::open(&config(dir.path(), "0..6", mode)).expect("open");
        let all = worlds(&mut whole, 0..6);
        let on_0: Vec<usize> = (0..whole.gaussians().len())
            .filter(|&i| whole.gaussians().binding().expect("bound").triangles[i].index() == 0)
            .collect();
        assert_eq!(on_0.len(), 3);
        for f in [2, 3] {
            for &i in &on_0 {
                // Frame 1's rotation and scales; the mean moved with the centroid only.
                assert_eq!(
                    all[f].rotations()[i],
                    all[1].rotations()[i],
                    "{mode:?} frame {f}"
                );
                assert_eq!(
                    all[f].log_scales()[i],
                    all[1].log_scales()[i],
                    "{mode:?} frame {f}"
                );
            }
        }
        // Triangle 1 never collapses: its Gaussians follow every frame.
        let other = (0..whole.gaussians().len())
            .find(|i| !on_0.contains(i))
            .expect("one");
        assert!(all.iter().all(|w| w.means()[other].is_finite()));
        // A shard starting at the collapse, and one starting right after it.
        for start in [2, 3, 4] {
            let mut shard =
                Session::open(&config(dir.path(), &format!("{start}..6"), mode)).expect("open");
            let part = worlds(&mut shard, start..6);
            assert_eq!(&part[..], &all[start..], "{mode:?} from frame {start}");
        }
        // A session that renders sampled frames when it opens (to decide which Gaussians
        // the point methods use) deforms every frame of its run as one that did not.
        for (start, frames) in [(0, "0..6"), (2, "2..6")] {
            let mut c = config(dir.path(), frames, mode);
            c.methods = vec![Method::Alpha];
            let mut sampled = Session::open(&c).expect("open");
            assert_eq!(sampled.visibility().used.poses, 5, "{mode:?} {frames}");
            let part = worlds(&mut sampled, start..6);
            assert_eq!(&part[..], &all[start..], "{mode:?} {frames} after sampling");
        }
        // Frames deformed out of order look the history up again.
        let mut jumping = Session::open(&config(dir.path(), "0..6", mode)).expect("open");
        for f in [4, 2, 5, 3, 3] {
            assert_eq!(
                jumping.world(f).expect("world"),
                all[f],
                "{mode:?} jump to {f}"
            );
        }
        // Every output finite.
        for w in &all {
            assert!(w.means().iter().all(|m| m.is_finite()));
            assert!(w.log_scales().iter().all(|s| s.is_finite()));
        }
    }
}

#[test]
fn frames_count_their_collapsed_triangles() {
    let dir = scene();
    let mut session = Session::open(&config(dir.path(), "0..6", Mode::Binding)).expect("open");
    let counts: Vec<usize> = (0..6)
        .map(|f| session.frame(f).expect("frame").collapsed.total())
        .collect();
    assert_eq!(counts, [0, 0, 1, 1, 0, 0]);
    let held: Vec<usize> = {
        let mut s = Session::open(&config(dir.path(), "2..4", Mode::Binding)).expect("open");
        (2..4)
            .map(|f| s.frame(f).expect("frame").collapsed.held)
            .collect()
    };
    assert_eq!(
        held,
        [1, 1],
        "a shard from the collapse still holds frame 1's"
    );
}
