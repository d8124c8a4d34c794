//! The session's part of `--targets rig`: a method's first key mesh and what it is bound to.

use super::Session;
use crate::config::Method;
use crate::error::PipelineError;
use crate::rig::RigError;
use crate::rig_output::RigInputs;

impl Session {
    /// Refuses `--targets rig` before any frame when the animation has no glTF rig to move
    /// (not a glTF template's clip or morph targets under a weights track, or a template
    /// without a skin and morph targets), naming the template and `method`.
    ///
    /// # Errors
    /// [`PipelineError::Rig`].
    pub(crate) fn check_rig(&self, method: Method) -> Result<(), PipelineError> {
        let fail = |cause: RigError| PipelineError::Rig {
            path: self.template_path.clone(),
            method,
            cause: Box::new(cause),
        };
        let template = self.animation.get().gltf_rig().ok_or_else(|| {
            fail(RigError::NoRig(
                "the animation is not a glTF template's skin or morph targets (driven by its \
                 clip or by a weights track): there is no rig to transfer"
                    .to_owned(),
            ))
        })?;
        template.rig().map(|_| ()).map_err(|e| fail(e.into()))
    }

    /// What the rig of `method`'s first key mesh is made from (module `rig_output`); the key
    /// is made first when this run has not made it (every frame resumed). `None` for a method
    /// the run does not mesh.
    ///
    /// # Errors
    /// As [`Session::frame`].
    pub(crate) fn rig_inputs(
        &mut self,
        method: Method,
    ) -> Result<Option<RigInputs<'_>>, PipelineError> {
        let keyed = |s: &Self| {
            s.meshers
                .iter()
                .any(|(m, _, c)| *m == method && c.first_key().is_some())
        };
        if !keyed(self) {
            self.replay(1);
        }
        let carried = self
            .meshers
            .iter()
            .find(|(m, _, _)| *m == method)
            .and_then(|c| c.2.first_key());
        let (welded, animation, origin) = (&self.welded, self.animation.get(), self.origin);
        Ok(carried.map(|carried| RigInputs {
            carried,
            welded,
            animation,
            origin,
        }))
    }
}
