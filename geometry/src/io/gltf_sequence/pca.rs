//! The principal morph basis of one run of frames of one topology, in three streaming passes
//! over its frames (module `basis` holds the stored form and its evaluation):
//!
//! 1. **Sketch.** Frame `k`'s offsets from the run's base on the basis grid (`d_k`, grid steps)
//!    are kept at every `s`-th vertex only (at most [`SKETCH_VERTICES`] vertices, `f32`;
//!    from the positions the survey kept of those vertices when it has them, so this pass
//!    does not read the frames again), and
//!    their frames × frames Gram matrix is formed (`f64` across chunks). Its leading
//!    eigenpairs (`eigen`) give the principal directions in frame space, `y_i` with
//!    eigenvalue `λ_i`. The smallest rank that puts every sketched vertex of every frame within
//!    [`SKETCH_SHARE`] of the tolerance (residuals of the projections on the sketch's
//!    principal vectors, added one at a time) estimates the rank needed, `r₀`.
//! 2. **Vectors.** The first `R = min(r₀ + r₀ / 2 + 4, limit)` principal vectors in full,
//!    `u_i = Σ_k y_ik d_k / sqrt(λ_i)`, accumulated as the frames stream (blocks of frames,
//!    chunks of coordinates in parallel), then each scaled to the `SHORT` range and rounded:
//!    the vectors as stored.
//! 3. **Check.** Every frame's least-squares weights on the first `r` stored vectors (`f32`;
//!    after a residual vector is added, only its dot products with the block's frames are
//!    computed, the others kept)
//!    and its largest vertex error as stored, for a few candidate ranks `r₀ ≤ r ≤ R`; the
//!    smallest rank at which every frame is within the tolerance is kept (a candidate is
//!    dropped at its first frame over it). None: the run keeps one target per frame.
//!
//! Memory: the survey's kept positions (`frames × 4096` `f64` points, 96 MB for 973 frames,
//! freed frame by frame as the sketch is formed), the sketch (`frames × 3 × 4096` `f32`,
//! 48 MB for 973 frames), the Gram matrix
//! (`frames²` `f64`, 7.6 MB), a block of frames' offsets, and the `R` vectors (`f32` while
//! accumulated, then `i16`). Every sum is formed in fixed chunks and then in order, so the
//! basis does not depend on the number of threads.

use std::ops::Range;
use std::path::Path;

use glam::DVec3;
use rayon::prelude::*;

use super::basis::{
    Basis, BasisFit, BasisLimits, CHUNK, add_scaled_all, chunk, chunked_dot, chunked_dots4,
    max_vertex_length, offsets, sampled_offsets,
};
use super::eigen::{Eigenpair, leading};
use super::quantize::Grid;
use super::source::FrameSource;
use crate::io::error::IoError;

/// The most vertices of a frame kept in the sketch.
const SKETCH_VERTICES: usize = 4096;

/// The sketch's rank estimate asks its vertices to be within this share of the tolerance (the
/// full frames have more vertices, and a larger largest error).
const SKETCH_SHARE: f64 = 0.8;

/// Principal directions sought beyond the most vectors allowed (the subspace iteration's
/// oversampling).
const OVERSAMPLING: usize = 12;

/// A vector is stored in 1/`UNITS` grid steps at its largest weight in the run (capped to
/// the `SHORT` range): its rounding then moves a vertex by at most `0.87 / UNITS` steps, and
/// the vectors of small components are small integers, which compress well.
const UNITS: f64 = 16.0;

/// The most frames whose full offsets are held at once.
const BLOCK: usize = 16;

/// The sketch keeps every `sketch_stride(vertices)`-th vertex of a frame of `vertices`.
pub(super) fn sketch_stride(vertices: usize) -> usize {
    vertices.div_ceil(SKETCH_VERTICES).max(1)
}

/// Fits a principal basis to frames `run` of `frames`, whose base (the run's first frame) is
/// `base` on `grid`; `None` when it does not meet `limits` (the caller keeps one target per
/// frame). `sampled` is every frame's positions at every [`sketch_stride`]-th vertex when the
/// survey kept them (one per frame of the run), else empty (the frames are read for the
/// sketch): the same basis either way.
///
/// # Errors
/// The source's errors; a frame whose vertex count differs from the base's.
pub(super) fn fit(
    path: &Path,
    frames: &dyn FrameSource,
    run: Range<usize>,
    grid: &Grid,
    base: &[[i16; 3]],
    sampled: Vec<Vec<DVec3>>,
    limits: BasisLimits,
) -> Result<Option<BasisFit>, IoError> {
    let n = run.len();
    if n == 0 || base.is_empty() || limits.max_vectors == 0 {
        return Ok(None);
    }
    let stride = sketch_stride(base.len());
    let sketch = if sampled.len() == n {
        sampled
            .into_iter()
            .zip(run.clone())
            .map(|(p, k)| sampled_offsets(path, k, &p, grid, base, stride))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        run.clone()
            .map(|k| offsets(path, frames, k, grid, base, stride))
            .collect::<Result<Vec<_>, _>>()?
    };
    let gram = gram(&sketch);
    let pairs = leading(&gram, n, (limits.max_vectors + OVERSAMPLING).min(n));
    let Some(needed) = sketch_rank(&sketch, &gram, &pairs, SKETCH_SHARE * limits.tolerance) else {
        return Ok(None);
    };
    drop(sketch);
    // At least one vector: a glTF mesh's `targets` may not be empty.
    let needed = needed.max(1);
    let most = limits.max_vectors.min(pairs.len());
    if needed > most {
        return Ok(None);
    }
    let built = (needed + needed / 4 + 4).min(most);
    let basis = vectors(path, frames, run.clone(), grid, base, &pairs[..built])?;
    if basis.len() < needed {
        return Ok(None);
    }
    let candidates = [needed, needed.midpoint(basis.len())];
    let Some((basis, (rank, weights, errors))) =
        check(path, frames, run, grid, base, basis, &candidates, limits)?
    else {
        return Ok(None);
    };
    Ok(Some(BasisFit {
        vectors: basis.stored(rank),
        weights: weights.concat(),
        errors,
    }))
}

/// The frames × frames Gram matrix of the sketch (row-major, symmetric).
fn gram(sketch: &[Vec<f32>]) -> Vec<f64> {
    let n = sketch.len();
    let rows: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut row = Vec::with_capacity(i + 1);
            let mut j = 0;
            while j + 4 <= i + 1 {
                let four = [j, j + 1, j + 2, j + 3].map(|j| sketch[j].as_slice());
                row.extend(chunked_dots4(&sketch[i], four));
                j += 4;
            }
            row.extend((j..=i).map(|j| chunked_dot(&sketch[i], &sketch[j])));
            row
        })
        .collect();
    let mut g = vec![0.0; n * n];
    for (i, row) in rows.iter().enumerate() {
        for (j, &x) in row.iter().enumerate() {
            g[i * n + j] = x;
            g[j * n + i] = x;
        }
    }
    g
}

/// The smallest rank whose principal projection puts every sketched vertex of every frame
/// within `target` (grid steps); `None` when all of `pairs` do not.
fn sketch_rank(
    sketch: &[Vec<f32>],
    gram: &[f64],
    pairs: &[Eigenpair],
    target: f64,
) -> Option<usize> {
    let n = sketch.len();
    let m = sketch.first().map_or(0, Vec::len);
    // The sketch's principal vectors z_i = S y_i / sqrt(λ_i) (orthonormal), and each frame's
    // coefficient on them, z_i · s_k = (G y_i)_k / sqrt(λ_i).
    let z: Vec<Vec<f32>> = pairs
        .par_iter()
        .map(|pair| {
            let scale = 1.0 / pair.value.sqrt();
            let mut out = vec![0.0f64; m];
            for (row, &y) in sketch.iter().zip(&pair.vector) {
                let c = y * scale;
                for (o, &x) in out.iter_mut().zip(row) {
                    *o += c * f64::from(x);
                }
            }
            #[expect(clippy::cast_possible_truncation, reason = "f32 vectors")]
            out.into_iter().map(|x| x as f32).collect()
        })
        .collect();
    let coefficients: Vec<Vec<f64>> = pairs
        .par_iter()
        .map(|pair| {
            let scale = 1.0 / pair.value.sqrt();
            (0..n)
                .map(|k| {
                    let row = &gram[k * n..(k + 1) * n];
                    row.iter()
                        .zip(&pair.vector)
                        .map(|(g, y)| g * y)
                        .sum::<f64>()
                        * scale
                })
                .collect()
        })
        .collect();
    let ranks: Vec<Option<usize>> = sketch
        .par_iter()
        .enumerate()
        .map(|(k, row)| {
            let mut residual = row.clone();
            if max_vertex_length(&residual) <= target {
                return Some(0);
            }
            for (i, zi) in z.iter().enumerate() {
                #[expect(clippy::cast_possible_truncation, reason = "f32 residuals")]
                let c = coefficients[i][k] as f32;
                for (r, x) in residual.iter_mut().zip(zi) {
                    *r -= c * x;
                }
                if max_vertex_length(&residual) <= target {
                    return Some(i + 1);
                }
            }
            None
        })
        .collect();
    ranks.into_iter().try_fold(0, |a, r| r.map(|r| a.max(r)))
}

/// The stored basis of the principal directions `pairs`: `u_i = Σ_k y_ik d_k / sqrt(λ_i)`
/// over frames `run`, accumulated block by block; a vector that would be (numerically) in the
/// span of those before it ends the basis.
fn vectors(
    path: &Path,
    frames: &dyn FrameSource,
    run: Range<usize>,
    grid: &Grid,
    base: &[[i16; 3]],
    pairs: &[Eigenpair],
) -> Result<Basis, IoError> {
    let r = pairs.len();
    let m = 3 * base.len();
    let scales: Vec<f64> = pairs.iter().map(|p| 1.0 / p.value.sqrt()).collect();
    // Frame k holds about sqrt(λ_i) y_ik of u_i: stored at its largest, in 1/UNITS steps.
    #[expect(clippy::cast_possible_truncation, reason = "a scale")]
    let stored_scales: Vec<f32> = pairs
        .iter()
        .map(|p| {
            let largest = p.vector.iter().fold(0.0f64, |a, y| a.max(y.abs()));
            (UNITS * p.value.sqrt() * largest) as f32
        })
        .collect();
    // Chunk-major: chunk c of every vector together (r × its length), so that a block of
    // frames updates one chunk of every vector while it is in cache.
    let mut acc = vec![0.0f32; r * m];
    let mut next = run.start;
    while next < run.end {
        let end = (next + BLOCK).min(run.end);
        let block = (next..end)
            .map(|k| offsets(path, frames, k, grid, base, 1))
            .collect::<Result<Vec<_>, _>>()?;
        let coefficients: Vec<Vec<f32>> = (0..r)
            .map(|i| {
                (next..end)
                    .map(|k| {
                        #[expect(clippy::cast_possible_truncation, reason = "f32 coefficients")]
                        let c = (pairs[i].vector[k - run.start] * scales[i]) as f32;
                        c
                    })
                    .collect()
            })
            .collect();
        acc.par_chunks_mut(r * CHUNK)
            .enumerate()
            .for_each(|(c, slab)| {
                let range = chunk(c, m);
                let len = range.len();
                for (i, out) in slab.chunks_exact_mut(len).enumerate() {
                    let terms = block
                        .iter()
                        .zip(&coefficients[i])
                        .map(|(d, &w)| (&d[range.clone()], w));
                    add_scaled_all(out, terms);
                }
            });
        next = end;
    }
    let mut basis = Basis::default();
    let mut vector = vec![0.0f32; m];
    for (i, &scale) in stored_scales.iter().enumerate() {
        for c in 0..m.div_ceil(CHUNK) {
            let range = chunk(c, m);
            let len = range.len();
            let from = c * r * CHUNK + i * len;
            vector[range].copy_from_slice(&acc[from..from + len]);
        }
        if !basis.add(&vector, scale) {
            break;
        }
    }
    Ok(basis)
}

/// A rank that holds every frame, its frames' weights (as stored) and errors (grid steps).
type Checked = (usize, Vec<Vec<f32>>, Vec<f64>);

/// The smallest of `candidates` (ascending ranks below `basis.len()`) at which every frame of
/// `run`, weighted by least squares on that many vectors of `basis` as stored, is within
/// `tolerance`; else the whole basis, where a frame over the tolerance adds its residual as a
/// vector (up to `max_vectors`; earlier frames weigh it 0, which leaves them as they were).
/// Returns the basis with what was checked.
#[expect(
    clippy::too_many_arguments,
    reason = "the run, its grid and what to check"
)]
fn check(
    path: &Path,
    frames: &dyn FrameSource,
    run: Range<usize>,
    grid: &Grid,
    base: &[[i16; 3]],
    mut basis: Basis,
    candidates: &[usize],
    limits: BasisLimits,
) -> Result<Option<(Basis, Checked)>, IoError> {
    let tolerance = limits.tolerance;
    let within = |e: &f64| e.is_finite() && *e <= tolerance;
    let mut smaller: Vec<Checked> = candidates
        .iter()
        .filter(|&&r| r < basis.len())
        .map(|&r| {
            (
                r,
                Vec::with_capacity(run.len()),
                Vec::with_capacity(run.len()),
            )
        })
        .collect();
    let mut whole: Option<Checked> = Some((0, Vec::new(), Vec::new()));
    let mut next = run.start;
    while next < run.end && (whole.is_some() || !smaller.is_empty()) {
        let end = (next + BLOCK).min(run.end);
        let mut block = (next..end)
            .map(|k| offsets(path, frames, k, grid, base, 1))
            .collect::<Result<Vec<_>, _>>()?;
        let mut first = true;
        let mut dots = basis.dots(&block);
        while !block.is_empty() {
            let r_all = basis.len();
            if first {
                for (rank, weights, errors) in &mut smaller {
                    let w: Vec<Vec<f32>> = dots
                        .chunks_exact(r_all)
                        .map(|d| basis.weights(d, *rank))
                        .collect();
                    errors.extend(basis.errors(&block, &w));
                    weights.extend(w);
                }
                smaller.retain(|(_, _, errors)| errors.iter().all(within));
                first = false;
            }
            let Some((_, weights, errors)) = whole.as_mut() else {
                break;
            };
            let w: Vec<Vec<f32>> = dots
                .chunks_exact(r_all)
                .map(|d| basis.weights(d, r_all))
                .collect();
            let e = basis.errors(&block, &w);
            let passed = e.iter().position(|x| !within(x)).unwrap_or(e.len());
            weights.extend_from_slice(&w[..passed]);
            errors.extend_from_slice(&e[..passed]);
            if passed == block.len() {
                break;
            }
            let residual = basis.residual(&block[passed], &w[passed]);
            #[expect(clippy::cast_possible_truncation, reason = "a scale")]
            let added = basis.len() < limits.max_vectors && basis.add(&residual, UNITS as f32);
            if !added {
                whole = None;
                break;
            }
            // The failing frame is evaluated again with its residual in the basis; the dot
            // products with the vectors before it stay, only the new vector's are computed.
            block.drain(..passed);
            dots = basis.extend_dots(&dots[passed * r_all..], r_all, &block);
        }
        next = end;
    }
    if let Some(best) = smaller.into_iter().next() {
        return Ok(Some((basis, best)));
    }
    Ok(whole.map(|(_, mut weights, errors)| {
        let r = basis.len();
        for w in &mut weights {
            w.resize(r, 0.0);
        }
        (basis, (r, weights, errors))
    }))
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::mesh::TriMesh;
    use crate::rng::Rng;

    /// A 40 × 40 grid of vertices (2 triangles, enough for a mesh) moved by `shapes` with
    /// per-frame weights from `weight(k, i)`, and a little noise of amplitude `noise`.
    fn frames(
        n: usize,
        shapes: usize,
        noise: f64,
        weight: impl Fn(usize, usize) -> f64,
    ) -> Vec<TriMesh> {
        let side = 40;
        let rest: Vec<DVec3> = (0..side * side)
            .map(|v| {
                DVec3::new(
                    (v % side) as f64 / side as f64,
                    (v / side) as f64 / side as f64,
                    0.0,
                )
            })
            .collect();
        let shape = |i: usize, p: DVec3| -> DVec3 {
            let f = (i + 1) as f64;
            DVec3::new(
                (f * 2.1 * p.y).sin(),
                (f * 1.3 * p.x + 0.4).cos(),
                (f * p.x * p.y * 3.0).sin(),
            ) * 0.05
        };
        let mut rng = Rng::new(3);
        (0..n)
            .map(|k| {
                let p = rest
                    .iter()
                    .map(|&p| {
                        let mut q = p;
                        for i in 0..shapes {
                            q += weight(k, i) * shape(i, p);
                        }
                        q + noise
                            * DVec3::new(
                                rng.uniform_f64() - 0.5,
                                rng.uniform_f64() - 0.5,
                                rng.uniform_f64() - 0.5,
                            )
                    })
                    .collect();
                TriMesh::new(p, vec![[0, 1, 2], [1, 3, 2]])
            })
            .collect()
    }

    /// The run's basis grid, its base, and the tolerance (grid steps) for `share` of the
    /// smallest frame diagonal, as the writer sets them up.
    fn setup(frames: &[TriMesh], share: f64) -> (Grid, Vec<[i16; 3]>, f64) {
        let mut lo = DVec3::INFINITY;
        let mut hi = DVec3::NEG_INFINITY;
        let mut smallest = f64::INFINITY;
        for f in frames {
            let (a, b) = f
                .positions()
                .iter()
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(a, b), p| {
                    (a.min(*p), b.max(*p))
                });
            smallest = smallest.min((b - a).length());
            (lo, hi) = (lo.min(a), hi.max(b));
        }
        let grid = Grid::for_basis((lo, hi), (hi - lo).length());
        let base = grid
            .quantize(Path::new("t.glb"), 0, frames[0].positions())
            .expect("base");
        (grid, base, share * smallest / grid.step())
    }

    fn run_fit(frames: &[TriMesh], share: f64, max_vectors: usize) -> Option<BasisFit> {
        let (grid, base, tolerance) = setup(frames, share);
        let limits = BasisLimits {
            tolerance,
            max_vectors,
        };
        fit(
            Path::new("t.glb"),
            &frames,
            0..frames.len(),
            &grid,
            &base,
            Vec::new(),
            limits,
        )
        .expect("fit")
    }

    /// Every frame evaluated independently from the stored vectors and weights (`f64`), in
    /// grid steps: the largest vertex error.
    fn evaluated(frames: &[TriMesh], fit: &BasisFit) -> Vec<f64> {
        let (grid, base, _) = setup(frames, 1.0);
        let r = fit.vectors.len();
        frames
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let w = &fit.weights[k * r..(k + 1) * r];
                f.positions()
                    .iter()
                    .enumerate()
                    .map(|(v, p)| {
                        let mut q = DVec3::from(base[v].map(f64::from));
                        for (vector, &wi) in fit.vectors.iter().zip(w) {
                            q += f64::from(wi) * DVec3::from(vector[v].map(f64::from));
                        }
                        ((*p - grid.origin()) / grid.step() - q).length()
                    })
                    .fold(0.0, f64::max)
            })
            .collect()
    }

    #[test]
    fn a_few_shapes_need_a_few_vectors_and_every_frame_is_within_the_tolerance() {
        let frames = frames(30, 3, 1e-6, |k, i| ((k * (i + 2)) as f64 * 0.37).sin());
        let fit = run_fit(&frames, 8e-5, 20).expect("a basis");
        let r = fit.vectors.len();
        assert!((3..=5).contains(&r), "{r} vectors for 3 shapes");
        assert_eq!(fit.weights.len(), r * frames.len());
        let (_, _, tolerance) = setup(&frames, 8e-5);
        let independent = evaluated(&frames, &fit);
        for (k, (mine, theirs)) in fit.errors.iter().zip(&independent).enumerate() {
            assert!(*theirs <= tolerance, "frame {k}: {theirs} over {tolerance}");
            assert!(
                (mine - theirs).abs() < 1e-3,
                "frame {k}: {mine} vs {theirs}"
            );
        }
    }

    #[test]
    fn more_shapes_than_allowed_or_noise_keep_one_target_per_frame() {
        let many = frames(30, 8, 0.0, |k, i| ((k * (i + 2)) as f64 * 0.37).sin());
        assert!(
            run_fit(&many, 8e-5, 4).is_none(),
            "8 shapes, 4 vectors allowed"
        );
        assert!(run_fit(&many, 8e-5, 12).is_some(), "8 shapes, 12 allowed");
        let noise = frames(12, 0, 0.01, |_, _| 0.0);
        assert!(run_fit(&noise, 8e-5, 10).is_none(), "independent noise");
    }

    #[test]
    fn equal_frames_and_a_single_frame() {
        // Every frame the same: one vector (the base's rounding), or none at all needed.
        let same = frames(6, 1, 0.0, |_, _| 0.5);
        let equal = run_fit(&same, 8e-5, 4).expect("a basis");
        assert_eq!(equal.vectors.len(), 1);
        assert!(
            equal.errors.iter().all(|e| *e <= 0.87),
            "{:?}",
            equal.errors
        );
        let one = &same[..1];
        if let Some(single) = run_fit(one, 8e-5, 1) {
            assert_eq!(single.vectors.len(), 1);
            assert_eq!(single.errors.len(), 1);
        }
        // A frame exactly on the grid: nothing to fit, no basis (a mesh needs a target).
        let (grid, base, tolerance) = setup(&same, 8e-5);
        let on_grid: Vec<TriMesh> = (0..4)
            .map(|_| {
                let p = base
                    .iter()
                    .map(|q| grid.origin() + grid.step() * DVec3::from(q.map(f64::from)))
                    .collect();
                TriMesh::new(p, same[0].triangles().to_vec())
            })
            .collect();
        let limits = BasisLimits {
            tolerance,
            max_vectors: 2,
        };
        let path = Path::new("t.glb");
        let got = fit(
            path,
            &on_grid.as_slice(),
            0..4,
            &grid,
            &base,
            Vec::new(),
            limits,
        )
        .expect("fit");
        if let Some(got) = got {
            // Only rounding noise to fit: whatever it holds is within the tolerance.
            assert!(got.errors.iter().all(|e| *e <= 1e-3), "{:?}", got.errors);
        }
    }

    /// The sketch from the survey's positions (every sketched vertex kept when the frames
    /// were first read) gives the same basis, bit for bit, as the frames read again; a
    /// sampled frame of another length is an error naming the frame.
    #[test]
    fn the_surveyed_sketch_gives_the_same_basis_as_reading_the_frames() {
        let frames = frames(20, 3, 1e-5, |k, i| ((k * (i + 2)) as f64 * 0.41).sin());
        let (grid, base, tolerance) = setup(&frames, 8e-5);
        let limits = BasisLimits {
            tolerance,
            max_vectors: 10,
        };
        let path = Path::new("t.glb");
        // The fixture has 1,600 vertices, so force a stride above 1 through a larger mesh too.
        for frames in [frames.clone(), widened(&frames, 3)] {
            let (grid, base) = if frames[0].vertex_count() == base.len() {
                (grid, base.clone())
            } else {
                let (g, b, _) = setup(&frames, 8e-5);
                (g, b)
            };
            let stride = sketch_stride(base.len());
            let sampled: Vec<Vec<DVec3>> = frames
                .iter()
                .map(|f| f.positions().iter().step_by(stride).copied().collect())
                .collect();
            let n = frames.len();
            let read = fit(
                path,
                &frames.as_slice(),
                0..n,
                &grid,
                &base,
                Vec::new(),
                limits,
            )
            .expect("fit")
            .expect("a basis");
            let kept = fit(
                path,
                &frames.as_slice(),
                0..n,
                &grid,
                &base,
                sampled,
                limits,
            )
            .expect("fit")
            .expect("a basis");
            assert_eq!(read.vectors, kept.vectors, "stride {stride}");
            assert_eq!(read.weights, kept.weights);
            assert_eq!(read.errors, kept.errors);
        }
        let mut short: Vec<Vec<DVec3>> = frames.iter().map(|f| f.positions().to_vec()).collect();
        short[7].pop();
        let n = frames.len();
        let err = fit(path, &frames.as_slice(), 0..n, &grid, &base, short, limits)
            .err()
            .expect("a short sketch is refused");
        assert!(err.to_string().contains("frame 7"), "{err}");
    }

    /// `frames` with every vertex repeated `times` times (slightly moved), so that the sketch
    /// keeps every few vertices only.
    fn widened(frames: &[TriMesh], times: usize) -> Vec<TriMesh> {
        frames
            .iter()
            .map(|f| {
                let p: Vec<DVec3> = (0..times)
                    .flat_map(|t| {
                        f.positions()
                            .iter()
                            .map(move |&p| p + DVec3::splat(1e-3 * t as f64))
                    })
                    .collect();
                TriMesh::new(p, f.triangles().to_vec())
            })
            .collect()
    }

    #[test]
    fn the_basis_does_not_depend_on_the_number_of_threads() {
        let frames = frames(24, 4, 1e-5, |k, i| ((k * (i + 1)) as f64 * 0.53).cos());
        let with = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            pool.install(|| run_fit(&frames, 8e-5, 12).expect("a basis"))
        };
        let (a, b) = (with(1), with(3));
        assert_eq!(a.vectors, b.vectors);
        assert_eq!(a.weights, b.weights);
        assert_eq!(a.errors, b.errors);
    }
}
