//! Perspective-aware evaluation (TGA, docs/conventions.md §5): each Gaussian is evaluated at its maximum along
//! the pixel ray in 3D instead of through the affine (EWA) approximation of the projection.
//!
//! # The kernel
//! In camera space a Gaussian has centre `v = z (xc, yc, 1)` and covariance `Σ'` (below). The
//! ray through pixel `(px, py)` has direction `d = ((px − cx)/fx, (py − cy)/fy, 1)`. The largest
//! value of the Gaussian on the ray's line is `exp(−D²/2)` with `D²` the squared Mahalanobis
//! distance from the centre to the line; it equals the 2D Mahalanobis distance after projecting
//! along `d`, which has the closed form (no inverse of `Σ'`, so flat Gaussians are fine)
//!
//! ```text
//! D² = (d × v)ᵀ Σ' (d × v) / (dᵀ adj(Σ') d)
//! ```
//!
//! With `d = (xc + δx, yc + δy, 1)` (`δ` = pixel offset from the projected centre over the
//! focal lengths), `d × v = z (δy, −δx, δx yc − δy xc)` is computed without cancellation.
//! `alpha = opacity exp(−D²/2)`, composited with gsplat's rules ([`CompositeRules::GSPLAT`]).
//! The depth a pixel sees is the camera z of that maximum, `z* = z dᵀ adj(Σ') (xc, yc, 1) /
//! dᵀ adj(Σ') d` (the centre's z where that is not finite and positive). The maximum is taken
//! over the ray's whole line, as in the closed form.
//!
//! # The screen-space dilation
//! gsplat adds `0.3 I` to the projected 2D covariance. Adding `Dil = diag(0.3 z²/fx², 0.3 z²/fy²,
//! 0)` (camera axes, `z` the centre's depth) to the 3D covariance gives exactly the same 2D
//! covariance under the EWA Jacobian at any pixel (its third row meets `Dil`'s zero), so
//! `Σ' = W Σ Wᵀ + Dil` keeps this mode equal to 3DGS mode wherever the affine approximation is
//! exact (small Gaussians, narrow fields of view), and keeps sub-pixel Gaussians visible.
//! Antialiased mode multiplies the opacity by gsplat's compensation computed with the EWA
//! Jacobian at the centre.
//!
//! # The screen box
//! The pixels where `D² ≤ k²` are the image of the ellipsoid `(x − μ)ᵀ Σ'⁻¹ (x − μ) ≤ k²`: the
//! inside of the conic `z² (ṽ × δ)ᵀ Σ' (ṽ × δ) − k² dᵀ adj(Σ') d ≤ 0` (`ṽ = v/z`). Its exact
//! bounding box comes from the dual conic (tangent lines `δx = const`, `δy = const`), with
//! `k = min(3.33, sqrt(2 ln(255 opacity)))` as in gsplat, so every pixel with `alpha ≥ 1/255`
//! is inside it. When the conic is not an ellipse (the camera is inside the ellipsoid, or the
//! ellipsoid reaches behind the camera plane) the box is the whole image.

use glam::{DMat3, DVec2, DVec3};
use trisplat_geometry::Camera;

use super::composite::{ALPHA_THRESHOLD, CompositeRules};
use super::options::RenderOptions;
use super::pinhole::Pinhole;
use super::project::{EPS_2D, GSPLAT_EXTENT};
use super::screen::{
    Sample, ScreenEntry, ScreenSplats, SplatKernel, facing_normal, gather_visible, shade,
};
use crate::gaussians::GaussianSet;
use crate::gaussians::sigmoid;

/// Screen boxes are widened by this many pixels so that `f32` rounding of their centre and
/// radius cannot drop a pixel centre lying on the exact silhouette.
pub const BOX_MARGIN: f64 = 0.5;

/// The compositing rules of this mode: gsplat's (pixel centres at `j + 0.5`).
pub const PERSPECTIVE_RULES: CompositeRules = CompositeRules::GSPLAT;

/// A symmetric 3×3 matrix as `[xx, xy, xz, yy, yz, zz]`.
type Sym3 = [f64; 6];

#[inline]
fn sym_quad(m: &Sym3, a: DVec3, b: DVec3) -> f64 {
    a.x * (m[0] * b.x + m[1] * b.y + m[2] * b.z)
        + a.y * (m[1] * b.x + m[3] * b.y + m[4] * b.z)
        + a.z * (m[2] * b.x + m[4] * b.y + m[5] * b.z)
}

fn sym_from(m: DMat3) -> Sym3 {
    [
        m.x_axis.x,
        0.5 * (m.y_axis.x + m.x_axis.y),
        0.5 * (m.z_axis.x + m.x_axis.z),
        m.y_axis.y,
        0.5 * (m.z_axis.y + m.y_axis.z),
        m.z_axis.z,
    ]
}

/// The adjugate (transposed cofactor matrix) of a symmetric matrix, itself symmetric.
fn sym_adjugate(m: &Sym3) -> Sym3 {
    let [a, b, c, d, e, f] = *m;
    [
        d * f - e * e,
        c * e - b * f,
        b * e - c * d,
        a * f - c * c,
        b * c - a * e,
        a * d - b * b,
    ]
}

/// Per-pixel data of one Gaussian in this mode.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PerspectiveSplat {
    /// Projected centre in pixels `(fx xc + cx, fy yc + cy)`.
    pub center: DVec2,
    /// Centre direction `(xc, yc) = (x/z, y/z)`.
    pub dir: DVec2,
    /// Camera z of the centre.
    pub z: f64,
    /// `1/fx`, `1/fy`.
    pub inv_focal: DVec2,
    /// Dilated camera-space covariance `Σ'`.
    pub cov: Sym3,
    /// `adj(Σ')`.
    pub adj: Sym3,
    /// Opacity (× compensation when antialiased).
    pub opacity: f64,
}

/// A Gaussian's value at a pixel in this mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayMax {
    /// Squared Mahalanobis distance from the centre to the pixel ray's line.
    pub dist_sq: f64,
    /// Camera z of the Gaussian's maximum on the ray.
    pub depth: f64,
}

impl PerspectiveSplat {
    /// `D²` and the depth of the maximum along the ray through pixel coordinates `(px, py)`;
    /// `None` when the ray is degenerate for this Gaussian (a value is not finite).
    #[inline]
    #[must_use]
    pub fn ray_max(&self, px: f64, py: f64) -> Option<RayMax> {
        let dx = (px - self.center.x) * self.inv_focal.x;
        let dy = (py - self.center.y) * self.inv_focal.y;
        let (xc, yc) = (self.dir.x, self.dir.y);
        let w = DVec3::new(dy, -dx, dx * yc - dy * xc);
        let d = DVec3::new(xc + dx, yc + dy, 1.0);
        let den = sym_quad(&self.adj, d, d);
        if den.is_nan() || den <= 0.0 {
            return None;
        }
        let dist_sq = self.z * self.z * sym_quad(&self.cov, w, w) / den;
        let along = self.z * sym_quad(&self.adj, d, DVec3::new(xc, yc, 1.0)) / den;
        let depth = if along.is_finite() && along > 0.0 {
            along
        } else {
            self.z
        };
        dist_sq.is_finite().then_some(RayMax { dist_sq, depth })
    }
}

/// The perspective-aware kernel: `alpha = opacity exp(−D²/2)` at the ray's maximum.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PerspectiveKernel {
    /// One entry per visible splat, indexed like the [`ScreenSplats`].
    pub splats: Vec<PerspectiveSplat>,
}

impl SplatKernel for PerspectiveKernel {
    #[inline]
    fn sample(&self, i: usize, px: f32, py: f32) -> Option<Sample> {
        let s = self.splats.get(i)?;
        let m = s.ray_max(f64::from(px), f64::from(py))?;
        Some(Sample {
            alpha: (s.opacity * (-0.5 * m.dist_sq).exp()) as f32,
            depth: m.depth as f32,
        })
    }
}

/// A projected Gaussian: kernel data and its screen box (centre, half sizes in pixels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectedPerspective {
    /// Per-pixel data.
    pub splat: PerspectiveSplat,
    /// Box centre in pixels.
    pub box_center: DVec2,
    /// Box half sizes in pixels (including [`BOX_MARGIN`]).
    pub box_radius: DVec2,
}

fn project_with(
    v: &Pinhole,
    t: DVec3,
    cov: DMat3,
    opacity: f64,
    (near, far): (f64, f64),
    antialiased: bool,
) -> Option<ProjectedPerspective> {
    let z = t.z;
    if z.is_nan() || z <= near || z >= far || opacity < f64::from(ALPHA_THRESHOLD) {
        return None;
    }
    let (xc, yc) = (t.x / z, t.y / z);
    let mut sigma = sym_from(cov);
    // gsplat's 0.3 px² dilation, lifted to 3D (module docs).
    let (dil_x, dil_y) = (
        EPS_2D * z * z / (v.fx * v.fx),
        EPS_2D * z * z / (v.fy * v.fy),
    );
    let opacity = if antialiased {
        // Compensation with the EWA Jacobian at the centre.
        let j0 = DVec3::new(v.fx / z, 0.0, -v.fx * xc / z);
        let j1 = DVec3::new(0.0, v.fy / z, -v.fy * yc / z);
        let (a, b, c) = (
            sym_quad(&sigma, j0, j0),
            sym_quad(&sigma, j0, j1),
            sym_quad(&sigma, j1, j1),
        );
        let det = a * c - b * b;
        let det_dilated = (a + EPS_2D) * (c + EPS_2D) - b * b;
        opacity * (det / det_dilated).max(0.0).sqrt()
    } else {
        opacity
    };
    if opacity.is_nan() || opacity < f64::from(ALPHA_THRESHOLD) {
        return None;
    }
    sigma[0] += dil_x;
    sigma[3] += dil_y;
    let adj = sym_adjugate(&sigma);
    let splat = PerspectiveSplat {
        center: DVec2::new(v.fx * xc + v.cx, v.fy * yc + v.cy),
        dir: DVec2::new(xc, yc),
        z,
        inv_focal: DVec2::new(1.0 / v.fx, 1.0 / v.fy),
        cov: sigma,
        adj,
        opacity,
    };
    if !(splat.center.is_finite() && sigma.iter().chain(&adj).all(|x| x.is_finite())) {
        return None;
    }
    let k_sq =
        (GSPLAT_EXTENT * GSPLAT_EXTENT).min(2.0 * (opacity / f64::from(ALPHA_THRESHOLD)).ln());
    let (box_center, box_radius) = match silhouette_box(&splat, k_sq) {
        Some((lo, hi)) => {
            let lo = splat.center + lo * DVec2::new(v.fx, v.fy);
            let hi = splat.center + hi * DVec2::new(v.fx, v.fy);
            (0.5 * (lo + hi), 0.5 * (hi - lo) + DVec2::splat(BOX_MARGIN))
        }
        None => {
            let half = 0.5 * DVec2::new(v.width, v.height);
            (half, half + DVec2::splat(BOX_MARGIN))
        }
    };
    let lo = box_center - box_radius;
    let hi = box_center + box_radius;
    if hi.x <= 0.0 || hi.y <= 0.0 || lo.x >= v.width || lo.y >= v.height {
        return None;
    }
    Some(ProjectedPerspective {
        splat,
        box_center,
        box_radius,
    })
}

/// The bounding box `(lo, hi)` of `D² ≤ k²` in `δ = ((px − ucx)/fx, (py − ucy)/fy)`
/// coordinates, or `None` when that set is not a bounded ellipse.
fn silhouette_box(s: &PerspectiveSplat, k_sq: f64) -> Option<(DVec2, DVec2)> {
    let (xc, yc) = (s.dir.x, s.dir.y);
    // ṽ × δ = B δ with B's columns (0, 1, −yc) and (−1, 0, xc).
    let b0 = DVec3::new(0.0, 1.0, -yc);
    let b1 = DVec3::new(-1.0, 0.0, xc);
    let z2 = s.z * s.z;
    // d = A e with e = (δx, δy, 1): columns of A are e_x, e_y, ṽ.
    let vt = DVec3::new(xc, yc, 1.0);
    let (ex, ey) = (DVec3::X, DVec3::Y);
    let q00 = z2 * sym_quad(&s.cov, b0, b0) - k_sq * sym_quad(&s.adj, ex, ex);
    let q01 = z2 * sym_quad(&s.cov, b0, b1) - k_sq * sym_quad(&s.adj, ex, ey);
    let q11 = z2 * sym_quad(&s.cov, b1, b1) - k_sq * sym_quad(&s.adj, ey, ey);
    let q02 = -k_sq * sym_quad(&s.adj, ex, vt);
    let q12 = -k_sq * sym_quad(&s.adj, ey, vt);
    let q22 = -k_sq * sym_quad(&s.adj, vt, vt);
    // A bounded ellipse needs a positive definite quadratic part.
    let det2 = q00 * q11 - q01 * q01;
    if !(q00 > 0.0 && det2 > 0.0) {
        return None;
    }
    let dual = sym_adjugate(&[q00, q01, q02, q11, q12, q22]);
    // Tangent lines δx = t: dual_00 − 2 t dual_02 + t² dual_22 = 0 (dual_22 = det2 > 0).
    let solve = |a: f64, b: f64, c: f64| {
        let disc = b * b - a * c;
        (disc >= 0.0).then(|| {
            let r = disc.sqrt();
            ((b - r) / c, (b + r) / c)
        })
    };
    let (x0, x1) = solve(dual[0], dual[2], dual[5])?;
    let (y0, y1) = solve(dual[3], dual[4], dual[5])?;
    let (lo, hi) = (DVec2::new(x0, y0), DVec2::new(x1, y1));
    (lo.is_finite() && hi.is_finite()).then_some((lo, hi))
}

/// Projects the Gaussians of `set` (world space) for perspective-aware evaluation (module
/// documentation), for [`super::composite::rasterize`] with [`PERSPECTIVE_RULES`]. Culling as
/// gsplat: centre not in `(near, far)`, opacity below 1/255, box off the image. Colours are
/// evaluated only when `options.outputs.rgb`; normals (the shortest axis facing the camera, as
/// in 3DGS mode) only when `options.outputs.normal`.
#[must_use]
pub fn project_perspective(
    set: &GaussianSet,
    camera: &Camera,
    options: &RenderOptions,
) -> (ScreenSplats, PerspectiveKernel) {
    let view = Pinhole::of(camera);
    let clip = (f64::from(options.near), f64::from(options.far));
    let (screen, splats) = gather_visible(set.len(), options.outputs, |i| {
        let mean = set.means()[i].as_dvec3();
        let opacity = f64::from(sigmoid(set.opacity_logits()[i]));
        let rot = set.rotation_matrix(i);
        let s = set.scale(i).as_dvec3();
        let l = view.w2c * DMat3::from_cols(rot.x_axis * s.x, rot.y_axis * s.y, rot.z_axis * s.z);
        let t = view.w2c * (mean - view.position);
        let p = project_with(
            &view,
            t,
            l * l.transpose(),
            opacity,
            clip,
            options.antialiased,
        )?;
        let (color, normal) = shade(set, i, mean - view.position, options.outputs, || {
            facing_normal(rot, s, mean - view.position, view.w2c, options.normal_frame)
        });
        let entry = ScreenEntry {
            id: i as u32,
            center: [p.box_center.x as f32, p.box_center.y as f32],
            radius: [p.box_radius.x as f32, p.box_radius.y as f32],
            depth: p.splat.z as f32,
            color,
            normal,
        };
        Some((entry, p.splat))
    });
    (screen, PerspectiveKernel { splats })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(fov: f64, size: (u32, u32)) -> Camera {
        Camera::look_at(
            "c",
            DVec3::new(0.0, 0.0, -3.0),
            DVec3::ZERO,
            DVec3::Y,
            size,
            fov,
        )
        .expect("camera")
    }

    /// Covariance with axes `rot` and standard deviations `s`.
    fn cov(rot: DMat3, s: DVec3) -> DMat3 {
        let l = DMat3::from_cols(rot.x_axis * s.x, rot.y_axis * s.y, rot.z_axis * s.z);
        l * l.transpose()
    }

    /// Brute force: the minimum over the line of the Mahalanobis distance (Σ' invertible).
    fn brute_dist_sq(sigma: &Sym3, mean: DVec3, d: DVec3) -> f64 {
        let m = DMat3::from_cols(
            DVec3::new(sigma[0], sigma[1], sigma[2]),
            DVec3::new(sigma[1], sigma[3], sigma[4]),
            DVec3::new(sigma[2], sigma[4], sigma[5]),
        );
        let a = m.inverse();
        // min_t (t d − μ)ᵀ A (t d − μ) = μᵀAμ − (dᵀAμ)² / dᵀAd.
        let dam = d.dot(a * mean);
        mean.dot(a * mean) - dam * dam / d.dot(a * d)
    }

    #[test]
    fn closed_form_matches_the_inverse_form() {
        let cam = camera(100.0, (80, 60));
        let view = Pinhole::of(&cam);
        let mean = DVec3::new(0.7, -0.4, 2.5);
        let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.8, 1.1);
        let p = project_with(
            &view,
            mean,
            cov(rot, DVec3::new(0.5, 0.05, 0.2)),
            0.9,
            (0.01, 1e10),
            false,
        )
        .expect("visible");
        for (px, py) in [
            (10.5, 20.5),
            (55.5, 12.5),
            (p.splat.center.x, p.splat.center.y),
        ] {
            let m = p.splat.ray_max(px, py).expect("finite");
            let d = cam.unproject(px, py);
            let want = brute_dist_sq(&p.splat.cov, mean, d);
            assert!(
                (m.dist_sq - want).abs() < 1e-9 * want.max(1.0),
                "{} vs {want}",
                m.dist_sq
            );
            // The depth is where the ray is closest in the metric.
            let m3 = DMat3::from_cols(
                DVec3::new(p.splat.cov[0], p.splat.cov[1], p.splat.cov[2]),
                DVec3::new(p.splat.cov[1], p.splat.cov[3], p.splat.cov[4]),
                DVec3::new(p.splat.cov[2], p.splat.cov[4], p.splat.cov[5]),
            )
            .inverse();
            let t = d.dot(m3 * mean) / d.dot(m3 * d);
            assert!((m.depth - t * d.z).abs() < 1e-9 * t, "{} vs {t}", m.depth);
        }
    }

    #[test]
    fn box_bounds_the_visible_region() {
        let cam = camera(120.0, (96, 64));
        let view = Pinhole::of(&cam);
        let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.2, 0.9, -0.4);
        for (mean, s, o) in [
            (DVec3::new(1.2, 0.3, 1.5), DVec3::new(0.8, 0.05, 0.1), 0.95),
            (DVec3::new(-0.3, -0.2, 2.0), DVec3::new(0.1, 0.1, 0.1), 0.5),
            (DVec3::new(0.0, 0.4, 0.8), DVec3::new(0.3, 0.02, 0.02), 0.3),
        ] {
            let p =
                project_with(&view, mean, cov(rot, s), o, (0.01, 1e10), false).expect("visible");
            let lo = p.box_center - p.box_radius;
            let hi = p.box_center + p.box_radius;
            let mut inside = 0;
            for row in 0..64 {
                for col in 0..96 {
                    let (px, py) = (f64::from(col) + 0.5, f64::from(row) + 0.5);
                    let m = p.splat.ray_max(px, py).expect("finite");
                    let alpha = o * (-0.5 * m.dist_sq).exp();
                    if alpha >= f64::from(ALPHA_THRESHOLD) {
                        inside += 1;
                        assert!(
                            px >= lo.x && px <= hi.x && py >= lo.y && py <= hi.y,
                            "pixel ({px}, {py}) alpha {alpha} outside {lo} {hi}"
                        );
                    }
                }
            }
            assert!(inside > 0);
            // Tight: the box is not much larger than the visible region needs.
            assert!(p.box_radius.x < 96.0 && p.box_radius.y < 64.0);
        }
    }

    #[test]
    fn extremes_are_finite() {
        let cam = camera(90.0, (32, 24));
        let view = Pinhole::of(&cam);
        let clip = (0.01, 1e10);
        // Log-scale −29: the dilation alone, a gsplat-sized blob (3.33 σ of √0.3 px ≈ 2 px).
        let tiny = project_with(
            &view,
            DVec3::new(0.0, 0.0, 3.0),
            cov(DMat3::IDENTITY, DVec3::splat((-29f64).exp())),
            0.9,
            clip,
            false,
        )
        .expect("visible");
        assert!(tiny.box_radius.x < 3.0, "{}", tiny.box_radius);
        let m = tiny.splat.ray_max(16.0, 12.0).expect("centre");
        assert!(m.dist_sq.abs() < 1e-12 && (m.depth - 3.0).abs() < 1e-9);
        // Scale 1e3: the camera is inside, the box is the whole image, values finite.
        let huge = project_with(
            &view,
            DVec3::new(0.0, 0.0, 3.0),
            cov(DMat3::IDENTITY, DVec3::splat(1e3)),
            0.9,
            clip,
            false,
        )
        .expect("visible");
        assert_eq!(huge.box_center, DVec2::new(16.0, 12.0));
        for (px, py) in [(0.5, 0.5), (31.5, 23.5)] {
            let m = huge.splat.ray_max(px, py).expect("finite");
            assert!(m.dist_sq >= 0.0 && m.dist_sq < 1e-3 && m.depth.is_finite());
        }
        // Behind the camera, on the near plane, zero opacity: culled.
        let c = cov(DMat3::IDENTITY, DVec3::splat(0.1));
        assert!(project_with(&view, DVec3::new(0.0, 0.0, -1.0), c, 0.9, clip, false).is_none());
        assert!(project_with(&view, DVec3::new(0.0, 0.0, 0.01), c, 0.9, clip, false).is_none());
        assert!(project_with(&view, DVec3::new(0.0, 0.0, 2.0), c, 0.0, clip, false).is_none());
        // Antialiased opacity is reduced for a sub-pixel Gaussian.
        let aa =
            project_with(&view, DVec3::new(0.0, 0.0, 3.0), c, 0.9, clip, true).expect("visible");
        assert!(aa.splat.opacity <= 0.9);
    }
}
