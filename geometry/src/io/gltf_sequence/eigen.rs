//! The leading eigenpairs of a symmetric positive semi-definite matrix (a run's frames × frames
//! Gram matrix): subspace iteration from a fixed pseudo-random start, then Rayleigh-Ritz with
//! a cyclic Jacobi eigensolver on the small projected matrix. `f64` throughout; every product
//! is computed by one thread in a fixed order, so the result does not depend on the number of
//! threads.

use rayon::prelude::*;

use crate::rng::Rng;

/// Subspace iterations (products with the matrix) before the Rayleigh-Ritz step.
const ITERATIONS: usize = 8;

/// Jacobi sweeps at most (it converges quadratically, in well under 20).
const MAX_SWEEPS: usize = 60;

/// An eigenvalue at most this share of the largest is treated as zero (dropped).
const ZERO_SHARE: f64 = 1e-13;

/// A column whose norm falls below this share of its norm before orthogonalisation lies in
/// the span of the columns before it and is set to zero.
const DEPENDENT_SHARE: f64 = 1e-10;

/// An eigenpair: eigenvalue and unit eigenvector.
pub(super) struct Eigenpair {
    pub(super) value: f64,
    pub(super) vector: Vec<f64>,
}

/// Up to `width` leading eigenpairs of the symmetric `n × n` matrix `a` (row-major), largest
/// first, eigenvalues above zero only. Exact (up to rounding) when `width ≥ n`; otherwise the
/// Ritz pairs of a `width`-dimensional subspace after [`ITERATIONS`] subspace iterations.
pub(super) fn leading(a: &[f64], n: usize, width: usize) -> Vec<Eigenpair> {
    let width = width.min(n);
    if width == 0 {
        return Vec::new();
    }
    // Columns of the subspace, each of length n.
    let mut basis: Vec<Vec<f64>> = if width == n {
        (0..n)
            .map(|j| (0..n).map(|i| f64::from(u8::from(i == j))).collect())
            .collect()
    } else {
        let mut rng = Rng::new(0x5eed_ba51);
        let mut start: Vec<Vec<f64>> = (0..width)
            .map(|_| (0..n).map(|_| rng.uniform_f64() - 0.5).collect())
            .collect();
        orthonormalise(&mut start);
        for _ in 0..ITERATIONS {
            start = multiply(a, n, &start);
            orthonormalise(&mut start);
        }
        start
    };
    basis.retain(|c| c.iter().any(|&x| x != 0.0));
    let w = basis.len();
    let product = multiply(a, n, &basis);
    // The projected matrix basis^T a basis, symmetrised.
    let mut t = vec![0.0; w * w];
    for i in 0..w {
        for j in 0..=i {
            let x = 0.5 * (dot(&basis[i], &product[j]) + dot(&basis[j], &product[i]));
            t[i * w + j] = x;
            t[j * w + i] = x;
        }
    }
    let (values, vectors) = jacobi(t, w);
    let mut order: Vec<usize> = (0..w).collect();
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]).then(i.cmp(&j)));
    let largest = order.first().map_or(0.0, |&i| values[i]);
    order
        .into_iter()
        .filter(|&i| values[i] > ZERO_SHARE * largest && values[i] > 0.0)
        .map(|i| {
            let mut vector = vec![0.0; n];
            for (j, column) in basis.iter().enumerate() {
                let c = vectors[j * w + i];
                for (v, x) in vector.iter_mut().zip(column) {
                    *v += c * x;
                }
            }
            let norm = dot(&vector, &vector).sqrt();
            vector.iter_mut().for_each(|v| *v /= norm);
            Eigenpair {
                value: values[i],
                vector,
            }
        })
        .collect()
}

/// `a · b`, in order.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `a` (`n × n`, row-major) times each column.
pub(super) fn multiply(a: &[f64], n: usize, columns: &[Vec<f64>]) -> Vec<Vec<f64>> {
    columns
        .par_iter()
        .map(|c| (0..n).map(|i| dot(&a[i * n..(i + 1) * n], c)).collect())
        .collect()
}

/// Modified Gram-Schmidt on the columns; a column (numerically) in the span of those before it
/// becomes zero.
fn orthonormalise(columns: &mut [Vec<f64>]) {
    for j in 0..columns.len() {
        let (done, rest) = columns.split_at_mut(j);
        let c = &mut rest[0];
        let before = dot(c, c).sqrt();
        for q in done.iter() {
            let p = dot(q, c);
            for (x, y) in c.iter_mut().zip(q) {
                *x -= p * y;
            }
        }
        let norm = dot(c, c).sqrt();
        if norm > DEPENDENT_SHARE * before && norm > 0.0 {
            c.iter_mut().for_each(|x| *x /= norm);
        } else {
            c.iter_mut().for_each(|x| *x = 0.0);
        }
    }
}

/// The eigenvalues and eigenvectors (columns of a row-major `w × w` matrix) of the symmetric
/// `t`, by cyclic Jacobi rotations.
fn jacobi(mut t: Vec<f64>, w: usize) -> (Vec<f64>, Vec<f64>) {
    let mut v = vec![0.0; w * w];
    for i in 0..w {
        v[i * w + i] = 1.0;
    }
    let total: f64 = t.iter().map(|x| x * x).sum();
    for _ in 0..MAX_SWEEPS {
        let off: f64 = (0..w)
            .flat_map(|i| (0..w).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| t[i * w + j] * t[i * w + j])
            .sum();
        if off <= 1e-30 * total || off == 0.0 {
            break;
        }
        for p in 0..w {
            for q in p + 1..w {
                let apq = t[p * w + q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (t[q * w + q] - t[p * w + p]) / (2.0 * apq);
                let tan = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (tan * tan + 1.0).sqrt();
                let s = tan * c;
                for k in 0..w {
                    let (kp, kq) = (t[k * w + p], t[k * w + q]);
                    t[k * w + p] = c * kp - s * kq;
                    t[k * w + q] = s * kp + c * kq;
                }
                for k in 0..w {
                    let (pk, qk) = (t[p * w + k], t[q * w + k]);
                    t[p * w + k] = c * pk - s * qk;
                    t[q * w + k] = s * pk + c * qk;
                }
                for k in 0..w {
                    let (kp, kq) = (v[k * w + p], v[k * w + q]);
                    v[k * w + p] = c * kp - s * kq;
                    v[k * w + q] = s * kp + c * kq;
                }
            }
        }
    }
    ((0..w).map(|i| t[i * w + i]).collect(), v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A matrix with known eigenpairs: `Q diag(values) Q^T` for an orthonormal `Q`.
    fn known(n: usize, values: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
        let mut rng = Rng::new(7);
        let mut q: Vec<Vec<f64>> = (0..n)
            .map(|_| (0..n).map(|_| rng.uniform_f64() - 0.5).collect())
            .collect();
        orthonormalise(&mut q);
        let mut a = vec![0.0; n * n];
        for (value, column) in values.iter().zip(&q) {
            for i in 0..n {
                for j in 0..n {
                    a[i * n + j] += value * column[i] * column[j];
                }
            }
        }
        (a, q)
    }

    #[test]
    fn leading_pairs_of_a_known_matrix() {
        let n = 60;
        // A fast-decaying spectrum (as a run's frames have), rank 20.
        let values: Vec<f64> = (0..20).map(|i| 10f64.powi(6 - i / 3)).collect();
        let (a, q) = known(n, &values);
        for width in [n, 28] {
            let pairs = leading(&a, n, width);
            assert_eq!(pairs.len(), 20, "width {width}: rank 20");
            for (i, pair) in pairs.iter().take(12).enumerate() {
                assert!(
                    (pair.value - values[i]).abs() <= 1e-8 * values[0],
                    "width {width}, pair {i}: {} for {}",
                    pair.value,
                    values[i]
                );
            }
            // The leading subspace of dimension 3 (one distinct value) is recovered.
            for pair in &pairs[..3] {
                let inside: f64 = q[..3].iter().map(|c| dot(c, &pair.vector).powi(2)).sum();
                assert!((inside - 1.0).abs() < 1e-9, "width {width}: {inside}");
            }
        }
    }

    #[test]
    fn degenerate_matrices() {
        assert!(leading(&[0.0; 9], 3, 3).is_empty(), "zero: no pairs");
        assert!(leading(&[], 0, 4).is_empty(), "empty");
        // Rank one (every frame the same): one pair, the all-ones direction.
        let n = 10;
        let pairs = leading(&vec![2.0; n * n], n, 4);
        assert_eq!(pairs.len(), 1);
        assert!((pairs[0].value - 20.0).abs() < 1e-9);
        let one = pairs[0].vector.iter().map(|x| x.abs()).fold(0.0, f64::max);
        assert!((one - 1.0 / (n as f64).sqrt()).abs() < 1e-9);
        // One frame.
        let pairs = leading(&[4.0], 1, 8);
        assert_eq!(pairs.len(), 1);
        assert!((pairs[0].value - 4.0).abs() < 1e-12);
    }
}
