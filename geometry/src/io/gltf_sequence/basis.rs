//! A run's morph basis as the file stores it, and its evaluation: basis vectors (the run's
//! morph targets, `SHORT`, each scaled to ±32767) and per-frame `f32` weights, measured
//! against every frame's true offsets. Module `pca` chooses the vectors.
//!
//! Frame `k`'s offsets from the run's base (its first frame on the basis grid), in grid steps,
//! are `d_k` (`f32`, 3 per vertex). Its weights on the first `r` vectors are the least-squares
//! coefficients of `d_k` on those vectors as stored (integers), solved in `f64` through the
//! leading `r × r` block of a Cholesky factor of their Gram matrix (exact: integer products
//! summed in `f64` stay below 2^53), then rounded to `f32`, as the file holds them. Its error
//! is the largest distance of a vertex from its place, `max_v |d_k,v − Σ_i w_i b_i,v|`,
//! evaluated in `f32` as a viewer evaluates morph targets.
//!
//! Frames are evaluated in blocks (one sweep over the basis serves the whole block), chunks of
//! vertices in parallel with rayon. Dot products accumulate in `f32` over a chunk of 1,536
//! coordinates and in `f64` across chunks, summed in chunk order; errors are a maximum over
//! chunks: neither depends on the number of threads.

use std::ops::Range;
use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;

use super::quantize::Grid;
use super::source::{FrameSource, surveyed_frame};
use crate::io::error::IoError;

/// Coordinates per parallel chunk (512 vertices: a multiple of 3, so vertices stay whole).
pub(super) const CHUNK: usize = 3 * 512;

/// The largest |component| of a stored basis vector (`SHORT`).
const VECTOR_RANGE: f32 = 32767.0;

/// A vector whose part outside the span of the basis has less than this share of its squared
/// length is not added: it would make the Gram matrix (numerically) singular.
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

/// Basis vectors as stored (integers, 3 per vertex) and the Cholesky factor of their Gram
/// matrix.
#[derive(Default)]
pub(super) struct Basis {
    vectors: Vec<Vec<i16>>,
    /// Lower-triangular rows: row `i` holds `i + 1` entries.
    cholesky: Vec<Vec<f64>>,
}

/// Frame `k`'s offsets from `base`, in steps of `grid`, 3 per vertex, at every `stride`-th
/// vertex (1: all).
///
/// # Errors
/// The source's errors; a frame whose vertex count differs from the base's.
pub(super) fn offsets(
    path: &Path,
    frames: &dyn FrameSource,
    k: usize,
    grid: &Grid,
    base: &[[i16; 3]],
    stride: usize,
) -> Result<Vec<f32>, IoError> {
    let frame = surveyed_frame(path, frames, k, base.len())?;
    let (origin, step) = (grid.origin(), grid.step());
    let positions = frame.positions();
    let stride = stride.max(1);
    // Written in place, chunks of vertices in parallel (an indexed fill, no gathering).
    let mut out = vec![0.0f32; 3 * base.len().div_ceil(stride)];
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, slab)| {
        let first = c * CHUNK / 3;
        for (i, o) in slab.chunks_exact_mut(3).enumerate() {
            let v = (first + i) * stride;
            o.copy_from_slice(&offset(positions[v], origin, step, base[v]));
        }
    });
    Ok(out)
}

/// [`offsets`] of a frame at every `stride`-th vertex from those vertices' positions
/// (`sampled`, taken when the frame was surveyed): the same values.
///
/// # Errors
/// `sampled` holds another number of vertices (the frame changed), named by `path` and `k`.
pub(super) fn sampled_offsets(
    path: &Path,
    k: usize,
    sampled: &[DVec3],
    grid: &Grid,
    base: &[[i16; 3]],
    stride: usize,
) -> Result<Vec<f32>, IoError> {
    let stride = stride.max(1);
    let expected = base.len().div_ceil(stride);
    if sampled.len() != expected {
        return Err(IoError::malformed(
            path,
            format!("frame {k}"),
            format!(
                "has {} sketched vertices, {expected} expected \
                 (a frame changed while the sequence was written)",
                sampled.len()
            ),
        ));
    }
    let (origin, step) = (grid.origin(), grid.step());
    Ok(sampled
        .iter()
        .enumerate()
        .flat_map(|(i, &p)| offset(p, origin, step, base[i * stride]))
        .collect())
}

/// The offset of a vertex at `p` from its base point `q` on the grid at `origin` with `step`,
/// in grid steps.
fn offset(p: DVec3, origin: DVec3, step: f64, q: [i16; 3]) -> [f32; 3] {
    let s = ((p - origin) / step).to_array();
    #[expect(clippy::cast_possible_truncation, reason = "f32 offsets")]
    std::array::from_fn(|a| (s[a] - f64::from(q[a])) as f32)
}

/// The coordinates of chunk `c` of `m`.
pub(super) fn chunk(c: usize, m: usize) -> Range<usize> {
    c * CHUNK..((c + 1) * CHUNK).min(m)
}

/// `a · b`: eight `f32` lanes over the slice (a chunk), summed in `f64`.
pub(super) fn dot(a: &[f32], b: &[f32]) -> f64 {
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

/// `a · b_q` for `Q` slices `b_q`, each exactly as [`dot`] computes it. One [`dot`] after
/// another: a loop over the `Q` slices within each group of eight lanes (one load of `a` for
/// `Q` products) was measured 15% slower, the compiler vectorising it across the slices with
/// shuffles instead of along the lanes (2026-11-28, issue #31).
fn dot_many<const Q: usize>(a: &[f32], b: [&[f32]; Q]) -> [f64; Q] {
    b.map(|s| dot(a, s))
}

/// Coordinates a tiled kernel keeps in registers at once (a multiple of 8).
pub(super) const SLAB: usize = 32;

/// `out = d − Σ_i w_i v_i`, where `v_i` is `vectors[i * len..(i + 1) * len]` (`len =
/// d.len()`), each coordinate updated in the order of `i` as [`subtract_scaled`] does, [`SLAB`]
/// coordinates at a time held in registers.
fn subtract_all(out: &mut [f32], d: &[f32], vectors: &[f32], w: &[f32]) {
    let len = d.len();
    for start in (0..len).step_by(SLAB) {
        let end = (start + SLAB).min(len);
        if end - start < SLAB {
            out[start..end].copy_from_slice(&d[start..end]);
            for (i, &wi) in w.iter().enumerate() {
                subtract_scaled(
                    &mut out[start..end],
                    &vectors[i * len + start..i * len + end],
                    wi,
                );
            }
            continue;
        }
        let mut acc = [0.0f32; SLAB];
        acc.copy_from_slice(&d[start..end]);
        for (i, &wi) in w.iter().enumerate() {
            let v: &[f32; SLAB] = vectors[i * len + start..i * len + end]
                .try_into()
                .unwrap_or(&[0.0; SLAB]);
            for l in 0..SLAB {
                acc[l] -= wi * v[l];
            }
        }
        out[start..end].copy_from_slice(&acc);
    }
}

/// `out += Σ_f w_f x_f` over `(x_f, w_f)` in order, each coordinate updated in that order as
/// `*o += w * x` one frame at a time would, [`SLAB`] coordinates at a time held in registers.
pub(super) fn add_scaled_all<'a>(
    out: &mut [f32],
    terms: impl Iterator<Item = (&'a [f32], f32)> + Clone,
) {
    let len = out.len();
    for start in (0..len).step_by(SLAB) {
        let end = (start + SLAB).min(len);
        if end - start < SLAB {
            for (x, w) in terms.clone() {
                for (o, x) in out[start..end].iter_mut().zip(&x[start..end]) {
                    *o += w * x;
                }
            }
            continue;
        }
        let mut acc = [0.0f32; SLAB];
        acc.copy_from_slice(&out[start..end]);
        for (x, w) in terms.clone() {
            let x: &[f32; SLAB] = x[start..end].try_into().unwrap_or(&[0.0; SLAB]);
            for l in 0..SLAB {
                acc[l] += w * x[l];
            }
        }
        out[start..end].copy_from_slice(&acc);
    }
}

/// `a · b` over whole vectors: [`dot`] per chunk, the chunks summed in order in `f64`.
pub(super) fn chunked_dot(a: &[f32], b: &[f32]) -> f64 {
    (0..a.len().div_ceil(CHUNK))
        .map(|c| {
            let range = chunk(c, a.len());
            dot(&a[range.clone()], &b[range])
        })
        .sum()
}

/// [`chunked_dot`] of `a` with four slices at once (each the same sum, in the same order).
pub(super) fn chunked_dots4(a: &[f32], b: [&[f32]; 4]) -> [f64; 4] {
    let parts: Vec<[f64; 4]> = (0..a.len().div_ceil(CHUNK))
        .map(|c| {
            let range = chunk(c, a.len());
            dot_many(&a[range.clone()], b.map(|s| &s[range.clone()]))
        })
        .collect();
    std::array::from_fn(|q| parts.iter().map(|p| p[q]).sum())
}

/// The largest length of a vertex (3 coordinates) of `residual`: the root of the largest
/// squared length (the same value as the largest root, `sqrt` being correctly rounded and
/// monotonic, with one root instead of one per vertex).
pub(super) fn max_vertex_length(residual: &[f32]) -> f64 {
    residual
        .chunks_exact(3)
        .map(|v| {
            let (x, y, z) = (f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
            x * x + y * y + z * z
        })
        .fold(0.0, f64::max)
        .sqrt()
}

/// `out -= w × v` (a chunk of the evaluation).
fn subtract_scaled(out: &mut [f32], v: &[f32], w: f32) {
    for (o, x) in out.iter_mut().zip(v) {
        *o -= w * x;
    }
}

impl Basis {
    /// The number of vectors.
    pub(super) fn len(&self) -> usize {
        self.vectors.len()
    }

    /// The first `r` vectors as stored: one `SHORT` VEC3 per vertex each.
    pub(super) fn stored(&self, r: usize) -> Vec<Vec<[i16; 3]>> {
        self.vectors[..r]
            .iter()
            .map(|v| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
            .collect()
    }

    /// Chunk `c` (of `m` coordinates) of the first `r` vectors, as `f32`, one after another.
    fn chunk_f32(&self, c: usize, m: usize, r: usize, out: &mut Vec<f32>) {
        self.chunk_f32_of(c, m, 0..r, out);
    }

    /// Chunk `c` (of `m` coordinates) of vectors `vectors`, as `f32`, one after another.
    fn chunk_f32_of(&self, c: usize, m: usize, vectors: Range<usize>, out: &mut Vec<f32>) {
        out.clear();
        let range = chunk(c, m);
        for v in &self.vectors[vectors] {
            out.extend(v[range.clone()].iter().map(|&x| f32::from(x)));
        }
    }

    /// Each frame of `block` dotted with every vector: `block.len() × len()`, frame-major.
    pub(super) fn dots(&self, block: &[Vec<f32>]) -> Vec<f64> {
        self.dots_with(block, 0..self.len())
    }

    /// [`Self::dots`] of frames whose dot products with the first `known` vectors are
    /// already `old` (frame-major, `known` per frame): only the later vectors' are computed,
    /// each exactly as [`Self::dots`] computes it (the same chunks, summed in the same
    /// order), so the result equals `self.dots(block)` bit for bit.
    pub(super) fn extend_dots(&self, old: &[f64], known: usize, block: &[Vec<f32>]) -> Vec<f64> {
        let (r, n) = (self.len(), block.len());
        if known == 0 || known >= r {
            return if known == r {
                old[..n * r].to_vec()
            } else {
                self.dots(block)
            };
        }
        let new = self.dots_with(block, known..r);
        old.chunks_exact(known)
            .zip(new.chunks_exact(r - known))
            .take(n)
            .flat_map(|(a, b)| a.iter().chain(b).copied())
            .collect()
    }

    /// Each frame of `block` dotted with vectors `vectors`: `block.len() × vectors.len()`,
    /// frame-major.
    fn dots_with(&self, block: &[Vec<f32>], vectors: Range<usize>) -> Vec<f64> {
        let (r, n) = (vectors.len(), block.len());
        let Some(m) = block.first().map(Vec::len) else {
            return Vec::new();
        };
        let partial: Vec<Vec<f64>> = (0..m.div_ceil(CHUNK))
            .into_par_iter()
            .map_init(Vec::new, |scratch, c| {
                self.chunk_f32_of(c, m, vectors.clone(), scratch);
                let range = chunk(c, m);
                let len = range.len();
                let mut out = vec![0.0; n * r];
                let frames: Vec<&[f32]> = block.iter().map(|d| &d[range.clone()]).collect();
                for i in 0..r {
                    let v = &scratch[i * len..(i + 1) * len];
                    let mut quads = frames.chunks_exact(4);
                    for (q, four) in quads.by_ref().enumerate() {
                        let got = dot_many(v, [four[0], four[1], four[2], four[3]]);
                        for (j, x) in got.into_iter().enumerate() {
                            out[(4 * q + j) * r + i] = x;
                        }
                    }
                    let done = n - quads.remainder().len();
                    for (j, d) in quads.remainder().iter().enumerate() {
                        out[(done + j) * r + i] = dot(v, d);
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
        sums
    }

    /// The stored (`f32`) least-squares weights on the first `r` vectors of a frame whose
    /// dot products with every vector are `dots`.
    pub(super) fn weights(&self, dots: &[f64], r: usize) -> Vec<f32> {
        self.solve(&dots[..r])
            .into_iter()
            .map(|w| {
                #[expect(clippy::cast_possible_truncation, reason = "stored as f32")]
                let w = w as f32;
                w
            })
            .collect()
    }

    /// Each frame of `block`'s error (grid steps) with `weights` (one list per frame, on the
    /// first vectors), evaluated in `f32`.
    pub(super) fn errors(&self, block: &[Vec<f32>], weights: &[Vec<f32>]) -> Vec<f64> {
        let Some(m) = block.first().map(Vec::len) else {
            return Vec::new();
        };
        let r = weights.iter().map(Vec::len).max().unwrap_or(0);
        let per_chunk: Vec<Vec<f64>> = (0..m.div_ceil(CHUNK))
            .into_par_iter()
            .map_init(
                || (Vec::new(), vec![0.0f32; CHUNK]),
                |(scratch, buffer), c| {
                    self.chunk_f32(c, m, r, scratch);
                    let range = chunk(c, m);
                    let len = range.len();
                    let buffer = &mut buffer[..len];
                    block
                        .iter()
                        .zip(weights)
                        .map(|(d, w)| {
                            subtract_all(buffer, &d[range.clone()], &scratch[..w.len() * len], w);
                            max_vertex_length(buffer)
                        })
                        .collect()
                },
            )
            .collect();
        (0..block.len())
            .map(|f| per_chunk.iter().map(|e| e[f]).fold(0.0, f64::max))
            .collect()
    }

    /// `d − Σ w_i v_i` (on the first `w.len()` vectors), as [`Self::errors`] measures it.
    pub(super) fn residual(&self, d: &[f32], w: &[f32]) -> Vec<f32> {
        let m = d.len();
        let mut out = d.to_vec();
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each_init(Vec::new, |scratch, (c, out)| {
                self.chunk_f32(c, m, w.len(), scratch);
                let len = out.len();
                for (i, &wi) in w.iter().enumerate() {
                    subtract_scaled(out, &scratch[i * len..(i + 1) * len], wi);
                }
            });
        out
    }

    /// Adds `vector` × `scale` (at most the scale that fills the `SHORT` range), rounded;
    /// `false` (nothing added) when it is zero, not finite or (numerically) in the span of the
    /// basis. A small scale keeps small integers (they compress well) where the vector's
    /// rounding costs little.
    pub(super) fn add(&mut self, vector: &[f32], scale: f32) -> bool {
        let largest = vector.iter().fold(0.0f32, |a, x| a.max(x.abs()));
        if !(largest > 0.0 && largest.is_finite()) {
            return false;
        }
        let scale = if scale > 0.0 && scale.is_finite() {
            scale.min(VECTOR_RANGE / largest)
        } else {
            VECTOR_RANGE / largest
        };
        #[expect(clippy::cast_possible_truncation, reason = "rounded within ±32767")]
        let v: Vec<i16> = vector
            .par_iter()
            .map(|x| (x * scale).round().clamp(-VECTOR_RANGE, VECTOR_RANGE) as i16)
            .collect();
        let m = v.len();
        // Exact integer dot products (|products| ≤ 2^30, sums below 2^53).
        let exact = |a: &[i16], b: &[i16]| -> f64 {
            (0..m.div_ceil(CHUNK))
                .into_par_iter()
                .map(|c| {
                    let range = chunk(c, m);
                    a[range.clone()]
                        .iter()
                        .zip(&b[range])
                        .map(|(x, y)| f64::from(i32::from(*x) * i32::from(*y)))
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

    /// The least-squares weights of dot products `c` (`B^T d`) on the first `c.len()` vectors:
    /// `(B^T B)^{-1} c` through the leading block of the Cholesky factor.
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

    /// The tiled kernels give the same bits as the one-at-a-time loops they replace (lengths
    /// with and without a partial slab, lane remainder and chunk tail).
    #[test]
    fn tiled_kernels_match_the_plain_loops_bit_for_bit() {
        let value =
            |seed: usize, j: usize| ((j * 7919 + seed * 104_729) % 1013) as f32 / 37.0 - 13.0;
        for len in [5, 8, 37, 64, 1536, 3000] {
            let a: Vec<f32> = (0..len).map(|j| value(1, j)).collect();
            let b: Vec<Vec<f32>> = (0..4)
                .map(|q| (0..len).map(|j| value(q + 2, j) * 1e-3).collect())
                .collect();
            let refs = [&b[0][..], &b[1][..], &b[2][..], &b[3][..]];
            let many = dot_many(&a, refs);
            let chunked = chunked_dots4(&a, refs);
            for q in 0..4 {
                assert_eq!(many[q].to_bits(), dot(&a, &b[q]).to_bits(), "dot {len} {q}");
                assert_eq!(
                    chunked[q].to_bits(),
                    chunked_dot(&a, &b[q]).to_bits(),
                    "chunked {len} {q}"
                );
            }
            let w = [0.7f32, -1.3, 2.9e-3, 11.0];
            let flat: Vec<f32> = b.concat();
            let mut plain = a.clone();
            for (i, &wi) in w.iter().enumerate() {
                subtract_scaled(&mut plain, &b[i], wi);
            }
            let mut tiled = vec![0.0; len];
            subtract_all(&mut tiled, &a, &flat, &w);
            assert_eq!(
                plain.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                tiled.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                "subtract {len}"
            );
            let mut plain = a.clone();
            for (x, &wi) in b.iter().zip(&w) {
                for (o, x) in plain.iter_mut().zip(x) {
                    *o += wi * x;
                }
            }
            let mut tiled = a.clone();
            add_scaled_all(
                &mut tiled,
                b.iter().zip(&w).map(|(x, &wi)| (x.as_slice(), wi)),
            );
            assert_eq!(
                plain.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                tiled.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                "add {len}"
            );
        }
    }

    /// The dot products extended by a new vector's (the check's incremental rule) equal the
    /// plain recomputation over every vector bit for bit, for frames dropped from the front
    /// of the block too; and the one-root largest vertex length equals the largest root.
    #[test]
    fn extended_dots_equal_the_plain_recomputation() {
        let value = |seed: usize, j: usize| {
            ((j * 7919 + seed * 104_729) % 2003) as f32 / 61.0 - 16.0 + (j % 7) as f32 * 1e-3
        };
        // Lengths below, at and across chunks, with quads and a remainder of frames.
        for (m, n) in [(3 * 11, 3), (CHUNK, 5), (2 * CHUNK + 3 * 37, 9)] {
            let block: Vec<Vec<f32>> = (0..n)
                .map(|f| (0..m).map(|j| value(f + 10, j)).collect())
                .collect();
            let mut basis = Basis::default();
            for i in 0..3 {
                let v: Vec<f32> = (0..m).map(|j| value(i + 1, j)).collect();
                assert!(basis.add(&v, 1.0));
            }
            let old = basis.dots(&block);
            for dropped in [0, 1, n - 1] {
                let mut grown = Basis {
                    vectors: basis.vectors.clone(),
                    cholesky: basis.cholesky.clone(),
                };
                let extra: Vec<f32> = (0..m).map(|j| value(dropped + 40, j) * 0.5).collect();
                assert!(grown.add(&extra, 1.0));
                let rest = &block[dropped..];
                let extended = grown.extend_dots(&old[dropped * 3..], 3, rest);
                let plain = grown.dots(rest);
                assert_eq!(
                    extended.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    plain.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    "m {m}, n {n}, dropped {dropped}"
                );
                assert_eq!(grown.extend_dots(&plain, 4, rest), plain, "nothing new");
            }
            for f in &block {
                let roots = f
                    .chunks_exact(3)
                    .map(|v| {
                        let (x, y, z) = (f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
                        (x * x + y * y + z * z).sqrt()
                    })
                    .fold(0.0, f64::max);
                assert_eq!(max_vertex_length(f).to_bits(), roots.to_bits());
            }
        }
    }

    /// The normal equations solved through the factor reproduce a known combination, on all
    /// the vectors and on a leading subset.
    #[test]
    fn weights_recover_a_known_combination() {
        let mut basis = Basis::default();
        let m = 3 * 700;
        let a: Vec<f32> = (0..m).map(|j| ((j * 7919) % 201) as f32 - 100.0).collect();
        let b: Vec<f32> = (0..m).map(|j| ((j * 104_729) % 97) as f32 - 48.0).collect();
        assert!(basis.add(&a, f32::INFINITY));
        assert!(basis.add(&b, 4.0));
        assert!(
            !basis.add(&a, f32::INFINITY),
            "a dependent vector is refused"
        );
        assert!(!basis.add(&vec![0.0; m], 1.0), "a zero vector is refused");
        let stored = basis.stored(2);
        let flat = |i: usize| -> Vec<f32> {
            stored[i]
                .iter()
                .flat_map(|v| v.map(f32::from))
                .collect::<Vec<_>>()
        };
        let (va, vb) = (flat(0), flat(1));
        assert_eq!(va.iter().fold(0.0f32, |a, x| a.max(x.abs())), 32767.0);
        assert!(vb.iter().zip(&b).all(|(x, y)| *x == 4.0 * y), "scaled by 4");
        let d: Vec<f32> = va
            .iter()
            .zip(&vb)
            .map(|(x, y)| 0.25 * x - 0.5 * y)
            .collect();
        let block = [d.clone()];
        let dots = basis.dots(&block);
        let w = basis.weights(&dots, 2);
        assert!(
            (w[0] - 0.25).abs() < 1e-6 && (w[1] + 0.5).abs() < 1e-6,
            "{w:?}"
        );
        let error = basis.errors(&block, &[w])[0];
        assert!(error < 1e-3, "{error}");
        // On the first vector alone: the least-squares fit, and the residual it leaves.
        let w1 = basis.weights(&dots, 1);
        let expected = chunked_dot(&va, &d) / chunked_dot(&va, &va);
        assert!((f64::from(w1[0]) - expected).abs() < 1e-6, "{w1:?}");
        let residual: Vec<f32> = d.iter().zip(&va).map(|(x, v)| x - w1[0] * v).collect();
        let error1 = basis.errors(&block, &[w1])[0];
        assert!((error1 - max_vertex_length(&residual)).abs() < 1e-3);
    }
}
