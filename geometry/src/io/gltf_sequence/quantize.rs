//! The grid of `KHR_mesh_quantization`: positions as integer steps from a segment's centre, the
//! step a fixed fraction of the whole sequence's bounding-box diagonal; normals as normalised
//! bytes.

use std::path::Path;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::io::error::IoError;

/// Grid steps per bounding-box diagonal of the sequence (2^14). A vertex lies within half a
/// step of its true place on each axis, so within `sqrt(3) / 2 / 16384 = 5.3e-5` of the
/// diagonal; the bound is `1e-4`. A segment's box is at most one diagonal across, so
/// its steps from its centre stay within ±8193, and the difference of two frames (a morph
/// delta) within ±16386: both fit `SHORT`.
pub const POSITION_STEPS_PER_DIAGONAL: f64 = 16384.0;

/// The largest |step count| a position may have, so that deltas fit `SHORT` too.
const MAX_STEPS: f64 = 16383.0;

/// Grid steps per bounding-box diagonal of the base of a run stored as a morph basis: the base
/// is its only position data (the basis vectors are scaled on their own), so it may use
/// nearly the whole `SHORT` range (a run's box is at most one diagonal across, so its steps
/// from the centre stay within ±30,001), and its rounding, at most
/// `sqrt(3) / 2 / 60000 = 1.4e-5` of the diagonal, leaves most of the tolerance to the basis.
pub(super) const BASIS_STEPS_PER_DIAGONAL: f64 = 60000.0;

/// The largest |step count| of a basis run's base (no deltas are taken of it).
const MAX_BASIS_STEPS: f64 = 32767.0;

/// One segment's grid: `position = origin + step × q` for integer `q`, `origin` and `step`
/// being exactly the `f32` values written to the node's `translation` and `scale`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Grid {
    origin: DVec3,
    step: f64,
    /// The largest |step count| a position may have.
    limit: f64,
}

impl Grid {
    /// The grid of a segment whose vertices lie in `bounds` (min, max), for a sequence whose
    /// bounding box has `diagonal`.
    pub(super) fn new(bounds: (DVec3, DVec3), diagonal: f64) -> Self {
        Self::with_steps(bounds, diagonal, POSITION_STEPS_PER_DIAGONAL, MAX_STEPS)
    }

    /// The finer grid of a run stored as a morph basis ([`BASIS_STEPS_PER_DIAGONAL`]).
    pub(super) fn for_basis(bounds: (DVec3, DVec3), diagonal: f64) -> Self {
        Self::with_steps(bounds, diagonal, BASIS_STEPS_PER_DIAGONAL, MAX_BASIS_STEPS)
    }

    fn with_steps(bounds: (DVec3, DVec3), diagonal: f64, steps: f64, limit: f64) -> Self {
        let step = if diagonal.is_finite() && diagonal > 0.0 {
            diagonal / steps
        } else {
            1.0
        };
        let centre = if bounds.0.cmple(bounds.1).all() {
            (bounds.0 + bounds.1) * 0.5
        } else {
            DVec3::ZERO
        };
        Self {
            origin: centre.as_vec3().as_dvec3(),
            step: f64::from(as_f32(step)),
            limit,
        }
    }

    /// The grid's origin (exactly the `f32` node translation).
    pub(super) fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The grid's step (exactly the `f32` node scale).
    pub(super) fn step(&self) -> f64 {
        self.step
    }

    /// The node `translation` that undoes the quantisation.
    pub(super) fn translation(&self) -> [f32; 3] {
        self.origin.as_vec3().to_array()
    }

    /// The node `scale` (uniform) that undoes the quantisation.
    pub(super) fn scale(&self) -> f32 {
        as_f32(self.step)
    }

    /// Frame `k`'s positions on the grid.
    ///
    /// # Errors
    /// A vertex outside the segment's box by more than the grid holds (the frame changed
    /// between the survey and now), named.
    pub(super) fn quantize(
        &self,
        path: &Path,
        k: usize,
        positions: &[DVec3],
    ) -> Result<Vec<[i16; 3]>, IoError> {
        let steps: Vec<Option<[i16; 3]>> = positions
            .par_iter()
            .map(|p| {
                let q = ((*p - self.origin) / self.step).round();
                if q.abs().max_element() <= self.limit {
                    #[expect(clippy::cast_possible_truncation, reason = "checked to fit")]
                    Some([q.x as i16, q.y as i16, q.z as i16])
                } else {
                    None
                }
            })
            .collect();
        steps
            .iter()
            .enumerate()
            .map(|(v, q)| {
                q.ok_or_else(|| {
                    IoError::malformed(
                        path,
                        format!("frame {k} vertex {v}"),
                        "lies outside its segment's quantisation grid \
                         (the frame changed while the sequence was written)",
                    )
                })
            })
            .collect()
    }
}

/// `b - a` per component (morph deltas on the grid; both within ±16383, so it fits).
pub(super) fn delta(a: &[[i16; 3]], b: &[[i16; 3]]) -> Vec<[i16; 3]> {
    a.iter()
        .zip(b)
        .map(|(a, b)| std::array::from_fn(|c| b[c] - a[c]))
        .collect()
}

/// Unit normals as normalised `BYTE`s: `round(127 x)`.
pub(super) fn normal_bytes(normals: &[Vec3]) -> Vec<[i8; 3]> {
    normals
        .iter()
        .map(|n| {
            #[expect(clippy::cast_possible_truncation, reason = "a unit component × 127")]
            n.to_array()
                .map(|x| (x * 127.0).round().clamp(-127.0, 127.0) as i8)
        })
        .collect()
}

/// Normal deltas as normalised `BYTE`s: the difference of the quantised normals, clamped to
/// ±127 (a component that changes by more than 1 from the segment's first frame, a turn of
/// over 60°, is cut to ±1; viewers normalise the morphed normal).
pub(super) fn normal_delta_bytes(base: &[[i8; 3]], frame: &[[i8; 3]]) -> Vec<[i8; 3]> {
    base.iter()
        .zip(frame)
        .map(|(a, b)| {
            std::array::from_fn(|c| {
                #[expect(clippy::cast_possible_truncation, reason = "clamped to i8")]
                let d = (i16::from(b[c]) - i16::from(a[c])).clamp(-127, 127) as i8;
                d
            })
        })
        .collect()
}

#[expect(clippy::cast_possible_truncation, reason = "glTF stores f32")]
fn as_f32(x: f64) -> f32 {
    x as f32
}
