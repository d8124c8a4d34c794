//! The data every splatting mode hands to the shared tile/sort/composite stages, and the
//! extension point through which a mode evaluates its splats at pixels.
//!
//! # Adding a splatting mode
//! A mode (3DGS EWA in [`super::project`], 2DGS surfels, perspective-aware evaluation) turns a
//! [`crate::GaussianSet`] seen by a camera into
//! 1. a [`ScreenSplats`]: one entry per *visible* splat (culled ones are left out), with its
//!    screen box (centre and half sizes in pixels, used for tile binning and, under
//!    [`super::composite::CompositeRules::clip_to_box`], to skip pixels), its sort depth (camera
//!    z, > 0), and — only when asked — its colour and unit normal;
//! 2. a type implementing [`SplatKernel`] holding whatever it needs to evaluate splat `i` at a
//!    pixel centre (conic, ray-plane data, ...), indexed like the [`ScreenSplats`].
//!
//! and calls [`super::composite::rasterize`], which bins splats into 16×16 tiles, sorts each tile
//! by depth and composites front to back with the [`super::composite::CompositeRules`] the mode
//! chooses (alpha clamp, skip threshold, stop rule, pixel-centre offset, median-depth rule).

/// One splat's contribution at one pixel, before the compositing rules are applied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// `opacity × falloff`, not yet clamped (the rules clamp it and apply the skip threshold);
    /// never NaN.
    pub alpha: f32,
    /// The depth this splat contributes at this pixel (3DGS: the centre's camera z; 2DGS: the
    /// ray-splat intersection's z).
    pub depth: f32,
}

/// Evaluates visible splat `i` at a pixel centre. Implementations must be cheap, allocation
/// free and deterministic: the compositor calls [`SplatKernel::sample`] once per (splat, pixel)
/// pair in the splat's box, from several threads.
pub trait SplatKernel: Sync {
    /// The contribution of splat `i` at pixel centre `(px, py)` (pixel coordinates, the pixel
    /// offset of the rules already added), or `None` where the splat does not contribute
    /// (3DGS: negative exponent; 2DGS: no ray-plane intersection).
    fn sample(&self, i: usize, px: f32, py: f32) -> Option<Sample>;
}

/// Per-visible-splat screen data, as a structure of arrays (all `Vec`s indexed alike).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScreenSplats {
    /// Index of each splat in the source [`crate::GaussianSet`].
    pub ids: Vec<u32>,
    /// Centre of the screen box in pixel coordinates (3DGS: the projected mean).
    pub centers: Vec<[f32; 2]>,
    /// Half sizes of the screen box in pixels (gsplat's per-axis `radii`), > 0.
    pub radii: Vec<[f32; 2]>,
    /// Sort key: the camera z of the splat's centre (> 0). Ties keep the source order.
    pub depths: Vec<f32>,
    /// Colour, filled only when rgb is rendered (empty otherwise).
    pub colors: Vec<[f32; 3]>,
    /// Unit normal facing the camera in the requested frame, filled only when normals are
    /// rendered (empty otherwise).
    pub normals: Vec<[f32; 3]>,
}

impl ScreenSplats {
    /// Number of visible splats.
    #[must_use]
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether no splat is visible.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }
}
