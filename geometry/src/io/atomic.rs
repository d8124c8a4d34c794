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
