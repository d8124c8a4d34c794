//! Scoring the held-out views of a fit: rgb by PSNR and SSIM, geometry by the depth and
//! normal errors inside the target's mask (docs/conventions.md §5 "Fitting").

use glam::DVec3;
use trisplat_geometry::Camera;
use trisplat_splat::fit::bound::{BoundParams, TriangleFrames, to_world};
use trisplat_splat::fit::loss::{Ssim, psnr};
use trisplat_splat::render::{GaussianParams, RenderMode, RenderOptions, render_with_grad};

use super::inputs::{FitFrame, Target};

/// Means over the held-out views (`None` where no view gives the value).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Scores {
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub depth_l1: Option<f64>,
    pub normal_deg: Option<f64>,
}

/// Running sum and count of one score.
#[derive(Clone, Copy, Default)]
struct Mean(f64, usize);

impl Mean {
    fn add(&mut self, v: Option<f64>) {
        if let Some(v) = v.filter(|v| v.is_finite()) {
            self.0 += v;
            self.1 += 1;
        }
    }

    fn get(self) -> Option<f64> {
        (self.1 > 0).then(|| self.0 / self.1 as f64)
    }
}

/// Scores the bound set on every held-out view: PSNR and SSIM of rgb; where the target has
/// depth and a mask, the mean absolute z-depth error over the mask's pixels (a pixel the render
/// leaves empty counts with depth 0: holes are not forgiven); where it has normals and a mask,
/// the mean angle in degrees between the target normal and the rendered one over the mask's
/// pixels where both exist (2DGS: the surfels' normal image; 3DGS: the normal of the rendered
/// depth's points by central differences, as 2DGS's depth–normal term).
pub(super) fn evaluate(
    bound: &BoundParams,
    held_out: &[FitFrame],
    frames: &[TriangleFrames],
    render: &RenderOptions,
) -> Scores {
    let mut world = GaussianParams::default();
    let (mut p, mut s, mut d, mut a) = (
        Mean::default(),
        Mean::default(),
        Mean::default(),
        Mean::default(),
    );
    for (f, fr) in held_out.iter().enumerate() {
        to_world(bound, &frames[f], &mut world);
        for t in &fr.targets {
            let Ok(out) = render_with_grad::<f32, _>(&world, &t.camera, render) else {
                continue;
            };
            p.add(Some(psnr(&out.rgb, &t.rgb)));
            let mut ssim = Ssim::new(t.camera.width as usize, t.camera.height as usize);
            s.add(Some(ssim.ssim(&out.rgb, &t.rgb, 3, 0.0, None)));
            d.add(depth_l1(t, &out.depth));
            let normals = if render.mode == RenderMode::Surfel2d {
                out.normal
            } else {
                depth_normals(&t.camera, &out.depth)
            };
            a.add(normal_deg(t, &normals));
        }
    }
    Scores {
        psnr: p.get(),
        ssim: s.get(),
        depth_l1: d.get(),
        normal_deg: a.get(),
    }
}

fn inside(t: &Target) -> Option<impl Iterator<Item = usize> + '_> {
    let mask = t.alpha.as_ref()?;
    Some((0..mask.len()).filter(|&p| mask[p] > 0.5))
}

/// Mean `|rendered − target|` z-depth over the target mask (`None` without depth or mask, or
/// with an empty mask).
fn depth_l1(t: &Target, depth: &[f32]) -> Option<f64> {
    let target = t.depth.as_ref()?;
    let mut m = Mean::default();
    for p in inside(t)? {
        m.add(Some((f64::from(depth[p]) - f64::from(target[p])).abs()));
    }
    m.get()
}

/// Mean angle (degrees) between target and rendered normals, both turned to face the camera,
/// over the target mask's pixels where the rendered normal is non-zero.
fn normal_deg(t: &Target, normals: &[f32]) -> Option<f64> {
    let target = t.normal.as_ref()?;
    if normals.len() != target.len() {
        return None;
    }
    let w = t.camera.width as usize;
    let mut m = Mean::default();
    for p in inside(t)? {
        let ray = pixel_ray(&t.camera, p / w, p % w);
        let facing = |v: &[f32]| {
            let n = DVec3::new(v[3 * p].into(), v[3 * p + 1].into(), v[3 * p + 2].into());
            let len = n.length();
            if !(len > 0.0 && len.is_finite()) {
                return None;
            }
            Some(n * if n.dot(ray) > 0.0 { -1.0 } else { 1.0 } / len)
        };
        if let (Some(a), Some(b)) = (facing(target), facing(normals)) {
            m.add(Some(a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()));
        }
    }
    m.get()
}

/// Unnormalised normals `dy × dx` of the depth map's back-projected points by central
/// differences (camera frame, `[H, W, 3]`), zero on the border and where the pixel or one of
/// its four neighbours has no depth.
fn depth_normals(camera: &Camera, depth: &[f32]) -> Vec<f32> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut out = vec![0.0f32; 3 * w * h];
    let point = |i: usize, j: usize| pixel_ray(camera, i, j) * f64::from(depth[i * w + j]);
    let valid = |i: usize, j: usize| depth[i * w + j] > 0.0;
    for i in 1..h.saturating_sub(1) {
        for j in 1..w.saturating_sub(1) {
            if !(valid(i, j)
                && valid(i - 1, j)
                && valid(i + 1, j)
                && valid(i, j - 1)
                && valid(i, j + 1))
            {
                continue;
            }
            let dx = point(i, j + 1) - point(i, j - 1);
            let dy = point(i + 1, j) - point(i - 1, j);
            let p = i * w + j;
            out[3 * p..3 * p + 3].copy_from_slice(&dy.cross(dx).as_vec3().to_array());
        }
    }
    out
}

/// The ray through the centre of pixel (row `i`, column `j`), camera frame, `z = 1`.
fn pixel_ray(camera: &Camera, i: usize, j: usize) -> DVec3 {
    DVec3::new(
        (j as f64 + 0.5 - camera.cx) / camera.fx,
        (i as f64 + 0.5 - camera.cy) / camera.fy,
        1.0,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(w: u32, h: u32) -> Camera {
        Camera::look_at(
            "c",
            DVec3::new(0.0, 0.0, -3.0),
            DVec3::ZERO,
            DVec3::Y,
            (w, h),
            50.0,
        )
        .unwrap()
    }

    #[test]
    fn a_fronto_parallel_plane_has_the_view_axis_as_normal() {
        let cam = camera(16, 12);
        let depth = vec![2.0f32; 16 * 12];
        let n = depth_normals(&cam, &depth);
        let p = 5 * 16 + 7;
        let v = [n[3 * p], n[3 * p + 1], n[3 * p + 2]];
        assert!(
            v[0].abs() < 1e-9 && v[1].abs() < 1e-9 && v[2] != 0.0,
            "{v:?}"
        );
        assert_eq!(n[0..3], [0.0; 3], "border left out");
    }

    #[test]
    fn depth_and_normal_errors_are_measured_inside_the_mask() {
        let cam = camera(16, 12);
        let px = 16 * 12;
        let mut alpha = vec![0.0f32; px];
        for i in 3..9 {
            for j in 3..13 {
                alpha[i * 16 + j] = 1.0;
            }
        }
        // A target plane at z = 2 facing the camera; the render is 0.1 deeper and tilted
        // by 30° about x, and leaves one masked pixel empty.
        let mut normal = vec![0.0f32; 3 * px];
        for p in 0..px {
            normal[3 * p + 2] = -1.0;
        }
        let t = Target {
            camera: cam.clone(),
            rgb: vec![0.0; 3 * px],
            alpha: Some(alpha),
            depth: Some(vec![2.0; px]),
            normal: Some(normal),
        };
        let mut depth = vec![2.1f32; px];
        depth[4 * 16 + 4] = 0.0;
        let masked = 60.0;
        let want = (59.0 * 0.1 + 2.0) / masked;
        assert!((depth_l1(&t, &depth).unwrap() - want).abs() < 1e-6);
        let (s, c) = 30f32.to_radians().sin_cos();
        let mut tilted = vec![0.0f32; 3 * px];
        for p in 0..px {
            tilted[3 * p + 1] = s;
            tilted[3 * p + 2] = c; // faces away: turned round before the angle is taken
        }
        assert!((normal_deg(&t, &tilted).unwrap() - 30.0).abs() < 1e-4);
        let no_mask = Target { alpha: None, ..t };
        assert_eq!(depth_l1(&no_mask, &depth), None);
    }
}
