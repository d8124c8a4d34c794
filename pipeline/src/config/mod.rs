//! What the main job is asked to do: inputs, methods and options, composed of one struct per
//! stage, each with its defaults beside it in its own file (flattened into the command line by
//! the `cli` feature's derives):
//!
//! - `method`: the extraction methods by name;
//! - `input`: animation ([`AnimationOptions`]: clip, rate, deform mode) and bind
//!   ([`BindOptions`], [`GaussianLayout`]);
//! - `tsdf`: the tsdf method's rig, depth maps and fusion ([`TsdfOptions`]);
//! - `points`: the point methods ([`DelaunayOptions`], [`AlphaOptions`]) and the rule of which
//!   Gaussians they mesh ([`VisibilityRule`]);
//! - `report`: metrics ([`MetricOptions`]), outputs ([`OutputOptions`]) and [`Limits`];
//! - `shard`: the part of the frames a run takes ([`ShardOptions`], [`Shard`]);
//! - `topology`: per-frame meshes or one carried through the track ([`TopologyOptions`]);
//! - `opacity`: the opacity method's field and pieces ([`OpacityMethodOptions`]);
//! - `finish`: decimation and vertex colours of every mesh ([`FinishOptions`]).
//!
//! This module composes them ([`ExtractOptions`], [`ExtractConfig`], [`RunControl`]); the
//! stage files import nothing from it or from the modules that read them.

use std::path::PathBuf;

#[cfg(feature = "cli")]
mod arg;
mod finish;
mod input;
mod method;
mod opacity;
mod points;
mod report;
mod shard;
mod topology;
mod tsdf;

pub use finish::{FinishOptions, SimplifyBorder, VertexColors};
pub use input::{
    AnimationOptions, BIND_NORMAL_SCALE, BIND_OPACITY, BIND_TANGENT_SCALE, BindOptions,
    DEFAULT_PER_TRIANGLE, GaussianLayout, Mode,
};
pub use method::Method;
pub use opacity::{
    OpacityField, OpacityMethodOptions, OpacityPieces, TEMPLATE_DEPTH_SAMPLES, TEMPLATE_SMOOTHING,
};
pub use points::{
    ALPHA_STEPS_PER_DOUBLING, AlphaOptions, AlphaRule, DEFAULT_ALPHA_CEILING_SPACINGS,
    DEFAULT_ALPHA_FLOOR_SPACINGS, DEFAULT_ALPHA_PIECES, DEFAULT_ALPHA_SPACINGS,
    DEFAULT_FLOATER_NEIGHBORS, DEFAULT_MIN_CONTRIBUTION, DelaunayOptions, VisibilityRule,
};
pub use report::{
    DEFAULT_CONSISTENCY_RESOLUTION, DEFAULT_CONSISTENCY_VIEWS, DEFAULT_MAX_SAMPLES,
    DEFAULT_MAX_VIEWS, DEFAULT_MAX_VOXELS, DEFAULT_MORPH_ABOVE_MB, DEFAULT_SAMPLES, DEFAULT_TAU,
    DEFAULT_TAU_FRACTION, Limits, MetricOptions, OutputOptions, OutputTarget, morph_basis,
};
pub use shard::{KUBERNETES_INDEX, SLURM_VARIABLES, Shard, ShardOptions, ShardSpec};
pub use topology::{
    DEFAULT_HOP_DISTANCE, DEFAULT_KEY_HOPS, DEFAULT_KEY_STRETCH, Topology, TopologyOptions,
};
pub use tsdf::{
    COARSEST_VOXELS_PER_RADIUS, DEFAULT_FOV_DEG, DEFAULT_FRONT_ALPHA, DEFAULT_RESOLUTION,
    DEFAULT_VIEWS, DEFAULT_VOXELS_PER_RADIUS, DepthKind, RENDERED_ALPHA_MIN, SplatDepthRule,
    TsdfAnchor, TsdfOptions,
};

/// The ground truth of the metrics.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GroundTruth {
    /// Each frame's deformed template (`--gt template`).
    Template,
    /// Each frame's surface of the Gaussians' centres (`--gt gaussians`): the template as
    /// stored with vertex `i` at the deformed centre of Gaussian `i`, for avatars with one
    /// Gaussian per template vertex (LAM's layout), where the centres sit up to centimetres
    /// off the skin.
    Gaussians,
    /// One static mesh for every frame.
    Mesh(PathBuf),
    /// One mesh per frame (`--gt-sequence`): a folder or pattern of OBJ/PLY files, taken in
    /// order, the file at position `i` being the ground truth of animation frame `i`; their
    /// topologies may differ (scans).
    Sequence(String),
}

impl GroundTruth {
    /// Parses a `--gt` value: the word `template`, else a mesh file.
    #[must_use]
    pub fn parse(value: &str) -> Self {
        if value == "template" {
            Self::Template
        } else if value == "gaussians" {
            Self::Gaussians
        } else {
            Self::Mesh(PathBuf::from(value))
        }
    }

    /// The value as given (`template` or the path).
    #[must_use]
    pub fn label(&self) -> String {
        match self {
            Self::Template => "template".to_owned(),
            Self::Gaussians => "gaussians".to_owned(),
            Self::Mesh(p) => p.display().to_string(),
            Self::Sequence(spec) => spec.clone(),
        }
    }
}

/// The knobs of the main job, one struct per stage; unset values are derived from the
/// template (see each field).
#[derive(Clone, Debug, Default, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct ExtractOptions {
    /// The animation and how the Gaussians follow it.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub animation: AnimationOptions,
    /// How the Gaussians are read or bound.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub bind: BindOptions,
    /// The tsdf method.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub tsdf: TsdfOptions,
    /// The alpha method.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub alpha: AlphaOptions,
    /// The opacity method.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub opacity: OpacityMethodOptions,
    /// Which Gaussians delaunay and alpha mesh.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub visibility: VisibilityRule,
    /// The delaunay method.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub delaunay: DelaunayOptions,
    /// The metrics against a ground truth.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub metrics: MetricOptions,
    /// What the run writes.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub outputs: OutputOptions,
    /// Resource limits.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub limits: Limits,
    /// Which part of the frames the run takes when the track is split over machines.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub shard: ShardOptions,
    /// Whether each frame is meshed from scratch or one mesh is carried through the track.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub topology: TopologyOptions,
    /// Decimation and vertex colours of every mesh.
    #[cfg_attr(feature = "cli", command(flatten))]
    pub finish: FinishOptions,
}

/// How a run treats an output folder that already holds a run, and frames that fail.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct RunControl {
    /// Continue the run in the output folder: frames its journal lists as done are kept, the
    /// others (and failed ones) are run. Refused if the inputs or options changed.
    #[cfg_attr(feature = "cli", arg(long, conflicts_with = "force"))]
    pub resume: bool,
    /// Start over in an output folder that holds a previous run (its outputs are removed).
    #[cfg_attr(feature = "cli", arg(long))]
    pub force: bool,
    /// Stop at the first frame that fails (completed frames are kept) instead of recording it
    /// and going on.
    #[cfg_attr(feature = "cli", arg(long))]
    pub fail_fast: bool,
    /// Run the methods of each frame one after another, so that each method's ms/frame is its
    /// time alone; by default they run side by side (a shorter run; each method's time then
    /// includes waiting for cores the others hold). The meshes are the same either way.
    #[cfg_attr(feature = "cli", arg(long))]
    pub serial_methods: bool,
}

/// A whole `trisplat extract` run.
#[derive(Clone, Debug, PartialEq)]
pub struct ExtractConfig {
    /// The template mesh (rest shape; a glTF may carry its own animation).
    pub template: PathBuf,
    /// The animation: a glTF, a folder or pattern of OBJ/PLY frames; `None`: the template's
    /// own glTF clip, or the template alone as one frame.
    pub animation: Option<String>,
    /// Bound Gaussians; `None`: the pipeline binds new ones.
    pub gaussians: Option<PathBuf>,
    /// Methods, each run on every frame (duplicates are ignored).
    pub methods: Vec<Method>,
    /// Output folder.
    pub output: PathBuf,
    /// Frame selection `A..B`, `A..=B`, `A..`, `..B` or `A` (animation frame indices).
    pub frames: Option<String>,
    /// Ground truth of the metrics; `None`: no metrics.
    pub gt: Option<GroundTruth>,
    /// The knobs.
    pub options: ExtractOptions,
}

impl ExtractConfig {
    /// The methods asked for, without duplicates, in report order (tsdf, delaunay, alpha).
    #[must_use]
    pub fn methods(&self) -> Vec<Method> {
        Method::ALL
            .into_iter()
            .filter(|m| self.methods.contains(m))
            .collect()
    }
}

#[cfg(all(test, feature = "cli"))]
mod tests {
    use super::*;
    use clap::Parser as _;
    use trisplat_geometry::metrics::Tau;

    #[derive(clap::Parser)]
    struct Args {
        #[command(flatten)]
        options: ExtractOptions,
    }

    fn parse(args: &[&str]) -> Result<ExtractOptions, clap::Error> {
        Args::try_parse_from(std::iter::once("extract").chain(args.iter().copied()))
            .map(|a| a.options)
    }

    #[test]
    fn tau_is_relative_by_default_absolute_when_given() {
        let default = parse(&[]).expect("defaults");
        assert_eq!(default, ExtractOptions::default());
        assert_eq!(default.metrics.tau_fraction, Some(DEFAULT_TAU_FRACTION));
        assert_eq!(
            report::DEFAULT_TAU_FRACTION_ARG.parse(),
            Ok(DEFAULT_TAU_FRACTION)
        );
        assert_eq!(
            default.metrics.threshold(),
            Tau::Fraction(DEFAULT_TAU_FRACTION)
        );
        let absolute = parse(&["--tau", "0.01"]).expect("absolute");
        assert_eq!(absolute.metrics.tau_fraction, None);
        assert_eq!(absolute.metrics.threshold(), Tau::Absolute(0.01));
        let relative = parse(&["--tau-fraction", "0.02"]).expect("relative");
        assert_eq!(relative.metrics.threshold(), Tau::Fraction(0.02));
        assert!(parse(&["--tau", "0.01", "--tau-fraction", "0.02"]).is_err());
    }
}
