//! [`RenderOptions`]: what to render and by which rules.

use trisplat_geometry::mesh_render::NormalFrame;

/// gsplat's near plane (camera z below which Gaussians are culled).
pub const DEFAULT_NEAR: f32 = 0.01;
/// The original 3DGS rasterizer's near plane.
pub const ORIGINAL_3DGS_NEAR: f32 = 0.2;
/// gsplat's far plane.
pub const DEFAULT_FAR: f32 = 1e10;

/// Which splatting model renders the Gaussians.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RenderMode {
    /// 3DGS EWA splatting (affine projection of each 3D Gaussian to a 2D Gaussian).
    #[default]
    Gaussian3d,
    /// 2DGS surfels (hbb1's ray-splat intersection), see [`super::surfel`].
    Surfel2d,
    /// Perspective-aware evaluation along each pixel ray (TGA), see [`super::perspective`].
    Perspective,
}

/// Which compositing and projection rules a 3DGS render follows (docs/conventions.md §5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Rules {
    /// gsplat 1.5.3: alpha clamp 0.999, stop when `next_T <= 1e-4`, pixel centres at
    /// `(j + 0.5, i + 0.5)`, per-axis 3.33σ boxes, near plane 0.01.
    #[default]
    Gsplat,
    /// The original 3DGS (INRIA `diff-gaussian-rasterization`) rules: alpha clamp 0.99, stop when
    /// `next_T < 1e-4`, integer pixel centres (means shifted by −0.5 px, the same geometry),
    /// one radius `ceil(3 sqrt(λmax))`, every pixel of a touched tile evaluated. Use with
    /// [`ORIGINAL_3DGS_NEAR`] (see [`RenderOptions::original_3dgs`]).
    Original3dgs,
}

/// Which depth a 3DGS splat gives the pixels it covers (depth, median depth); 2DGS surfels and
/// the perspective-aware mode intersect each pixel's ray and ignore it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SplatDepth {
    /// The camera z of the Gaussian's mean over its whole footprint (3DGS, gsplat): each
    /// splat is a flat step at its centre's depth.
    #[default]
    Mean,
    /// The depth of the point of highest density on the pixel's ray (RaDe-GS, GOF),
    /// linearised around the ray through the mean: `z + g · (pixel − projected mean)` with
    /// `g = −z² (Σ⁻¹t)_xy / ((fx, fy) tᵀΣ⁻¹t)` for the camera-space mean `t` and covariance `Σ`,
    /// and the offset from `z` clamped to 3 times the largest scale. A flat Gaussian gives
    /// the depth of its own plane, so rendered surfaces are piecewise planar instead of
    /// stepped. Expected and median depth only; gradients are not computed for it.
    Ray,
}

/// Which images to compute. Only these are computed: a geometry-only render (no `rgb`) skips
/// the spherical-harmonics evaluation entirely.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Outputs {
    /// Colour `[H, W, 3]`: `Σ w c + (1 − alpha) background`.
    pub rgb: bool,
    /// Accumulated opacity `[H, W]`: `Σ w = 1 − T`.
    pub alpha: bool,
    /// Expected z-depth `[H, W]`: `Σ w z / Σ w`, 0 where nothing was hit.
    pub depth: bool,
    /// Median z-depth `[H, W]`: z of the splat at which the transmittance first drops below
    /// 0.5, 0 where it never does.
    pub median_depth: bool,
    /// Composited normals `[H, W, 3]`: `Σ w n` with unit per-splat normals facing the camera
    /// (not re-normalised: their length is the alpha of the surface).
    pub normal: bool,
}

impl Default for Outputs {
    fn default() -> Self {
        Self::RGB_ALPHA_DEPTH
    }
}

impl Outputs {
    /// Nothing.
    pub const NONE: Self = Self {
        rgb: false,
        alpha: false,
        depth: false,
        median_depth: false,
        normal: false,
    };
    /// Everything.
    pub const ALL: Self = Self {
        rgb: true,
        alpha: true,
        depth: true,
        median_depth: true,
        normal: true,
    };
    /// rgb, alpha and expected depth (the default).
    pub const RGB_ALPHA_DEPTH: Self = Self {
        rgb: true,
        alpha: true,
        depth: true,
        median_depth: false,
        normal: false,
    };

    /// Parses a comma-separated list of `rgb`, `alpha`, `depth`, `median_depth`, `normal`
    /// (also `all`).
    ///
    /// # Errors
    /// The first unknown name.
    pub fn parse_list(list: &str) -> Result<Self, String> {
        let mut out = Self::NONE;
        for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            match name {
                "rgb" => out.rgb = true,
                "alpha" => out.alpha = true,
                "depth" => out.depth = true,
                "median_depth" => out.median_depth = true,
                "normal" | "normals" => out.normal = true,
                "all" => out = Self::ALL,
                other => {
                    return Err(format!(
                        "unknown output '{other}' (expected rgb, alpha, depth, median_depth, normal)"
                    ));
                }
            }
        }
        Ok(out)
    }

    /// Whether no image is asked for.
    #[must_use]
    pub fn is_empty(self) -> bool {
        self == Self::NONE
    }
}

/// Options of [`super::render`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// The splatting model.
    pub mode: RenderMode,
    /// gsplat's rules or the original 3DGS ones (3DGS mode only).
    pub rules: Rules,
    /// Antialiased mode (gsplat `rasterize_mode="antialiased"`): opacity multiplied by the
    /// compensation `sqrt(det(Σ2D) / det(Σ2D + 0.3 I))`.
    pub antialiased: bool,
    /// The images to compute.
    pub outputs: Outputs,
    /// Background colour added with weight `1 − alpha` to `rgb`.
    pub background: [f32; 3],
    /// Gaussians with camera z `<= near` are culled (must be > 0).
    pub near: f32,
    /// Gaussians with camera z `>= far` are culled.
    pub far: f32,
    /// The frame of the normal map.
    pub normal_frame: NormalFrame,
    /// The depth of a 3DGS splat at each pixel (3DGS mode only).
    pub splat_depth: SplatDepth,
    /// Also return each Gaussian's largest blending weight `α·T` over the image
    /// ([`super::RenderOutput::contribution`]): what it adds to any pixel, for leaving out
    /// Gaussians that render nothing.
    pub contribution: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            mode: RenderMode::Gaussian3d,
            rules: Rules::Gsplat,
            antialiased: false,
            outputs: Outputs::default(),
            background: [0.0; 3],
            near: DEFAULT_NEAR,
            far: DEFAULT_FAR,
            normal_frame: NormalFrame::World,
            splat_depth: SplatDepth::Mean,
            contribution: false,
        }
    }
}

impl RenderOptions {
    /// The original 3DGS rasterizer's rules and near plane ([`Rules::Original3dgs`]).
    #[must_use]
    pub fn original_3dgs() -> Self {
        Self {
            rules: Rules::Original3dgs,
            near: ORIGINAL_3DGS_NEAR,
            ..Self::default()
        }
    }
}
