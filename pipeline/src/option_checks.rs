//! The checks of a run's options that need no file: each names the option, its value and
//! what it should be.

use crate::config::{ExtractConfig, OutputTarget};
use crate::error::PipelineError;

/// Checks the options a session uses before any file is read.
pub(crate) fn check_options(config: &ExtractConfig) -> Result<(), PipelineError> {
    let o = &config.options;
    if !(o.metrics.tau.is_finite() && o.metrics.tau > 0.0) {
        return Err(PipelineError::BadOption {
            name: "tau",
            value: o.metrics.tau,
            expected: "a finite positive distance",
        });
    }
    if let Some(f) = o.metrics.tau_fraction
        && !(f.is_finite() && f > 0.0)
    {
        return Err(PipelineError::BadOption {
            name: "tau-fraction",
            value: f,
            expected: "a finite positive fraction of the ground truth's bounding-box diagonal",
        });
    }
    if !(o.delaunay.hop_threshold.is_finite() && o.delaunay.hop_threshold >= 0.0) {
        return Err(PipelineError::BadOption {
            name: "hop-threshold",
            value: o.delaunay.hop_threshold,
            expected: "a finite number >= 0 (multiples of the mean template edge)",
        });
    }
    let t = &o.topology;
    for (name, value) in [("key-hops", t.key_hops), ("key-stretch", t.key_stretch)] {
        if !(0.0..=1.0).contains(&value) {
            return Err(PipelineError::BadOption {
                name,
                value,
                expected: "a share in [0, 1]",
            });
        }
    }
    let motion = t.key_motion.map(|m| ("key-motion", m));
    for (name, value) in std::iter::once(("key-offset", t.key_offset)).chain(motion) {
        if !(value.is_finite() && value >= 0.0) {
            return Err(PipelineError::BadOption {
                name,
                value,
                expected: "a finite number >= 0 of mean template edges",
            });
        }
    }
    if !(t.hop_distance.is_finite() && t.hop_distance > 0.0) {
        return Err(PipelineError::BadOption {
            name: "hop-distance",
            value: t.hop_distance,
            expected: "a finite positive number of mean template edges",
        });
    }
    if !(o.animation.fps.is_finite() && o.animation.fps > 0.0) {
        return Err(PipelineError::BadOption {
            name: "fps",
            value: o.animation.fps,
            expected: "a positive number of frames per second",
        });
    }
    if !(o.tsdf.alpha_cut > 0.0 && o.tsdf.alpha_cut <= 1.0) {
        return Err(PipelineError::BadOption {
            name: "tsdf-alpha-cut",
            value: f64::from(o.tsdf.alpha_cut),
            expected: "a rendered alpha in (0, 1]",
        });
    }
    if !(o.tsdf.front_alpha >= 0.0 && o.tsdf.front_alpha < 1.0) {
        return Err(PipelineError::BadOption {
            name: "tsdf-front-alpha",
            value: f64::from(o.tsdf.front_alpha),
            expected: "a rendered alpha in [0, 1) (0: free space up to the fused depth)",
        });
    }
    if !(o.visibility.min_contribution >= 0.0 && o.visibility.min_contribution < 1.0) {
        return Err(PipelineError::BadOption {
            name: "min-contribution",
            value: f64::from(o.visibility.min_contribution),
            expected: "a blending weight in [0, 1) (0 keeps every Gaussian)",
        });
    }
    if let Some(r) = o.visibility.floater_std_ratio
        && !(r.is_finite() && r >= 0.0)
    {
        return Err(PipelineError::BadOption {
            name: "floater-std-ratio",
            value: r,
            expected: "a finite number of standard deviations >= 0",
        });
    }
    if o.visibility.floater_neighbors == 0 {
        return Err(PipelineError::BadOption {
            name: "floater-neighbors",
            value: 0.0,
            expected: "at least one neighbour",
        });
    }
    if o.outputs.error_colors && config.gt.is_none() {
        return Err(PipelineError::BadCombination {
            problem: "--error-colors colours the meshes by their distance to the ground truth: \
                      give --gt or --gt-sequence",
        });
    }
    if o.outputs.error_colors && o.tsdf.colors {
        return Err(PipelineError::BadCombination {
            problem: "--error-colors and --tsdf-colors both colour the vertices: choose one",
        });
    }
    if o.outputs.writes(OutputTarget::Rig) && !o.topology.topology.carries() {
        return Err(PipelineError::BadCombination {
            problem: "--targets rig moves the template's rig onto a carried key mesh: give \
                      --topology fixed or adaptive",
        });
    }
    if o.metrics.samples == 0 {
        return Err(PipelineError::BadOption {
            name: "samples",
            value: 0.0,
            expected: "at least one sample",
        });
    }
    if o.metrics.samples > o.limits.max_samples {
        return Err(PipelineError::OverLimit {
            name: "samples",
            value: o.metrics.samples as f64,
            limit: o.limits.max_samples as f64,
            what: "samples per mesh",
            option: "max-samples",
        });
    }
    if o.tsdf.views > o.limits.max_views {
        return Err(PipelineError::OverLimit {
            name: "views",
            value: o.tsdf.views as f64,
            limit: o.limits.max_views as f64,
            what: "views per frame",
            option: "max-views",
        });
    }
    Ok(())
}
