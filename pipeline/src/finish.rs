//! What is done to each mesh a method makes before it is carried or written (`--faces`,
//! `--simplify-error`, `--vertex-colors`; docs/conventions.md §10): decimated through
//! geometry's [`simplify`], then coloured from the frame's Gaussians
//! ([`crate::vertex_colors`]). With a carried topology it runs on each key mesh before the key
//! is bound, so the carried frames are the decimated, coloured key deformed.

use std::time::Instant;

use trisplat_geometry::simplify::{SimplifyOptions, SimplifyTarget, simplify};

use crate::config::{FinishOptions, Method, SimplifyBorder, VertexColors};
use crate::error::PipelineError;
use crate::methods::{FrameInput, MethodOutput};
use crate::records::SimplifyFrame;
use crate::vertex_colors::gaussian_colors;

/// The finishing steps of a run's meshes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Finish {
    simplify: Option<SimplifyOptions>,
    colors: VertexColors,
}

impl Finish {
    /// The steps `options` ask for (`--faces` wins if both targets are given; the command
    /// line refuses that).
    #[must_use]
    pub fn new(options: &FinishOptions) -> Self {
        let target = match (options.faces, options.simplify_error) {
            (Some(n), _) => Some(SimplifyTarget::Faces(n)),
            (None, Some(e)) => Some(SimplifyTarget::Error(e)),
            (None, None) => None,
        };
        Self {
            simplify: target.map(|target| SimplifyOptions {
                target,
                lock_border: options.simplify_border == SimplifyBorder::Locked,
            }),
            colors: options.vertex_colors,
        }
    }

    /// Whether meshes are coloured from the Gaussians (the frame's deformed set is needed).
    #[must_use]
    pub fn colors(&self) -> bool {
        self.colors == VertexColors::Gaussians
    }

    /// Decimates `output`'s mesh of `input` (recording what it cost in `output.simplify`; a
    /// mesh without a triangle is left as it is) and colours its vertices from `input.world`
    /// unless the method coloured them itself; the time goes into `output.ms`.
    ///
    /// # Errors
    /// [`PipelineError::Simplify`] for a target out of range or a result that cannot be
    /// measured; [`PipelineError::Internal`] when colours are asked without the frame's
    /// Gaussians.
    pub fn apply(
        &self,
        method: Method,
        output: &mut MethodOutput,
        input: &FrameInput<'_>,
    ) -> Result<(), PipelineError> {
        let start = Instant::now();
        let has_triangle = output
            .mesh
            .triangles()
            .iter()
            .any(|&[a, b, c]| a != b && b != c && a != c);
        if let Some(options) = &self.simplify
            && has_triangle
        {
            let s = simplify(&output.mesh, options).map_err(|cause| PipelineError::Simplify {
                frame: input.frame,
                method,
                cause,
            })?;
            output.mesh = s.mesh;
            output.simplify = Some(SimplifyFrame {
                faces_before: s.faces_before,
                faces_after: s.faces_after,
                meshopt_error: s.error,
                hausdorff: s.hausdorff,
                mean_distance: s.mean_distance,
                ms: start.elapsed().as_secs_f64() * 1e3,
            });
        }
        if self.colors() && output.mesh.colors().is_none() && output.mesh.vertex_count() > 0 {
            let world = input.world.ok_or(PipelineError::Internal {
                what: "vertex colours without the frame's deformed Gaussians",
            })?;
            if world.is_empty() {
                output.ms += start.elapsed().as_secs_f64() * 1e3;
                return Ok(());
            }
            let colors =
                gaussian_colors(output.mesh.positions(), world).ok_or(PipelineError::Internal {
                    what: "vertex colours from Gaussians that cannot be indexed",
                })?;
            let mesh = std::mem::take(&mut output.mesh);
            output.mesh = mesh
                .with_colors(colors)
                .map_err(|_| PipelineError::Internal {
                    what: "one colour per vertex",
                })?;
        }
        output.ms += start.elapsed().as_secs_f64() * 1e3;
        Ok(())
    }
}
