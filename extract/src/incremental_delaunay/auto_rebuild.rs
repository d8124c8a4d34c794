//! The automatic choice between updating and rebuilding: [`AutoRebuild`].

use super::stats::FrameStats;

/// At hop threshold τ > 0 (where the choice changes the meshes and must not depend on the
/// machine), an update that fully checks more than this fraction of the Gaussians (their
/// motion certificates failed) is judged to cost more than a rebuild: on the LAM head (20k
/// Gaussians up to centimetres off their triangles, the head turning every frame) 13% checks
/// cost 1.4x a rebuild, 23% 1.8x, 50% 3.5-5x; on the FLAME benchmark 5% cost a fifth of one.
pub const AUTO_REBUILD_CHECKED: f64 = 0.10;
/// At τ > 0, an update that redoes more than this fraction of the charts is judged to cost
/// about a rebuild.
pub const AUTO_REBUILD_CHARTS: f64 = 0.25;
/// Rebuilds before the first probe of the update path after a costly update. A probe is
/// dear (the first update after a rebuild certifies every Gaussian: 0.5-1.2 s on the LAM head
/// against a 37 ms rebuild), hence long runs of rebuilds between probes.
const AUTO_BACKOFF_FIRST: usize = 64;
/// Factor by which a costly probe lengthens the next run of rebuilds.
const AUTO_BACKOFF_GROWTH: usize = 4;
/// Longest run of rebuilds between probes.
const AUTO_BACKOFF_MAX: usize = 1024;

/// The automatic choice between updating and rebuilding
/// ([`DelaunayOptions::auto_rebuild`](super::DelaunayOptions::auto_rebuild)).
/// An update judged costly is followed by a run of rebuilds; after it the update path is
/// probed again, and a probe judged costly makes the next run [`AUTO_BACKOFF_GROWTH`] times
/// longer ([`AUTO_BACKOFF_FIRST`] up to [`AUTO_BACKOFF_MAX`]). The first update after a
/// rebuild certifies every Gaussian and is not judged; the second is.
///
/// The verdict: at hop threshold 0 an update equals a rebuild (tested), so the choice changes
/// only the time and is made by the clock (the update took longer than the last rebuild); at
/// τ > 0 a rebuild resets the hysteresis and changes the meshes, so the choice counts work
/// instead ([`AUTO_REBUILD_CHECKED`], [`AUTO_REBUILD_CHARTS`]) and a run gives the same meshes
/// on any machine.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AutoRebuild {
    /// Rebuilds still to do before the next probe.
    pub(super) rebuilds_left: usize,
    /// Rebuilds after the next costly update.
    backoff: usize,
    /// Wall time of the last rebuild, milliseconds.
    pub(super) rebuild_ms: f64,
}

impl Default for AutoRebuild {
    fn default() -> Self {
        Self {
            rebuilds_left: 0,
            backoff: AUTO_BACKOFF_FIRST,
            rebuild_ms: f64::INFINITY,
        }
    }
}

impl AutoRebuild {
    /// Whether an update that took `update_ms` with these counts cost more than a rebuild.
    pub(super) fn costly(
        &self,
        stats: &FrameStats,
        update_ms: f64,
        by_clock: bool,
        gaussians: usize,
        charts: usize,
    ) -> bool {
        if by_clock {
            update_ms > self.rebuild_ms
        } else {
            stats.searches as f64 > AUTO_REBUILD_CHECKED * gaussians as f64
                || stats.charts_redone as f64 > AUTO_REBUILD_CHARTS * charts as f64
        }
    }

    /// Takes the verdict on a judged update.
    pub(super) fn judge(&mut self, costly: bool) {
        if costly {
            self.rebuilds_left = self.backoff;
            self.backoff = (self.backoff * AUTO_BACKOFF_GROWTH).min(AUTO_BACKOFF_MAX);
        } else {
            self.backoff = AUTO_BACKOFF_FIRST;
        }
    }
}
