//! Long runs through the real binary: a used output folder is refused unless `--resume` or
//! `--force`; a run killed after some frames and resumed writes the same bytes as one that ran
//! through; a changed configuration is not resumed; a failing frame is recorded and the run
//! goes on (exit 1, the other frames written), or stops with `--fail-fast`.

mod common;

use std::path::{Path, PathBuf};

use common::{fresh_dir, one_error_line, report, run, run_ok, s};
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::{WriteOptions, read_mesh, write_mesh};
use trisplat_splat::glam::DVec3;

/// A template and a folder of six frames of it (a slow stretch), as PLY files.
fn frames_case(dir: &Path) -> (PathBuf, PathBuf) {
    let rest = read_mesh(&trisplat_fixtures::path("anim/RiggedFigure.glb")).expect("figure");
    let template = dir.join("template.ply");
    write_mesh(&template, &rest, WriteOptions::default()).expect("template");
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).expect("frames folder");
    for k in 0..6 {
        let s = 1.0 + 0.03 * f64::from(k);
        let positions: Vec<DVec3> = rest
            .positions()
            .iter()
            .map(|p| DVec3::new(p.x * s, p.y, p.z / s))
            .collect();
        let mesh = TriMesh::new(positions, rest.triangles().to_vec());
        write_mesh(
            &frames.join(format!("f_{k:03}.ply")),
            &mesh,
            WriteOptions::default(),
        )
        .expect("frame");
    }
    (template, frames)
}

fn extract_args<'a>(template: &'a Path, frames: &'a Path, out: &'a Path) -> Vec<&'a str> {
    vec![
        "extract",
        "--template",
        s(template),
        "--animation",
        s(frames),
        "--method",
        "delaunay,alpha",
        "--gt",
        "template",
        "--samples",
        "2000",
        "-q",
        "-o",
        s(out),
    ]
}

/// Every output file's bytes except the journal, reports and plot (they hold timings).
fn mesh_outputs(out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    for m in ["delaunay", "alpha"] {
        let mut names: Vec<String> = std::fs::read_dir(out.join(m))
            .expect("method folder")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        for n in names {
            let bytes = std::fs::read(out.join(m).join(&n)).expect("frame");
            files.push((format!("{m}/{n}"), bytes));
        }
        let glb = format!("{m}.glb");
        files.push((glb.clone(), std::fs::read(out.join(&glb)).expect("glb")));
    }
    files
}

#[test]
fn a_used_folder_is_refused_unless_resumed_or_forced() {
    let dir = fresh_dir("used");
    let (template, frames) = frames_case(&dir);
    let out = dir.join("out");
    let args = extract_args(&template, &frames, &out);
    run_ok(&args);
    let first = mesh_outputs(&out);
    let line = one_error_line(&run(&args));
    assert!(
        line.contains("previous run") && line.contains("--resume") && line.contains("--force"),
        "{line}"
    );
    assert_eq!(mesh_outputs(&out), first, "the refused run changed nothing");
    // --force starts over; --resume of a finished run redoes nothing.
    let mut force = args.clone();
    force.push("--force");
    run_ok(&force);
    let mut resume = args.clone();
    resume.push("--resume");
    let before = std::fs::read(out.join("journal.jsonl")).expect("journal");
    run_ok(&resume);
    let after = std::fs::read(out.join("journal.jsonl")).expect("journal");
    assert!(before == after, "nothing was run again");
    assert_eq!(report(&out)["frames"].as_array().map(Vec::len), Some(6));
    // Resuming with other options is refused.
    let mut other = resume.clone();
    other.extend(["--hop-threshold", "0.1"]);
    let line = one_error_line(&run(&other));
    assert!(
        line.contains("cannot resume") && line.contains("other inputs or options"),
        "{line}"
    );
    // Nothing to resume.
    let empty = dir.join("empty");
    let mut nothing = extract_args(&template, &frames, &empty);
    nothing.push("--resume");
    assert!(one_error_line(&run(&nothing)).contains("nothing to resume"));
}

#[test]
fn a_killed_run_resumes_to_the_same_bytes() {
    let dir = fresh_dir("resume");
    let (template, frames) = frames_case(&dir);
    let through = dir.join("through");
    run_ok(&extract_args(&template, &frames, &through));

    // The same run, killed after frame 2: the journal lists frames 0-2 and ends in a line cut
    // short, frame 3's files were written but not journalled, nothing after that exists.
    let killed = dir.join("killed");
    run_ok(&extract_args(&template, &frames, &killed));
    let journal = std::fs::read_to_string(killed.join("journal.jsonl")).expect("journal");
    let mut cut: String = journal.lines().take(4).map(|l| format!("{l}\n")).collect();
    cut.push_str(r#"{"kind":"frame","frame":3,"ti"#);
    std::fs::write(killed.join("journal.jsonl"), cut).expect("cut journal");
    for m in ["delaunay", "alpha"] {
        for k in 4..6 {
            std::fs::remove_file(killed.join(m).join(format!("frame_{k:06}.ply"))).expect("rm");
        }
        std::fs::remove_file(killed.join(format!("{m}.glb"))).expect("rm glb");
    }
    for name in ["report.json", "report.md", "error_vs_time.png"] {
        std::fs::remove_file(killed.join(name)).expect("rm report");
    }
    // What a kill in the middle of an atomic write leaves behind.
    let stale = killed.join("delaunay").join(".trisplat-x1y2z3.tmp");
    std::fs::write(&stale, b"half a frame").expect("stale temporary");
    let mut resume = extract_args(&template, &frames, &killed);
    resume.push("--resume");
    let ran = run_ok(&resume);
    assert!(!stale.exists(), "the stale temporary is removed");
    assert!(
        String::from_utf8_lossy(&ran.stderr).contains("resuming: 3 of 6 frame(s) already done")
    );
    assert_same_run(&through, &killed, "the resume");
}

/// Two run folders hold the same frame files and glTFs byte for byte, and the same frames and
/// per-frame metrics in their reports (timings aside).
fn assert_same_run(x: &Path, y: &Path, what: &str) {
    let (a, b) = (mesh_outputs(x), mesh_outputs(y));
    assert_eq!(a.len(), b.len());
    for ((name_a, bytes_a), (name_b, bytes_b)) in a.iter().zip(&b) {
        assert_eq!(name_a, name_b);
        assert!(bytes_a == bytes_b, "{name_a} differs after {what}");
    }
    let (ra, rb) = (report(x), report(y));
    for key in [
        "frames",
        "frame_times",
        "resolved",
        "gaussian_count",
        "failed_frames",
    ] {
        assert_eq!(ra[key], rb[key], "{key} after {what}");
    }
    for m in ["delaunay", "alpha"] {
        for k in 0..6 {
            let metrics = |r: &serde_json::Value| r["methods"][m]["frames"][k]["metrics"].clone();
            assert_eq!(metrics(&ra), metrics(&rb), "{m} frame {k} after {what}");
        }
        let fscore = |r: &serde_json::Value| r["methods"][m]["mean"]["fscore"].clone();
        assert_eq!(fscore(&ra), fscore(&rb), "{m} mean after {what}");
    }
}

#[test]
fn a_failing_frame_is_recorded_and_the_run_goes_on() {
    let dir = fresh_dir("failing");
    let (template, frames) = frames_case(&dir);
    let good = std::fs::read(frames.join("f_003.ply")).expect("frame 3");
    std::fs::write(
        frames.join("f_003.ply"),
        b"ply\nformat ascii 1.0\nend_header\n",
    )
    .expect("break frame 3");
    let out = dir.join("out");
    let args = extract_args(&template, &frames, &out);
    // Exit 1; the failure is told as it happens (a warning) and summed up in the last line.
    let ran = run(&args);
    assert_eq!(ran.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&ran.stderr);
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 2, "{stderr}");
    assert!(
        lines[0].starts_with("warning: frame 3 failed, the run goes on"),
        "{stderr}"
    );
    let line = lines[1];
    assert!(
        line.starts_with("error: 1 frame(s) failed") && line.contains("frame 3"),
        "{line}"
    );
    let r = report(&out);
    assert_eq!(r["frames"], serde_json::json!([0, 1, 2, 4, 5]));
    assert_eq!(r["failed_frames"][0]["frame"], 3);
    assert!(out.join("delaunay/frame_000005.ply").is_file());
    assert!(!out.join("delaunay/frame_000003.ply").exists());
    assert!(
        std::fs::read_to_string(out.join("report.md"))
            .expect("md")
            .contains("failed frames")
    );
    // Repaired, the frame is run on --resume and the run completes.
    std::fs::write(frames.join("f_003.ply"), good).expect("repair frame 3");
    let mut resume = args.clone();
    resume.push("--resume");
    run_ok(&resume);
    assert_eq!(report(&out)["frames"].as_array().map(Vec::len), Some(6));
    assert!(out.join("delaunay/frame_000003.ply").is_file());

    // --fail-fast stops at the failure and keeps what was done.
    std::fs::write(
        frames.join("f_003.ply"),
        b"ply\nformat ascii 1.0\nend_header\n",
    )
    .expect("break frame 3");
    let fast_out = dir.join("fast");
    let mut fast = extract_args(&template, &frames, &fast_out);
    fast.push("--fail-fast");
    assert!(one_error_line(&run(&fast)).contains("f_003.ply"));
    assert!(fast_out.join("alpha/frame_000002.ply").is_file());
    assert!(!fast_out.join("alpha/frame_000004.ply").exists());
    assert!(!fast_out.join("report.json").exists());
}

#[test]
fn two_shards_merge_to_one_run() {
    let dir = fresh_dir("shards");
    let (template, frames) = frames_case(&dir);
    let through = dir.join("through");
    run_ok(&extract_args(&template, &frames, &through));
    let shard = |name: &str, range: &'static str| {
        let out = dir.join(name);
        let mut args = extract_args(&template, &frames, &out);
        args.extend(["--frames", range]);
        run_ok(&args);
        out
    };
    let (a, b) = (shard("a", "0..3"), shard("b", "3..6"));
    let merged = dir.join("merged");
    // Shards in any order.
    run_ok(&["merge", s(&b), s(&a), "-q", "-o", s(&merged)]);
    assert_same_run(&through, &merged, "the merge");
    let (rx, ry) = (report(&through), report(&merged));
    assert_eq!(
        rx["methods"]["delaunay"]["delaunay"]["frames"]
            .as_array()
            .map(Vec::len),
        ry["methods"]["delaunay"]["delaunay"]["frames"]
            .as_array()
            .map(Vec::len)
    );

    // Overlapping shards, another job, the output among the shards, a used output: refused.
    let overlap = shard("overlap", "2..4");
    let line = one_error_line(&run(&[
        "merge",
        s(&a),
        s(&overlap),
        "-o",
        s(&dir.join("m2")),
    ]));
    assert!(line.contains("frame 2 is also in shard"), "{line}");
    let other = dir.join("other");
    let mut args = extract_args(&template, &frames, &other);
    args.extend(["--frames", "3..6", "--tau", "0.01"]);
    run_ok(&args);
    let line = one_error_line(&run(&["merge", s(&a), s(&other), "-o", s(&dir.join("m3"))]));
    assert!(
        line.contains("another job") && line.contains("tau"),
        "{line}"
    );
    let line = one_error_line(&run(&["merge", s(&a), s(&b), "-o", s(&a)]));
    assert!(line.contains("is also the output folder"), "{line}");
    let line = one_error_line(&run(&["merge", s(&a), s(&b), "-o", s(&merged)]));
    assert!(line.contains("previous run"), "{line}");
    run_ok(&["merge", s(&a), s(&b), "-q", "-o", s(&merged), "--force"]);
    // A shard missing a frame file its report lists, a shard without a readable report.
    std::fs::remove_file(b.join("alpha/frame_000004.ply")).expect("rm");
    let line = one_error_line(&run(&["merge", s(&a), s(&b), "-o", s(&dir.join("m4"))]));
    assert!(
        line.contains("frame_000004.ply") && line.contains("missing"),
        "{line}"
    );
    std::fs::write(b.join("report.json"), b"{}").expect("break report");
    let line = one_error_line(&run(&["merge", s(&a), s(&b), "-o", s(&dir.join("m5"))]));
    assert!(line.contains("not a trisplat report"), "{line}");
    std::fs::remove_file(b.join("report.json")).expect("rm report");
    let line = one_error_line(&run(&["merge", s(&a), s(&b), "-o", s(&dir.join("m6"))]));
    assert!(line.contains("is the run finished"), "{line}");
}

/// `--shard auto` reads a Slurm array task's or a Kubernetes pod's index; `merge` joins the
/// shards of one split to one run, refuses an incomplete split and frames in no shard, names
/// what is wrong, and writes nothing then.
#[test]
fn shards_from_the_environment_merge_and_incomplete_splits_are_refused() {
    let dir = fresh_dir("shard_auto");
    let (template, frames) = frames_case(&dir);
    let through = dir.join("through");
    run_ok(&extract_args(&template, &frames, &through));
    let shard = |name: &str, env: &[(&str, &str)], extra: &[&str]| {
        let out = dir.join(name);
        let mut args = extract_args(&template, &frames, &out);
        args.extend(["--shard", "auto"]);
        args.extend(extra);
        let mut command = std::process::Command::new(common::BIN);
        command.args(&args);
        for var in [
            "SLURM_ARRAY_TASK_ID",
            "SLURM_ARRAY_TASK_COUNT",
            "SLURM_ARRAY_TASK_MIN",
            "SLURM_ARRAY_TASK_STEP",
            "JOB_COMPLETION_INDEX",
        ] {
            command.env_remove(var);
        }
        command.envs(env.iter().copied());
        (out, command.output().expect("run trisplat"))
    };
    // An array 1-3 (`sbatch --array=1-3`): task 3 is shard 2/3, frames 4..6.
    let slurm = |id: &'static str| {
        let vars = [
            ("SLURM_ARRAY_TASK_ID", id),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ];
        let (out, o) = shard(&format!("slurm_{id}"), &vars, &[]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out
    };
    let (a, c) = (slurm("1"), slurm("3"));
    assert_eq!(report(&c)["frames"], serde_json::json!([4, 5]));
    assert_eq!(
        report(&c)["shard"],
        serde_json::json!({"index": 2, "count": 3, "job_frames": [0, 6]})
    );
    let refused = dir.join("refused");
    let line = one_error_line(&run(&["merge", s(&a), s(&c), "-o", s(&refused)]));
    assert!(line.contains("shard(s) missing: 1/3"), "{line}");
    assert!(!refused.exists(), "a refused merge created its folder");
    // The middle shard from a Kubernetes pod: the same split.
    let (b, o) = shard(
        "k8s_1",
        &[("JOB_COMPLETION_INDEX", "1")],
        &["--shard-count", "3"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let merged = dir.join("merged");
    run_ok(&["merge", s(&c), s(&a), s(&b), "-q", "-o", s(&merged)]);
    assert_same_run(&through, &merged, "the merge of --shard auto runs");
    let line = one_error_line(&run(&["merge", s(&a), s(&b), s(&a), "-o", s(&refused)]));
    assert!(line.contains("is given twice"), "{line}");

    // Missing and inconsistent variables: a usage error, nothing written.
    for (vars, says) in [
        (&[][..], "neither a Slurm array task"),
        (
            &[("SLURM_ARRAY_TASK_ID", "2")][..],
            "SLURM_ARRAY_TASK_COUNT is not",
        ),
        (
            &[
                ("SLURM_ARRAY_TASK_ID", "7"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ][..],
            "out of range",
        ),
    ] {
        let (out, o) = shard("bad", vars, &[]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{vars:?}: {stderr}");
        assert!(
            stderr.starts_with("error: ") && stderr.contains(says),
            "{vars:?}: {stderr}"
        );
        assert!(
            !out.exists(),
            "{vars:?}: the refused run created its folder"
        );
    }

    // `--frames` shards with a gap between them: the frames in none are named.
    let frames_shard = |name: &str, range: &'static str| {
        let out = dir.join(name);
        let mut args = extract_args(&template, &frames, &out);
        args.extend(["--frames", range]);
        run_ok(&args);
        out
    };
    let (x, y) = (frames_shard("x", "0..2"), frames_shard("y", "4..6"));
    let line = one_error_line(&run(&["merge", s(&x), s(&y), "-o", s(&refused)]));
    assert!(
        line.contains("frame(s) 2..4 of the job are in no shard"),
        "{line}"
    );
    // A shard whose run still holds its lock.
    let held = trisplat_pipeline::FolderLock::acquire(&y).expect("lock");
    let line = one_error_line(&run(&["merge", s(&x), s(&y), "-o", s(&refused)]));
    assert!(line.contains("is still running"), "{line}");
    drop(held);
    assert!(!refused.exists());
}

/// `--gt-sequence`: one ground-truth mesh per frame. The frames of the animation themselves as
/// ground truth score as `--gt template` does (the same surfaces); a sequence shorter than the
/// frames is refused naming the option; `--gt` and `--gt-sequence` exclude each other.
#[test]
fn a_ground_truth_per_frame() {
    let dir = fresh_dir("gt_sequence");
    let (template, frames) = frames_case(&dir);
    let by_template = dir.join("by_template");
    run_ok(&extract_args(&template, &frames, &by_template));
    let by_sequence = dir.join("by_sequence");
    let args: Vec<&str> = extract_args(&template, &frames, &by_sequence)
        .into_iter()
        .map(|a| if a == "template" { s(&frames) } else { a })
        .collect();
    let args: Vec<&str> = args
        .iter()
        .map(|a| if *a == "--gt" { "--gt-sequence" } else { a })
        .collect();
    run_ok(&args);
    let (a, b) = (report(&by_template), report(&by_sequence));
    assert_eq!(b["ground_truth"], serde_json::json!(s(&frames)));
    for m in ["delaunay", "alpha"] {
        for k in 0..6 {
            let chamfer = |r: &serde_json::Value| {
                r["methods"][m]["frames"][k]["metrics"]["chamfer_l1"]
                    .as_f64()
                    .expect("measured")
            };
            let (x, y) = (chamfer(&a), chamfer(&b));
            assert!(
                (x - y).abs() <= 0.05 * x.max(y) + 1e-9,
                "{m} frame {k}: {x} vs {y}"
            );
        }
    }
    // Too short: only 4 meshes for 6 frames.
    let short = dir.join("short");
    std::fs::create_dir_all(&short).expect("folder");
    for k in 0..4 {
        let name = format!("f_{k:03}.ply");
        std::fs::copy(frames.join(&name), short.join(&name)).expect("copy");
    }
    let short_out = dir.join("short_out");
    let mut too_short = args.clone();
    let gt_at = too_short
        .iter()
        .position(|a| *a == "--gt-sequence")
        .expect("flag")
        + 1;
    too_short[gt_at] = s(&short);
    let out_at = too_short.len() - 1;
    too_short[out_at] = s(&short_out);
    let line = one_error_line(&run(&too_short));
    assert!(
        line.contains("--gt-sequence") && line.contains("4 mesh file(s)"),
        "{line}"
    );
    let mut both = args.clone();
    both.extend(["--gt", "template"]);
    assert_eq!(run(&both).status.code(), Some(2));
}

/// `--targets` writes only what is asked for (the journal always); the glb alone is assembled
/// from frame files that are removed afterwards.
#[test]
fn targets_choose_the_outputs() {
    let dir = fresh_dir("targets");
    let (template, frames) = frames_case(&dir);
    let ply_count = |out: &Path| {
        ["delaunay", "alpha"]
            .iter()
            .map(|m| std::fs::read_dir(out.join(m)).map_or(0, |d| d.count()))
            .sum::<usize>()
    };
    for (targets, meshes, glb, report_json) in [
        ("report", false, false, true),
        ("glb", false, true, false),
        ("meshes", true, false, false),
        ("meshes,glb,report", true, true, true),
    ] {
        let out = dir.join(targets.replace(',', "_"));
        let mut args = extract_args(&template, &frames, &out);
        // Plain f32 glTF, which the static reader reads (not the compressed default).
        args.extend(["--targets", targets, "--gltf-compression", "none"]);
        run_ok(&args);
        assert_eq!(ply_count(&out) > 0, meshes, "{targets}: frame files");
        assert_eq!(out.join("delaunay.glb").is_file(), glb, "{targets}: glb");
        assert_eq!(
            out.join("report.json").is_file(),
            report_json,
            "{targets}: report"
        );
        assert!(out.join("journal.jsonl").is_file(), "{targets}: journal");
        if glb {
            let doc = read_mesh(&out.join("delaunay.glb")).expect("glb reads");
            assert!(doc.triangle_count() > 0);
        }
    }
    let explained = run_ok(&[
        "extract",
        "--template",
        s(&template),
        "--method",
        "alpha",
        "--targets",
        "report",
        "-o",
        s(&dir.join("explain")),
        "--explain",
    ]);
    let plan = String::from_utf8_lossy(&explained.stdout);
    assert!(
        plan.contains("--targets names neither meshes, glb nor usd"),
        "{plan}"
    );
}

#[test]
fn methods_side_by_side_or_one_after_another_write_the_same_outputs() {
    let dir = fresh_dir("serial");
    let (template, frames) = frames_case(&dir);
    let side_by_side = dir.join("side_by_side");
    run_ok(&extract_args(&template, &frames, &side_by_side));
    let serial = dir.join("serial");
    let mut args = extract_args(&template, &frames, &serial);
    args.push("--serial-methods");
    run_ok(&args);
    assert_same_run(&side_by_side, &serial, "--serial-methods");
    assert_eq!(report(&side_by_side)["serial_methods"], false);
    assert_eq!(report(&serial)["serial_methods"], true);
    let md = std::fs::read_to_string(serial.join("report.md")).expect("report.md");
    assert!(md.contains("one after another (--serial-methods)"), "{md}");
}

#[test]
fn a_second_run_into_a_folder_in_use_is_refused() {
    let dir = fresh_dir("busy");
    let (template, frames) = frames_case(&dir);
    let shard = dir.join("shard");
    run_ok(&extract_args(&template, &frames, &shard));
    let out = dir.join("out");
    std::fs::create_dir_all(&out).expect("folder");
    // Another run holds the folder's lock (here: this test).
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .write(true)
        .truncate(false)
        .open(out.join(".trisplat.lock"))
        .expect("lock file");
    lock.lock().expect("lock");
    let line = one_error_line(&run(&extract_args(&template, &frames, &out)));
    assert!(
        line.contains("another trisplat run") && line.contains(".trisplat.lock"),
        "{line}"
    );
    assert!(!out.join("journal.jsonl").exists(), "nothing written");
    let line = one_error_line(&run(&["merge", s(&shard), "-o", s(&out)]));
    assert!(line.contains("another trisplat run"), "{line}");
    // Released (as when the other process ends, however it ends): the run goes through.
    drop(lock);
    run_ok(&extract_args(&template, &frames, &out));
}

#[test]
fn ctrl_c_leaves_no_temporary_file_and_the_run_resumes_to_the_same_bytes() {
    let dir = fresh_dir("ctrl_c");
    let template = trisplat_fixtures::path("anim/CesiumMan.glb");
    let args = |out: &Path| -> Vec<String> {
        let template = s(&template);
        [
            "extract",
            "--template",
            template,
            "--frames",
            "0..30",
            "--method",
            "delaunay,alpha",
            "-q",
            "-o",
            s(out),
        ]
        .map(str::to_owned)
        .to_vec()
    };
    let through = dir.join("through");
    run_ok(
        &args(&through)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    // The same run, interrupted (SIGINT, as Ctrl-C) once a few frames are journalled.
    let stopped = dir.join("stopped");
    let mut child = std::process::Command::new(common::BIN)
        .args(args(&stopped))
        .spawn()
        .expect("spawn");
    let journal = stopped.join("journal.jsonl");
    let start = std::time::Instant::now();
    while std::fs::read_to_string(&journal).map_or(0, |t| t.lines().count()) < 4 {
        assert!(start.elapsed().as_secs() < 60, "the run did not start");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let killed = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
    let status = child.wait().expect("wait");
    assert_eq!(status.code(), Some(130), "ended by the interrupt");
    let mut temporaries = Vec::new();
    for folder in [
        stopped.clone(),
        stopped.join("delaunay"),
        stopped.join("alpha"),
    ] {
        for e in std::fs::read_dir(&folder).expect("folder").flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.ends_with(".tmp") {
                temporaries.push(name);
            }
        }
    }
    assert!(temporaries.is_empty(), "{temporaries:?}");
    let mut resume = args(&stopped);
    resume.push("--resume".to_owned());
    run_ok(&resume.iter().map(String::as_str).collect::<Vec<_>>());
    for m in ["delaunay", "alpha"] {
        for f in 0..30 {
            let name = format!("{m}/frame_{f:06}.ply");
            assert!(
                std::fs::read(through.join(&name)).expect("through")
                    == std::fs::read(stopped.join(&name)).expect("resumed"),
                "{name}"
            );
        }
    }
}
