//! The session's ground truth of one frame (`--gt template|gaussians|--gt-sequence`),
//! sampled and indexed, its surface index refitted from the previous frame's when the
//! triangles are the same (every frame of `template` and `gaussians`).

use glam::DVec3;
use trisplat_geometry::TriMesh;
use trisplat_geometry::io::read_mesh;

use super::Session;
use crate::config::GroundTruth;
use crate::error::PipelineError;
use crate::metrics::GtSamples;
use crate::plan::Stage;

impl Session {
    /// Frame `frame`'s ground truth when the plan measures against one that changes per
    /// frame (`None` for a static one or none); `positions` are the frame's deformed template
    /// vertices (local).
    ///
    /// # Errors
    /// [`PipelineError::EmptyGroundTruth`] for a mesh without area; a sequence file that
    /// cannot be read.
    pub(super) fn frame_ground_truth(
        &mut self,
        frame: usize,
        positions: &[DVec3],
    ) -> Result<Option<GtSamples>, PipelineError> {
        let mut previous = self.previous_gt.take();
        Ok(match (&self.gt, self.plan.runs(Stage::Metrics)) {
            (Some(GroundTruth::Template), true) => {
                let mut mesh = TriMesh::new_unchecked(
                    positions.to_vec(),
                    self.template().triangles().to_vec(),
                );
                mesh.translate(self.origin);
                Some(
                    GtSamples::reusing(mesh, self.samples, previous.take()).ok_or(
                        PipelineError::EmptyGroundTruth {
                            gt: "template".to_owned(),
                            frame,
                        },
                    )?,
                )
            }
            (Some(GroundTruth::Gaussians), true) => {
                let origin = self.origin;
                let mesh = TriMesh::new_unchecked(
                    self.scratch
                        .means
                        .iter()
                        .map(|m| m.as_dvec3() + origin)
                        .collect(),
                    self.gaussian_gt_triangles.clone(),
                );
                Some(
                    GtSamples::reusing(mesh, self.samples, previous.take()).ok_or(
                        PipelineError::EmptyGroundTruth {
                            gt: "gaussians".to_owned(),
                            frame,
                        },
                    )?,
                )
            }
            (Some(GroundTruth::Sequence(_)), true) => {
                let path = self.gt_files.get(frame).ok_or(PipelineError::Internal {
                    what: "a frame past the checked ground-truth sequence",
                })?;
                let mesh = read_mesh(path)?;
                Some(
                    GtSamples::reusing(mesh, self.samples, previous.take()).ok_or_else(|| {
                        PipelineError::EmptyGroundTruth {
                            gt: path.display().to_string(),
                            frame,
                        }
                    })?,
                )
            }
            _ => None,
        })
    }
}
