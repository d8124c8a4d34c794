//! 2DGS surfels after hbb1's `diff-surfel-rasterization` (docs/conventions.md §5): ray-splat intersection
//! through two planes, the screen-space low-pass filter, per-pixel intersection depth.
//!
//! A surfel is the disc of a Gaussian in the plane of its first two axes: centre `μ`, tangent
//! axes `s_u t_u`, `s_v t_v` (scales of the first two axes; a three-scale set's third scale is
//! ignored), normal `t_w` (the third axis). With `K` the intrinsics and camera-space columns
//! `Tu = W s_u t_u`, `Tv = W s_v t_v`, `p = W (μ − c)`, the 3×3 matrix `M = K [Tu Tv p]` maps
//! surfel coordinates `(u, v, 1)` to homogeneous pixels `(x z, y z, z)` (2DGS Eq. 7). Its rows
//! are hbb1's `Tu`, `Tv`, `Tw` ([`SurfelSplat::rows`]). Per pixel `(x, y)`:
//! - the planes `k = x Tw − Tu` and `l = y Tw − Tv` meet the surfel plane in the point with
//!   homogeneous surfel coordinates `k × l`; no intersection when its third component is 0;
//! - `rho3d = u² + v²` at that point, `rho2d = FILTER_INV_SQUARE · |centre − pixel|²` with the
//!   centre of the screen box below; `rho = min(rho3d, rho2d)`;
//! - depth: the intersection's z (`u Tw.x + v Tw.y + Tw.z`) where `rho3d ≤ rho2d`, else the
//!   centre's z; pixels whose depth is below the near plane are skipped;
//! - `alpha = min(0.99, opacity exp(−rho / 2))`, composited with 3DGS's rules (skip below 1/255,
//!   stop when `T (1 − alpha) < 1e-4`), median depth from the last splat met while `T > 0.5`
//!   ([`SURFEL_RULES`]).
//!
//! Screen box (hbb1 `computeAABB`): with `d = Tw.x² + Tw.y² − Tw.z²` and `f = (1, 1, −1)/d`, the
//! centre is `(f·(Tu∘Tw), f·(Tv∘Tw))` and the half extents `sqrt(max(0, centre² − f·(Tu∘Tu)))`
//! (the box of the projected unit circle); radius `ceil(3 max(extent_x, extent_y, FILTER_SIZE))`.
//! Like hbb1, every pixel of every 16×16 tile that box touches (3DGS `getRect`) counts, but only
//! those inside [`SurfelSplat::contributing_box`] are evaluated (outside it alpha is below the
//! 1/255 skip threshold, so the images are the same).
//!
//! hbb1 samples integer pixel centres with the principal point at `(W − 1)/2`; this module uses
//! the same geometry in trisplat's convention by shifting the principal point by −0.5 and
//! sampling integer pixel coordinates, so pixel (i, j) sees the ray through `(j + 0.5, i + 0.5)`
//! of docs/conventions.md §2. Normals are the surfel's third axis in camera space turned so that its z
//! component is negative (hbb1's `DUAL_VISIABLE`), reported in the requested frame.
//! All per-surfel and per-pixel arithmetic is `f64`.

use glam::{DMat3, DVec2, DVec3};
use trisplat_geometry::Camera;
use trisplat_geometry::mesh_render::NormalFrame;

use super::composite::{ALPHA_THRESHOLD, CompositeRules, MedianRule};
use super::options::RenderOptions;
use super::pinhole::Pinhole;
use super::screen::{Sample, ScreenEntry, ScreenSplats, SplatKernel, gather_visible, shade};
use super::tiles::{TILE_SIZE, TileRect, tile_range};
use crate::gaussians::GaussianSet;
use crate::gaussians::sigmoid;

/// hbb1's `FilterInvSquare`: `rho2d = 2 |centre − pixel|²`, a screen-space Gaussian of
/// variance ½ px² (Botsch et al. 2005's low-pass filter).
pub const FILTER_INV_SQUARE: f64 = 2.0;
/// hbb1's `FilterSize` (√2/2 as written in its source): the smallest extent of a screen box.
#[expect(
    clippy::approx_constant,
    reason = "hbb1's literal, which is not exactly 1/sqrt(2)"
)]
pub const FILTER_SIZE: f64 = 0.707106;
/// hbb1's box radius in units of the surfel's scale (`truncated_R` without `TIGHTBBOX`).
pub const SURFEL_EXTENT: f64 = 3.0;
/// hbb1's near plane (`in_frustum` and `NEAR_PLANE`); see [`RenderOptions::near`].
pub const SURFEL_NEAR: f32 = 0.2;

/// hbb1's compositing rules: alpha clamp 0.99, skip below 1/255, stop when the transmittance
/// would fall strictly below 1e-4, integer pixel centres (the module shifts the principal
/// point), every pixel of the touched tiles, 3DGS `getRect` tiles, median depth from the last
/// splat met while `T > 0.5`.
/// These are the original 3DGS rules but for the median.
pub const SURFEL_RULES: CompositeRules = CompositeRules {
    median: MedianRule::LastWhileAboveHalf,
    ..CompositeRules::ORIGINAL_3DGS
};

/// Per-pixel data of one projected surfel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfelSplat {
    /// Rows `Tu`, `Tv`, `Tw` of `M = K [Tu Tv p]` (hbb1's `transMat`), in pixel coordinates
    /// whose integer points are pixel centres.
    pub rows: [DVec3; 3],
    /// Centre of the screen box (the low-pass filter's centre), same pixel coordinates.
    pub center: DVec2,
    /// Opacity.
    pub opacity: f64,
    /// Pixels whose depth is below this are skipped.
    pub near: f64,
}

/// A surfel's contribution at a pixel before the compositing rules: unclamped alpha and depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfelSample {
    /// `opacity exp(−rho / 2)`.
    pub alpha: f64,
    /// Intersection z, or the centre's z where the low-pass filter wins.
    pub depth: f64,
    /// `u² + v²` at the ray-plane intersection (infinite without one).
    pub rho3d: f64,
    /// The low-pass filter's `2 |centre − pixel|²`.
    pub rho2d: f64,
}

/// A surfel met by a pixel's ray: [`SurfelSplat::evaluate`]'s values and the intermediates of
/// its vector-Jacobian product.
pub(crate) struct SurfelHit {
    /// `k = x Tw − Tu`, `l = y Tw − Tv`, `p = k × l`.
    pub(crate) k: DVec3,
    pub(crate) l: DVec3,
    pub(crate) p: DVec3,
    /// Surfel coordinates of the intersection.
    pub(crate) s: DVec2,
    /// Whether the ray-splat term won (`rho3d ≤ rho2d`).
    pub(crate) on_disc: bool,
    /// `exp(−rho / 2)`.
    pub(crate) falloff: f64,
    /// `opacity × falloff`, unclamped.
    pub(crate) alpha: f64,
    pub(crate) depth: f64,
    pub(crate) rho3d: f64,
    pub(crate) rho2d: f64,
}

impl SurfelSplat {
    /// Evaluates the surfel at pixel coordinates `(x, y)` (integer values are pixel centres);
    /// `None` when the ray is parallel to the surfel (hbb1's `BACKFACE_CULL`), the depth is
    /// below the near plane, or a value is not finite.
    #[inline]
    #[must_use]
    pub fn evaluate(&self, x: f64, y: f64) -> Option<SurfelSample> {
        self.hit(x, y).map(|h| SurfelSample {
            alpha: h.alpha,
            depth: h.depth,
            rho3d: h.rho3d,
            rho2d: h.rho2d,
        })
    }

    /// [`Self::evaluate`] with the intermediates its vector-Jacobian product needs (the
    /// differentiable renderer's 2DGS mode).
    #[inline(always)]
    pub(crate) fn hit(&self, x: f64, y: f64) -> Option<SurfelHit> {
        let [tu, tv, tw] = self.rows;
        let k = x * tw - tu;
        let l = y * tw - tv;
        let p = k.cross(l);
        if p.z == 0.0 {
            return None;
        }
        let s = DVec2::new(p.x / p.z, p.y / p.z);
        let rho3d = s.length_squared();
        let rho2d = FILTER_INV_SQUARE * (self.center - DVec2::new(x, y)).length_squared();
        let on_disc = rho3d <= rho2d;
        let (rho, depth) = if on_disc {
            (rho3d, s.x * tw.x + s.y * tw.y + tw.z)
        } else {
            (rho2d, tw.z)
        };
        if depth.is_nan() || depth < self.near || !rho.is_finite() {
            return None;
        }
        let falloff = (-0.5 * rho).exp();
        Some(SurfelHit {
            k,
            l,
            p,
            s,
            on_disc,
            falloff,
            alpha: self.opacity * falloff,
            depth,
            rho3d,
            rho2d,
        })
    }

    /// A box of pixel coordinates (integer values are pixel centres) outside of which this surfel
    /// certainly has alpha below the skip threshold, so the loops need not evaluate it there:
    /// `alpha ≥ t` needs `rho ≤ R = 2 ln(opacity / t)`, so either the filter term (pixels within
    /// `sqrt(R / 2)` of the filter centre) or the ray-splat term (the image of the disc of radius
    /// `sqrt(R)`, whose box is hbb1's computeAABB of the rows with `u`, `v` scaled by `sqrt(R)`:
    /// exact while the disc lies wholly in front of the camera, else the whole image). Widened by
    /// a pixel and a slack in `R` for rounding, so the images are those of every-pixel evaluation.
    #[must_use]
    pub fn contributing_box(&self) -> [f64; 4] {
        const EVERYWHERE: [f64; 4] = [
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
        ];
        const MARGIN: f64 = 1.0;
        let rho_max = 2.0 * (self.opacity / f64::from(ALPHA_THRESHOLD)).ln();
        if !rho_max.is_finite() {
            return EVERYWHERE;
        }
        let r = (rho_max.max(0.0) * 1.001 + 1e-3).sqrt();
        let [tu, tv, tw] = self.rows;
        // Nearest camera z of the disc of radius r: Tw.z − r |Tw.xy| (Tw is M's depth row).
        let nearest = tw.z - r * tw.x.hypot(tw.y);
        if nearest.is_nan() || nearest <= 0.0 {
            return EVERYWHERE;
        }
        let scale = DVec3::new(r, r, 1.0);
        let (ru, rv, rw) = (tu * scale, tv * scale, tw * scale);
        let sign = DVec3::new(1.0, 1.0, -1.0);
        let f = sign / sign.dot(rw * rw);
        let center = DVec2::new(f.dot(ru * rw), f.dot(rv * rw));
        let h = center * center - DVec2::new(f.dot(ru * ru), f.dot(rv * rv));
        let extent = DVec2::new(h.x.max(0.0).sqrt(), h.y.max(0.0).sqrt());
        let filter = r / FILTER_INV_SQUARE.sqrt();
        let b = [
            (center.x - extent.x).min(self.center.x - filter) - MARGIN,
            (center.x + extent.x).max(self.center.x + filter) + MARGIN,
            (center.y - extent.y).min(self.center.y - filter) - MARGIN,
            (center.y + extent.y).max(self.center.y + filter) + MARGIN,
        ];
        if b.iter().all(|v| !v.is_nan()) {
            b
        } else {
            EVERYWHERE
        }
    }
}

/// The 2DGS surfel kernel ([`SurfelSplat::evaluate`] for each visible surfel).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfelKernel {
    /// One entry per visible surfel, indexed like the [`ScreenSplats`].
    pub splats: Vec<SurfelSplat>,
    /// Each surfel's [`SurfelSplat::contributing_box`] in `f32`, clamped to ±[`BOX_LIMIT`]
    /// (`None`: no bound), for [`SplatKernel::row_span`].
    bounds: Vec<Option<[f32; 4]>>,
}

/// Bound on [`SurfelKernel`]'s row-span coordinates (far outside any image, well inside the
/// range where the compositor's `as usize` conversions are exact).
const BOX_LIMIT: f64 = 1e7;

impl SurfelKernel {
    /// The kernel of `splats`, with their contributing boxes.
    #[must_use]
    pub fn new(splats: Vec<SurfelSplat>) -> Self {
        use rayon::prelude::*;
        let bounds = splats
            .par_iter()
            .map(|s| {
                let b = s.contributing_box();
                b.iter()
                    .all(|v| v.is_finite())
                    .then(|| b.map(|v| v.clamp(-BOX_LIMIT, BOX_LIMIT) as f32))
            })
            .collect();
        Self { splats, bounds }
    }
}

impl SplatKernel for SurfelKernel {
    #[inline]
    fn sample(&self, i: usize, px: f32, py: f32) -> Option<Sample> {
        let s = self.splats.get(i)?.evaluate(f64::from(px), f64::from(py))?;
        Some(Sample {
            alpha: s.alpha as f32,
            depth: s.depth as f32,
        })
    }

    /// The contributing box's columns on rows inside it, an empty span elsewhere
    /// ([`SurfelSplat::contributing_box`]; `f32` rounding is inside its one-pixel margin).
    #[inline]
    fn row_span(&self, i: usize, py: f32) -> Option<(f32, f32)> {
        let [x0, x1, y0, y1] = (*self.bounds.get(i)?)?;
        if py >= y0 && py <= y1 {
            Some((x0, x1))
        } else {
            Some((BOX_LIMIT as f32, -BOX_LIMIT as f32))
        }
    }
}

/// A surfel after projection: its kernel data, screen box, sort depth and normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectedSurfel {
    /// Per-pixel data.
    pub splat: SurfelSplat,
    /// hbb1's box half extents (before the `3 ×` and the filter floor).
    pub extent: DVec2,
    /// hbb1's radius: `ceil(3 max(extent.x, extent.y, FILTER_SIZE))` pixels.
    pub radius: f64,
    /// Camera z of the centre (the sort key).
    pub depth: f64,
    /// Unit normal in camera space with a negative (or zero) z component.
    pub normal_camera: DVec3,
}

/// What the surfel projection needs of the camera.
#[derive(Clone, Copy, Debug)]
pub(crate) struct View {
    /// The camera, its principal point shifted by −0.5 (integer pixel centres).
    pub(crate) cam: Pinhole,
    pub(crate) near: f64,
    pub(crate) far: f64,
}

impl View {
    pub(crate) fn new(camera: &Camera, near: f64, far: f64) -> Self {
        let cam = Pinhole::of(camera);
        Self {
            cam: Pinhole {
                cx: cam.cx - 0.5,
                cy: cam.cy - 0.5,
                ..cam
            },
            near,
            far,
        }
    }
}

/// Projects one surfel (world-space centre, rotation whose columns are the tangent axes and the
/// normal, the two tangent scales, opacity) into `camera` with hbb1's rules; `None` when it is
/// culled: centre not in `(near, far)`, no screen box (`d = 0`), or a non-finite value.
#[must_use]
pub fn project_surfel(
    camera: &Camera,
    (mean, rotation, scale, opacity): (DVec3, DMat3, DVec2, f64),
    (near, far): (f64, f64),
) -> Option<ProjectedSurfel> {
    project_with(
        &View::new(camera, near, far),
        mean,
        rotation,
        scale,
        opacity,
    )
}

pub(crate) fn project_with(
    v: &View,
    mean: DVec3,
    rotation: DMat3,
    scale: DVec2,
    opacity: f64,
) -> Option<ProjectedSurfel> {
    let t = v.cam.w2c * (mean - v.cam.position);
    if !(t.z > v.near && t.z < v.far) {
        return None;
    }
    let tu = v.cam.w2c * (rotation.x_axis * scale.x);
    let tv = v.cam.w2c * (rotation.y_axis * scale.y);
    let row = |c: DVec3| {
        DVec3::new(
            v.cam.fx * c.x + v.cam.cx * c.z,
            v.cam.fy * c.y + v.cam.cy * c.z,
            c.z,
        )
    };
    // Columns of M = K [Tu Tv p]; hbb1's Tu, Tv, Tw are its rows.
    let (c0, c1, c2) = (row(tu), row(tv), row(t));
    let rows = [
        DVec3::new(c0.x, c1.x, c2.x),
        DVec3::new(c0.y, c1.y, c2.y),
        DVec3::new(c0.z, c1.z, c2.z),
    ];
    let [ru, rv, rw] = rows;
    // hbb1 computeAABB.
    let sign = DVec3::new(1.0, 1.0, -1.0);
    let d = sign.dot(rw * rw);
    if d == 0.0 || !d.is_finite() {
        return None;
    }
    let f = sign / d;
    let center = DVec2::new(f.dot(ru * rw), f.dot(rv * rw));
    let h0 = center * center - DVec2::new(f.dot(ru * ru), f.dot(rv * rv));
    let extent = DVec2::new(h0.x.max(0.0).sqrt(), h0.y.max(0.0).sqrt());
    let radius = (SURFEL_EXTENT * extent.x.max(extent.y).max(FILTER_SIZE)).ceil();
    if !(center.is_finite() && radius.is_finite()) {
        return None;
    }
    let n = v.cam.w2c * rotation.z_axis;
    let normal_camera = if n.z < 0.0 { n } else { -n };
    Some(ProjectedSurfel {
        splat: SurfelSplat {
            rows,
            center,
            opacity,
            near: v.near,
        },
        extent,
        radius,
        depth: t.z,
        normal_camera,
    })
}

/// Projects the Gaussians of `set` (world space) as 2DGS surfels into `camera` (module
/// documentation), for [`super::composite::rasterize`] with [`SURFEL_RULES`]. Surfels with
/// opacity below 1/255 are left out (none of their samples could pass the skip threshold), as
/// are those whose tile rectangle is empty. Colours are evaluated only when
/// `options.outputs.rgb`, normals only when `options.outputs.normal`. Uses `options.near`
/// (hbb1: [`SURFEL_NEAR`]) and `options.far`.
#[must_use]
pub fn project_surfels(
    set: &GaussianSet,
    camera: &Camera,
    options: &RenderOptions,
) -> (ScreenSplats, SurfelKernel) {
    let view = View::new(camera, f64::from(options.near), f64::from(options.far));
    let c2w = camera.rotation();
    let tiles = (
        camera.width.div_ceil(TILE_SIZE),
        camera.height.div_ceil(TILE_SIZE),
    );
    let (screen, splats) = gather_visible(set.len(), options.outputs, |i| {
        let opacity = f64::from(sigmoid(set.opacity_logits()[i]));
        if opacity < f64::from(ALPHA_THRESHOLD) {
            return None;
        }
        let mean = set.means()[i].as_dvec3();
        let s = set.scale(i).as_dvec3();
        let p = project_with(
            &view,
            mean,
            set.rotation_matrix(i),
            DVec2::new(s.x, s.y),
            opacity,
        )?;
        let (x0, x1, y0, y1) = tile_range(
            TileRect::Original3dgs,
            [p.splat.center.x as f32, p.splat.center.y as f32],
            [p.radius as f32; 2],
            tiles.0,
            tiles.1,
        );
        if x0 >= x1 || y0 >= y1 {
            return None;
        }
        let (color, normal) = shade(set, i, mean - view.cam.position, options.outputs, || {
            match options.normal_frame {
                NormalFrame::Camera => p.normal_camera,
                NormalFrame::World => c2w * p.normal_camera,
            }
            .as_vec3()
            .to_array()
        });
        let entry = ScreenEntry {
            id: i as u32,
            center: [p.splat.center.x as f32, p.splat.center.y as f32],
            radius: [p.radius as f32; 2],
            depth: p.depth as f32,
            color,
            normal,
        };
        Some((entry, p.splat))
    });
    (screen, SurfelKernel::new(splats))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(fov: f64) -> Camera {
        Camera::look_at(
            "c",
            DVec3::new(0.0, 0.0, -3.0),
            DVec3::ZERO,
            DVec3::Y,
            (64, 48),
            fov,
        )
        .expect("camera")
    }

    #[test]
    fn fronto_parallel_surfel_matches_the_analytic_disc() {
        // A surfel at the origin facing the camera (normal ±z), scales 0.3 and 0.1: at the
        // pixel through the world point (a, b, 0) the surfel coordinates are (a/0.3, b/0.1)
        // up to the axes' signs, the depth is 3 everywhere.
        let cam = camera(40.0);
        let p = project_surfel(
            &cam,
            (DVec3::ZERO, DMat3::IDENTITY, DVec2::new(0.3, 0.1), 0.8),
            (0.2, 1e10),
        )
        .expect("visible");
        assert!((p.depth - 3.0).abs() < 1e-12);
        assert!((p.normal_camera - DVec3::NEG_Z).length() < 1e-12);
        // The box centre is the projected centre (pixel coordinates shifted by −0.5).
        assert!((p.splat.center - DVec2::new(31.5, 23.5)).length() < 1e-9);
        for (a, b) in [(0.0, 0.0), (0.1, 0.05), (-0.25, 0.02), (0.2, -0.1)] {
            let uv = cam.project(cam.world_to_camera(DVec3::new(a, b, 0.0)));
            let s = p
                .splat
                .evaluate(uv.x - 0.5, uv.y - 0.5)
                .expect("intersects");
            let want = (a / 0.3).powi(2) + (b / 0.1).powi(2);
            assert!(
                (s.rho3d - want).abs() < 1e-9,
                "{a} {b}: {} vs {want}",
                s.rho3d
            );
            let rho = want.min(s.rho2d);
            assert!((s.alpha - 0.8 * (-0.5 * rho).exp()).abs() < 1e-12);
            assert!((s.depth - 3.0).abs() < 1e-9);
        }
        // Box: the unit circle (scale 0.3 along x) projects to a half extent of
        // 0.3 f / 3 pixels in x.
        let want = 0.3 * cam.fx / 3.0;
        assert!((p.extent.x - want).abs() < 1e-9, "{} vs {want}", p.extent.x);
        assert_eq!(p.radius, (3.0 * want).ceil());
    }

    #[test]
    fn tilted_surfel_depth_is_the_ray_plane_intersection() {
        let cam = camera(60.0);
        // Normal tilted 50° about y.
        let rot = DMat3::from_rotation_y(50f64.to_radians());
        let p = project_surfel(
            &cam,
            (DVec3::new(0.1, 0.05, 0.2), rot, DVec2::new(0.4, 0.3), 0.9),
            (0.2, 1e10),
        )
        .expect("visible");
        let normal = rot.z_axis;
        let centre = DVec3::new(0.1, 0.05, 0.2);
        for (row, col) in [(24u32, 32u32), (20, 30), (27, 36)] {
            let (o, d) = cam.pixel_ray(row, col);
            let t = (centre - o).dot(normal) / d.dot(normal);
            let z = cam.world_to_camera(o + d * t).z;
            let s = p
                .splat
                .evaluate(f64::from(col), f64::from(row))
                .expect("hit");
            assert!(s.rho3d <= s.rho2d, "inside the disc");
            assert!((s.depth - z).abs() < 1e-9 * z, "{} vs {z}", s.depth);
        }
        // Camera-space normal faces the camera (negative z) and is unit.
        assert!(p.normal_camera.z < 0.0);
        assert!((p.normal_camera.length() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn edge_on_tiny_and_near_surfels() {
        let cam = camera(50.0);
        // Edge-on: the normal is perpendicular to the view axis; only the low-pass filter
        // remains where rays miss the plane's disc; values stay finite.
        let edge = project_surfel(
            &cam,
            (
                DVec3::ZERO,
                DMat3::from_rotation_y(90f64.to_radians()),
                DVec2::new(0.2, 0.2),
                0.7,
            ),
            (0.2, 1e10),
        )
        .expect("visible");
        for x in 25..40 {
            if let Some(s) = edge.splat.evaluate(f64::from(x), 23.0) {
                assert!(s.alpha.is_finite() && s.depth.is_finite());
            }
        }
        // Log-scale −29: a sub-pixel surfel is drawn by the filter alone, radius 3 px.
        let tiny = project_surfel(
            &cam,
            (
                DVec3::ZERO,
                DMat3::IDENTITY,
                DVec2::splat((-29f64).exp()),
                0.7,
            ),
            (0.2, 1e10),
        )
        .expect("visible");
        assert_eq!(tiny.radius, 3.0);
        let s = tiny.splat.evaluate(31.5, 23.5).expect("centre");
        assert!((s.alpha - 0.7).abs() < 1e-12);
        // Centres at or in front of the near plane are culled.
        let near = project_surfel(
            &cam,
            (
                DVec3::new(0.0, 0.0, -2.85),
                DMat3::IDENTITY,
                DVec2::splat(0.1),
                0.7,
            ),
            (0.2, 1e10),
        );
        assert!(near.is_none());
    }
}
