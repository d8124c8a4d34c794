//! Triangle frames for the two binding conventions of docs/conventions.md §4, computed in `f64`.
//!
//! **GaussianAvatars** ([`gaussian_avatars_frame`]), from the posed triangle `(v0, v1, v2)`:
//! `a0 = normalize(v1 - v0)`, `a1 = normalize(a0 × (v2 - v0))` (the normal, local y; computed
//! as `a0 × (v2 - v1)`, the same vector, when that edge is shorter, which keeps needles accurate),
//! `a2 = -normalize(a1 × a0)`, `R = [a0 | a1 | a2]`, origin the centroid,
//! `k = (|v1 - v0| + |a2 · (v2 - v0)|) / 2`.
//!
//! **SurFhead / TGA** ([`surfhead_frame`], [`deformation_gradient`]): the canonical frame has axes
//! (edge, in-plane, normal): `b0 = a0`, `b2 = normalize(n)`, `b1 = b2 × b0` (so `b1 = -a2`), with
//! the same origin and `k`; the deformation gradient is
//! `J = E(deformed) E(canonical)⁻¹` with `E(v) = [v1 - v0 | v2 - v0 | n / √|n|]`,
//! `n = (v1 - v0) × (v2 - v0)`. Normals move by `J⁻ᵀ` ([`transform_normal`]).
//!
//! # Degenerate triangles
//! A triangle is degenerate when its longest edge `L` is 0, its first edge is shorter than
//! `degenerate_tol · L`, or `|n| ≤ degenerate_tol · L²` (collinear or repeated vertices). Then:
//! - axes: `a0` is the direction of `v1 - v0` if that edge is usable, else of the longest edge,
//!   else the x axis; the normal is completed orthonormally (cross `a0` with the coordinate axis
//!   least aligned with it); the third axis follows the convention's handedness. The frame is
//!   always a proper rotation.
//! - scale: `k = max(|v1 - v0| + |a2 · (v2 - v0)|, L) / 2`, at least `min_scale`; a triangle
//!   collapsed to a point gets `min_scale`.
//! - Jacobian: if the canonical triangle is degenerate, `J` is the similarity between the two
//!   fallback frames, `J = k_def R_def (k_can R_can)ᵀ` (finite, full rank); if only the deformed
//!   one is, `E(deformed)` uses a zero third column where `n = 0` and `J` is singular but finite.
//!
//! Every output is finite for finite input.

use glam::{DMat3, DVec3};

/// Default relative tolerance below which a triangle counts as degenerate (see the module
/// documentation). Relative to the triangle's own longest edge; far below the `f32` precision
/// of the coordinates, so only truly collapsed triangles take the fallback.
pub const DEFAULT_DEGENERATE_TOL: f64 = 1e-12;

/// Default smallest frame scale, relative to the template's bounding-box diagonal.
pub const DEFAULT_MIN_SCALE_REL: f64 = 1e-9;

/// Absolute smallest frame scale used when no template scale is known.
pub const FALLBACK_MIN_SCALE: f64 = 1e-12;

/// Tolerances of frame computations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameOptions {
    /// Relative degeneracy tolerance ([`DEFAULT_DEGENERATE_TOL`]).
    pub degenerate_tol: f64,
    /// Smallest frame scale and smallest output Gaussian scale, in the template's units.
    pub min_scale: f64,
}

impl Default for FrameOptions {
    fn default() -> Self {
        Self {
            degenerate_tol: DEFAULT_DEGENERATE_TOL,
            min_scale: FALLBACK_MIN_SCALE,
        }
    }
}

impl FrameOptions {
    /// Options scaled to a template: `min_scale` = [`DEFAULT_MIN_SCALE_REL`] × the bounding-box
    /// diagonal of `positions` (or [`FALLBACK_MIN_SCALE`] when that is 0 or not finite).
    #[must_use]
    pub fn for_positions(positions: &[DVec3]) -> Self {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for &p in positions {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let diag = (hi - lo).length();
        let min_scale = if diag.is_finite() && diag > 0.0 {
            diag * DEFAULT_MIN_SCALE_REL
        } else {
            FALLBACK_MIN_SCALE
        };
        Self {
            min_scale,
            ..Self::default()
        }
    }
}

/// Frame conventions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Convention {
    /// GaussianAvatars: axes (edge, normal, -(normal × edge)).
    #[default]
    GaussianAvatars,
    /// SurFhead / TGA: axes (edge, in-plane, normal).
    SurfHead,
}

/// A triangle's frame: `world = scale · rotation · local + origin`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleFrame {
    /// Orthonormal axes as columns (a proper rotation).
    pub rotation: DMat3,
    /// The centroid.
    pub origin: DVec3,
    /// The scale `k`.
    pub scale: f64,
    /// Whether the degenerate fallback was used.
    pub degenerate: bool,
}

/// A unit vector orthogonal to the unit vector `a`: `a` crossed with the coordinate axis least
/// aligned with it.
fn orthogonal_unit(a: DVec3) -> DVec3 {
    let abs = a.abs();
    let axis = if abs.x <= abs.y && abs.x <= abs.z {
        DVec3::X
    } else if abs.y <= abs.z {
        DVec3::Y
    } else {
        DVec3::Z
    };
    a.cross(axis).normalize_or(DVec3::Y)
}

/// `e2 = v2 - v0` or `e3 = v2 - v1`, whichever is shorter: `e1 × e2 = e1 × e3` (as
/// `e2 = e1 + e3`), but for a needle whose short edge is `v1 v2` the long `e2` is nearly parallel
/// to `e1` and their cross product cancels to ~`ε L / |e3|` relative error (1e-10 at aspect
/// ratio 1e6), while `e1 × e3` keeps full precision (docs/numerics.md).
fn shorter_side(e2: DVec3, e3: DVec3) -> DVec3 {
    if e3.length_squared() < e2.length_squared() {
        e3
    } else {
        e2
    }
}

/// Edge direction and unit normal of a triangle, with the degenerate fallback.
/// Returns `(a0, normal, degenerate, first edge length, longest edge length)`.
fn edge_and_normal(v: [DVec3; 3], tol: f64) -> (DVec3, DVec3, bool, f64, f64) {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let e3 = v[2] - v[1];
    let (l1, l2, l3) = (e1.length(), e2.length(), e3.length());
    let longest = l1.max(l2).max(l3);
    let other = shorter_side(e2, e3);
    let n = e1.cross(other);
    let n_len = n.length();
    let ok = longest > 0.0 && l1 > tol * longest && n_len > tol * longest * longest;
    if ok {
        let a0 = e1 / l1;
        // a1 = normalize(a0 × e2) = n / |n| up to rounding (the published formula, with e2
        // replaced by the equal cross product of `shorter_side`).
        let a1 = a0.cross(other).normalize_or(n / n_len);
        return (a0, a1, false, l1, longest);
    }
    let a0 = if longest > 0.0 && l1 > tol * longest {
        e1 / l1
    } else if longest > 0.0 {
        let e = if l2 >= l3 { e2 } else { e3 };
        e / e.length()
    } else {
        DVec3::X
    };
    (a0, orthogonal_unit(a0), true, l1, longest)
}

/// Whether the triangle `v` is degenerate by the rule of the module documentation (the same
/// test the frames and [`CanonicalTriangle`] use).
#[must_use]
pub fn is_degenerate(v: [DVec3; 3], tol: f64) -> bool {
    edge_and_normal(v, tol).2
}

fn frame_scale(
    l1: f64,
    in_plane: DVec3,
    e2: DVec3,
    longest: f64,
    degenerate: bool,
    o: &FrameOptions,
) -> f64 {
    let k = 0.5 * (l1 + in_plane.dot(e2).abs());
    let k = if degenerate { k.max(0.5 * longest) } else { k };
    if k.is_finite() {
        k.max(o.min_scale)
    } else {
        o.min_scale
    }
}

/// The GaussianAvatars frame of the triangle `v` (see the module documentation).
#[must_use]
pub fn gaussian_avatars_frame(v: [DVec3; 3], o: &FrameOptions) -> TriangleFrame {
    let (a0, a1, degenerate, l1, longest) = edge_and_normal(v, o.degenerate_tol);
    // a0 and a1 are orthonormal, so the cross product is already unit; normalise as published.
    let a2 = -a1.cross(a0).normalize_or_zero();
    let e2 = v[2] - v[0];
    TriangleFrame {
        rotation: DMat3::from_cols(a0, a1, a2),
        origin: (v[0] + v[1] + v[2]) / 3.0,
        scale: frame_scale(l1, a2, e2, longest, degenerate, o),
        degenerate,
    }
}

/// The SurFhead/TGA canonical frame of the triangle `v`: axes (edge, in-plane, normal).
#[must_use]
pub fn surfhead_frame(v: [DVec3; 3], o: &FrameOptions) -> TriangleFrame {
    let (b0, b2, degenerate, l1, longest) = edge_and_normal(v, o.degenerate_tol);
    let b1 = b2.cross(b0);
    let e2 = v[2] - v[0];
    TriangleFrame {
        rotation: DMat3::from_cols(b0, b1, b2),
        origin: (v[0] + v[1] + v[2]) / 3.0,
        scale: frame_scale(l1, b1, e2, longest, degenerate, o),
        degenerate,
    }
}

/// The frame of `v` in `convention`.
#[must_use]
pub fn frame(convention: Convention, v: [DVec3; 3], o: &FrameOptions) -> TriangleFrame {
    match convention {
        Convention::GaussianAvatars => gaussian_avatars_frame(v, o),
        Convention::SurfHead => surfhead_frame(v, o),
    }
}

/// `E(v) = [v1 - v0 | v2 - v0 | n / √|n|]`; the third column is 0 when `n = 0`.
#[must_use]
pub fn edge_matrix(v: [DVec3; 3]) -> DMat3 {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let n = e1.cross(shorter_side(e2, v[2] - v[1]));
    let len = n.length();
    let third = if len > 0.0 && len.is_finite() {
        n / len.sqrt()
    } else {
        DVec3::ZERO
    };
    DMat3::from_cols(e1, e2, third)
}

/// A deformation gradient and whether the degenerate fallback was used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Jacobian {
    /// `J`.
    pub matrix: DMat3,
    /// Whether the canonical triangle was degenerate (then `J` is the similarity between the
    /// fallback frames).
    pub degenerate: bool,
}

/// `J = E(deformed) E(canonical)⁻¹` (SurFhead/TGA), with the fallback of the module
/// documentation for a degenerate canonical triangle.
#[must_use]
pub fn deformation_gradient(
    canonical: [DVec3; 3],
    deformed: [DVec3; 3],
    o: &FrameOptions,
) -> Jacobian {
    let (_, _, degenerate, _, _) = edge_and_normal(canonical, o.degenerate_tol);
    if !degenerate {
        let ec = edge_matrix(canonical);
        let ed = edge_matrix(deformed);
        // |det E(canonical)| = |n|^1.5 > 0 here.
        let m = ed * ec.inverse();
        if m.is_finite() {
            return Jacobian {
                matrix: m,
                degenerate: false,
            };
        }
    }
    let fc = surfhead_frame(canonical, o);
    let fd = surfhead_frame(deformed, o);
    Jacobian {
        matrix: (fd.rotation * fc.rotation.transpose()) * (fd.scale / fc.scale),
        degenerate: true,
    }
}

/// Precomputed `E(canonical)⁻¹` data of a triangle, so per-frame gradients cost one product.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CanonicalTriangle {
    /// `E(canonical)⁻¹` (unused when `degenerate`).
    pub inverse_edges: DMat3,
    /// The canonical SurFhead frame.
    pub frame: TriangleFrame,
    /// Whether the canonical triangle is degenerate.
    pub degenerate: bool,
}

impl CanonicalTriangle {
    /// Precomputes the canonical data of `v`.
    #[must_use]
    pub fn new(v: [DVec3; 3], o: &FrameOptions) -> Self {
        let frame = surfhead_frame(v, o);
        let inverse = edge_matrix(v).inverse();
        let degenerate = frame.degenerate || !inverse.is_finite();
        Self {
            inverse_edges: if degenerate { DMat3::IDENTITY } else { inverse },
            frame,
            degenerate,
        }
    }

    /// `J` for the deformed corners (same result as [`deformation_gradient`]).
    #[must_use]
    pub fn gradient(&self, deformed: [DVec3; 3], o: &FrameOptions) -> DMat3 {
        if self.degenerate {
            let fd = surfhead_frame(deformed, o);
            (fd.rotation * self.frame.rotation.transpose()) * (fd.scale / self.frame.scale)
        } else {
            edge_matrix(deformed) * self.inverse_edges
        }
    }
}

/// The cofactor matrix `cof(J) = det(J) J⁻ᵀ`, defined for singular `J` too.
#[must_use]
pub fn cofactor(j: DMat3) -> DMat3 {
    DMat3::from_cols(
        j.y_axis.cross(j.z_axis),
        j.z_axis.cross(j.x_axis),
        j.x_axis.cross(j.y_axis),
    )
}

/// A normal moved by `J`: `normalize(J⁻ᵀ n)`, computed as `sign(det J) cof(J) n` so that a
/// singular `J` still gives the normal of its image plane. `None` when the result vanishes.
#[must_use]
pub fn transform_normal(j: DMat3, n: DVec3) -> Option<DVec3> {
    let m = cofactor(j) * n;
    let m = if j.determinant() < 0.0 { -m } else { m };
    m.try_normalize()
}

/// The corners of triangle `t` in `f64` (0 for an index past `positions`).
#[must_use]
pub fn corners_of(positions: &[DVec3], t: [u32; 3]) -> [DVec3; 3] {
    t.map(|i| positions.get(i as usize).copied().unwrap_or(DVec3::ZERO))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;
    use trisplat_geometry::rng::Rng;

    /// f64 arithmetic on O(1) inputs: agreement with hand values.
    const TOL: f64 = 1e-12;

    trait MaxAbs {
        fn max_abs(&self) -> f64;
    }
    impl MaxAbs for DMat3 {
        fn max_abs(&self) -> f64 {
            self.to_cols_array().iter().fold(0.0, |m, v| m.max(v.abs()))
        }
    }

    fn d(x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(x, y, z)
    }

    fn assert_rotation(r: DMat3) {
        assert!((r.transpose() * r - DMat3::IDENTITY).max_abs() < TOL, "{r}");
        assert!((r.determinant() - 1.0).abs() < TOL, "{r}");
    }

    fn random_triangle(rng: &mut Rng) -> [DVec3; 3] {
        [0; 3].map(|_: i32| d(rng.uniform_f64(), rng.uniform_f64(), rng.uniform_f64()) * 2.0 - 1.0)
    }

    #[test]
    fn gaussian_avatars_frame_by_hand() {
        let v = [d(0.0, 0.0, 0.0), d(2.0, 0.0, 0.0), d(0.0, 1.0, 0.0)];
        let f = gaussian_avatars_frame(v, &FrameOptions::default());
        assert_eq!(f.rotation, DMat3::from_cols(DVec3::X, DVec3::Z, -DVec3::Y));
        assert_eq!(f.scale, 1.5);
        assert!((f.origin - d(2.0 / 3.0, 1.0 / 3.0, 0.0)).length() < TOL);
        assert!(!f.degenerate);
        let s = surfhead_frame(v, &FrameOptions::default());
        assert_eq!(s.rotation, DMat3::IDENTITY);
        assert_eq!(s.scale, 1.5);
    }

    #[test]
    fn frames_are_rotations_and_follow_rigid_motions() {
        let mut rng = Rng::new(1);
        let o = FrameOptions::default();
        for _ in 0..500 {
            let v = random_triangle(&mut rng);
            let q = crate::test_util::random_rotation(&mut rng);
            let t = d(3.0, -1.0, 0.5);
            let moved = v.map(|p| q * p * 2.0 + t);
            for conv in [Convention::GaussianAvatars, Convention::SurfHead] {
                let f = frame(conv, v, &o);
                assert_rotation(f.rotation);
                let g = frame(conv, moved, &o);
                // The frame moves with the triangle: R' = Q R, k' = 2 k, c' = 2 Q c + t.
                let rq = DMat3::from_quat(q) * f.rotation;
                assert!((g.rotation - rq).max_abs() < 1e-9);
                assert!((g.scale - 2.0 * f.scale).abs() < 1e-9);
                assert!((g.origin - (q * f.origin * 2.0 + t)).length() < 1e-9);
            }
        }
    }

    #[test]
    fn stretching_x_by_two_gives_diag_2_1_sqrt2() {
        let o = FrameOptions::default();
        let c = [d(0.0, 0.0, 0.0), d(1.0, 0.0, 0.0), d(0.0, 1.0, 0.0)];
        let s = c.map(|p| d(2.0 * p.x, p.y, p.z));
        let j = deformation_gradient(c, s, &o);
        assert!(!j.degenerate);
        let want = DMat3::from_diagonal(d(2.0, 1.0, 2f64.sqrt()));
        assert!((j.matrix - want).max_abs() < TOL, "{}", j.matrix);
        // Also for a triangle not at the origin and not axis aligned in the plane.
        let c = [d(0.3, 0.2, 1.0), d(1.1, 0.5, 1.0), d(0.4, 1.7, 1.0)];
        let s = c.map(|p| d(2.0 * p.x, p.y, p.z));
        let j = deformation_gradient(c, s, &o);
        assert!((j.matrix - want).max_abs() < 1e-9, "{}", j.matrix);
        let pre = CanonicalTriangle::new(c, &o).gradient(s, &o);
        assert!((pre - j.matrix).max_abs() < TOL);
    }

    #[test]
    fn rotation_only_deformation_gives_orthogonal_jacobian() {
        let mut rng = Rng::new(2);
        let o = FrameOptions::default();
        for _ in 0..200 {
            let v = random_triangle(&mut rng);
            let q = DQuat::from_euler(
                glam::EulerRot::XYZ,
                rng.uniform_f64() * 6.0,
                rng.uniform_f64() * 6.0,
                rng.uniform_f64() * 6.0,
            );
            let moved = v.map(|p| q * p + d(1.0, 2.0, 3.0));
            let j = deformation_gradient(v, moved, &o).matrix;
            assert!((j.transpose() * j - DMat3::IDENTITY).max_abs() < 1e-8);
            assert!((j - DMat3::from_quat(q)).max_abs() < 1e-8);
        }
    }

    #[test]
    fn jacobian_maps_edges_and_normals_transform_by_inverse_transpose() {
        let mut rng = Rng::new(3);
        let o = FrameOptions::default();
        for _ in 0..500 {
            let c = random_triangle(&mut rng);
            let s = random_triangle(&mut rng);
            let j = deformation_gradient(c, s, &o).matrix;
            assert!((j * (c[1] - c[0]) - (s[1] - s[0])).length() < 1e-7);
            assert!((j * (c[2] - c[0]) - (s[2] - s[0])).length() < 1e-7);
            let nc = (c[1] - c[0]).cross(c[2] - c[0]).normalize();
            let nd = (s[1] - s[0]).cross(s[2] - s[0]).normalize();
            let moved = transform_normal(j, nc).unwrap();
            assert!((moved - nd).length() < 1e-7, "{moved} vs {nd}");
            // Explicit J^-T agrees where J is well conditioned.
            let explicit = (j.inverse().transpose() * nc).normalize();
            assert!((explicit - moved).length() < 1e-6);
        }
    }

    #[test]
    fn degenerate_triangles_give_finite_frames() {
        let o = FrameOptions::for_positions(&[DVec3::ZERO, DVec3::ONE]);
        let p = d(0.5, -0.25, 2.0);
        let cases: Vec<[DVec3; 3]> = vec![
            [p, p, p],                                                     // a point
            [d(0.0, 0.0, 0.0), d(1.0, 0.0, 0.0), d(2.0, 0.0, 0.0)],        // collinear
            [d(0.0, 0.0, 0.0), d(0.0, 0.0, 0.0), d(0.0, 3.0, 0.0)],        // v0 = v1
            [d(0.0, 0.0, 0.0), d(1.0, 1.0, 1.0), d(0.0, 0.0, 0.0)],        // v0 = v2
            [d(0.0, 0.0, 0.0), d(1.0, 1.0, 1.0), d(1.0, 1.0, 1.0)],        // v1 = v2
            [d(0.0, 0.0, 0.0), d(1.0, 0.0, 0.0), d(0.5, 1e-14, 0.0)],      // sliver
            [d(1e30, 0.0, 0.0), d(1e30, 0.0, 0.0), d(1e30, 1.0, 0.0)],     // huge + repeated
            [d(0.0, 0.0, 0.0), d(-1e-300, 0.0, 0.0), d(0.0, 1e-300, 0.0)], // tiny
        ];
        let good = [d(0.0, 0.0, 0.0), d(1.0, 0.0, 0.0), d(0.0, 1.0, 0.0)];
        for (i, v) in cases.iter().enumerate() {
            for conv in [Convention::GaussianAvatars, Convention::SurfHead] {
                let f = frame(conv, *v, &o);
                assert!(f.degenerate, "case {i}");
                assert_rotation(f.rotation);
                assert!(
                    f.scale.is_finite() && f.scale >= o.min_scale,
                    "case {i}: {}",
                    f.scale
                );
                assert!(f.origin.is_finite());
            }
            for (a, b) in [(*v, good), (good, *v), (*v, *v)] {
                let j = deformation_gradient(a, b, &o);
                assert!(j.matrix.is_finite(), "case {i}: {}", j.matrix);
                let pre = CanonicalTriangle::new(a, &o).gradient(b, &o);
                assert!(pre.is_finite());
                assert!((pre - j.matrix).max_abs() <= 1e-12 * j.matrix.max_abs().max(1.0));
            }
        }
        // Documented scales: collinear (0, 1, 2) -> max(1 + 0, 2) / 2 = 1; v0 = v1 -> 3 / 2;
        // a point -> min_scale.
        assert_eq!(gaussian_avatars_frame(cases[1], &o).scale, 1.0);
        assert_eq!(gaussian_avatars_frame(cases[2], &o).scale, 1.5);
        assert_eq!(gaussian_avatars_frame(cases[0], &o).scale, o.min_scale);
        // A degenerate canonical triangle maps by the similarity of the fallback frames: here the
        // collinear segment doubled in length maps by 2 x a rotation.
        let c = cases[1];
        let j = deformation_gradient(c, c.map(|p| p * 2.0), &o);
        assert!(j.degenerate);
        assert!((j.matrix - DMat3::IDENTITY * 2.0).max_abs() < TOL);
        // A triangle collapsed onto a line gives a finite rank-1 J, which has no normal
        // direction: `None`, never NaN. A rank-2 J moves normals to the normal of its image plane.
        let flat = deformation_gradient(good, cases[1], &o).matrix;
        assert!(flat.is_finite());
        assert_eq!(transform_normal(flat, DVec3::Z), None);
        let squash = DMat3::from_diagonal(d(1.0, 2.0, 0.0));
        assert_eq!(transform_normal(squash, d(0.3, 0.0, 1.0)), Some(DVec3::Z));
    }
}
