//! The SH degree schedule of a fit (3DGS `oneupSHdegree`): the render uses the bands up to an
//! *active* degree that starts at 0 and rises by one every `every` iterations up to the set's
//! degree; the inactive bands get no gradient and stay as they are.
//!
//! The renderer takes the degree from the data layout ([`GaussianParams::sh_degree`]), so the
//! fitter renders a copy of the world parameters cut to the active degree ([`truncate_sh`],
//! in place, no allocation) and widens the gradient back to the full layout with zeros for the
//! inactive bands ([`expand_sh_grads`]). Cutting the bands gives exactly the render of the set
//! with those bands at zero (the colour is linear in the coefficients), at the cost of the
//! active degree only.
//!
//! Layout (file order, per Gaussian, `K = (degree + 1)²`): `f_dc_0..2` (one per channel), then
//! `f_rest` channel-major (`K − 1` per channel).

use crate::render::GaussianParams;
use crate::sh::sh_coeffs_per_channel;

/// The active degree after `done` iterations (3DGS: one more every `every` iterations, counted
/// from 1), capped at `max`; `None` keeps every band from the start.
#[must_use]
pub fn active_degree(done: usize, every: Option<usize>, max: u8) -> u8 {
    match every {
        Some(n) if n > 0 => u8::try_from(done / n).unwrap_or(u8::MAX).min(max),
        _ => max,
    }
}

/// Position of coefficient `j` (file order, degree `from`) in the layout of degree `to`
/// (`None` when the coefficient is past `to`'s bands).
fn position(j: usize, from: u8, to: u8) -> Option<usize> {
    let kf = sh_coeffs_per_channel(from);
    let kt = sh_coeffs_per_channel(to);
    if j < 3 {
        return Some(j);
    }
    let r = j - 3;
    let (c, m) = (r / (kf - 1), r % (kf - 1));
    (m < kt - 1).then(|| 3 + c * (kt - 1) + m)
}

/// Cuts `params`' SH coefficients to `degree` in place (no-op when it is not lower than the
/// current degree): the bands above are dropped, the layout becomes that of `degree`.
pub fn truncate_sh(params: &mut GaussianParams, degree: u8) {
    let from = params.sh_degree.min(3);
    if degree >= from {
        return;
    }
    let (kf, kt) = (
        3 * sh_coeffs_per_channel(from),
        3 * sh_coeffs_per_channel(degree),
    );
    let n = params.sh.len() / kf;
    // Every coefficient moves to an index not above its old one, in the same order: a forward
    // copy never overwrites a value still to be read.
    for i in 0..n {
        for j in 0..kf {
            if let Some(t) = position(j, from, degree) {
                params.sh[i * kt + t] = params.sh[i * kf + j];
            }
        }
    }
    params.sh.truncate(n * kt);
    params.sh_degree = degree;
}

/// Widens per-Gaussian SH gradients of `n` Gaussians from the layout of degree `active` to
/// that of degree `full` in place, with zeros for the inactive bands (no-op when
/// `active >= full`).
///
/// # Panics
/// When `sh` does not hold `n` Gaussians of degree `active`.
pub fn expand_sh_grads(sh: &mut Vec<f64>, n: usize, active: u8, full: u8) {
    let (active, full) = (active.min(3), full.min(3));
    if active >= full {
        return;
    }
    let (ka, kf) = (
        3 * sh_coeffs_per_channel(active),
        3 * sh_coeffs_per_channel(full),
    );
    assert_eq!(sh.len(), n * ka, "expand_sh_grads: SH layout");
    sh.resize(n * kf, 0.0);
    // Backwards: every value moves to an index not below its old one.
    for i in (0..n).rev() {
        let mut block = [0.0f64; 48];
        block[..ka].copy_from_slice(&sh[i * ka..(i + 1) * ka]);
        let out = &mut sh[i * kf..(i + 1) * kf];
        for (j, o) in out.iter_mut().enumerate() {
            *o = position(j, full, active).map_or(0.0, |a| block[a]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_rises_every_n_and_caps() {
        assert_eq!(active_degree(0, Some(1000), 3), 0);
        assert_eq!(active_degree(999, Some(1000), 3), 0);
        assert_eq!(active_degree(1000, Some(1000), 3), 1);
        assert_eq!(active_degree(3500, Some(1000), 3), 3);
        assert_eq!(active_degree(9000, Some(1000), 2), 2);
        assert_eq!(active_degree(0, None, 3), 3);
    }

    #[test]
    fn truncate_then_expand_keeps_the_active_bands_in_place() {
        // Two Gaussians of degree 2 (27 coefficients), value = 100 i + j.
        let n = 2;
        let mut p = GaussianParams {
            sh_degree: 2,
            sh: (0..n * 27)
                .map(|x| (100 * (x / 27) + x % 27) as f64)
                .collect(),
            ..GaussianParams::default()
        };
        let full = p.sh.clone();
        truncate_sh(&mut p, 1);
        assert_eq!(p.sh_degree, 1);
        assert_eq!(p.sh.len(), n * 12);
        // DC, then 3 degree-1 coefficients per channel (channels start at 3, 11, 19 in
        // degree 2).
        let want_one = [0, 1, 2, 3, 4, 5, 11, 12, 13, 19, 20, 21];
        for i in 0..n {
            for (t, &j) in want_one.iter().enumerate() {
                assert_eq!(p.sh[i * 12 + t], full[i * 27 + j]);
            }
        }
        let mut g = p.sh.clone();
        expand_sh_grads(&mut g, n, 1, 2);
        for i in 0..n {
            for j in 0..27 {
                let want = if want_one.contains(&j) {
                    full[i * 27 + j]
                } else {
                    0.0
                };
                assert_eq!(g[i * 27 + j], want, "gaussian {i} coefficient {j}");
            }
        }
        truncate_sh(&mut p, 0);
        assert_eq!(p.sh, vec![0.0, 1.0, 2.0, 100.0, 101.0, 102.0]);
    }
}
