//! The run journal, `journal.jsonl` in the output folder: what a run is (its configuration) and
//! what it has done, one JSON line per frame, appended and flushed as each frame's files exist.
//!
//! It is what makes a long run safe to interrupt: a run killed at any point (Ctrl-C, `kill`, a
//! crash) leaves complete frame files (they are written atomically) and a journal whose
//! complete lines name them; `--resume` reads it back, refuses a changed configuration, and
//! runs only the frames it does not list (an incomplete last line is dropped). Without
//! `--resume` or `--force`, a folder that holds a journal or a report is refused, so two runs
//! never mix their outputs.
//!
//! Lines: first `{"kind":"run","version":…,"config":…}`, then per frame either
//! `{"kind":"frame","frame":F,"time":…,"deform_ms":…,"collapsed_triangles":…,"methods":{NAME: FrameRecord},"delaunay":…}`
//! or `{"kind":"failed","frame":F,"error":"…"}`.

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use trisplat_geometry::io::{IoError, write_atomically};

use crate::config::ExtractConfig;
use crate::error::PipelineError;
use crate::records::{FailedFrame, FrameEntry};

/// File name of the journal in the output folder.
pub const JOURNAL: &str = "journal.jsonl";

#[derive(serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum Line {
    Run { version: String, config: String },
    Frame(FrameEntry),
    Failed(FailedFrame),
}

/// The journal of the run in progress, open for appending.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
}

/// What a resumed journal held: the frames done (the last entry per frame wins; failed frames
/// are not kept, they are run again).
#[derive(Debug, Default)]
pub struct Previous {
    /// Frames done, by frame index.
    pub done: BTreeMap<usize, FrameEntry>,
}

/// The configuration as the journal records it: everything that decides the outputs (the
/// output folder itself excluded, so a moved folder still resumes).
#[must_use]
pub fn fingerprint(config: &ExtractConfig) -> String {
    let mut c = config.clone();
    c.output = PathBuf::new();
    // Limits decide what is refused, not what is written.
    c.options.limits = crate::config::Limits::default();
    format!("{c:?}")
}

impl Journal {
    /// Starts a new journal in `dir` with the run line (replacing any old one).
    ///
    /// # Errors
    /// [`PipelineError::Io`] when it cannot be written.
    pub fn create(dir: &Path, config: &ExtractConfig) -> Result<Self, PipelineError> {
        Self::write_and_open(dir, config, &[])
    }

    /// Reads the journal in `dir` for `--resume`: the frames it lists as done. The journal is
    /// rewritten without an incomplete last line and without failures (they are retried).
    ///
    /// # Errors
    /// [`PipelineError::Resume`] when there is no journal or it was written for another
    /// configuration or version; [`PipelineError::Io`] when it cannot be read or rewritten.
    pub fn resume(dir: &Path, config: &ExtractConfig) -> Result<(Self, Previous), PipelineError> {
        let path = dir.join(JOURNAL);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                PipelineError::Resume {
                    path: dir.to_path_buf(),
                    problem: format!("nothing to resume: no {JOURNAL}"),
                }
            } else {
                PipelineError::Io(IoError::os(&path, e))
            }
        })?;
        let mut lines = text.split_inclusive('\n').filter(|l| l.ends_with('\n'));
        let header: Option<Line> = lines.next().and_then(|l| serde_json::from_str(l).ok());
        match header {
            Some(Line::Run { version, config: c })
                if version == env!("CARGO_PKG_VERSION") && c == fingerprint(config) => {}
            Some(Line::Run { version, .. }) if version != env!("CARGO_PKG_VERSION") => {
                return Err(PipelineError::Resume {
                    path: path.clone(),
                    problem: format!(
                        "the run was started by trisplat {version}, this is {}",
                        env!("CARGO_PKG_VERSION")
                    ),
                });
            }
            Some(_) => {
                return Err(PipelineError::Resume {
                    path: path.clone(),
                    problem: "the run was started with other inputs or options; start over with \
                              --force, or resume with the same arguments"
                        .to_owned(),
                });
            }
            None => {
                return Err(PipelineError::Resume {
                    path: path.clone(),
                    problem: "its first line is not a run record".to_owned(),
                });
            }
        }
        let mut previous = Previous::default();
        // The lines kept, verbatim, by frame (the last one of a frame wins).
        let mut kept: BTreeMap<usize, &str> = BTreeMap::new();
        for text in lines {
            // A line cut short by a kill does not parse (it was the last one): skipped.
            if let Ok(Line::Frame(entry)) = serde_json::from_str(text) {
                kept.insert(entry.frame, text);
                previous.done.insert(entry.frame, entry);
            }
        }
        let kept: Vec<&str> = kept.into_values().collect();
        let journal = Self::write_and_open(dir, config, &kept)?;
        Ok((journal, previous))
    }

    /// Writes the run line and the frame lines `kept` atomically, then opens the file for
    /// appending.
    fn write_and_open(
        dir: &Path,
        config: &ExtractConfig,
        kept: &[&str],
    ) -> Result<Self, PipelineError> {
        let path = dir.join(JOURNAL);
        let mut text = line(&Line::Run {
            version: env!("CARGO_PKG_VERSION").to_owned(),
            config: fingerprint(config),
        });
        for l in kept {
            text.push_str(l);
        }
        write_atomically(&path, |w| {
            w.write_all(text.as_bytes())
                .map_err(|e| IoError::os(&path, e))
        })?;
        let file = OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(|e| IoError::os(&path, e))?;
        Ok(Self { path, file })
    }

    /// Appends a frame done (its files already written).
    ///
    /// # Errors
    /// [`PipelineError::Io`] when the line cannot be written.
    pub fn frame(&mut self, entry: &FrameEntry) -> Result<(), PipelineError> {
        self.append(&Line::Frame(entry.clone()))
    }

    /// Appends a failed frame.
    ///
    /// # Errors
    /// [`PipelineError::Io`] when the line cannot be written.
    pub fn failed(&mut self, failed: &FailedFrame) -> Result<(), PipelineError> {
        self.append(&Line::Failed(failed.clone()))
    }

    fn append(&mut self, l: &Line) -> Result<(), PipelineError> {
        self.file
            .write_all(line(l).as_bytes())
            .and_then(|()| self.file.sync_data())
            .map_err(|e| PipelineError::Io(IoError::os(&self.path, e)))
    }
}

/// One JSON line (serialising these plain records cannot fail).
fn line(l: &Line) -> String {
    let mut s = serde_json::to_string(l).unwrap_or_default();
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::MetricOptions;
    use crate::config::{ExtractOptions, Method};

    fn config(tau: f64) -> ExtractConfig {
        ExtractConfig {
            template: PathBuf::from("t.glb"),
            animation: None,
            gaussians: None,
            methods: vec![Method::Alpha],
            output: PathBuf::from("out"),
            frames: None,
            gt: None,
            options: ExtractOptions {
                metrics: MetricOptions {
                    tau,
                    ..Default::default()
                },
                ..ExtractOptions::default()
            },
        }
    }

    fn entry(frame: usize) -> FrameEntry {
        FrameEntry {
            frame,
            time: frame as f64 / 30.0,
            deform_ms: 0.1,
            collapsed_triangles: 0,
            methods: BTreeMap::new(),
            delaunay: None,
        }
    }

    fn problem(result: Result<(Journal, Previous), PipelineError>) -> String {
        match result {
            Err(PipelineError::Resume { problem, .. }) => problem,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn resume_keeps_complete_frames_and_refuses_another_run() {
        let dir = tempfile::tempdir().expect("dir");
        let c = config(0.0025);
        assert!(problem(Journal::resume(dir.path(), &c)).contains("nothing to resume"));
        let mut j = Journal::create(dir.path(), &c).expect("create");
        j.frame(&entry(0)).expect("frame 0");
        j.failed(&FailedFrame {
            frame: 1,
            error: "broken".into(),
        })
        .expect("failed 1");
        j.frame(&entry(2)).expect("frame 2");
        drop(j);
        let path = dir.path().join(JOURNAL);
        let mut text = std::fs::read_to_string(&path).expect("read");
        text.push_str(r#"{"kind":"frame","frame":3,"#);
        std::fs::write(&path, &text).expect("cut");
        let (_, previous) = Journal::resume(dir.path(), &c).expect("resume");
        assert_eq!(previous.done.keys().copied().collect::<Vec<_>>(), [0, 2]);
        assert_eq!(previous.done[&2], entry(2));
        // Rewritten without the cut line and the failure: three complete lines.
        let rewritten = std::fs::read_to_string(&path).expect("read");
        assert_eq!(rewritten.lines().count(), 3, "{rewritten}");
        assert!(rewritten.ends_with('\n'));
        // Another configuration, another version, not a journal.
        assert!(problem(Journal::resume(dir.path(), &config(0.01))).contains("other inputs"));
        let mut relative = c.clone();
        relative.options.metrics.tau_fraction = Some(0.01);
        assert!(problem(Journal::resume(dir.path(), &relative)).contains("other inputs"));
        let other_version = rewritten.replacen(env!("CARGO_PKG_VERSION"), "0.0.0-other", 1);
        std::fs::write(&path, other_version).expect("write");
        assert!(problem(Journal::resume(dir.path(), &c)).contains("trisplat 0.0.0-other"));
        std::fs::write(&path, "not json\n").expect("write");
        assert!(problem(Journal::resume(dir.path(), &c)).contains("not a run record"));
    }
}
