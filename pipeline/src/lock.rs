//! One run per output folder: `extract` and `merge` hold an advisory lock on
//! `DIR/.trisplat.lock` while they write into `DIR`, so a second run into the same folder is
//! refused at once instead of mixing its files with the first's. The operating system releases
//! the lock when the process ends, however it ends (Ctrl-C, kill, crash), so a killed run never
//! leaves a stale lock behind; the empty lock file itself stays and is harmless.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::Path;

use crate::error::PipelineError;

/// The lock file's name inside the output folder.
pub const LOCK_FILE: &str = ".trisplat.lock";

/// The held lock of an output folder; dropping it releases the lock.
#[derive(Debug)]
pub struct FolderLock {
    _file: File,
}

impl FolderLock {
    /// Takes the lock of the existing folder `dir`, without waiting.
    ///
    /// # Errors
    /// [`PipelineError::Busy`] when another process holds it, [`PipelineError::Lock`] when the
    /// lock file cannot be opened or locked.
    pub fn acquire(dir: &Path) -> Result<Self, PipelineError> {
        let path = dir.join(LOCK_FILE);
        let file = OpenOptions::new()
            .create(true)
            .write(true)
            .truncate(false)
            .open(&path)
            .map_err(|cause| PipelineError::Lock {
                path: path.clone(),
                cause,
            })?;
        match file.try_lock() {
            Ok(()) => Ok(Self { _file: file }),
            Err(TryLockError::WouldBlock) => Err(PipelineError::Busy {
                path: dir.to_path_buf(),
                lock: LOCK_FILE.to_owned(),
            }),
            Err(TryLockError::Error(cause)) => Err(PipelineError::Lock { path, cause }),
        }
    }

    /// Takes the lock of `dir` when it has a lock file, without creating one (so a folder
    /// that is only read is not written to); `None` when it has none.
    ///
    /// # Errors
    /// As [`FolderLock::acquire`].
    pub fn acquire_existing(dir: &Path) -> Result<Option<Self>, PipelineError> {
        if dir.join(LOCK_FILE).is_file() {
            Self::acquire(dir).map(Some)
        } else {
            Ok(None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_holder_is_refused_until_the_first_lets_go() {
        let dir = tempfile::tempdir().expect("temp dir");
        let first = FolderLock::acquire(dir.path()).expect("free folder");
        let second = FolderLock::acquire(dir.path());
        assert!(
            matches!(&second, Err(PipelineError::Busy { .. })),
            "{second:?}"
        );
        let message = second.expect_err("busy").to_string();
        assert!(message.contains("another trisplat run") && message.contains(LOCK_FILE));
        drop(first);
        FolderLock::acquire(dir.path()).expect("released");
    }
}
