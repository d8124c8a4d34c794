//! Exact orientation and in-sphere signs with symbolic perturbation.
//!
//! The signs come from Shewchuk's adaptive predicates (`robust` crate): they are exact for any
//! `f64` input whose products do not overflow (see [`super::MAX_COORDINATE`]).
//!
//! **Symbolic perturbation** (the "lifting" scheme, as in CGAL's `side_of_power_sphere` and
//! geogram's `side4_3d_SOS`): point `i` is lifted to `|p_i|^2 + eps_i`, with
//! `eps_i = eps^(N - i)` for an infinitesimal `eps`, so the point with the larger input index has
//! the dominant perturbation. The in-sphere determinant
//!
//! ```text
//!     | ax ay az |a|^2 1 |
//!     | bx by bz |b|^2 1 |
//! D = | cx cy cz |c|^2 1 |   = robust::insphere(a, b, c, d, e)
//!     | dx dy dz |d|^2 1 |
//!     | ex ey ez |e|^2 1 |
//! ```
//!
//! is affine in the lifts, so the perturbed determinant is `D + sum_i eps_i * C_i` with
//! `C_i = (-1)^(i+4) * orient3d(the other four points, in order)` (`i` = 1..5, the row). When `D`
//! is exactly zero its sign is the sign of the first non-zero `C_i` in order of decreasing
//! input index. For a non-degenerate tetrahedron `abcd` the coefficient of `e` is
//! `-orient3d(a, b, c, d) != 0`, so the perturbed test never returns zero. Coordinates are not
//! perturbed: coplanar points stay coplanar, which only matters on the convex hull, where a
//! point coplanar with a hull face conflicts with the outside iff it conflicts with the finite
//! tetrahedron behind that face (the limit of the circumsphere of the face and a far point).

use robust::Coord3D;

/// A point as the `robust` crate wants it.
#[inline(always)]
fn c(p: [f64; 3]) -> Coord3D<f64> {
    Coord3D {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

/// Shewchuk's `orient3d`: positive when `d` lies below the plane of `a, b, c`, "below" meaning
/// that `a, b, c` appear counter-clockwise seen from above (equivalently
/// `det[a - d, b - d, c - d] > 0`). Exact sign.
#[inline(always)]
pub(crate) fn orient3d(a: [f64; 3], b: [f64; 3], c_: [f64; 3], d: [f64; 3]) -> f64 {
    robust::orient3d(c(a), c(b), c(c_), c(d))
}

/// Shewchuk's `insphere` for a positively oriented `a, b, c, d`: positive when `e` lies inside
/// their circumsphere. Exact sign.
#[inline(always)]
pub(crate) fn insphere(a: [f64; 3], b: [f64; 3], c_: [f64; 3], d: [f64; 3], e: [f64; 3]) -> f64 {
    robust::insphere(c(a), c(b), c(c_), c(d), c(e))
}

/// The sign of the perturbed in-sphere determinant of the five points `p` (positions) with
/// input indices `ids`: `+1` when `p[4]` is inside the circumsphere of the positively oriented
/// `p[0..4]`, `-1` outside. Returns `0` only when all five points are coplanar (never for a
/// non-degenerate tetrahedron).
#[inline]
pub(crate) fn insphere_sos(p: [[f64; 3]; 5], ids: [u32; 5]) -> i32 {
    let det = insphere(p[0], p[1], p[2], p[3], p[4]);
    if det > 0.0 {
        return 1;
    }
    if det < 0.0 {
        return -1;
    }
    insphere_tie(p, ids)
}

/// The perturbation terms of [`insphere_sos`] for an exactly co-spherical (or coplanar) set.
#[cold]
fn insphere_tie(p: [[f64; 3]; 5], ids: [u32; 5]) -> i32 {
    // Rows in order of decreasing input index (dominant perturbation first).
    let mut order = [0usize, 1, 2, 3, 4];
    order.sort_unstable_by(|&i, &j| ids[j].cmp(&ids[i]));
    for &row in &order {
        let mut others = [[0.0; 3]; 4];
        let mut k = 0;
        for (i, q) in p.iter().enumerate() {
            if i != row {
                others[k] = *q;
                k += 1;
            }
        }
        let minor = orient3d(others[0], others[1], others[2], others[3]);
        if minor != 0.0 {
            // (-1)^(row + 4) with 1-based rows = (-1)^(row0 + 1) with 0-based rows.
            let sign = if row % 2 == 0 { -1.0 } else { 1.0 };
            return if sign * minor > 0.0 { 1 } else { -1 };
        }
    }
    0
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: [f64; 3] = [0.0, 0.0, 0.0];
    const B: [f64; 3] = [1.0, 0.0, 0.0];
    const C: [f64; 3] = [0.0, 1.0, 0.0];
    const D: [f64; 3] = [0.0, 0.0, 1.0];

    #[test]
    fn orientation_convention() {
        // d above the counter-clockwise triangle abc (seen from +z) is negative.
        assert!(orient3d(A, B, C, D) < 0.0);
        assert!(orient3d(A, C, B, D) > 0.0);
        let centroid = [0.25, 0.25, 0.25];
        assert!(insphere(A, C, B, D, centroid) > 0.0);
        assert!(insphere(A, C, B, D, [5.0, 5.0, 5.0]) < 0.0);
    }

    /// The symbolic answer equals the numeric answer for a tiny explicit lift of the dominant
    /// point: moving the highest-index point outward (its lift up) puts it outside.
    #[test]
    fn tie_breaks_by_the_dominant_lift() {
        // e = (1,1,1) lies on the circumsphere of the unit corner tetrahedron.
        let e = [1.0, 1.0, 1.0];
        let t = [A, C, B, D];
        assert_eq!(insphere(t[0], t[1], t[2], t[3], e), 0.0);
        // e has the largest index: its lift goes up, so it is outside.
        assert_eq!(
            insphere_sos([t[0], t[1], t[2], t[3], e], [0, 1, 2, 3, 4]),
            -1
        );
    }

    /// Numeric check of the sign formula: perturb the lifts explicitly (exactly representable
    /// small numbers) and compare with the symbolic sign.
    #[test]
    fn perturbation_signs_match_an_explicit_lift() {
        let pts = [A, C, B, D, [1.0, 1.0, 1.0]];
        for dominant in 0..5 {
            let mut ids = [0u32; 5];
            for (i, id) in ids.iter_mut().enumerate() {
                *id = if i == dominant { 10 } else { i as u32 };
            }
            let symbolic = insphere_sos(pts, ids);
            // Explicit 5x5 determinant with one lift raised by delta.
            let delta = 1e-3;
            let mut m = [[0.0f64; 5]; 5];
            for (i, p) in pts.iter().enumerate() {
                let lift = p[0] * p[0]
                    + p[1] * p[1]
                    + p[2] * p[2]
                    + if i == dominant { delta } else { 0.0 };
                m[i] = [p[0], p[1], p[2], lift, 1.0];
            }
            let numeric = det5(m);
            assert_eq!(
                symbolic,
                if numeric > 0.0 { 1 } else { -1 },
                "dominant {dominant}"
            );
        }
    }

    #[allow(clippy::needless_range_loop)]
    fn det5(m: [[f64; 5]; 5]) -> f64 {
        // Gaussian elimination with partial pivoting.
        let mut a = m;
        let mut det = 1.0;
        for col in 0..5 {
            let pivot = (col..5)
                .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
                .unwrap_or(col);
            if a[pivot][col] == 0.0 {
                return 0.0;
            }
            if pivot != col {
                a.swap(pivot, col);
                det = -det;
            }
            det *= a[col][col];
            for row in col + 1..5 {
                let f = a[row][col] / a[col][col];
                for k in col..5 {
                    a[row][k] -= f * a[col][k];
                }
            }
        }
        det
    }
}
