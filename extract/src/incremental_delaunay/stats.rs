//! What one update did: [`FrameStats`].

/// What one update did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Number of updates before this one.
    pub frame: usize,
    /// Whether this update rebuilt everything (first frame or rebuild period).
    pub rebuilt: bool,
    /// Gaussians that changed chart (all assigned Gaussians on a rebuild are not counted).
    pub hopped: usize,
    /// Charts whose mesh was replaced: triangulated, or (on an update) taken back from the
    /// chart's last meshes when its members are again what they were then.
    pub charts_redone: usize,
    /// Gaussians whose full nearest-triangle check ran (the others were settled by their
    /// motion certificate, possibly with an exact comparison against a few listed close
    /// competitors; see module `certify`).
    pub searches: usize,
    /// Gaussians that are not vertices of the mesh (duplicates, degenerate charts).
    pub unmeshed: usize,
    /// Wall time of the update in milliseconds.
    pub millis: f64,
}
