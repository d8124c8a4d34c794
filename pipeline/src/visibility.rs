//! Which Gaussians the point methods (delaunay, alpha) mesh: the ones that render
//! (docs/conventions.md §6, "Which Gaussians extraction uses"). The tsdf method needs no such
//! rule: it renders every Gaussian of each frame, so its depth maps hold what that frame
//! shows (a mouth that opens shows its inside) and nothing that renders nothing.
//!
//! Decided once per run and applied to every frame (the same Gaussians in every frame, so the
//! incremental Delaunay mesher keeps one point set), from the rest pose and frames sampled
//! over the whole track ([`VISIBILITY_FRAMES`] of them, whatever frames the run meshes, so
//! that the shards of a track decide as one run does), so that what one of them exposes (the
//! inside of an opening mouth) is kept:
//!
//! 1. **hidden**: the Gaussians of each pose are rendered (3DGS, gsplat's rules) from the tsdf
//!    method's rig: `views` cameras of `resolution`² pixels on a Fibonacci sphere around the
//!    bounding sphere of the pose's template and means (the session uses at least 24 views of
//!    256²). A Gaussian whose largest blending weight `w = α·T` at any pixel of any view of
//!    any pose is below `min_contribution` is left out: it changes no pixel of those views by
//!    that much. The default, 1/255, is one step of an 8-bit image. Interior Gaussians (inside
//!    the closed mouth, behind the eyes, under the skin) and nearly transparent ones fall
//!    here.
//! 2. **floaters** (only when `floater_std_ratio` is given): among the others, Open3D's
//!    statistical outlier rule on the rest-pose means (`remove_statistical_outlier(neighbors,
//!    std_ratio)`, geometry's [`statistical_outliers`]): a Gaussian whose mean distance to
//!    its `neighbors` nearest means (itself included) exceeds the mean of those distances
//!    plus `std_ratio` standard deviations is left out. Off by default: the rule knows
//!    density, not surfaces, so on a bound avatar it also takes the sparse parts of the skin
//!    (CesiumMan at 3 standard deviations: 502 of 18,688 Gaussians, alpha's Chamfer distance
//!    3.4 → 7.8 mm; LAM: 219 of 20,018, hair strands among them, both point methods' Chamfer
//!    distances worse).
//!
//! `min_contribution = 0` without a floater rule keeps every Gaussian.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::outliers::statistical_outliers;
use trisplat_geometry::{bounding_sphere, sphere_rig};
use trisplat_splat::GaussianSet;
use trisplat_splat::render::{Outputs, RenderOptions, render};

use crate::config::{DEFAULT_FOV_DEG, VisibilityRule};
use crate::records::GaussiansUsed;

/// Frames of the track, besides the rest pose, whose poses the session gives [`decide`] (evenly
/// spaced over the whole track, whatever frames the run meshes; every frame of a shorter
/// track).
pub const VISIBILITY_FRAMES: usize = 4;

/// Which Gaussians the point methods use.
#[derive(Clone, Debug, PartialEq)]
pub struct Visibility {
    /// The counts.
    pub used: GaussiansUsed,
    /// Indices of the kept Gaussians, ascending; `None` when every Gaussian is kept.
    kept: Option<Vec<usize>>,
}

impl Visibility {
    /// Every one of `n` Gaussians kept.
    #[must_use]
    pub fn all(n: usize) -> Self {
        Self {
            used: GaussiansUsed {
                total: n,
                kept: n,
                ..GaussiansUsed::default()
            },
            kept: None,
        }
    }

    /// The kept indices, ascending; `None` when every Gaussian is kept.
    #[must_use]
    pub fn kept(&self) -> Option<&[usize]> {
        self.kept.as_deref()
    }

    /// `values` (one per Gaussian) of the kept Gaussians into `out` (cleared first; no
    /// allocation once `out` has grown).
    pub fn gather<T: Copy>(&self, values: &[T], out: &mut Vec<T>) {
        out.clear();
        match &self.kept {
            Some(kept) => out.extend(kept.iter().filter_map(|&i| values.get(i).copied())),
            None => out.extend_from_slice(values),
        }
    }
}

/// Why the decision of which Gaussians the point methods use failed.
#[derive(Debug, thiserror::Error)]
pub enum VisibilityError {
    /// The rig could not be placed.
    #[error("camera rig: {0}")]
    Cameras(#[from] trisplat_geometry::CameraError),
    /// A view could not be rendered.
    #[error("rendering camera {camera}: {cause}")]
    Render {
        /// The camera's name.
        camera: String,
        /// The renderer's error.
        cause: trisplat_splat::render::RenderError,
    },
    /// The floater rule refused its input.
    #[error("floaters: {0}")]
    Floaters(#[from] trisplat_geometry::outliers::OutlierError),
}

/// One pose of the Gaussians for [`decide`]: the world-space set and the template's positions
/// in that pose.
#[derive(Clone, Copy, Debug)]
pub struct Pose<'a> {
    /// The Gaussians, world space.
    pub set: &'a GaussianSet,
    /// The template's vertices (only the rig's bounding sphere uses them).
    pub positions: &'a [DVec3],
}

/// Decides which Gaussians the point methods use from `poses` (the same Gaussians in each;
/// the first is the rest pose), each rendered from the tsdf rig of `views` cameras of
/// `resolution`² pixels around it: a Gaussian is hidden when its largest weight in every
/// view of every pose is below the threshold, and the floater rule runs on the first pose's
/// means (see the module documentation).
///
/// # Errors
/// [`VisibilityError`]: only for inputs the session has not checked (an unplaceable rig).
pub fn decide(
    poses: &[Pose<'_>],
    views: usize,
    resolution: u32,
    rule: &VisibilityRule,
) -> Result<Visibility, VisibilityError> {
    let Some(first) = poses.first() else {
        return Ok(Visibility::all(0));
    };
    let n = first.set.len();
    let mut keep = vec![true; n];
    let mut hidden = 0;
    if rule.min_contribution > 0.0 && n > 0 {
        let mut largest = vec![0.0f32; n];
        for pose in poses.iter().filter(|p| p.set.len() == n) {
            raise_largest_weights(pose, views, resolution, &mut largest)?;
        }
        for (k, w) in keep.iter_mut().zip(&largest) {
            if *w < rule.min_contribution {
                *k = false;
                hidden += 1;
            }
        }
    }
    let mut floaters = 0;
    if let Some(std_ratio) = rule.floater_std_ratio {
        let candidates: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
        let means: Vec<Vec3> = candidates.iter().map(|&i| first.set.means()[i]).collect();
        let outliers = statistical_outliers(&means, rule.floater_neighbors, std_ratio)?;
        for (&i, &out) in candidates.iter().zip(&outliers) {
            if out {
                keep[i] = false;
                floaters += 1;
            }
        }
    }
    let used = GaussiansUsed {
        min_contribution: rule.min_contribution,
        floater_std_ratio: rule.floater_std_ratio,
        floater_neighbors: rule.floater_neighbors,
        total: n,
        kept: n - hidden - floaters,
        hidden,
        floaters,
        poses: poses.len(),
    };
    let kept = (used.kept < n).then(|| (0..n).filter(|&i| keep[i]).collect());
    Ok(Visibility { used, kept })
}

/// Raises `largest` to each Gaussian's largest blending weight over the rig's views of `pose`
/// (the views one after another: each render is parallel inside).
fn raise_largest_weights(
    pose: &Pose<'_>,
    views: usize,
    resolution: u32,
    largest: &mut [f32],
) -> Result<(), VisibilityError> {
    let Some((center, radius)) = bounding_sphere(pose.positions, pose.set.means()) else {
        return Ok(());
    };
    let cameras = sphere_rig(
        center,
        radius,
        views,
        (resolution, resolution),
        DEFAULT_FOV_DEG,
    )?;
    let options = RenderOptions {
        outputs: Outputs {
            alpha: true,
            ..Outputs::NONE
        },
        contribution: true,
        ..RenderOptions::default()
    };
    for camera in &cameras {
        let out = render(pose.set, camera, &options).map_err(|cause| VisibilityError::Render {
            camera: camera.name.clone(),
            cause,
        })?;
        if let Some(weights) = out.contribution {
            largest
                .par_iter_mut()
                .zip(&weights)
                .for_each(|(l, &w)| *l = l.max(w));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_splat::{GaussianParts, ParameterSpace, ScaleDims, logit};

    /// A sphere of `n` Gaussians of radius 1 (opaque, flat, tangent), one Gaussian at its
    /// centre and one far outside.
    fn shell_with_core_and_floater(n: usize) -> GaussianSet {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        let mut means: Vec<Vec3> = (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let r = (1.0 - y * y).sqrt();
                let phi = golden * i as f32;
                Vec3::new(r * phi.cos(), y, r * phi.sin())
            })
            .collect();
        let mut rotations: Vec<[f32; 4]> = means
            .iter()
            .map(|m| {
                let q = glam::Quat::from_rotation_arc(Vec3::Z, *m);
                [q.w, q.x, q.y, q.z]
            })
            .collect();
        let spacing = (4.0 * std::f32::consts::PI / n as f32).sqrt();
        let mut log_scales = vec![Vec3::new(spacing.ln(), spacing.ln(), (0.01 * spacing).ln()); n];
        means.push(Vec3::ZERO);
        means.push(Vec3::new(3.0, 0.0, 0.0));
        rotations.extend([[1.0, 0.0, 0.0, 0.0]; 2]);
        log_scales.extend([Vec3::splat(0.05f32.ln()); 2]);
        let m = means.len();
        GaussianSet::try_new(GaussianParts {
            means,
            log_scales,
            scale_dims: ScaleDims::Three,
            rotations,
            opacity_logits: vec![logit(0.95); m],
            sh_degree: 0,
            sh: vec![0.0; 3 * m],
            binding: None,
            material: None,
            space: ParameterSpace::World,
            extras: Vec::new(),
            property_order: None,
        })
        .expect("valid set")
    }

    fn pose<'a>(set: &'a GaussianSet, positions: &'a [DVec3]) -> Pose<'a> {
        Pose { set, positions }
    }

    #[test]
    fn what_one_pose_shows_is_kept() {
        let rest = shell_with_core_and_floater(1000);
        let mut parts = rest.clone().into_parts();
        // In the second pose the core has come out of the shell.
        parts.means[1000] = Vec3::new(0.0, 0.0, 1.5);
        let out = GaussianSet::try_new(parts).expect("valid");
        let rule = VisibilityRule::default();
        let only_rest = decide(&[pose(&rest, &[])], 24, 128, &rule).expect("decides");
        assert_eq!(only_rest.used.hidden, 1);
        let both = decide(&[pose(&rest, &[]), pose(&out, &[])], 24, 128, &rule).expect("decides");
        assert_eq!((both.used.hidden, both.used.poses), (0, 2));
        assert!(both.kept().is_none());
    }

    #[test]
    fn the_core_is_hidden_and_the_floater_is_left_out() {
        let set = shell_with_core_and_floater(2000);
        let positions = [DVec3::splat(-1.0), DVec3::splat(1.0)];
        let rule = VisibilityRule {
            floater_std_ratio: Some(3.0),
            ..VisibilityRule::default()
        };
        let v = decide(&[pose(&set, &positions)], 24, 128, &rule).expect("decides");
        let kept = v.kept().expect("some left out");
        assert!(!kept.contains(&2000), "the core is kept");
        assert!(!kept.contains(&2001), "the floater is kept");
        assert_eq!(v.used.hidden, 1, "{:?}", v.used);
        assert_eq!(v.used.floaters, 1, "{:?}", v.used);
        assert_eq!(v.used.kept, 2000);
        let mut means = Vec::new();
        v.gather(set.means(), &mut means);
        assert_eq!(means.len(), 2000);
    }

    #[test]
    fn keep_all_keeps_all() {
        let set = shell_with_core_and_floater(500);
        let keep_all = VisibilityRule {
            min_contribution: 0.0,
            ..VisibilityRule::default()
        };
        assert!(keep_all.keeps_all());
        let v = decide(&[pose(&set, &[])], 24, 64, &keep_all).expect("decides");
        assert_eq!(v.kept(), None);
        assert_eq!((v.used.kept, v.used.total), (502, 502));
        let mut means = Vec::new();
        v.gather(set.means(), &mut means);
        assert_eq!(means, set.means());
    }

    #[test]
    fn transparent_gaussians_are_hidden() {
        let mut parts = shell_with_core_and_floater(500).into_parts();
        // Opacity 1/1000: no pixel moves by 1/255.
        parts.opacity_logits[7] = logit(1e-3);
        let set = GaussianSet::try_new(parts).expect("valid");
        let v = decide(&[pose(&set, &[])], 24, 64, &VisibilityRule::default()).expect("decides");
        let kept = v.kept().expect("some hidden");
        assert!(!kept.contains(&7) && !kept.contains(&500));
        assert_eq!(v.used.hidden, 2);
    }

    #[test]
    fn an_empty_set() {
        let set = shell_with_core_and_floater(10).select(&[]);
        let v = decide(&[pose(&set, &[])], 24, 64, &VisibilityRule::default()).expect("decides");
        assert_eq!((v.used.total, v.used.kept), (0, 0));
    }
}
