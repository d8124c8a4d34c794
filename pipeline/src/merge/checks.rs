//! What makes shard folders one job that `merge` may join: none still running, the same
//! inputs and options, the parts of one `--shard` split each once, and every frame of the job
//! in exactly one shard.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::PipelineError;
use crate::lock::FolderLock;
use crate::report::Report;

/// A shard folder's report, with the folder.
pub(super) type ShardReport<'a> = (&'a Path, Report);

fn refused(path: &Path, problem: String) -> PipelineError {
    PipelineError::Merge {
        path: path.to_path_buf(),
        problem,
    }
}

/// The shard's lock, held so that it cannot start running during the merge; `None` for a
/// folder without a lock file (a run of an older version, or copied without it).
///
/// # Errors
/// [`PipelineError::Merge`] when a run still holds it.
pub(super) fn not_running(shard: &Path) -> Result<Option<FolderLock>, PipelineError> {
    match FolderLock::acquire_existing(shard) {
        Err(PipelineError::Busy { .. }) => Err(refused(
            shard,
            "is still running (another trisplat process holds its lock); merge once every \
             shard has finished"
                .to_owned(),
        )),
        other => other,
    }
}

/// Refuses shards that are not one job: a field of their reports that differs, or `--shard`
/// runs that are not the parts of one split, each once.
///
/// # Errors
/// [`PipelineError::Merge`] naming the shard and what differs, or the missing shards.
pub(super) fn one_job(reports: &[ShardReport<'_>]) -> Result<(), PipelineError> {
    let (first_shard, first) = (reports[0].0, &reports[0].1);
    for (shard, r) in &reports[1..] {
        if let Some(field) = job_difference(first, r) {
            return Err(refused(
                shard,
                format!(
                    "is another job than {}: its {field} differs (shards must differ only in \
                     --frames or --shard)",
                    first_shard.display()
                ),
            ));
        }
    }
    let split = reports.iter().find_map(|(p, r)| r.shard.map(|s| (*p, s)));
    let Some((split_shard, split)) = split else {
        return Ok(());
    };
    let mut by_index: BTreeMap<usize, &Path> = BTreeMap::new();
    for (shard, r) in reports {
        let Some(s) = r.shard else {
            return Err(refused(
                shard,
                format!(
                    "is not a --shard run, but {} is shard {}/{}: merge the shards of one split",
                    split_shard.display(),
                    split.index,
                    split.count
                ),
            ));
        };
        if (s.count, s.job_frames) != (split.count, split.job_frames) {
            return Err(refused(
                shard,
                format!(
                    "is shard {}/{} of frames {}..{}, but {} is shard {}/{} of frames {}..{}: \
                     another split",
                    s.index,
                    s.count,
                    s.job_frames[0],
                    s.job_frames[1],
                    split_shard.display(),
                    split.index,
                    split.count,
                    split.job_frames[0],
                    split.job_frames[1]
                ),
            ));
        }
        if let Some(other) = by_index.insert(s.index, shard) {
            return Err(refused(
                shard,
                format!(
                    "is shard {}/{}, as is {}",
                    s.index,
                    s.count,
                    other.display()
                ),
            ));
        }
    }
    let missing: Vec<String> = (0..split.count)
        .filter(|i| !by_index.contains_key(i))
        .map(|i| format!("{i}/{}", split.count))
        .collect();
    if !missing.is_empty() {
        return Err(refused(
            split_shard,
            format!(
                "{} of {} shard(s) missing: {}",
                missing.len(),
                split.count,
                missing.join(", ")
            ),
        ));
    }
    Ok(())
}

/// The shard (its position in `reports`) that made each frame, done or failed: refuses a
/// frame in two shards, and frames of the job in none (the frames of the `--shard` split, or
/// else those between the first and the last frame of the shards).
///
/// # Errors
/// [`PipelineError::Merge`] naming the shards of a frame made twice, or the missing frames.
pub(super) fn frame_owners(
    reports: &[ShardReport<'_>],
) -> Result<BTreeMap<usize, usize>, PipelineError> {
    let mut owner: BTreeMap<usize, usize> = BTreeMap::new();
    for (i, (shard, r)) in reports.iter().enumerate() {
        for &f in r
            .frames
            .iter()
            .chain(r.failed_frames.iter().map(|x| &x.frame))
        {
            if let Some(&j) = owner.get(&f) {
                return Err(refused(
                    shard,
                    format!("frame {f} is also in shard {}", reports[j].0.display()),
                ));
            }
            owner.insert(f, i);
        }
    }
    let job = match reports[0].1.shard {
        Some(s) => s.job_frames[0]..s.job_frames[1],
        None => match (owner.keys().next(), owner.keys().next_back()) {
            (Some(&a), Some(&b)) => a..b + 1,
            _ => 0..0,
        },
    };
    let missing = ranges(job.filter(|f| !owner.contains_key(f)));
    if !missing.is_empty() {
        return Err(refused(
            reports[0].0,
            format!(
                "frame(s) {} of the job are in no shard (a shard missing, or not run over \
                 them)",
                missing.join(", ")
            ),
        ));
    }
    Ok(owner)
}

/// Increasing frames as compact ranges: `3`, `5..9` (9 excluded).
fn ranges(frames: impl Iterator<Item = usize>) -> Vec<String> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for f in frames {
        match runs.last_mut() {
            Some((_, end)) if *end == f => *end = f + 1,
            _ => runs.push((f, f + 1)),
        }
    }
    runs.iter()
        .map(|&(a, b)| {
            if b == a + 1 {
                a.to_string()
            } else {
                format!("{a}..{b}")
            }
        })
        .collect()
}

/// The first field (by report name) in which two shard reports are not the same job.
fn job_difference(a: &Report, b: &Report) -> Option<&'static str> {
    let fields: [(&'static str, bool); 15] = [
        ("version", a.version == b.version),
        ("template", a.template == b.template),
        (
            "template_vertices",
            a.template_vertices == b.template_vertices,
        ),
        ("welded_vertices", a.welded_vertices == b.welded_vertices),
        ("animation", a.animation == b.animation),
        ("gaussians", a.gaussians == b.gaussians),
        ("gaussian_count", a.gaussian_count == b.gaussian_count),
        ("mode", a.mode == b.mode),
        ("ground_truth", a.ground_truth == b.ground_truth),
        ("samples", a.samples == b.samples),
        ("tau", a.tau == b.tau),
        ("tau_fraction", a.tau_fraction == b.tau_fraction),
        ("resolved", a.resolved == b.resolved),
        ("gaussians_used", a.gaussians_used == b.gaussians_used),
        (
            "methods",
            a.methods.len() == b.methods.len()
                && a.methods.iter().all(|(name, m)| {
                    b.methods
                        .get(name)
                        .is_some_and(|n| n.parameters == m.parameters)
                }),
        ),
    ];
    fields.iter().find(|(_, same)| !same).map(|(name, _)| *name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::ShardRecord;
    use crate::report::plot::tests::report;

    fn shard(frames: std::ops::Range<usize>, split: Option<(usize, usize, [usize; 2])>) -> Report {
        let mut r = report(false, false);
        r.frames = frames.collect();
        r.failed_frames.clear();
        r.shard = split.map(|(index, count, job_frames)| ShardRecord {
            index,
            count,
            job_frames,
        });
        r
    }

    fn problem(result: Result<impl std::fmt::Debug, PipelineError>) -> String {
        result.expect_err("refused").to_string()
    }

    #[test]
    fn frames_in_no_shard_are_named() {
        let (a, b) = (Path::new("a"), Path::new("b"));
        let gap = [(a, shard(0..4, None)), (b, shard(6..9, None))];
        let e = problem(frame_owners(&gap));
        assert!(
            e.contains("frame(s) 4..6 of the job are in no shard"),
            "{e}"
        );
        let joined = [(b, shard(4..9, None)), (a, shard(0..4, None))];
        let owner = frame_owners(&joined).expect("contiguous");
        assert_eq!((owner[&0], owner[&8]), (1, 0));
        let overlap = [(a, shard(0..5, None)), (b, shard(4..9, None))];
        assert!(problem(frame_owners(&overlap)).contains("frame 4 is also in shard a"));
        // A split knows its job: the last shard's frames are missing without it.
        let split = [(a, shard(0..3, Some((0, 2, [0, 6]))))];
        assert!(problem(frame_owners(&split)).contains("frame(s) 3..6"));
        assert_eq!(
            ranges([1, 2, 3, 7, 9, 10].into_iter()),
            ["1..4", "7", "9..11"]
        );
    }

    #[test]
    fn a_split_must_be_whole_and_each_shard_once() {
        let (a, b, c) = (Path::new("a"), Path::new("b"), Path::new("c"));
        let s = |i: usize, n: usize, job: [usize; 2]| shard(0..1, Some((i, n, job)));
        let missing = [(a, s(0, 3, [0, 9])), (b, s(2, 3, [0, 9]))];
        assert!(problem(one_job(&missing)).contains("1 of 3 shard(s) missing: 1/3"));
        let twice = [
            (a, s(0, 2, [0, 9])),
            (b, s(1, 2, [0, 9])),
            (c, s(1, 2, [0, 9])),
        ];
        assert!(problem(one_job(&twice)).contains("is shard 1/2, as is b"));
        let other_split = [(a, s(0, 2, [0, 9])), (b, s(1, 3, [0, 9]))];
        assert!(problem(one_job(&other_split)).contains("another split"));
        let other_frames = [(a, s(0, 2, [0, 9])), (b, s(1, 2, [0, 8]))];
        assert!(problem(one_job(&other_frames)).contains("another split"));
        let mixed = [(a, s(0, 2, [0, 9])), (b, shard(5..9, None))];
        assert!(problem(one_job(&mixed)).contains("is not a --shard run"));
        let whole = [(b, s(1, 2, [0, 9])), (a, s(0, 2, [0, 9]))];
        one_job(&whole).expect("one split");
        let mut other_version = s(1, 2, [0, 9]);
        other_version.version = "0.0.0".to_owned();
        let versions = [(a, s(0, 2, [0, 9])), (b, other_version)];
        assert!(problem(one_job(&versions)).contains("its version differs"));
    }

    #[test]
    fn a_running_shard_is_refused() {
        let dir = tempfile::tempdir().expect("temp dir");
        assert!(not_running(dir.path()).expect("no lock file").is_none());
        let held = FolderLock::acquire(dir.path()).expect("free");
        assert!(problem(not_running(dir.path())).contains("is still running"));
        drop(held);
        assert!(not_running(dir.path()).expect("finished").is_some());
    }
}
