//! Real spherical harmonics of degree 0..=3 with the constants of the 3DGS reference code and
//! gsplat, and colour evaluation (docs/conventions.md §3).
//!
//! Basis order within a degree follows 3DGS `eval_sh`: for degree 1 `(-C1 y, C1 z, -C1 x)`, and so
//! on. Colour: `rgb = max(Σ_k sh_k Y_k(dir) + 0.5, 0)` with `dir = normalize(mean - camera)`.

use glam::{DMat3, DVec3};

/// Number of SH coefficients per colour channel for `degree`: `(degree + 1)²`.
#[must_use]
pub const fn sh_coeffs_per_channel(degree: u8) -> usize {
    let d = degree as usize + 1;
    d * d
}

/// `Y_0^0 = 1 / (2 √π)`.
pub const SH_C0: f64 = 0.282_094_791_773_878_14;
/// Degree-1 constant `√(3 / (4π))`.
pub const SH_C1: f64 = 0.488_602_511_902_919_9;
/// Degree-2 constants.
pub const SH_C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
/// Degree-3 constants.
pub const SH_C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// The 16 basis values `Y_k(dir)` for degrees 0..=3; only the first `(degree + 1)²` are filled,
/// the rest are 0. `dir` is normalised here; a zero (or non-finite) direction gives only the
/// constant term (the view-dependent terms vanish).
#[must_use]
pub fn sh_basis(degree: u8, dir: DVec3) -> [f64; 16] {
    let mut y = [0.0; 16];
    y[0] = SH_C0;
    if degree == 0 {
        return y;
    }
    let Some(d) = dir.try_normalize() else {
        return y;
    };
    let (x, yy, z) = (d.x, d.y, d.z);
    y[1] = -SH_C1 * yy;
    y[2] = SH_C1 * z;
    y[3] = -SH_C1 * x;
    if degree == 1 {
        return y;
    }
    let (xx, y2, zz) = (x * x, yy * yy, z * z);
    let (xy, yz, xz) = (x * yy, yy * z, x * z);
    y[4] = SH_C2[0] * xy;
    y[5] = SH_C2[1] * yz;
    y[6] = SH_C2[2] * (2.0 * zz - xx - y2);
    y[7] = SH_C2[3] * xz;
    y[8] = SH_C2[4] * (xx - y2);
    if degree == 2 {
        return y;
    }
    y[9] = SH_C3[0] * yy * (3.0 * xx - y2);
    y[10] = SH_C3[1] * xy * z;
    y[11] = SH_C3[2] * yy * (4.0 * zz - xx - y2);
    y[12] = SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * y2);
    y[13] = SH_C3[4] * x * (4.0 * zz - xx - y2);
    y[14] = SH_C3[5] * z * (xx - y2);
    y[15] = SH_C3[6] * x * (xx - 3.0 * y2);
    y
}

/// Colour of one Gaussian: `coeffs` are its `3 (degree + 1)²` coefficients in file order
/// (`f_dc_0..2`, then `f_rest` channel-major). Accumulates in `f64`. Degrees above 3 are
/// evaluated as degree 3; missing coefficients count as 0.
#[must_use]
pub fn eval_rgb(degree: u8, coeffs: &[f32], dir: DVec3) -> [f32; 3] {
    let degree = degree.min(3);
    let k = sh_coeffs_per_channel(degree);
    let y = sh_basis(degree, dir);
    let mut rgb = [0.0f32; 3];
    for (c, out) in rgb.iter_mut().enumerate() {
        let mut sum = f64::from(coeffs.get(c).copied().unwrap_or(0.0)) * y[0];
        for (j, yj) in y.iter().enumerate().take(k).skip(1) {
            let idx = 3 + c * (k - 1) + (j - 1);
            sum += f64::from(coeffs.get(idx).copied().unwrap_or(0.0)) * yj;
        }
        *out = (sum + 0.5).max(0.0) as f32;
    }
    rgb
}

/// The DC coefficient that gives colour `rgb` (in 0..1) for a degree-0 Gaussian:
/// `(rgb - 0.5) / SH_C0`.
#[must_use]
pub fn rgb_to_dc(rgb: f32) -> f32 {
    ((f64::from(rgb) - 0.5) / SH_C0) as f32
}

/// Entries of a band's change matrix this close to 0 or ±1 are set to it, so that sign flips
/// and permutations map coefficients exactly (the least-squares fit leaves about 1e-15).
const SNAP: f64 = 1e-12;

/// The change of SH coefficients under an orthogonal change of axes `m` (a rotation or a
/// mirror, `p_new = m p_old`): the new coefficients `c'` give `f'(d) = f(mᵀ d)`, the same
/// colour for the same physical direction. Band by band (degree 0 is unchanged), each a
/// `(2l+1)²` matrix found by least squares on 64 directions spread over the sphere (exact in
/// exact arithmetic: the band is closed under rotations), entries near 0 and ±1 snapped.
#[derive(Clone, Debug, PartialEq)]
pub struct ShChange {
    degree: u8,
    /// Per band l = 1..=degree, row-major `(2l+1) x (2l+1)`: `c'_k = Σ_j t[k][j] c_j`.
    bands: Vec<Vec<f64>>,
}

impl ShChange {
    /// The change for coefficients up to `degree` (at most 3) under `m`.
    #[must_use]
    pub fn new(degree: u8, m: DMat3) -> Self {
        let degree = degree.min(3);
        const N: usize = 64;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let dirs: Vec<DVec3> = (0..N)
            .map(|i| {
                let z = 1.0 - (i as f64 + 0.5) * 2.0 / N as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * i as f64;
                DVec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect();
        let mt = m.transpose();
        let bands = (1..=usize::from(degree))
            .map(|l| {
                let nb = 2 * l + 1;
                let first = l * l;
                let a =
                    nalgebra::DMatrix::from_fn(N, nb, |j, k| sh_basis(degree, dirs[j])[first + k]);
                let b = nalgebra::DMatrix::from_fn(N, nb, |j, k| {
                    sh_basis(degree, mt * dirs[j])[first + k]
                });
                let ata = a.transpose() * &a;
                let atb = a.transpose() * b;
                let t = ata
                    .cholesky()
                    .map(|c| c.solve(&atb))
                    .unwrap_or_else(|| nalgebra::DMatrix::identity(nb, nb));
                let mut out = Vec::with_capacity(nb * nb);
                for k in 0..nb {
                    for j in 0..nb {
                        let v = t[(k, j)];
                        let snapped = [0.0, 1.0, -1.0]
                            .into_iter()
                            .find(|s| (v - s).abs() < SNAP)
                            .unwrap_or(v);
                        out.push(snapped);
                    }
                }
                out
            })
            .collect();
        Self { degree, bands }
    }

    /// Applies the change to one Gaussian's `3 (degree + 1)²` coefficients in file order
    /// (`f_dc_0..2`, then `f_rest` channel-major), in f64, rounding each result once.
    #[expect(clippy::cast_possible_truncation, reason = "f32 storage of SH")]
    pub fn apply(&self, coeffs: &mut [f32]) {
        let k_all = sh_coeffs_per_channel(self.degree);
        if coeffs.len() < 3 * k_all {
            return;
        }
        for c in 0..3 {
            let at = |j: usize| 3 + c * (k_all - 1) + (j - 1);
            for (band, t) in self.bands.iter().enumerate() {
                let l = band + 1;
                let nb = 2 * l + 1;
                let old: Vec<f64> = (0..nb).map(|k| f64::from(coeffs[at(l * l + k)])).collect();
                for k in 0..nb {
                    let v: f64 = (0..nb).map(|j| t[k * nb + j] * old[j]).sum();
                    coeffs[at(l * l + k)] = v as f32;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Agreement of the literal constants with their closed forms.
    const CONST_TOL: f64 = 1e-15;
    /// Midpoint quadrature over the sphere with the grid below integrates these polynomials to
    /// about 1e-7.
    const QUADRATURE_TOL: f64 = 1e-6;
    /// f32 coefficients, f64 accumulation, f32 output: agreement with the f64 hand evaluation.
    const HAND_TOL: f64 = 1e-6;

    #[test]
    fn constants_match_closed_forms() {
        let closed = [
            (SH_C0, 0.5 / PI.sqrt()),
            (SH_C1, (3.0 / (4.0 * PI)).sqrt()),
            (SH_C2[0], 0.5 * (15.0 / PI).sqrt()),
            (-SH_C2[1], 0.5 * (15.0 / PI).sqrt()),
            (SH_C2[2], 0.25 * (5.0 / PI).sqrt()),
            (SH_C2[4], 0.25 * (15.0 / PI).sqrt()),
            (-SH_C3[0], 0.25 * (35.0 / (2.0 * PI)).sqrt()),
            (SH_C3[1], 0.5 * (105.0 / PI).sqrt()),
            (-SH_C3[2], 0.25 * (21.0 / (2.0 * PI)).sqrt()),
            (SH_C3[3], 0.25 * (7.0 / PI).sqrt()),
            (SH_C3[5], 0.25 * (105.0 / PI).sqrt()),
        ];
        for (i, (lit, exact)) in closed.iter().enumerate() {
            assert!((lit - exact).abs() < CONST_TOL, "{i}: {lit} vs {exact}");
        }
        assert_eq!(SH_C0, 0.282_094_791_773_878_14);
    }

    #[test]
    fn basis_is_orthonormal_on_the_sphere() {
        // Midpoint rule in cos(theta) x uniform phi (exact in phi for these degrees).
        let (nt, np) = (10_000, 32);
        let mut gram = [[0.0f64; 16]; 16];
        for i in 0..nt {
            let ct = -1.0 + (i as f64 + 0.5) * 2.0 / nt as f64;
            let st = (1.0 - ct * ct).sqrt();
            for j in 0..np {
                let phi = 2.0 * PI * j as f64 / np as f64;
                let y = sh_basis(3, DVec3::new(st * phi.cos(), st * phi.sin(), ct));
                let w = (2.0 / nt as f64) * (2.0 * PI / np as f64);
                for a in 0..16 {
                    for b in 0..16 {
                        gram[a][b] += w * y[a] * y[b];
                    }
                }
            }
        }
        for (a, row) in gram.iter().enumerate() {
            for (b, v) in row.iter().enumerate() {
                let expect = if a == b { 1.0 } else { 0.0 };
                assert!((v - expect).abs() < QUADRATURE_TOL, "<Y{a},Y{b}> = {v}");
            }
        }
    }

    #[test]
    fn known_values() {
        let up = sh_basis(3, DVec3::new(0.0, 0.0, 2.0));
        assert_eq!(up[1], 0.0);
        assert_eq!(up[2], SH_C1);
        assert_eq!(up[3], 0.0);
        // Y_2^0 at the pole: 2 C2[2]; Y_3^0: 2 C3[3].
        assert_eq!(up[6], 2.0 * SH_C2[2]);
        assert_eq!(up[12], 2.0 * SH_C3[3]);
        // Zero direction: only the constant term.
        let zero = sh_basis(3, DVec3::ZERO);
        assert_eq!(zero[0], SH_C0);
        assert!(zero[1..].iter().all(|&v| v == 0.0));
        // Degree 0 colour and clamping.
        let rgb = eval_rgb(0, &[1.0, 0.0, -10.0], DVec3::X);
        assert_eq!(rgb, [(SH_C0 + 0.5) as f32, 0.5, 0.0]);
        assert!((f64::from(rgb_to_dc(0.25)) * SH_C0 + 0.5 - 0.25).abs() < HAND_TOL);
    }

    /// An independent evaluation: real SH written from the textbook formulas in (x, y, z), with
    /// 3DGS's sign convention, and the channel-major layout indexed by hand.
    fn hand_rgb(coeffs: &[f64], dir: [f64; 3]) -> [f64; 3] {
        let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        let (x, y, z) = (dir[0] / n, dir[1] / n, dir[2] / n);
        let s = |v: f64| v.sqrt();
        let basis = [
            0.5 * s(1.0 / PI),
            -s(3.0 / (4.0 * PI)) * y,
            s(3.0 / (4.0 * PI)) * z,
            -s(3.0 / (4.0 * PI)) * x,
            0.5 * s(15.0 / PI) * x * y,
            -0.5 * s(15.0 / PI) * y * z,
            0.25 * s(5.0 / PI) * (3.0 * z * z - 1.0),
            -0.5 * s(15.0 / PI) * x * z,
            0.25 * s(15.0 / PI) * (x * x - y * y),
            -0.25 * s(35.0 / (2.0 * PI)) * y * (3.0 * x * x - y * y),
            0.5 * s(105.0 / PI) * x * y * z,
            -0.25 * s(21.0 / (2.0 * PI)) * y * (5.0 * z * z - 1.0),
            0.25 * s(7.0 / PI) * z * (5.0 * z * z - 3.0),
            -0.25 * s(21.0 / (2.0 * PI)) * x * (5.0 * z * z - 1.0),
            0.25 * s(105.0 / PI) * z * (x * x - y * y),
            -0.25 * s(35.0 / (2.0 * PI)) * x * (x * x - 3.0 * y * y),
        ];
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let mut sum = coeffs[c] * basis[0];
            for k in 1..16 {
                sum += coeffs[3 + 15 * c + (k - 1)] * basis[k];
            }
            *o = (sum + 0.5).max(0.0);
        }
        out
    }

    #[test]
    fn degree3_colour_matches_hand_evaluation() {
        let mut rng = trisplat_geometry::rng::Rng::new(7);
        for _ in 0..200 {
            let coeffs: Vec<f32> = (0..48).map(|_| rng.uniform_f32() - 0.5).collect();
            let dir = DVec3::new(
                rng.uniform_f64() - 0.5,
                rng.uniform_f64() - 0.5,
                rng.uniform_f64() - 0.5,
            );
            let got = eval_rgb(3, &coeffs, dir);
            let c64: Vec<f64> = coeffs.iter().map(|&v| f64::from(v)).collect();
            let want = hand_rgb(&c64, dir.to_array());
            for c in 0..3 {
                assert!(
                    (f64::from(got[c]) - want[c]).abs() < HAND_TOL,
                    "{got:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn sh_change_keeps_colours_under_rotations_and_mirrors() {
        use crate::axes::Axes;
        let coeffs: Vec<f32> = (0..48)
            .map(|i| ((i * 37 % 23) as f32 - 11.0) / 13.0)
            .collect();
        let turn = DMat3::from_quat(glam::DQuat::from_axis_angle(
            DVec3::new(0.3, -0.5, 0.8).normalize(),
            1.1,
        ));
        let cases = [
            turn,
            Axes::Rdf.to(Axes::Rub),
            Axes::Lbd.to(Axes::Rub),
            Axes::Luf.to(Axes::Rfu),
            DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)),
        ];
        for m in cases {
            let change = ShChange::new(3, m);
            let mut new = coeffs.clone();
            change.apply(&mut new);
            for d in [
                DVec3::new(0.2, 0.9, -0.4),
                DVec3::new(-0.7, 0.1, 0.6),
                DVec3::Z,
            ] {
                let before = eval_rgb(3, &coeffs, d);
                let after = eval_rgb(3, &new, m * d);
                for c in 0..3 {
                    assert!(
                        (before[c] - after[c]).abs() < 1e-5,
                        "{m}: {before:?} {after:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn sh_change_of_axis_flips_is_exact() {
        use crate::axes::Axes;
        // RDF -> RUB (y and z negated): per basis function the sign of Y_k(x, -y, -z) / Y_k.
        let signs = [
            1.0f32, -1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, -1.0, 1.0, -1.0,
            1.0,
        ];
        let coeffs: Vec<f32> = (0..48).map(|i| (i as f32 * 0.731).sin()).collect();
        let mut new = coeffs.clone();
        ShChange::new(3, Axes::Rdf.to(Axes::Rub)).apply(&mut new);
        for c in 0..3 {
            assert_eq!(new[c], coeffs[c]);
            for (j, sign) in signs.iter().enumerate().skip(1) {
                let at = 3 + c * 15 + (j - 1);
                assert_eq!(new[at], sign * coeffs[at], "channel {c} coefficient {j}");
            }
        }
    }
}
