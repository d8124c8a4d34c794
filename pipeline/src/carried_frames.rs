//! The frames of carried meshes handed to the sequence writers (the `.glb`, the USD cache)
//! from the run itself, not read back from frame files (issue #31).
//!
//! A carried frame is its key mesh with every vertex placed on the template of that frame
//! (module `carry`), so the run needs to keep only the key meshes bound to the template (the
//! carriers keep them, [`crate::topology::Carrier::keep_keys`]) and the welded template's
//! positions of each frame. At the end the positions of every frame of the report are
//! computed again from the animation (the same function of the frame the run placed by) into
//! an unnamed spool file, and each method's frames are placed again, in order, as the writers
//! ask for them: the same `f64` arithmetic as the run, then the mesh as its frame file would
//! hold it (the PLY encoding applied in memory: colours on the 8-bit grid), so the outputs are
//! byte-identical to those assembled from the frame files.
//!
//! This needs no frame file, so a run without the `meshes` target writes none, and a resumed
//! run needs none either: frames done by an earlier process are placed like the others, their
//! keys met again while the carriers replay the track (a run whose frames were all done
//! replays it at the end, `Session::see_frames_before`).

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::ply::{mesh_to_ply, ply_to_mesh};
use trisplat_geometry::io::{FrameSource, IoError, PlyExtras};

use crate::carry::CarriedMesh;
use crate::config::{ExtractOptions, OutputTarget};

/// Whether a run's glTF and USD cache are made from its carried frames rather than from frame
/// files: the topology carries, an output is assembled from the frames, and no frame has its
/// own colours (`--error-colors` colours each frame by its distances).
#[must_use]
pub fn carries_frames(options: &ExtractOptions) -> bool {
    options.topology.topology.carries()
        && !options.outputs.error_colors
        && options
            .outputs
            .targets
            .iter()
            .any(|t| t.assembled_from_frames())
}

/// Whether the run writes frame files: asked for (`meshes`), or the glTF or USD cache is
/// assembled from them.
#[must_use]
pub fn writes_frame_files(options: &ExtractOptions) -> bool {
    options.outputs.writes(OutputTarget::Meshes)
        || (options.outputs.writes_frame_files() && !carries_frames(options))
}

/// The welded template's positions (local, as the carriers placed by) of a run's frames, in
/// an unnamed file beside the outputs (removed by the system when closed).
pub struct TemplateSpool {
    /// The spool, read under the lock (the writers of several methods share it).
    file: Mutex<File>,
    /// Each frame's byte offset.
    offsets: BTreeMap<usize, u64>,
    /// Vertices per frame.
    vertices: usize,
    /// The output folder (named in errors).
    folder: PathBuf,
}

impl TemplateSpool {
    /// The positions of `frames` given by `positions`, spooled in `folder`.
    ///
    /// # Errors
    /// `positions`'s errors; [`IoError::Os`] when the spool cannot be written; a frame whose
    /// vertex count differs from the first's.
    pub fn write<E: From<IoError>>(
        folder: &Path,
        frames: impl IntoIterator<Item = usize>,
        mut positions: impl FnMut(usize) -> Result<Vec<DVec3>, E>,
    ) -> Result<Self, E> {
        let os = |e| IoError::os(folder, e);
        let file = tempfile::tempfile_in(folder).map_err(os)?;
        let mut writer = BufWriter::with_capacity(1 << 20, file);
        let (mut offsets, mut vertices, mut at) = (BTreeMap::new(), None, 0u64);
        let mut bytes = Vec::new();
        for f in frames {
            let p = positions(f)?;
            if *vertices.get_or_insert(p.len()) != p.len() {
                return Err(IoError::malformed(
                    folder,
                    format!("frame {f}"),
                    "the template's vertex count changed during the run",
                )
                .into());
            }
            bytes.clear();
            bytes.extend(
                p.iter()
                    .flat_map(|v| v.to_array())
                    .flat_map(f64::to_le_bytes),
            );
            writer.write_all(&bytes).map_err(os)?;
            offsets.insert(f, at);
            at += bytes.len() as u64;
        }
        let file = writer.into_inner().map_err(|e| os(e.into_error()))?;
        Ok(Self {
            file: Mutex::new(file),
            offsets,
            vertices: vertices.unwrap_or(0),
            folder: folder.to_path_buf(),
        })
    }

    /// The positions of frame `frame`.
    fn read(&self, frame: usize) -> Result<Vec<DVec3>, IoError> {
        let offset = self.offsets.get(&frame).ok_or_else(|| {
            IoError::malformed(&self.folder, format!("frame {frame}"), "not spooled")
        })?;
        let mut bytes = vec![0u8; self.vertices * 24];
        {
            let mut file = self.file.lock().unwrap_or_else(PoisonError::into_inner);
            file.seek(SeekFrom::Start(*offset))
                .and_then(|_| file.read_exact(&mut bytes))
                .map_err(|e| IoError::os(&self.folder, e))?;
        }
        Ok(bytes
            .chunks_exact(24)
            .map(|c| {
                let x = |i: usize| {
                    let mut b = [0u8; 8];
                    b.copy_from_slice(&c[8 * i..8 * i + 8]);
                    f64::from_le_bytes(b)
                };
                DVec3::new(x(0), x(1), x(2))
            })
            .collect())
    }
}

/// One method's frames placed again from its kept keys: a [`FrameSource`] for the writers.
pub struct CarriedFrames<'a> {
    /// Each frame handed out: its animation frame and its key frame.
    frames: Vec<(usize, usize)>,
    /// The method's keys, by key frame.
    keys: &'a BTreeMap<usize, Arc<CarriedMesh>>,
    /// The template's positions per frame.
    spool: &'a TemplateSpool,
    /// The welded template's triangles.
    triangles: &'a [[u32; 3]],
    /// Added to every position, as the run did before writing (the run's local origin).
    origin: DVec3,
    /// The method folder (named in errors).
    folder: PathBuf,
    /// The last key used, as its frame file holds it.
    stored: Mutex<Option<(usize, Arc<TriMesh>)>>,
}

impl<'a> CarriedFrames<'a> {
    /// The frames `frames` (animation frame, key frame) of one method.
    #[must_use]
    pub fn new(
        frames: Vec<(usize, usize)>,
        keys: &'a BTreeMap<usize, Arc<CarriedMesh>>,
        spool: &'a TemplateSpool,
        triangles: &'a [[u32; 3]],
        origin: DVec3,
        folder: PathBuf,
    ) -> Self {
        Self {
            frames,
            keys,
            spool,
            triangles,
            origin,
            folder,
            stored: Mutex::new(None),
        }
    }

    /// Key `key`'s mesh as the frame file of its key frame holds it.
    fn stored_key(&self, frame: usize, key: usize) -> Result<Arc<TriMesh>, IoError> {
        let mut stored = self.stored.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((k, mesh)) = stored.as_ref()
            && *k == key
        {
            return Ok(Arc::clone(mesh));
        }
        let carried = self.keys.get(&key).ok_or_else(|| {
            IoError::malformed(
                &self.folder,
                format!("frame {frame}"),
                format!("its key, frame {key}, was not kept"),
            )
        })?;
        let mut mesh = carried.key().clone();
        mesh.translate(self.origin);
        let mesh = Arc::new(as_stored(&self.folder, &mesh)?);
        *stored = Some((key, Arc::clone(&mesh)));
        Ok(mesh)
    }
}

/// `mesh` as a PLY frame file holds it (written and read in memory).
fn as_stored(folder: &Path, mesh: &TriMesh) -> Result<TriMesh, IoError> {
    ply_to_mesh(folder, &mesh_to_ply(mesh, &PlyExtras::default())).map(|(mesh, _)| mesh)
}

impl FrameSource for CarriedFrames<'_> {
    fn frame_count(&self) -> usize {
        self.frames.len()
    }

    fn frame(&self, k: usize) -> Result<Cow<'_, TriMesh>, IoError> {
        let &(frame, key) = self.frames.get(k).ok_or_else(|| {
            IoError::malformed(&self.folder, format!("frame {k}"), "no such frame")
        })?;
        let stored = self.stored_key(frame, key)?;
        if frame == key {
            return Ok(Cow::Owned((*stored).clone()));
        }
        let positions = self.spool.read(frame)?;
        let mut vertices = Vec::new();
        self.keys[&key].place(&positions, self.triangles, &mut vertices);
        let mut mesh = (*stored).clone();
        mesh.set_positions(vertices).map_err(|e| {
            IoError::malformed(&self.folder, format!("frame {frame}"), e.to_string())
        })?;
        mesh.translate(self.origin);
        mesh.clear_normals();
        Ok(Cow::Owned(mesh))
    }
}
