//! The views a meshing run evaluates the field over: every view's bins prepared once and held
//! when they fit [`HELD_BYTES`] (each point can then walk the views in its own order, and a run
//! bins each view once instead of once per pass), else prepared anew for each pass, one at a
//! time, so memory does not grow with the number of views.

use trisplat_geometry::Camera;

use super::gaussians::Prepared;
use super::view::{CertifyAt, ViewBins};

/// Most bytes of bins held at once (beyond it views are streamed).
pub(crate) const HELD_BYTES: usize = 1 << 30;

/// The cameras, and their bins when held.
#[derive(Debug)]
pub(crate) struct Views<'a> {
    cameras: &'a [Camera],
    /// Every view's bins, or empty when streamed.
    held: Vec<ViewBins>,
    /// The one view prepared at a time when streamed.
    scratch: ViewBins,
    /// The level each view's tiles certify points at or above, and the rules.
    certify: Option<CertifyAt>,
}

impl<'a> Views<'a> {
    /// Bins `cameras` over `p`, holding them all when their size (estimated from the first
    /// view, times the number of views) is at most `budget` bytes. With `certify`, each view
    /// also certifies the points at or above that level ([`ViewBins::certify`]).
    pub fn new(
        p: &Prepared,
        cameras: &'a [Camera],
        budget: usize,
        certify: Option<CertifyAt>,
    ) -> Self {
        let mut scratch = ViewBins::default();
        let mut held = Vec::new();
        let prepare = |bins: &mut ViewBins, camera: &Camera| {
            bins.prepare(p, camera);
            if let Some(at) = certify {
                bins.certify(at);
            }
        };
        if let Some(first) = cameras.first() {
            prepare(&mut scratch, first);
            if scratch.held_bytes().saturating_mul(cameras.len()) <= budget {
                held.push(scratch.compact());
                for camera in &cameras[1..] {
                    prepare(&mut scratch, camera);
                    held.push(scratch.compact());
                }
                scratch = ViewBins::default();
            }
        }
        Self {
            cameras,
            held,
            scratch,
            certify,
        }
    }

    /// Number of views.
    pub fn len(&self) -> usize {
        self.cameras.len()
    }

    /// The level the views certify points at or above, if they do.
    pub fn certified_level(&self) -> Option<f64> {
        self.certify.map(|at| at.level)
    }

    /// Every view's bins, when held.
    pub fn held(&self) -> Option<&[ViewBins]> {
        (!self.held.is_empty()).then_some(self.held.as_slice())
    }

    /// View `v`'s bins: held, or prepared now (replacing the previous streamed view).
    pub fn stream(&mut self, p: &Prepared, v: usize) -> &ViewBins {
        if self.held.is_empty() {
            self.scratch.prepare(p, &self.cameras[v]);
            if let Some(at) = self.certify {
                self.scratch.certify(at);
            }
            &self.scratch
        } else {
            &self.held[v]
        }
    }
}
