//! Dense layers on a batch of rows: the forward `y = x W + b` (with `W` stored transposed,
//! input-major, so each input adds one contiguous row: an `axpy` the compiler vectorises) and
//! its backward (weight gradients as `axpy` again, input gradients as 8-lane dot products).

use super::config::LayerSlot;
use super::real::{Real, axpy, dot};

/// `out[r] = b + Σ_i x[r][i] W[i]` for each of `rows` rows, then `max(·, 0)` when `relu`.
/// `x` is `rows × slot.inputs`, `out` `rows × slot.outputs`, both row-major.
pub fn forward<T: Real>(
    params: &[T],
    slot: &LayerSlot,
    x: &[T],
    rows: usize,
    relu: bool,
    out: &mut [T],
) {
    let (ni, no) = (slot.inputs, slot.outputs);
    let w = &params[slot.weights..slot.weights + ni * no];
    let b = &params[slot.biases..slot.biases + no];
    for r in 0..rows {
        let xr = &x[r * ni..(r + 1) * ni];
        let yr = &mut out[r * no..(r + 1) * no];
        yr.copy_from_slice(b);
        for (i, &xi) in xr.iter().enumerate() {
            if xi != T::ZERO {
                axpy(xi, &w[i * no..(i + 1) * no], yr);
            }
        }
        if relu {
            for v in yr.iter_mut() {
                if !positive(*v) {
                    *v = T::ZERO;
                }
            }
        }
    }
}

/// The backward of [`forward`] (without its `relu`: `d_out` is already the gradient of the
/// pre-activation). Adds `xᵀ d_out` into `grads`' weights and the column sums of `d_out` into its
/// biases (`grads` laid out as `params`); with `d_x`, writes `d_out Wᵀ` there, zeroed where
/// `mask` (the layer's input, a ReLU output) is not positive.
#[expect(clippy::too_many_arguments, reason = "one kernel, its buffers named")]
pub fn backward<T: Real>(
    params: &[T],
    slot: &LayerSlot,
    x: &[T],
    d_out: &[T],
    rows: usize,
    grads: &mut [T],
    d_x: Option<&mut [T]>,
    mask_by_input: bool,
) {
    let (ni, no) = (slot.inputs, slot.outputs);
    {
        let (gw, gb) = grads[slot.weights..slot.biases + no].split_at_mut(ni * no);
        for r in 0..rows {
            let xr = &x[r * ni..(r + 1) * ni];
            let dr = &d_out[r * no..(r + 1) * no];
            for (b, &d) in gb.iter_mut().zip(dr) {
                *b += d;
            }
            for (i, &xi) in xr.iter().enumerate() {
                if xi != T::ZERO {
                    axpy(xi, dr, &mut gw[i * no..(i + 1) * no]);
                }
            }
        }
    }
    if let Some(d_x) = d_x {
        let w = &params[slot.weights..slot.weights + ni * no];
        for r in 0..rows {
            let xr = &x[r * ni..(r + 1) * ni];
            let dr = &d_out[r * no..(r + 1) * no];
            let gx = &mut d_x[r * ni..(r + 1) * ni];
            for i in 0..ni {
                gx[i] = if mask_by_input && !positive(xr[i]) {
                    T::ZERO
                } else {
                    dot(&w[i * no..(i + 1) * no], dr)
                };
            }
        }
    }
}

/// `v > 0` (false for NaN): the ReLU's pass-through test.
#[inline]
fn positive<T: Real>(v: T) -> bool {
    v > T::ZERO
}
