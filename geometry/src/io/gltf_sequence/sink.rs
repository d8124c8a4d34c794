//! Where the buffer's bytes go: nowhere (the layout pass), a vector, the output file, or a
//! spool file (compressed buffers, whose length is known only once they are made).

use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use crate::io::error::IoError;

/// Where the buffer's bytes go.
pub(super) trait Sink {
    /// Appends `bytes`.
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError>;
}

/// Counts the bytes (the layout pass).
pub(super) struct Counted(pub(super) usize);

impl Sink for Counted {
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.0 += bytes.len();
        Ok(())
    }
}

impl Sink for Vec<u8> {
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.extend_from_slice(bytes);
        Ok(())
    }
}

/// Writes straight into the output (the byte pass of a `.glb`).
pub(super) struct Stream<'a> {
    pub(super) out: &'a mut dyn Write,
    pub(super) path: &'a Path,
    pub(super) written: usize,
}

impl Sink for Stream<'_> {
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.written += bytes.len();
        self.out
            .write_all(bytes)
            .map_err(|e| IoError::os(self.path, e))
    }
}

/// An unnamed temporary file beside the output (removed by the system when closed), holding
/// a compressed buffer until its length is known and the `.glb` can be written around it.
pub(super) struct Spool<'a> {
    file: BufWriter<File>,
    path: &'a Path,
    /// Bytes written so far.
    pub(super) len: usize,
}

impl<'a> Spool<'a> {
    /// A spool in the folder of `path` (the output; errors name it).
    pub(super) fn beside(path: &'a Path) -> Result<Self, IoError> {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let file = tempfile::tempfile_in(dir).map_err(|e| IoError::os(path, e))?;
        Ok(Self {
            file: BufWriter::with_capacity(1 << 20, file),
            path,
            len: 0,
        })
    }

    /// Copies the spooled bytes into `out`.
    pub(super) fn copy_to(self, out: &mut dyn Write) -> Result<(), IoError> {
        let path = self.path;
        let mut file = self
            .file
            .into_inner()
            .map_err(|e| IoError::os(path, e.into_error()))?;
        file.rewind().map_err(|e| IoError::os(path, e))?;
        std::io::copy(&mut file, out).map_err(|e| IoError::os(path, e))?;
        Ok(())
    }
}

impl Sink for Spool<'_> {
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.len += bytes.len();
        self.file
            .write_all(bytes)
            .map_err(|e| IoError::os(self.path, e))
    }
}
