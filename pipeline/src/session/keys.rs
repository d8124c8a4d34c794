//! The session's part of the carried frames (module `carried_frames`): every key mesh kept,
//! and the frames a carrier has not seen shown to it, so that each carried frame of the run can
//! be placed again at the end without its frame file.

use std::collections::BTreeMap;
use std::sync::Arc;

use super::Session;
use crate::carry::CarriedMesh;
use crate::config::Method;

impl Session {
    /// Every method's carrier keeps each key it makes from now on (replays included).
    pub(crate) fn keep_keys(&mut self) {
        for (_, _, carrier) in &mut self.meshers {
            carrier.keep_keys();
        }
    }

    /// The keys `method`'s carrier kept (by key frame), if it keeps them.
    pub(crate) fn kept_keys(&self, method: Method) -> Option<&BTreeMap<usize, Arc<CarriedMesh>>> {
        self.meshers
            .iter()
            .find(|(m, _, _)| *m == method)
            .and_then(|(_, _, carrier)| carrier.kept_keys())
    }

    /// Shows every carrier the frames before `end` it must still see to decide its keys
    /// (meshing only at keys), as a frame at `end` would: a resumed run whose frames were all
    /// done before meets its keys this way.
    pub(crate) fn see_frames_before(&mut self, end: usize) {
        self.replay(end);
    }
}
