//! A compact morph basis for one run of frames of one topology: a few basis shapes (the run's
//! morph targets) and per-frame weights that put every vertex of every frame within a
//! tolerance of its true place, fitted in one pass over the frames.
//!
//! The fit is greedy and measures what is stored. Frame `k`'s offsets from the run's base (its
//! first frame on the basis grid), in grid steps, are `d_k` (`f32`, 3 per vertex). Its weights
//! are the least-squares coefficients of `d_k` on the basis vectors as stored (integers),
//! solved in `f64` through a Cholesky factor of their Gram matrix (exact: integer products
//! summed in `f64` stay below 2^53), then rounded to `f32`, as the file holds them. Its error
//! is the largest distance of a vertex from its place, `max_v |d_k,v − Σ_i w_i b_i,v|`,
//! evaluated in `f32` as a viewer evaluates morph targets. When it is over the tolerance, the
//! frame's residual becomes a new basis vector (scaled to the `SHORT` range ±32767 and
//! rounded) and the frame is evaluated again. A frame's weights are fixed when it passes;
//! vectors added later get weight 0 for it, which leaves its evaluation unchanged. A new
//! vector is the residual of a least-squares fit, so nearly orthogonal to the others: the Gram
//! matrix stays well conditioned.
//!
//! The fit gives up (the caller keeps one target per frame) when a run needs more vectors than
//! allowed, when a frame still fails right after its own residual was added, or when a
//! residual lies in the span of the basis (numerically).
//!
//! Cost: per frame one sweep over the basis for the dot products and one for the errors,
//! `2 × 3V × r` multiply-adds for `V` vertices and `r` vectors. Frames are evaluated in blocks
//! (one sweep serves the whole block; a block shrinks after it needed a vector and grows after
//! it did not), chunks of vertices in parallel with rayon. Dot products accumulate in `f32`
//! over a chunk of 1,536 coordinates and in `f64` across chunks, summed in chunk order, so the
//! result does not depend on the number of threads.

use std::ops::Range;
use std::path::Path;

use rayon::prelude::*;

use super::quantize::Grid;
use super::source::FrameSource;
use crate::io::error::IoError;

/// Coordinates per parallel chunk (512 vertices: a multiple of 3, so vertices stay whole).
const CHUNK: usize = 3 * 512;

/// The most frames evaluated in one sweep over the basis.
const MAX_BLOCK: usize = 32;

/// The largest |component| of a stored basis vector (`SHORT`).
const VECTOR_RANGE: f32 = 32767.0;

/// A residual whose part outside the span of the basis has less than this share of its
/// squared length is not added: it would make the Gram matrix (numerically) singular.
const MIN_PIVOT_SHARE: f64 = 1e-12;

/// A run's fitted basis.
pub(super) struct BasisFit {
    /// The basis vectors (the run's morph targets), one `SHORT` VEC3 per vertex.
    pub(super) vectors: Vec<Vec<[i16; 3]>>,
    /// Frame-major weights: `vectors.len()` per frame of the run, as stored (`f32`).
    pub(super) weights: Vec<f32>,
    /// Per frame of the run, the largest distance of a vertex from its true place, in grid
    /// steps.
    pub(super) errors: Vec<f64>,
}

/// What the fit may use.
#[derive(Clone, Copy, Debug)]
pub(super) struct BasisLimits {
    /// The largest error allowed, in grid steps.
    pub(super) tolerance: f64,
    /// The most vectors allowed.
    pub(super) max_vectors: usize,
}

/// The basis under construction: its vectors as `f32` (integer values) and the Cholesky
/// factor of their Gram matrix.
#[derive(Default)]
struct Basis {
    vectors: Vec<Vec<f32>>,
    /// Lower-triangular rows: row `i` holds `i + 1` entries.
    cholesky: Vec<Vec<f64>>,
}

/// Fits a basis to frames `run` of `frames`, whose base (the run's first frame) is `base` on
/// `grid`; `None` when it does not meet `limits` (the caller keeps one target per frame).
///
/// # Errors
/// The source's errors; a frame whose vertex count differs from the base's.
pub(super) fn fit(
    path: &Path,
    frames: &dyn FrameSource,
    run: Range<usize>,
    grid: &Grid,
    base: &[[i16; 3]],
    limits: BasisLimits,
) -> Result<Option<BasisFit>, IoError> {
    let mut basis = Basis::default();
    let mut weights: Vec<Vec<f32>> = Vec::with_capacity(run.len());
    let mut errors = Vec::with_capacity(run.len());
    let mut block_len = 1;
    let mut next = run.start;
    while next < run.end {
        let end = (next + block_len).min(run.end);
        let block = (next..end)
            .map(|k| offsets(path, frames, k, grid, base))
            .collect::<Result<Vec<_>, _>>()?;
        let (mut from, mut grew, mut just_added) = (0, false, None);
        while from < block.len() {
            let evaluated = basis.evaluate(&block[from..]);
            let failing = evaluated
                .iter()
                .position(|(_, error)| error.is_nan() || *error > limits.tolerance);
            let passed = failing.unwrap_or(evaluated.len());
            for (w, error) in &evaluated[..passed] {
                weights.push(w.clone());
                errors.push(*error);
            }
            let Some(j) = failing else { break };
            let at = from + j;
            if just_added == Some(at) || basis.vectors.len() >= limits.max_vectors {
                return Ok(None);
            }
            let residual = basis.residual(&block[at], &evaluated[j].0);
            if !basis.add(residual) {
                return Ok(None);
            }
            (from, grew, just_added) = (at, true, Some(at));
        }
        next = end;
        block_len = if grew {
            (block_len / 2).max(1)
        } else {
            (block_len * 2).min(MAX_BLOCK)
        };
    }
    let r = basis.vectors.len();
    let vectors = basis
        .vectors
        .iter()
        .map(|v| {
            v.chunks_exact(3)
                .map(|c| {
                    #[expect(clippy::cast_possible_truncation, reason = "integers within ±32767")]
                    let e = [c[0] as i16, c[1] as i16, c[2] as i16];
                    e
                })
                .collect()
        })
        .collect();
    let mut flat = Vec::with_capacity(r * weights.len());
    for w in &weights {
        flat.extend_from_slice(w);
        flat.extend(std::iter::repeat_n(0.0f32, r - w.len()));
    }
    Ok(Some(BasisFit {
        vectors,
        weights: flat,
        errors,
    }))
}

/// Frame `k`'s offsets from `base`, in steps of `grid`, 3 per vertex.
fn offsets(
    path: &Path,
    frames: &dyn FrameSource,
    k: usize,
    grid: &Grid,
    base: &[[i16; 3]],
) -> Result<Vec<f32>, IoError> {
    let frame = frames.frame(k)?;
    if frame.vertex_count() != base.len() {
        return Err(IoError::malformed(
            path,
            format!("frame {k}"),
            format!(
                "has {} vertices, {} when the sequence was surveyed \
                 (a frame changed while the sequence was written)",
                frame.vertex_count(),
                base.len()
            ),
        ));
    }
    let (origin, step) = (grid.origin(), grid.step());
    Ok(frame
        .positions()
        .par_iter()
        .zip(base)
        .flat_map_iter(|(p, q)| {
            let s = (*p - origin) / step;
            (0..3).map(move |c| {
                #[expect(clippy::cast_possible_truncation, reason = "f32 offsets")]
                let d = (s[c] - f64::from(q[c])) as f32;
                d
            })
        })
        .collect())
}

/// The coordinates of chunk `c` of `m`.
fn chunk(c: usize, m: usize) -> Range<usize> {
    c * CHUNK..((c + 1) * CHUNK).min(m)
}

/// `a · b`: eight `f32` lanes over the slice (a chunk), summed in `f64`.
fn dot(a: &[f32], b: &[f32]) -> f64 {
    let mut lanes = [0.0f32; 8];
    let (a8, b8) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (a8.remainder(), b8.remainder());
    for (x, y) in a8.zip(b8) {
        for l in 0..8 {
            lanes[l] += x[l] * y[l];
        }
    }
    let tail: f64 = ra
        .iter()
        .zip(rb)
        .map(|(x, y)| f64::from(*x) * f64::from(*y))
        .sum();
    lanes.iter().map(|&x| f64::from(x)).sum::<f64>() + tail
}

/// The largest length of a vertex (3 coordinates) of `residual`.
fn max_vertex_length(residual: &[f32]) -> f64 {
    residual
        .chunks_exact(3)
        .map(|v| {
            let (x, y, z) = (f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
            (x * x + y * y + z * z).sqrt()
        })
        .fold(0.0, f64::max)
}

/// `out -= w × v` (a chunk of the evaluation).
fn subtract_scaled(out: &mut [f32], v: &[f32], w: f32) {
    for (o, x) in out.iter_mut().zip(v) {
        *o -= w * x;
    }
}

impl Basis {
    /// Each of `frames`' weights (as stored, `f32`) and error (grid steps).
    fn evaluate(&self, frames: &[Vec<f32>]) -> Vec<(Vec<f32>, f64)> {
        let (r, n) = (self.vectors.len(), frames.len());
        let Some(m) = frames.first().map(Vec::len) else {
            return Vec::new();
        };
        let chunks = m.div_ceil(CHUNK);
        let weights: Vec<Vec<f32>> = if r == 0 {
            vec![Vec::new(); n]
        } else {
            let partial: Vec<Vec<f64>> = (0..chunks)
                .into_par_iter()
                .map(|c| {
                    let range = chunk(c, m);
                    let mut out = vec![0.0; n * r];
                    for (i, v) in self.vectors.iter().enumerate() {
                        let v = &v[range.clone()];
                        for (f, d) in frames.iter().enumerate() {
                            out[f * r + i] = dot(v, &d[range.clone()]);
                        }
                    }
                    out
                })
                .collect();
            let mut sums = vec![0.0f64; n * r];
            for p in &partial {
                for (s, x) in sums.iter_mut().zip(p) {
                    *s += x;
                }
            }
            sums.chunks_exact(r)
                .map(|c| {
                    self.solve(c)
                        .into_iter()
                        .map(|w| {
                            #[expect(clippy::cast_possible_truncation, reason = "stored as f32")]
                            let w = w as f32;
                            w
                        })
                        .collect()
                })
                .collect()
        };
        let per_chunk: Vec<Vec<f64>> = (0..chunks)
            .into_par_iter()
            .map_init(
                || vec![0.0f32; CHUNK],
                |buffer, c| {
                    let range = chunk(c, m);
                    let buffer = &mut buffer[..range.len()];
                    frames
                        .iter()
                        .zip(&weights)
                        .map(|(d, w)| {
                            buffer.copy_from_slice(&d[range.clone()]);
                            for (v, &wi) in self.vectors.iter().zip(w) {
                                subtract_scaled(buffer, &v[range.clone()], wi);
                            }
                            max_vertex_length(buffer)
                        })
                        .collect()
                },
            )
            .collect();
        weights
            .into_iter()
            .enumerate()
            .map(|(f, w)| {
                let error = per_chunk.iter().map(|e| e[f]).fold(0.0, f64::max);
                (w, error)
            })
            .collect()
    }

    /// `d − Σ w_i v_i`, as [`Self::evaluate`] measures it.
    fn residual(&self, d: &[f32], w: &[f32]) -> Vec<f32> {
        let mut out = d.to_vec();
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
            let range = chunk(c, d.len());
            for (v, &wi) in self.vectors.iter().zip(w) {
                subtract_scaled(out, &v[range.clone()], wi);
            }
        });
        out
    }

    /// Adds `residual`, scaled to the `SHORT` range and rounded; `false` (nothing added) when
    /// it is zero or (numerically) in the span of the basis.
    fn add(&mut self, residual: Vec<f32>) -> bool {
        let largest = residual.iter().fold(0.0f32, |a, x| a.max(x.abs()));
        if !(largest > 0.0 && largest.is_finite()) {
            return false;
        }
        let scale = VECTOR_RANGE / largest;
        let mut v = residual;
        for x in &mut v {
            *x = (*x * scale).round().clamp(-VECTOR_RANGE, VECTOR_RANGE);
        }
        let m = v.len();
        // Exact integer dot products (|products| ≤ 2^30, sums below 2^53).
        let exact = |a: &[f32], b: &[f32]| -> f64 {
            (0..m.div_ceil(CHUNK))
                .into_par_iter()
                .map(|c| {
                    let range = chunk(c, m);
                    a[range.clone()]
                        .iter()
                        .zip(&b[range])
                        .map(|(x, y)| f64::from(*x) * f64::from(*y))
                        .sum::<f64>()
                })
                .collect::<Vec<f64>>()
                .into_iter()
                .sum()
        };
        let gram: Vec<f64> = self.vectors.iter().map(|u| exact(u, &v)).collect();
        let length_sq = exact(&v, &v);
        let mut row = Vec::with_capacity(gram.len() + 1);
        for (i, g) in gram.iter().enumerate() {
            let known: f64 = row.iter().zip(&self.cholesky[i]).map(|(a, b)| a * b).sum();
            row.push((g - known) / self.cholesky[i][i]);
        }
        let pivot_sq = length_sq - row.iter().map(|x| x * x).sum::<f64>();
        if pivot_sq.is_nan() || pivot_sq <= MIN_PIVOT_SHARE * length_sq {
            return false;
        }
        row.push(pivot_sq.sqrt());
        self.cholesky.push(row);
        self.vectors.push(v);
        true
    }

    /// The least-squares weights of dot products `c` (`B^T d`): `(B^T B)^{-1} c` through the
    /// Cholesky factor.
    fn solve(&self, c: &[f64]) -> Vec<f64> {
        let r = c.len();
        let l = &self.cholesky;
        let mut y = vec![0.0; r];
        for i in 0..r {
            let known: f64 = (0..i).map(|k| l[i][k] * y[k]).sum();
            y[i] = (c[i] - known) / l[i][i];
        }
        let mut w = vec![0.0; r];
        for i in (0..r).rev() {
            let known: f64 = (i + 1..r).map(|k| l[k][i] * w[k]).sum();
            w[i] = (y[i] - known) / l[i][i];
        }
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The normal equations solved through the factor reproduce a known combination.
    #[test]
    fn solve_recovers_known_weights() {
        let mut basis = Basis::default();
        let m = 3 * 700;
        let a: Vec<f32> = (0..m).map(|j| ((j * 7919) % 201) as f32 - 100.0).collect();
        let b: Vec<f32> = (0..m).map(|j| ((j * 104_729) % 97) as f32 - 48.0).collect();
        assert!(basis.add(a.clone()));
        assert!(basis.add(b.clone()));
        assert!(!basis.add(a.clone()), "a dependent vector is refused");
        let (va, vb) = (&basis.vectors[0], &basis.vectors[1]);
        let d: Vec<f32> = va.iter().zip(vb).map(|(x, y)| 0.25 * x - 0.5 * y).collect();
        let evaluated = basis.evaluate(&[d]);
        let (w, error) = &evaluated[0];
        assert!(
            (w[0] - 0.25).abs() < 1e-6 && (w[1] + 0.5).abs() < 1e-6,
            "{w:?}"
        );
        assert!(*error < 1e-3, "{error}");
    }
}
