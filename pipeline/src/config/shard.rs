//! The part of a track one run takes when the track is split over machines (`--shard I/N`,
//! or `--shard auto` from a Slurm array's or a Kubernetes indexed job's environment).

use std::fmt;
use std::ops::Range;

/// Shard `index` of `count` equal parts of the selected frames (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Shard {
    /// This shard's position, `0..count`.
    pub index: usize,
    /// How many shards split the frames (at least 1).
    pub count: usize,
}

impl Shard {
    /// Shard `index` of `count`.
    ///
    /// # Errors
    /// When `count` is 0 or `index` is not below it.
    pub fn new(index: usize, count: usize) -> Result<Self, String> {
        if count == 0 {
            return Err("the shard count must be at least 1".to_owned());
        }
        if index >= count {
            return Err(format!(
                "shard index {index} is out of range: {count} shard(s) are numbered 0..{count}"
            ));
        }
        Ok(Self { index, count })
    }

    /// This shard's frames of `selected`: `[floor(I n / N), floor((I + 1) n / N))` offset by
    /// the selection's start, for `n` selected frames, so that the shards of a count cover
    /// the selection in order, each frame once, their sizes differing by at most one.
    ///
    /// # Errors
    /// When the shard has no frame (more shards than frames).
    pub fn frames(&self, selected: Range<usize>) -> Result<Range<usize>, String> {
        let n = selected.len();
        let at = |i: usize| selected.start + i * n / self.count;
        let part = at(self.index)..at(self.index + 1);
        if part.is_empty() {
            return Err(format!(
                "shard {self} has no frame: {} shards split {n} frame(s) ({}..{}); use at \
                 most {n} shard(s)",
                self.count, selected.start, selected.end
            ));
        }
        Ok(part)
    }

    /// Parses `I/N`.
    ///
    /// # Errors
    /// When the text is not two integers around a slash, or the shard is out of range.
    pub fn parse(text: &str) -> Result<Self, String> {
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| format!("expected I/N (e.g. 0/4) or `auto`, got '{text}'"))?;
        let number = |s: &str| {
            s.trim()
                .parse::<usize>()
                .map_err(|_| format!("'{s}' in '{text}' is not a non-negative integer"))
        };
        Self::new(number(i)?, number(n)?)
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// A `--shard` value: a given shard, or `auto` (from the environment).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardSpec {
    /// `I/N`.
    Given(Shard),
    /// `auto`: see [`ShardOptions::resolve`].
    Auto,
}

impl ShardSpec {
    /// Parses `I/N` or `auto`.
    ///
    /// # Errors
    /// As [`Shard::parse`].
    pub fn parse(text: &str) -> Result<Self, String> {
        if text.trim() == "auto" {
            Ok(Self::Auto)
        } else {
            Shard::parse(text).map(Self::Given)
        }
    }
}

/// The Slurm array variables `--shard auto` reads.
pub const SLURM_VARIABLES: [&str; 4] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_STEP",
];

/// The Kubernetes indexed job's variable `--shard auto` reads (with `--shard-count`).
pub const KUBERNETES_INDEX: &str = "JOB_COMPLETION_INDEX";

/// Which part of the selected frames (`--frames`, all by default) the run takes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct ShardOptions {
    /// Run shard I of N equal parts of the frames (0-based; `I/N`), or `auto`: from a Slurm
    /// array task (SLURM_ARRAY_TASK_ID, _MIN, _STEP and _COUNT) or a Kubernetes indexed job
    /// (JOB_COMPLETION_INDEX with --shard-count). Merge the shards with `trisplat merge`.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "I/N|auto", value_parser = ShardSpec::parse)
    )]
    pub shard: Option<ShardSpec>,
    /// The number of shards, for `--shard auto` in a Kubernetes indexed job (its
    /// completions); with Slurm it must equal SLURM_ARRAY_TASK_COUNT if given.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "N", requires = "shard", value_parser = super::arg::parse_positive)
    )]
    pub shard_count: Option<usize>,
}

impl ShardOptions {
    /// The shard this run is, `None` for the whole selection; `auto` is read from `env` (a
    /// lookup of environment variables: `|name| std::env::var(name).ok()`).
    ///
    /// A Slurm array task `id` of an array starting at `min` with step `step` (1 when unset)
    /// is shard `(id - min) / step` of `SLURM_ARRAY_TASK_COUNT`; a Kubernetes pod is shard
    /// `JOB_COMPLETION_INDEX` of `--shard-count`. Slurm's variables win when both are set.
    ///
    /// # Errors
    /// A message naming the variables and their values when they are missing, not numbers,
    /// or inconsistent (an index beyond the count, a task id off the array's steps, a
    /// `--shard-count` that differs from Slurm's), or `--shard-count` without `auto`.
    pub fn resolve(&self, env: &dyn Fn(&str) -> Option<String>) -> Result<Option<Shard>, String> {
        match (self.shard, self.shard_count) {
            (None, None) => Ok(None),
            (None, Some(_)) => Err("--shard-count is only for --shard auto".to_owned()),
            (Some(ShardSpec::Given(s)), None) => Ok(Some(s)),
            (Some(ShardSpec::Given(s)), Some(_)) => Err(format!(
                "--shard-count is only for --shard auto (--shard {s} names its count)"
            )),
            (Some(ShardSpec::Auto), count) => auto_shard(count, env).map(Some),
        }
    }
}

/// `--shard auto`: see [`ShardOptions::resolve`].
fn auto_shard(count: Option<usize>, env: &dyn Fn(&str) -> Option<String>) -> Result<Shard, String> {
    let number = |name: &str| -> Result<Option<usize>, String> {
        env(name)
            .map(|v| {
                v.trim().parse::<usize>().map_err(|_| {
                    format!("--shard auto: {name}={v:?} is not a non-negative integer")
                })
            })
            .transpose()
    };
    if let Some(id) = number(SLURM_VARIABLES[0])? {
        let slurm_count = number(SLURM_VARIABLES[1])?.ok_or_else(|| {
            format!(
                "--shard auto: SLURM_ARRAY_TASK_ID={id} is set but SLURM_ARRAY_TASK_COUNT is \
                 not (is this a Slurm array task, `sbatch --array`?)"
            )
        })?;
        let min = number(SLURM_VARIABLES[2])?.unwrap_or(0);
        let step = number(SLURM_VARIABLES[3])?.unwrap_or(1).max(1);
        let inconsistent = |why: String| {
            format!(
                "--shard auto: inconsistent Slurm variables (SLURM_ARRAY_TASK_ID={id}, \
                 SLURM_ARRAY_TASK_MIN={min}, SLURM_ARRAY_TASK_STEP={step}, \
                 SLURM_ARRAY_TASK_COUNT={slurm_count}): {why}"
            )
        };
        if id < min {
            return Err(inconsistent(
                "the task id is below the array's first".to_owned(),
            ));
        }
        if (id - min) % step != 0 {
            return Err(inconsistent(
                "the task id is not on the array's steps".to_owned(),
            ));
        }
        if let Some(n) = count.filter(|&n| n != slurm_count) {
            return Err(inconsistent(format!("--shard-count says {n}")));
        }
        return Shard::new((id - min) / step, slurm_count).map_err(inconsistent);
    }
    if let Some(index) = number(KUBERNETES_INDEX)? {
        let n = count.ok_or_else(|| {
            format!(
                "--shard auto: {KUBERNETES_INDEX}={index} is set: give the job's completions \
                 as --shard-count N"
            )
        })?;
        return Shard::new(index, n).map_err(|e| {
            format!("--shard auto: {KUBERNETES_INDEX}={index}, --shard-count {n}: {e}")
        });
    }
    Err(format!(
        "--shard auto: neither a Slurm array task (SLURM_ARRAY_TASK_ID and \
         SLURM_ARRAY_TASK_COUNT) nor a Kubernetes indexed job ({KUBERNETES_INDEX} with \
         --shard-count) is in the environment; give --shard I/N"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn env(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let map: HashMap<String, String> = pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect();
        move |name| map.get(name).cloned()
    }

    fn auto(count: Option<usize>) -> ShardOptions {
        ShardOptions {
            shard: Some(ShardSpec::Auto),
            shard_count: count,
        }
    }

    #[test]
    fn shards_cover_the_selection_once_in_order() {
        for n in 1..40 {
            for count in 1..=n {
                let mut next = 5;
                for index in 0..count {
                    let part = Shard::new(index, count)
                        .expect("shard")
                        .frames(5..5 + n)
                        .expect("frames");
                    assert_eq!(part.start, next, "n {n} count {count} index {index}");
                    assert!(part.len() == n / count || part.len() == n / count + 1);
                    next = part.end;
                }
                assert_eq!(next, 5 + n);
            }
        }
        let e = Shard::new(0, 5)
            .expect("shard")
            .frames(0..3)
            .expect_err("empty");
        assert!(e.contains("use at most 3"), "{e}");
    }

    #[test]
    fn given_shards_parse_and_bad_ones_are_refused() {
        assert_eq!(
            ShardSpec::parse("2/4"),
            Ok(ShardSpec::Given(Shard { index: 2, count: 4 }))
        );
        assert_eq!(ShardSpec::parse("auto"), Ok(ShardSpec::Auto));
        for (bad, says) in [
            ("4/4", "out of range"),
            ("0/0", "at least 1"),
            ("-1/4", "not a non-negative"),
            ("2", "expected I/N"),
            ("a/b", "not a non-negative"),
        ] {
            let e = ShardSpec::parse(bad).expect_err(bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn slurm_array_tasks_are_numbered_from_the_array_start() {
        let e = env(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(
            auto(None).resolve(&e),
            Ok(Some(Shard { index: 2, count: 4 }))
        );
        let stepped = env(&[
            ("SLURM_ARRAY_TASK_ID", "6"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(
            auto(Some(4)).resolve(&stepped),
            Ok(Some(Shard { index: 3, count: 4 }))
        );
    }

    #[test]
    fn missing_or_inconsistent_variables_are_named() {
        type Vars<'a> = &'a [(&'a str, &'a str)];
        let cases: [(Vars<'_>, Option<usize>, &str); 7] = [
            (&[], None, "neither a Slurm array task"),
            (
                &[("SLURM_ARRAY_TASK_ID", "1")],
                None,
                "SLURM_ARRAY_TASK_COUNT is not",
            ),
            (
                &[
                    ("SLURM_ARRAY_TASK_ID", "4"),
                    ("SLURM_ARRAY_TASK_COUNT", "4"),
                ],
                None,
                "out of range",
            ),
            (
                &[
                    ("SLURM_ARRAY_TASK_ID", "x"),
                    ("SLURM_ARRAY_TASK_COUNT", "4"),
                ],
                None,
                "SLURM_ARRAY_TASK_ID=\"x\" is not",
            ),
            (
                &[
                    ("SLURM_ARRAY_TASK_ID", "1"),
                    ("SLURM_ARRAY_TASK_COUNT", "4"),
                ],
                Some(3),
                "--shard-count says 3",
            ),
            (&[("JOB_COMPLETION_INDEX", "2")], None, "--shard-count N"),
            (&[("JOB_COMPLETION_INDEX", "2")], Some(2), "out of range"),
        ];
        for (vars, count, says) in cases {
            let e = auto(count).resolve(&env(vars)).expect_err(says);
            assert!(e.contains(says), "{vars:?}: {e}");
        }
        assert_eq!(
            auto(Some(3)).resolve(&env(&[("JOB_COMPLETION_INDEX", "2")])),
            Ok(Some(Shard { index: 2, count: 3 }))
        );
        let given = ShardOptions {
            shard: Some(ShardSpec::Given(Shard { index: 0, count: 2 })),
            shard_count: Some(2),
        };
        assert!(given.resolve(&env(&[])).is_err());
    }
}
