//! One module per `trisplat` command: its arguments and its `run`.

pub mod alpha_shape;
pub mod bind;
pub mod cameras;
pub mod completions;
pub mod convert;
pub mod deform;
pub mod demo;
pub mod densify;
pub mod eval;
pub mod extract;
pub mod fit;
pub mod fit_brdf;
pub mod fit_neural;
pub mod fit_run;
pub mod gaussian_io;
pub mod init;
pub mod man;
pub mod merge;
pub mod opacity_mesh;
pub mod prune;
pub mod refine;
pub mod render;
pub mod render_neural;
pub mod sample;
pub mod smooth;
pub mod tsdf;

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use trisplat_geometry::Camera;
use trisplat_geometry::{read_cameras_json, read_transforms_json};

use crate::progress::Progress;

/// A command line that parses but makes no sense (options that do not go together): reported
/// like clap's own usage errors, with exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// What every command gets besides its arguments.
#[derive(Clone, Copy, Debug)]
pub struct Context {
    /// Progress bar factory.
    pub progress: Progress,
    /// `--quiet`: no notes on stderr (warnings and errors still print).
    pub quiet: bool,
    /// `--json`: the result as one JSON object on stdout instead of text.
    pub json: bool,
}

impl Context {
    /// With `--json`, prints the command's result: `fields` (an object) with `"command"` set
    /// to `command`, on one line (docs/conventions.md §10 lists the keys of each command).
    /// Without it, nothing: the command prints its text.
    ///
    /// # Errors
    /// `fields` is not a JSON object (a bug).
    pub fn emit(&self, command: &str, fields: serde_json::Value) -> anyhow::Result<()> {
        if !self.json {
            return Ok(());
        }
        let serde_json::Value::Object(mut object) = fields else {
            anyhow::bail!("internal: the result of {command} is not a JSON object");
        };
        object.insert("command".into(), command.into());
        println!("{}", serde_json::Value::Object(object));
        Ok(())
    }
}

/// Refuses an output path that names the input file (also through links or `..`).
///
/// # Errors
/// When `output` and `input` are the same file.
pub fn refuse_to_overwrite(input: &Path, output: &Path) -> anyhow::Result<()> {
    let same = match (input.canonicalize(), canonical(output)) {
        (Ok(a), Some(b)) => a == b,
        _ => input == output,
    };
    if same {
        bail!(
            "{}: refusing to overwrite the input file; choose another output path",
            output.display()
        );
    }
    Ok(())
}

/// The absolute, symlink-free form of `path`, also when the file does not exist yet.
fn canonical(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(parent.canonicalize().ok()?.join(path.file_name()?))
}

/// Reads a 3DGS cameras.json (a JSON list) or a NeRF transforms.json (an object with `frames`),
/// told apart by the file's contents; `size` is the image size for a transforms.json without
/// `w`/`h`. Cameras of more than `max_pixels` pixels are refused before any image exists.
///
/// # Errors
/// An unreadable or malformed file, one without cameras, or a camera over `max_pixels`.
pub fn read_camera_file(
    path: &Path,
    size: Option<(u32, u32)>,
    max_pixels: u64,
) -> anyhow::Result<Vec<Camera>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let cameras = if text.trim_start().starts_with('{') {
        read_transforms_json(path, size)?
    } else {
        read_cameras_json(path)?
    };
    if cameras.is_empty() {
        bail!("{}: no cameras", path.display());
    }
    if let Some((i, c)) = cameras
        .iter()
        .enumerate()
        .find(|(_, c)| u64::from(c.width) * u64::from(c.height) > max_pixels)
    {
        bail!(
            "{}: camera {i} ('{}') is {}x{} pixels, over the limit of {max_pixels} pixels per \
             image (raise it with --max-pixels, up to {MAX_IMAGE_PIXELS})",
            path.display(),
            c.name,
            c.width,
            c.height
        );
    }
    Ok(cameras)
}

/// Most pixels of one camera's image (`render`, `tsdf`): 16384² (2^28, the renderer's own
/// ceiling: 1 GiB per float image), the default and the largest value of `--max-pixels`,
/// checked before any image is allocated.
pub const MAX_IMAGE_PIXELS: u64 = 16384 * 16384;

/// `--max-pixels N`: a positive number of pixels up to [`MAX_IMAGE_PIXELS`].
///
/// # Errors
/// A value that is not such a number.
pub fn parse_max_pixels(s: &str) -> Result<u64, String> {
    match s.parse::<u64>() {
        Ok(n) if (1..=MAX_IMAGE_PIXELS).contains(&n) => Ok(n),
        _ => Err(format!(
            "expected a number of pixels from 1 to {MAX_IMAGE_PIXELS} (the renderer's ceiling), \
             got '{s}'"
        )),
    }
}

/// A `--clip NAME|INDEX` value: a number is an index, anything else a name; none is the first
/// (the pipeline's parser, so that every command reads `--clip` alike).
pub use trisplat_pipeline::input::clip_of as parse_clip;
