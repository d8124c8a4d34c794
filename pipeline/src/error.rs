//! The one error type of the pipeline: every variant names the file, frame or option at fault.

use std::path::PathBuf;

use trisplat_extract::alpha_shape::AlphaError;
use trisplat_extract::incremental_delaunay::DelaunayError;
use trisplat_extract::tsdf::TsdfError;
use trisplat_geometry::CameraError;
use trisplat_geometry::animation::AnimationError;
use trisplat_geometry::io::IoError;
use trisplat_geometry::metrics::MetricsError;
use trisplat_splat::BindError;
use trisplat_splat::DeformError;
use trisplat_splat::LbsError;
use trisplat_splat::render::RenderError;

use crate::config::Method;

// Every variant prints its cause in its own message, so none is a `#[source]` (the wrapped
// errors are fields named `cause`, which thiserror does not chain): the CLI's `{:#}` cause
// chain prints each cause once.

impl From<IoError> for PipelineError {
    fn from(e: IoError) -> Self {
        Self::Io(e)
    }
}

impl From<trisplat_splat::ply::PlyError> for PipelineError {
    fn from(e: trisplat_splat::ply::PlyError) -> Self {
        Self::Ply(e)
    }
}

impl From<AnimationError> for PipelineError {
    fn from(e: AnimationError) -> Self {
        Self::Animation(e)
    }
}

/// Why the pipeline stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// A file could not be read or written (the error names it and the element).
    #[error("{0}")]
    Io(IoError),
    /// The Gaussian file could not be read (the error names it and the Gaussian).
    #[error("{0}")]
    Ply(trisplat_splat::ply::PlyError),
    /// The animation could not be opened or evaluated (the error names the file).
    #[error("{0}")]
    Animation(AnimationError),
    /// No extraction method was asked for.
    #[error("--method: name at least one of tsdf, delaunay, alpha")]
    NoMethod,
    /// An option is not a finite positive number (or out of its range).
    #[error("--{name} {value}: {expected}")]
    BadOption {
        /// The option's name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// An option asks for more than a resource limit allows (checked before allocating).
    #[error("--{name} {value}: over the limit of {limit} {what} (raise it with --{option})")]
    OverLimit {
        /// The option's name.
        name: &'static str,
        /// The value given (for `voxel`: the voxels it gives across the template).
        value: f64,
        /// The limit.
        limit: f64,
        /// What the limit counts.
        what: &'static str,
        /// The option that raises the limit.
        option: &'static str,
    },
    /// Two options that do not go together.
    #[error("{problem}")]
    BadCombination {
        /// What is wrong, naming the options.
        problem: &'static str,
    },
    /// `--frames` does not parse or selects no frame of the animation.
    #[error("--frames {spec}: {problem}")]
    Frames {
        /// The value given.
        spec: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The template has no triangles.
    #[error("{path}: the template has no triangles")]
    EmptyTemplate {
        /// The template file.
        path: PathBuf,
    },
    /// The animation's frames do not have the template's vertices or triangles.
    #[error("{animation}: {problem}")]
    Topology {
        /// The animation source.
        animation: String,
        /// The difference, naming the template file.
        problem: String,
    },
    /// The animation's frames are not at the template's scale (different units, or a
    /// transform applied to one of them only).
    #[error(
        "{animation}: frame {frame} has bounding radius {frame_radius:.4e}, {ratio:.3e} times \
         that of the template {template} ({template_radius:.4e}): the template and the \
         animation are not at the same scale (different units, or a node transform applied to \
         one of them only); bring them to one scale"
    )]
    ScaleMismatch {
        /// The animation source.
        animation: String,
        /// The template file.
        template: PathBuf,
        /// The animation frame compared (the first selected).
        frame: usize,
        /// Bounding radius of that frame.
        frame_radius: f64,
        /// Bounding radius of the template.
        template_radius: f64,
        /// `frame_radius / template_radius`.
        ratio: f64,
    },
    /// The animation argument cannot be used as given (a `--clip` for a non-glTF file, a
    /// weights file without morph targets, an empty targets folder, ...).
    #[error("{path}: {problem}")]
    BadAnimation {
        /// The file or folder at fault.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// The Gaussian file has no triangle binding.
    #[error(
        "{path}: the Gaussians are not bound to triangles (no `binding_0`/`binding` property); \
         use `trisplat bind` first (LAM's per-vertex offset.ply: --layout lam, or --avatar \
         DIR for the whole folder)"
    )]
    NotBound {
        /// The Gaussian file.
        path: PathBuf,
    },
    /// The Gaussians cannot be deformed with this template (bound to another template, world
    /// space parameters, ...).
    #[error("{path}: {cause} (template {template})")]
    Gaussians {
        /// The Gaussian file.
        path: PathBuf,
        /// The template file.
        template: PathBuf,
        /// What the deformer found.
        cause: DeformError,
    },
    /// Which Gaussians render could not be decided.
    #[error("{path}: deciding which Gaussians render at the rest pose: {cause}")]
    Visibility {
        /// The Gaussian file.
        path: PathBuf,
        /// What failed.
        cause: crate::visibility::VisibilityError,
    },
    /// A LAM avatar folder or one of its files does not fit LAM's layout.
    #[error("{path}: {problem}")]
    Avatar {
        /// The folder or file.
        path: PathBuf,
        /// What is wrong, with the numbers.
        problem: String,
    },
    /// A Gaussian file whose own validity report has a problem.
    #[error("{path}: {issue} (template {template})")]
    GaussianIssue {
        /// The Gaussian file.
        path: PathBuf,
        /// The template file.
        template: PathBuf,
        /// The first issue of the report.
        issue: String,
    },
    /// Binding new Gaussians to the template failed.
    #[error("{path}: binding Gaussians: {cause}")]
    Bind {
        /// The template file.
        path: PathBuf,
        /// Why.
        cause: BindError,
    },
    /// `--mode lbs` without a skinned glTF, or with a template that is not its rest shape.
    #[error("{path}: {problem}")]
    Lbs {
        /// The animation or template file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// The skinning rig could not be built or evaluated.
    #[error("{path}: frame {frame}: {cause}")]
    Skinning {
        /// The animation file.
        path: PathBuf,
        /// Animation frame (or 0 when building the rig).
        frame: usize,
        /// Why.
        cause: LbsError,
    },
    /// Deforming the Gaussians to a frame failed.
    #[error("{path}: frame {frame}: {cause}")]
    Deform {
        /// The animation source.
        path: String,
        /// Animation frame.
        frame: usize,
        /// Why.
        cause: DeformError,
    },
    /// The camera rig around a frame could not be built.
    #[error("frame {frame}: camera rig: {cause}")]
    Cameras {
        /// Animation frame.
        frame: usize,
        /// Why.
        cause: CameraError,
    },
    /// Rendering depth for the TSDF method failed.
    #[error("frame {frame}: rendering camera {camera}: {cause}")]
    Render {
        /// Animation frame.
        frame: usize,
        /// Camera name.
        camera: String,
        /// Why.
        cause: RenderError,
    },
    /// TSDF fusion failed.
    #[error("frame {frame}: tsdf: {cause}")]
    Tsdf {
        /// Animation frame.
        frame: usize,
        /// Why.
        cause: TsdfError,
    },
    /// Incremental Delaunay meshing failed.
    #[error("frame {frame}: delaunay: {cause}")]
    Delaunay {
        /// Animation frame (or the first selected frame when building).
        frame: usize,
        /// Why.
        cause: DelaunayError,
    },
    /// The alpha shape failed.
    #[error("frame {frame}: alpha: {cause}")]
    Alpha {
        /// Animation frame.
        frame: usize,
        /// Why.
        cause: AlphaError,
    },
    /// The opacity field could not be meshed.
    #[error("frame {frame}: opacity: {cause}")]
    Opacity {
        /// Animation frame.
        frame: usize,
        /// Why.
        cause: trisplat_extract::opacity::OpacityError,
    },
    /// A mesh could not be decimated.
    #[error("frame {frame}, method {method}: decimating the mesh: {cause}")]
    Simplify {
        /// Animation frame.
        frame: usize,
        /// The method.
        method: Method,
        /// Why.
        cause: trisplat_geometry::simplify::SimplifyError,
    },
    /// A meshing error ([`PipelineError::Delaunay`], [`PipelineError::Alpha`],
    /// [`PipelineError::Carry`], [`PipelineError::Simplify`]) on the vertices of `input`: the template (when a mesher is built) or the animation (per frame).
    #[error("{input}: {cause}")]
    Meshing {
        /// The template file or the animation's label.
        input: String,
        /// The meshing error.
        cause: Box<PipelineError>,
    },
    /// Metrics against the ground truth failed.
    #[error("{gt}: frame {frame}, method {method}: {cause}")]
    Metrics {
        /// The ground truth (file or `template`).
        gt: String,
        /// Animation frame.
        frame: usize,
        /// The method whose mesh was measured.
        method: Method,
        /// Why.
        cause: MetricsError,
    },
    /// The ground-truth mesh has no surface to compare against.
    #[error("{gt}: the ground truth has zero surface area (frame {frame})")]
    EmptyGroundTruth {
        /// The ground truth (file or `template`).
        gt: String,
        /// Animation frame.
        frame: usize,
    },
    /// An output would replace an input file.
    #[error("{path}: refusing to overwrite an input file; choose another output folder")]
    OverwriteInput {
        /// The output path.
        path: PathBuf,
    },
    /// The output folder cannot be created.
    #[error("{path}: cannot create the output folder: {cause}")]
    OutputDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// The output folder holds a previous run and neither `--resume` nor `--force` was given.
    #[error(
        "{path}: holds the outputs of a previous run ({found}); continue it with --resume, start \
         over with --force, or choose another output folder"
    )]
    UsedOutput {
        /// The folder.
        path: PathBuf,
        /// What shows the previous run.
        found: String,
    },
    /// Another run holds the output folder's lock ([`crate::lock::FolderLock`]).
    #[error(
        "{path}: another trisplat run is writing to this folder (it holds {lock}); wait for it \
         to end or choose another output folder"
    )]
    Busy {
        /// The folder.
        path: PathBuf,
        /// The lock file.
        lock: String,
    },
    /// The output folder's lock file cannot be opened or locked.
    #[error("{path}: cannot lock the output folder: {cause}")]
    Lock {
        /// The lock file.
        path: PathBuf,
        /// Why.
        cause: std::io::Error,
    },
    /// `--resume` cannot continue the run in the folder.
    #[error("{path}: cannot resume: {problem}")]
    Resume {
        /// The folder or its journal.
        path: PathBuf,
        /// Why.
        problem: String,
    },
    /// `--gt gaussians` with Gaussians that are not one per template vertex.
    #[error(
        "--gt gaussians needs one Gaussian per template vertex (LAM's layout, --avatar or \
         --layout lam): {problem}"
    )]
    GtGaussians {
        /// Why.
        problem: String,
    },
    /// A `--gt-sequence` that cannot serve the frames.
    #[error("--gt-sequence {spec}: {problem}")]
    GtSequence {
        /// The folder or pattern.
        spec: String,
        /// Why.
        problem: String,
    },
    /// A `--shard` that cannot be taken (no frame for it, `auto` without a job's variables).
    #[error("{problem}")]
    Shard {
        /// What is wrong, naming the values.
        problem: String,
    },
    /// Render consistency that cannot be measured.
    #[error("render consistency: {problem}")]
    Consistency {
        /// What went wrong.
        problem: String,
    },
    /// A key mesh that cannot be carried (`--topology fixed|adaptive`).
    #[error(
        "frame {frame}, method {method}: the mesh of key frame {key} cannot be carried: {cause}"
    )]
    Carry {
        /// Animation frame.
        frame: usize,
        /// The method.
        method: Method,
        /// The key frame.
        key: usize,
        /// Why.
        cause: crate::carry::CarryError,
    },
    /// The rig of a method's key mesh (`--targets rig`) that cannot be made or written.
    #[error("{path}: the rig of method {method}'s key mesh: {cause}")]
    Rig {
        /// The rig file.
        path: PathBuf,
        /// The method.
        method: Method,
        /// Why (boxed: it carries the template's animation error).
        cause: Box<crate::rig::RigError>,
    },
    /// Shards that cannot be merged.
    #[error("{path}: cannot merge: {problem}")]
    Merge {
        /// The shard folder or file at fault.
        path: PathBuf,
        /// Why.
        problem: String,
    },
    /// A broken invariant of the pipeline itself (a bug: please report it).
    #[error("internal error: {what}")]
    Internal {
        /// What went wrong.
        what: &'static str,
    },
}

/// The results of a parallel map in their order, or the first error in that order (not the
/// first a thread hit), so that the error reported does not depend on scheduling.
pub(crate) fn first_error_in_order<T: Send, E: Send>(
    results: impl rayon::iter::ParallelIterator<Item = Result<T, E>>,
) -> Result<Vec<T>, E> {
    // rayon collects into a Vec in the source order.
    results.collect::<Vec<_>>().into_iter().collect()
}

impl PipelineError {
    /// A Delaunay, alpha-shape, carrying or decimation error names `input`, whose vertices it
    /// came from; other errors name their files already and pass through.
    #[must_use]
    pub fn on_vertices_of(self, input: &str) -> Self {
        match self {
            Self::Delaunay { .. }
            | Self::Alpha { .. }
            | Self::Carry { .. }
            | Self::Simplify { .. } => Self::Meshing {
                input: input.to_owned(),
                cause: Box::new(self),
            },
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_error_in_order_is_reported_whatever_the_threads_do() {
        use rayon::prelude::*;
        for _ in 0..20 {
            let results = (0..1000usize)
                .into_par_iter()
                .map(|k| if k == 317 || k == 900 { Err(k) } else { Ok(k) });
            assert_eq!(first_error_in_order(results), Err(317));
        }
        let all = first_error_in_order((0..100usize).into_par_iter().map(Ok::<_, ()>));
        assert_eq!(all, Ok((0..100).collect()));
    }

    #[test]
    fn causes_print_once() {
        let e = PipelineError::OutputDir {
            path: PathBuf::from("out"),
            cause: std::io::Error::other("boom"),
        };
        assert!(std::error::Error::source(&e).is_none());
        assert_eq!(e.to_string(), "out: cannot create the output folder: boom");
        let e = PipelineError::Deform {
            path: "walk.glb".to_owned(),
            frame: 3,
            cause: DeformError::NotBound,
        };
        assert!(std::error::Error::source(&e).is_none());
        assert!(e.to_string().starts_with("walk.glb: frame 3: "), "{e}");
    }

    #[test]
    fn a_key_that_cannot_be_carried_names_the_input() {
        let e = PipelineError::Carry {
            frame: 0,
            method: Method::Delaunay,
            key: 0,
            cause: crate::carry::CarryError::Nothing("every triangle is degenerate".to_owned()),
        }
        .on_vertices_of("walk.obj");
        assert!(
            e.to_string()
                .starts_with("walk.obj: frame 0, method delaunay"),
            "{e}"
        );
    }
}
