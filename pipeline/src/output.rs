//! Output files: never over an input, and removed again when a run fails (docs/conventions.md §10).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use crate::error::PipelineError;

/// Name of frame `frame`'s file in an output folder (`frame_000042.ply`).
#[must_use]
pub fn frame_file(frame: usize) -> String {
    format!("frame_{frame:06}.ply")
}

/// The input files of a run, compared by canonical path (symbolic links and `..` resolved).
#[derive(Clone, Debug, Default)]
pub struct Inputs(HashSet<PathBuf>);

impl Inputs {
    /// The canonical paths of `paths` that exist (folders included: their files are not
    /// listed).
    #[must_use]
    pub fn new(paths: &[PathBuf]) -> Self {
        Self(paths.iter().filter_map(|p| p.canonicalize().ok()).collect())
    }

    /// Errors when writing `path` would replace one of the inputs.
    ///
    /// # Errors
    /// [`PipelineError::OverwriteInput`].
    pub fn check(&self, path: &Path) -> Result<(), PipelineError> {
        if path.canonicalize().is_ok_and(|c| self.0.contains(&c)) {
            return Err(PipelineError::OverwriteInput {
                path: path.to_path_buf(),
            });
        }
        Ok(())
    }
}

/// Files a run created, removed again if the run fails.
#[derive(Clone, Debug, Default)]
pub struct Created(Vec<PathBuf>);

impl Created {
    /// Records `path` as created by this run unless it `existed` before.
    pub fn note(&mut self, path: &Path, existed: bool) {
        if !existed {
            self.0.push(path.to_path_buf());
        }
    }

    /// Removes every recorded file (best effort: the error being reported matters more than a
    /// leftover file).
    pub fn remove(&self) {
        for p in &self.0 {
            let _ = std::fs::remove_file(p);
        }
    }
}
