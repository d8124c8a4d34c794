//! Where the tsdf method samples a frame (`--tsdf-anchor`, docs/conventions.md §6, "The tsdf
//! method's anchor").
//!
//! A TSDF resamples the surface on a voxel grid and through a camera rig. Placed in world
//! space, a surface that moves rigidly (a head turning) is sampled anew every frame, so two
//! frames' extractions differ by the sampling (0.2-0.4 mm between neighbouring frames of LAM
//! under a skeletal clip) even where the surface itself did not change, and a mesh carried
//! from a key cannot match them. Anchored (`rigid`, the default), the grid and the rig move
//! with the avatar:
//!
//! 1. **The anchor** `T_f` of frame `f` is the rigid motion that best maps the rest template
//!    onto the frame's deformed template ([`fit_rigid`]: least squares by Horn's quaternion
//!    method, refitted [`TRIM_ROUNDS`] times on the half of the vertices it fits best, so a
//!    turning head is followed and an opening jaw or a swinging arm does not pull the fit).
//!    It depends on that frame's template alone, so shards and one run agree.
//! 2. **The rig** is fixed in the anchor frame (the rest template's coordinates):
//!    [`sphere_rig`] around the box centre of the rest template and rest means, framing
//!    [`RIG_MARGIN`] times their bounding radius; a frame whose Gaussians, brought back by
//!    `T_f⁻¹`, reach beyond it widens the ball by whole [`RIG_STEPS`]ths of the radius.
//! 3. The depth maps are rendered from that rig moved by `T_f` (world cameras, so colours see
//!    the Gaussians as they are), fused on the grid of the anchor frame (voxel corners at
//!    integer multiples of the voxel there), and the mesh is moved back by `T_f`.
//!
//! A rigidly moving surface is then rendered from the same relative viewpoints and fused on the
//! same relative grid: its extraction moves with it, to rounding ([`tests`]).

use glam::{DMat3, DQuat, DVec3, Vec3};
use trisplat_geometry::{Camera, CameraError, TriMesh, bounding_sphere, sphere_rig};

/// Refits of [`fit_rigid`] on the better half of the vertices.
pub const TRIM_ROUNDS: usize = 2;
/// The anchored rig frames this many times the rest pose's bounding radius, so expressions
/// and small non-rigid motion keep the same rig.
pub const RIG_MARGIN: f64 = 1.1;
/// Beyond the margin, the rig's radius grows by whole `1 / RIG_STEPS` of the rest radius.
pub const RIG_STEPS: f64 = 8.0;

/// A rigid motion `x ↦ R x + t`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    /// `R`, a proper rotation.
    pub rotation: DMat3,
    /// `t`.
    pub translation: DVec3,
}

impl Rigid {
    /// No motion.
    pub const IDENTITY: Self = Self {
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
    };

    /// `R p + t`.
    #[must_use]
    pub fn apply(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    /// The inverse motion.
    #[must_use]
    pub fn inverse(&self) -> Self {
        let rotation = self.rotation.transpose();
        Self {
            rotation,
            translation: -(rotation * self.translation),
        }
    }

    /// `camera` moved by this motion (intrinsics, id and name kept).
    ///
    /// # Errors
    /// [`CameraError`] when the moved pose is not finite.
    pub fn camera(&self, camera: &Camera) -> Result<Camera, CameraError> {
        Camera::try_new(
            camera.id,
            camera.name.clone(),
            camera.width,
            camera.height,
            (camera.fx, camera.fy),
            (camera.cx, camera.cy),
            self.rotation * camera.rotation(),
            self.apply(camera.position()),
        )
    }

    /// `mesh` moved by this motion (stored normals turned with it).
    #[must_use]
    pub fn mesh(&self, mesh: TriMesh) -> TriMesh {
        let (positions, triangles, normals, uvs, colors) = mesh.into_parts();
        let positions: Vec<DVec3> = positions.into_iter().map(|p| self.apply(p)).collect();
        let rotation = self.rotation.as_mat3();
        let normals = normals.map(|n| n.into_iter().map(|v| rotation * v).collect::<Vec<Vec3>>());
        let mut moved = TriMesh::new_unchecked(positions, triangles);
        // The parts came from a valid mesh and keep their lengths.
        if let Some(n) = normals {
            moved = moved
                .with_normals(n)
                .unwrap_or_else(|e| unreachable!("{e}"));
        }
        if let Some(u) = uvs {
            moved = moved.with_uvs(u).unwrap_or_else(|e| unreachable!("{e}"));
        }
        if let Some(c) = colors {
            moved = moved.with_colors(c).unwrap_or_else(|e| unreachable!("{e}"));
        }
        moved
    }
}

/// The rigid motion that best maps `rest` onto `frame` (vertex `i` to vertex `i`): least
/// squares (Horn's quaternion method, sums in f64 in vertex order), then [`TRIM_ROUNDS`]
/// refits on the vertices whose residual is at most the median residual. `None` when the
/// lists differ in length, have fewer than three points, or hold a non-finite coordinate, or
/// when the fit is not finite.
#[must_use]
pub fn fit_rigid(rest: &[DVec3], frame: &[DVec3]) -> Option<Rigid> {
    if rest.len() != frame.len() || rest.len() < 3 {
        return None;
    }
    if !rest.iter().chain(frame).all(|p| p.is_finite()) {
        return None;
    }
    let mut keep = vec![true; rest.len()];
    let mut fit = horn(rest, frame, &keep)?;
    let mut residuals = Vec::with_capacity(rest.len());
    let mut sorted = Vec::with_capacity(rest.len());
    for _ in 0..TRIM_ROUNDS {
        residuals.clear();
        residuals.extend(
            rest.iter()
                .zip(frame)
                .map(|(&p, &q)| (fit.apply(p) - q).length_squared()),
        );
        sorted.clear();
        sorted.extend_from_slice(&residuals);
        let mid = sorted.len() / 2;
        let (_, median, _) = sorted.select_nth_unstable_by(mid, f64::total_cmp);
        let median = *median;
        for (k, r) in keep.iter_mut().zip(&residuals) {
            *k = *r <= median;
        }
        fit = horn(rest, frame, &keep)?;
    }
    Some(fit)
}

/// Horn's closed-form least-squares rigid motion of the kept pairs.
fn horn(rest: &[DVec3], frame: &[DVec3], keep: &[bool]) -> Option<Rigid> {
    let kept = || {
        rest.iter()
            .zip(frame)
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(pq, _)| pq)
    };
    let mut n = 0usize;
    let (mut cp, mut cq) = (DVec3::ZERO, DVec3::ZERO);
    for (p, q) in kept() {
        cp += *p;
        cq += *q;
        n += 1;
    }
    if n == 0 {
        return None;
    }
    cp /= n as f64;
    cq /= n as f64;
    // s[a][b] = Σ p'_a q'_b.
    let mut s = [[0.0f64; 3]; 3];
    for (p, q) in kept() {
        let (p, q) = ((*p - cp).to_array(), (*q - cq).to_array());
        for a in 0..3 {
            for b in 0..3 {
                s[a][b] += p[a] * q[b];
            }
        }
    }
    let [[xx, xy, xz], [yx, yy, yz], [zx, zy, zz]] = s;
    let mut m = [
        [xx + yy + zz, yz - zy, zx - xz, xy - yx],
        [yz - zy, xx - yy - zz, xy + yx, zx + xz],
        [zx - xz, xy + yx, -xx + yy - zz, yz + zy],
        [xy - yx, zx + xz, yz + zy, -xx - yy + zz],
    ];
    let [w, x, y, z] = largest_eigenvector(&mut m);
    let q = DQuat::from_xyzw(x, y, z, w);
    if !q.is_finite() || q.length_squared() == 0.0 {
        return None;
    }
    let rotation = DMat3::from_quat(q.normalize());
    let fit = Rigid {
        rotation,
        translation: cq - rotation * cp,
    };
    (fit.rotation.is_finite() && fit.translation.is_finite()).then_some(fit)
}

/// The unit eigenvector of the largest eigenvalue of the symmetric `m` (cyclic Jacobi
/// rotations; `m` is destroyed).
fn largest_eigenvector(m: &mut [[f64; 4]; 4]) -> [f64; 4] {
    let mut v = [[0.0f64; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let scale: f64 = m.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
    for _sweep in 0..64 {
        let off: f64 = (0..4)
            .flat_map(|i| (i + 1..4).map(move |j| (i, j)))
            .map(|(i, j)| m[i][j] * m[i][j])
            .sum::<f64>()
            .sqrt();
        if off <= 1e-15 * scale || off == 0.0 {
            break;
        }
        for p in 0..4 {
            for q in p + 1..4 {
                if m[p][q] == 0.0 {
                    continue;
                }
                let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
                // The smaller root of t² + 2θt − 1 = 0 (θ = 0: t = 1, signum(0) being 1).
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in m.iter_mut() {
                    let (mkp, mkq) = (row[p], row[q]);
                    row[p] = c * mkp - s * mkq;
                    row[q] = s * mkp + c * mkq;
                }
                let (rp, rq) = (m[p], m[q]);
                m[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
                m[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
                for row in &mut v {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    // The largest eigenvalue, the first on ties (deterministic).
    let best = (0..4).fold(0, |b, i| if m[i][i] > m[b][b] { i } else { b });
    [v[0][best], v[1][best], v[2][best], v[3][best]]
}

/// The anchored rig of a run: where its cameras sit in the anchor frame.
#[derive(Clone, Debug, PartialEq)]
pub struct AnchoredRig {
    /// The rest template (welded), which each frame's template is fitted to.
    rest: Vec<DVec3>,
    /// The rig's centre in the anchor frame.
    center: DVec3,
    /// The rest pose's bounding radius.
    rest_radius: f64,
}

/// One frame's anchor: the motion and the rig in the anchor frame.
#[derive(Clone, Debug)]
pub struct FrameAnchor {
    /// Anchor frame to the frame's (world or run-local) space.
    pub motion: Rigid,
    /// The rig in the anchor frame.
    pub cameras: Vec<Camera>,
}

impl AnchoredRig {
    /// The rig of the rest template `rest` (welded vertices, as frames give them) and the
    /// rest-pose means `rest_means`; `None` when they have no finite bounding sphere.
    #[must_use]
    pub fn new(rest: &[DVec3], rest_means: &[Vec3]) -> Option<Self> {
        let (center, rest_radius) = bounding_sphere(rest, rest_means)?;
        Some(Self {
            rest: rest.to_vec(),
            center,
            rest_radius,
        })
    }

    /// Frame `positions`' anchor ([`fit_rigid`] from the rest template; the identity when the
    /// fit fails, e.g. a frame with another vertex count) and the rig of `views` cameras of
    /// `resolution`² pixels, field of view `fov_deg`, framing the rest ball widened as the
    /// module docs say so that `positions` and `means` (moved back by the anchor) fit.
    ///
    /// # Errors
    /// [`CameraError`] from [`sphere_rig`].
    pub fn frame(
        &self,
        positions: &[DVec3],
        means: &[Vec3],
        views: usize,
        resolution: u32,
        fov_deg: f64,
    ) -> Result<FrameAnchor, CameraError> {
        let motion = fit_rigid(&self.rest, positions).unwrap_or(Rigid::IDENTITY);
        let back = motion.inverse();
        let reach = positions
            .iter()
            .copied()
            .chain(means.iter().map(|m| m.as_dvec3()))
            .map(|p| (back.apply(p) - self.center).length())
            .filter(|d| d.is_finite())
            .fold(0.0, f64::max);
        let base = RIG_MARGIN * self.rest_radius;
        let step = self.rest_radius / RIG_STEPS;
        let radius = if reach <= base {
            base
        } else {
            base + step * ((reach - base) / step).ceil()
        };
        let cameras = sphere_rig(
            self.center,
            radius,
            views,
            (resolution, resolution),
            fov_deg,
        )?;
        Ok(FrameAnchor { motion, cameras })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud() -> Vec<DVec3> {
        (0..200)
            .map(|i| {
                let t = i as f64;
                DVec3::new(
                    (t * 0.37).sin(),
                    (t * 0.91).cos() * 0.7,
                    (t * 0.13).sin() * 1.3,
                )
            })
            .collect()
    }

    fn motion() -> Rigid {
        Rigid {
            rotation: DMat3::from_quat(DQuat::from_axis_angle(
                DVec3::new(0.3, 1.0, -0.2).normalize(),
                0.7,
            )),
            translation: DVec3::new(0.123, -0.456, 0.789),
        }
    }

    #[test]
    fn the_fit_recovers_a_rigid_motion() {
        let rest = cloud();
        let t = motion();
        let frame: Vec<DVec3> = rest.iter().map(|&p| t.apply(p)).collect();
        let fit = fit_rigid(&rest, &frame).expect("fits");
        for (a, b) in [
            (fit.rotation.x_axis, t.rotation.x_axis),
            (fit.rotation.y_axis, t.rotation.y_axis),
            (fit.rotation.z_axis, t.rotation.z_axis),
            (fit.translation, t.translation),
        ] {
            assert!((a - b).length() < 1e-12, "{a} vs {b}");
        }
        let back = fit.inverse();
        assert!((back.apply(fit.apply(DVec3::ONE)) - DVec3::ONE).length() < 1e-12);
    }

    #[test]
    fn the_trimmed_fit_ignores_a_moving_part() {
        // A third of the points move off on their own (a jaw): the fit follows the rest.
        let rest = cloud();
        let t = motion();
        let frame: Vec<DVec3> = rest
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                t.apply(p)
                    + if i % 3 == 0 {
                        DVec3::X * 0.3
                    } else {
                        DVec3::ZERO
                    }
            })
            .collect();
        let fit = fit_rigid(&rest, &frame).expect("fits");
        assert!((fit.translation - t.translation).length() < 1e-9);
        // The untrimmed fit would be pulled by a tenth of the shift.
        let plain = horn(&rest, &frame, &vec![true; rest.len()]).expect("fits");
        assert!((plain.translation - t.translation).length() > 0.05);
    }

    #[test]
    fn no_fit_from_bad_input() {
        let rest = cloud();
        assert_eq!(fit_rigid(&rest, &rest[1..]), None);
        assert_eq!(fit_rigid(&rest[..2], &rest[..2]), None);
        let mut bad = rest.clone();
        bad[5].y = f64::NAN;
        assert_eq!(fit_rigid(&rest, &bad), None);
    }

    #[test]
    fn the_rig_is_fixed_in_the_anchor_frame_until_the_surface_leaves_it() {
        let rest = cloud();
        let anchored = AnchoredRig::new(&rest, &[]).expect("sphere");
        let t = motion();
        let frame: Vec<DVec3> = rest.iter().map(|&p| t.apply(p)).collect();
        let at_rest = anchored.frame(&rest, &[], 4, 16, 40.0).expect("rig");
        let moved = anchored.frame(&frame, &[], 4, 16, 40.0).expect("rig");
        for (a, b) in at_rest.cameras.iter().zip(&moved.cameras) {
            assert_eq!(a.position(), b.position());
        }
        // A Gaussian far out widens the ball by whole steps.
        let far = [(t.apply(anchored.center + DVec3::X * 3.0 * anchored.rest_radius)).as_vec3()];
        let wide = anchored.frame(&frame, &far, 4, 16, 40.0).expect("rig");
        let distance = |f: &FrameAnchor| (f.cameras[0].position() - anchored.center).length();
        assert!(distance(&wide) > 2.5 * distance(&moved));
    }
}
