//! Atomic file writes: temporary file in the destination folder, then rename.

use std::io::{BufWriter, Write};
use std::path::Path;

use super::IoError;

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
    let tmp = tempfile::Builder::new()
        .prefix(".trisplat-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(|e| IoError::os(path, e))?;
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
