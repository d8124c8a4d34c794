//! The session's part of `--targets rig`: a method's first key mesh and what it is bound to.

use super::Session;
use crate::config::Method;
use crate::error::PipelineError;
use crate::rig_output::RigInputs;

impl Session {
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
            self.replay(1)?;
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
