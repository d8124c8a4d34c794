//! Atomic file writes: temporary file in the destination folder, then rename.
//!
//! The temporary files being written are registered, so that an interrupt handler can stop
//! new writes and remove them ([`abandon_writes`]): Ctrl-C leaves neither a half-written
//! output nor a `.trisplat-*.tmp` file behind.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use super::error::IoError;

/// Writes `path` by calling `write` on a buffered temporary file in the same folder, then
/// renaming it over `path`. On any error the temporary file is removed and `path` is untouched.
///
/// # Errors
/// [`IoError::Os`] when the folder is not writable or the write or rename fails, or whatever
/// error `write` returns.
pub fn write_atomically<F>(path: &Path, write: F) -> Result<(), IoError>
where
    F: FnOnce(&mut dyn Write) -> Result<(), IoError>,
{
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let (tmp, _registered) = {
        let mut writes = IN_FLIGHT
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if writes.stopping {
            return Err(IoError::os(
                path,
                std::io::Error::new(std::io::ErrorKind::Interrupted, "the run was interrupted"),
            ));
        }
        let tmp = tempfile::Builder::new()
            .prefix(".trisplat-")
            .suffix(".tmp")
            .tempfile_in(dir)
            .map_err(|e| IoError::os(path, e))?;
        writes.files.push(tmp.path().to_path_buf());
        let registered = Registered(tmp.path().to_path_buf());
        (tmp, registered)
    };
    set_output_permissions(path, tmp.as_file()).map_err(|e| IoError::os(path, e))?;
    let mut writer = BufWriter::with_capacity(1 << 20, tmp);
    write(&mut writer)?;
    let tmp = writer
        .into_inner()
        .map_err(|e| IoError::os(path, e.into_error()))?;
    tmp.as_file()
        .sync_data()
        .map_err(|e| IoError::os(path, e))?;
    tmp.persist(path).map_err(|e| IoError::os(path, e.error))?;
    Ok(())
}

/// The atomic writes in progress.
struct InFlight {
    /// Their temporary files.
    files: Vec<PathBuf>,
    /// Set by [`abandon_writes`]: no new write starts.
    stopping: bool,
}

static IN_FLIGHT: Mutex<InFlight> = Mutex::new(InFlight {
    files: Vec::new(),
    stopping: false,
});

/// A registered temporary file, unregistered when the write ends (renamed or removed).
struct Registered(PathBuf);

impl Drop for Registered {
    fn drop(&mut self) {
        let mut writes = IN_FLIGHT
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(k) = writes.files.iter().position(|p| *p == self.0) {
            writes.files.swap_remove(k);
        }
    }
}

/// For an interrupt handler: stops every atomic write from starting and removes the temporary
/// files of those in progress (their outputs are never created: the rename that would have
/// made them fails). Returns how many were removed. The caller then ends the process.
pub fn abandon_writes() -> usize {
    let mut writes = IN_FLIGHT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    writes.stopping = true;
    writes
        .files
        .drain(..)
        .filter(|p| std::fs::remove_file(p).is_ok())
        .count()
}

/// Temporary files are created owner-only (0600); the output gets the permissions of the file
/// it replaces, or 0644 (read for everyone, as a plain create under the usual umask) when new.
#[cfg(unix)]
fn set_output_permissions(path: &Path, file: &std::fs::File) -> std::io::Result<()> {
    use std::os::unix::fs::PermissionsExt as _;
    const NEW_FILE_MODE: u32 = 0o644;
    let permissions = match std::fs::metadata(path) {
        Ok(existing) => existing.permissions(),
        Err(_) => std::fs::Permissions::from_mode(NEW_FILE_MODE),
    };
    file.set_permissions(permissions)
}

/// Elsewhere the temporary file's default permissions are kept.
#[cfg(not(unix))]
fn set_output_permissions(_path: &Path, _file: &std::fs::File) -> std::io::Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.ply");
        let err = write_atomically(&target, |w| {
            w.write_all(b"partial").map_err(|e| IoError::os("x", e))?;
            Err(IoError::malformed("x", "vertex 3", "bad"))
        });
        assert!(err.is_err());
        assert!(!target.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[cfg(unix)]
    #[test]
    fn new_files_are_readable_by_everyone() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("new.txt");
        write_atomically(&target, |w| {
            w.write_all(b"x").map_err(|e| IoError::os("x", e))
        })
        .unwrap();
        let mode = std::fs::metadata(&target).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o644);
    }

    #[test]
    fn successful_write_replaces_file() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.txt");
        std::fs::write(&target, b"old").unwrap();
        write_atomically(&target, |w| {
            w.write_all(b"new").map_err(|e| IoError::os("x", e))
        })
        .unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }
}
