//! The frames of a run: `--frames` selections against the animation's frame count.

use std::ops::Range;

use crate::config::ShardOptions;
use crate::error::PipelineError;
use crate::records::ShardRecord;

/// Parses `A..B` (B excluded), `A..=B`, `A..`, `..B` or `A` against `count` frames; `None` is
/// every frame.
///
/// # Errors
/// [`PipelineError::Frames`] for a malformed, empty or out-of-range selection.
pub fn parse_frames(spec: Option<&str>, count: usize) -> Result<Range<usize>, PipelineError> {
    let Some(spec) = spec else {
        return Ok(0..count);
    };
    let err = |problem: String| PipelineError::Frames {
        spec: spec.to_owned(),
        problem,
    };
    let num = |s: &str, default: usize| -> Result<usize, PipelineError> {
        let s = s.trim();
        if s.is_empty() {
            Ok(default)
        } else {
            s.parse::<usize>()
                .map_err(|_| err(format!("`{s}` is not a frame number")))
        }
    };
    let range = if let Some((a, b)) = spec.split_once("..=") {
        num(a, 0)?..num(b, usize::MAX)?.saturating_add(1)
    } else if let Some((a, b)) = spec.split_once("..") {
        num(a, 0)?..num(b, count)?
    } else {
        let f = num(spec, 0)?;
        f..f.saturating_add(1)
    };
    if range.start >= range.end {
        return Err(err("the range is empty".to_owned()));
    }
    if range.end > count {
        return Err(err(format!(
            "the animation has {count} frame(s) (0..{count})"
        )));
    }
    Ok(range)
}

/// The frames this run meshes: `shard`'s part of the `selected` frames (all of them without
/// `--shard`), and the shard as the report records it. `--shard auto` is read from the
/// process's environment here when the caller did not resolve it.
pub fn shard_frames(
    shard: &ShardOptions,
    selected: Range<usize>,
) -> Result<(Range<usize>, Option<ShardRecord>), PipelineError> {
    let refused = |problem| PipelineError::Shard { problem };
    let Some(s) = shard
        .resolve(&|name| std::env::var(name).ok())
        .map_err(refused)?
    else {
        return Ok((selected, None));
    };
    let frames = s.frames(selected.clone()).map_err(refused)?;
    let record = ShardRecord {
        index: s.index,
        count: s.count,
        job_frames: [selected.start, selected.end],
    };
    Ok((frames, Some(record)))
}
