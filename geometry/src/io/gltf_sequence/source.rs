//! Where the frames come from: memory, one mesh file per frame, or a run of another source.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use crate::io::error::IoError;
use crate::io::files::read_mesh;
use crate::mesh::TriMesh;

/// The frames of a sequence, handed to the writer one at a time: the writer reads each frame
/// up to three times (checks, sizes, bytes) and never holds more than the first frame, the
/// previous frame's triangles and the frame at hand, so a sequence read from files is written
/// in memory independent of its length.
pub trait FrameSource {
    /// Number of frames.
    fn frame_count(&self) -> usize;

    /// Frame `k` (`k < frame_count()`).
    ///
    /// # Errors
    /// The source's own (an unreadable frame file, named).
    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError>;
}

/// Frame `k` of `frames`, which the survey saw with `vertices` vertices.
///
/// # Errors
/// The source's errors; a frame whose vertex count is no longer `vertices` (the frame
/// changed while the sequence was written), named by `path` and the frame.
pub(super) fn surveyed_frame<'a>(
    path: &Path,
    frames: &'a dyn FrameSource,
    k: usize,
    vertices: usize,
) -> Result<Cow<'a, TriMesh>, IoError> {
    let frame = frames.frame(k)?;
    if frame.vertex_count() != vertices {
        return Err(IoError::malformed(
            path,
            format!("frame {k}"),
            format!(
                "has {} vertices, {vertices} when the sequence was surveyed \
                 (a frame changed while the sequence was written)",
                frame.vertex_count(),
            ),
        ));
    }
    Ok(frame)
}

impl FrameSource for &[TriMesh] {
    fn frame_count(&self) -> usize {
        self.len()
    }

    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError> {
        self.get(k)
            .map(Cow::Borrowed)
            .ok_or_else(|| IoError::malformed(Path::new(""), format!("frame {k}"), "no such frame"))
    }
}

/// Frames stored one per mesh file (any format [`super::read_mesh`] reads), read when needed.
#[derive(Clone, Copy, Debug)]
pub struct FrameFiles<'a>(pub &'a [PathBuf]);

impl FrameSource for FrameFiles<'_> {
    fn frame_count(&self) -> usize {
        self.0.len()
    }

    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError> {
        let path = self.0.get(k).ok_or_else(|| {
            IoError::malformed(Path::new(""), format!("frame {k}"), "no such frame file")
        })?;
        read_mesh(path).map(Cow::Owned)
    }
}

/// Frames `run` of another source.
pub(super) struct FrameRun<'a> {
    pub(super) frames: &'a dyn FrameSource,
    pub(super) run: std::ops::Range<usize>,
}

impl FrameSource for FrameRun<'_> {
    fn frame_count(&self) -> usize {
        self.run.len()
    }

    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError> {
        self.frames.frame(self.run.start + k)
    }
}
