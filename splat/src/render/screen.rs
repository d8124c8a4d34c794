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

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use trisplat_geometry::mesh_render::NormalFrame;

use super::options::Outputs;
use crate::gaussians::GaussianSet;
use crate::sh::eval_rgb;

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
/// pair in the splat's box (through [`SplatKernel::sample_row`]), from several threads.
pub trait SplatKernel: Sync {
    /// The contribution of splat `i` at pixel centre `(px, py)` (pixel coordinates, the pixel
    /// offset of the rules already added), or `None` where the splat does not contribute
    /// (3DGS: negative exponent; 2DGS: no ray-plane intersection).
    fn sample(&self, i: usize, px: f32, py: f32) -> Option<Sample>;

    /// Evaluates splat `i` at the pixel centres `(px0 + k, py)` for `k < alpha.len()`, writing
    /// the unclamped alpha (0 where [`SplatKernel::sample`] gives `None`) and the depth. The
    /// default calls [`SplatKernel::sample`] per pixel; a kernel may override it with a loop
    /// the compiler can vectorise (it must give the same values).
    #[inline]
    fn sample_row(&self, i: usize, py: f32, px0: f32, alpha: &mut [f32], depth: &mut [f32]) {
        for (k, (a, d)) in alpha.iter_mut().zip(depth.iter_mut()).enumerate() {
            match self.sample(i, px0 + k as f32, py) {
                Some(s) => {
                    *a = s.alpha;
                    *d = s.depth;
                }
                None => {
                    *a = 0.0;
                    *d = 0.0;
                }
            }
        }
    }

    /// Evaluates splat `i` at the four pixel centres `(px0 + k, py)`, `k = 0..4`: unclamped
    /// alpha and depth as [`SplatKernel::sample_row`] (the default calls it). The compositor
    /// works in these groups of four; a kernel may override it with SIMD code (`glam::Vec4`
    /// is SSE2 on x86-64) giving the same values.
    #[inline]
    fn sample4(&self, i: usize, py: f32, px0: f32) -> (glam::Vec4, glam::Vec4) {
        let mut alpha = [0.0f32; 4];
        let mut depth = [0.0f32; 4];
        self.sample_row(i, py, px0, &mut alpha, &mut depth);
        (glam::Vec4::from_array(alpha), glam::Vec4::from_array(depth))
    }

    /// Optional: a copy whose entry `k` is entry `order[k]` of `self` (`order` is a permutation
    /// of the entries: the depth order). The compositor then reads the kernel's data in memory
    /// order, which is faster for large scenes; the default `None` makes it index through
    /// `order` instead. Either way the images are the same.
    fn reordered(&self, order: &[u32]) -> Option<Self>
    where
        Self: Sized,
    {
        let _ = order;
        None
    }

    /// Optional: reads (any) one value of splat `i`'s data and returns it, so the compositor
    /// can start loading a splat it will need next while it works on the current one. The
    /// default reads nothing.
    #[inline]
    fn touch(&self, i: usize) -> f32 {
        let _ = i;
        0.0
    }

    /// Optional tightening: the interval of pixel-centre x coordinates on the row at `py` outside
    /// of which splat `i` certainly contributes nothing (alpha below the skip threshold), or
    /// `None` to scan the whole box. Must be conservative (widen by rounding margins): the
    /// compositor still calls [`SplatKernel::sample`] inside it, so a wider span only costs
    /// time, a narrower one changes images.
    #[inline]
    fn row_span(&self, i: usize, py: f32) -> Option<(f32, f32)> {
        let _ = (i, py);
        None
    }
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

    /// Empty arrays with room for `capacity` splats (colours and normals only when `outputs`
    /// asks for them).
    #[must_use]
    pub fn with_capacity(capacity: usize, outputs: Outputs) -> Self {
        Self {
            ids: Vec::with_capacity(capacity),
            centers: Vec::with_capacity(capacity),
            radii: Vec::with_capacity(capacity),
            depths: Vec::with_capacity(capacity),
            colors: Vec::with_capacity(if outputs.rgb { capacity } else { 0 }),
            normals: Vec::with_capacity(if outputs.normal { capacity } else { 0 }),
        }
    }

    /// Appends one visible splat; its colour and normal are kept only when `outputs` asks for
    /// them, so the arrays stay indexed alike.
    pub fn push(&mut self, entry: ScreenEntry, outputs: Outputs) {
        self.ids.push(entry.id);
        self.centers.push(entry.center);
        self.radii.push(entry.radius);
        self.depths.push(entry.depth);
        if outputs.rgb {
            self.colors.push(entry.color);
        }
        if outputs.normal {
            self.normals.push(entry.normal);
        }
    }
}

/// One visible splat's screen data, as [`ScreenSplats::push`] takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenEntry {
    /// Index in the source [`crate::GaussianSet`].
    pub id: u32,
    /// Centre of the screen box in pixels.
    pub center: [f32; 2],
    /// Half sizes of the screen box in pixels.
    pub radius: [f32; 2],
    /// Sort depth (camera z).
    pub depth: f32,
    /// Colour (ignored unless rgb is rendered).
    pub color: [f32; 3],
    /// Normal (ignored unless normals are rendered).
    pub normal: [f32; 3],
}

impl ScreenEntry {
    /// The entry of Gaussian `id` without colour or normal (the differentiable renderer keeps
    /// those with its own per-splat data): box `center ± radius`, sort depth `depth`.
    pub(crate) fn unshaded(id: usize, center: [f32; 2], radius: [f32; 2], depth: f64) -> Self {
        Self {
            id: id as u32,
            center,
            radius,
            depth: depth as f32,
            color: [0.0; 3],
            normal: [0.0; 3],
        }
    }
}

/// Gaussians projected per parallel chunk (results do not depend on the thread count).
const PROJECT_CHUNK: usize = 4096;

/// Runs `project` on every Gaussian index `0..n` in parallel chunks and gathers the visible
/// ones, in index order, into screen arrays plus the mode's own per-splat data.
pub(crate) fn gather_visible<S: Send>(
    n: usize,
    outputs: Outputs,
    project: impl Fn(usize) -> Option<(ScreenEntry, S)> + Sync,
) -> (ScreenSplats, Vec<S>) {
    let chunks: Vec<Vec<(ScreenEntry, S)>> = (0..n.div_ceil(PROJECT_CHUNK))
        .into_par_iter()
        .map(|c| {
            (c * PROJECT_CHUNK..((c + 1) * PROJECT_CHUNK).min(n))
                .filter_map(&project)
                .collect()
        })
        .collect();
    let visible: usize = chunks.iter().map(Vec::len).sum();
    let mut screen = ScreenSplats::with_capacity(visible, outputs);
    let mut splats = Vec::with_capacity(visible);
    for (entry, splat) in chunks.into_iter().flatten() {
        screen.push(entry, outputs);
        splats.push(splat);
    }
    (screen, splats)
}

/// Gaussian `i`'s colour seen along `view_dir` (camera to mean) and its normal (`normal()`),
/// each only when `outputs` asks for it (zeros otherwise).
#[inline]
pub(crate) fn shade(
    set: &GaussianSet,
    i: usize,
    view_dir: DVec3,
    outputs: Outputs,
    normal: impl FnOnce() -> [f32; 3],
) -> ([f32; 3], [f32; 3]) {
    let color = if outputs.rgb {
        eval_rgb(set.sh_degree(), set.sh_coeffs(i), view_dir)
    } else {
        [0.0; 3]
    };
    let normal = if outputs.normal { normal() } else { [0.0; 3] };
    (color, normal)
}

/// The Gaussian's shortest axis (first of equal ones) turned to face the camera (against
/// `view_dir`, camera to mean), in world or camera (`w2c`) coordinates.
pub(crate) fn facing_normal(
    rot: DMat3,
    s: DVec3,
    view_dir: DVec3,
    w2c: DMat3,
    frame: NormalFrame,
) -> [f32; 3] {
    let axis = if s.x <= s.y && s.x <= s.z {
        rot.x_axis
    } else if s.y <= s.z {
        rot.y_axis
    } else {
        rot.z_axis
    };
    let n = if axis.dot(view_dir) > 0.0 {
        -axis
    } else {
        axis
    };
    let n = match frame {
        NormalFrame::World => n,
        NormalFrame::Camera => w2c * n,
    };
    n.as_vec3().to_array()
}
