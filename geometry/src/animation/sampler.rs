//! Keyframe samplers: LINEAR (quaternion slerp on the shortest path), STEP and CUBICSPLINE
//! (cubic Hermite with tangents scaled by the keyframe interval), as glTF 2.0 §3.11 and
//! Appendix C define them. Times before the first key give the first value, times after the
//! last key give the last value.

use glam::DQuat;

/// Below this `sin θ` (θ the angle between two unit quaternions) slerp's weights are 0/0:
/// the quaternions are equal to f64 precision and a normalised lerp is exact enough.
const SLERP_MIN_SIN: f64 = 1e-12;

/// How a sampler interpolates between keyframes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Interpolation {
    /// Linear; spherical linear for rotations.
    Linear,
    /// Constant until the next key.
    Step,
    /// Cubic Hermite spline with in/out tangents per key.
    CubicSpline,
}

impl From<gltf::animation::Interpolation> for Interpolation {
    fn from(value: gltf::animation::Interpolation) -> Self {
        match value {
            gltf::animation::Interpolation::Linear => Self::Linear,
            gltf::animation::Interpolation::Step => Self::Step,
            gltf::animation::Interpolation::CubicSpline => Self::CubicSpline,
        }
    }
}

/// A validated sampler: strictly increasing finite times and `width` values per key
/// (times three for CUBICSPLINE: in-tangent, value, out-tangent).
#[derive(Clone, Debug)]
pub(crate) struct Sampler {
    times: Vec<f64>,
    values: Vec<f64>,
    width: usize,
    interpolation: Interpolation,
    quaternion: bool,
}

impl Sampler {
    /// Checks and builds a sampler. For rotations (`quaternion`, width 4, `x y z w` order)
    /// LINEAR and STEP key values are normalised here; a zero or non-finite quaternion is an
    /// error. CUBICSPLINE values are kept as written and the result is normalised after
    /// interpolation.
    pub(crate) fn new(
        times: Vec<f64>,
        mut values: Vec<f64>,
        width: usize,
        interpolation: Interpolation,
        quaternion: bool,
    ) -> Result<Self, String> {
        if times.is_empty() {
            return Err("the sampler has no keyframes".into());
        }
        if width == 0 {
            return Err("the sampler's target has no components".into());
        }
        if let Some(k) = times.iter().position(|t| !t.is_finite()) {
            return Err(format!("key time {k} is not finite"));
        }
        if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(format!(
                "key times must increase strictly: key {} at {} follows {}",
                k + 1,
                times[k + 1],
                times[k]
            ));
        }
        let per_key = if interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        let expected = times.len() * per_key * width;
        if values.len() != expected {
            return Err(format!(
                "{} keys need {expected} output values ({per_key} x {width} per key), found {}",
                times.len(),
                values.len()
            ));
        }
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return Err(format!("output value {k} is not finite"));
        }
        if quaternion {
            if width != 4 {
                return Err("rotation output must have 4 components".into());
            }
            for (k, chunk) in values.chunks_exact_mut(4).enumerate() {
                let is_value = per_key == 1 || k % 3 == 1;
                if !is_value {
                    continue;
                }
                let norm = chunk.iter().map(|v| v * v).sum::<f64>().sqrt();
                if !(norm > 0.0 && norm.is_finite()) {
                    return Err(format!(
                        "key {} holds a zero or non-finite quaternion",
                        k / per_key
                    ));
                }
                if per_key == 1 {
                    chunk.iter_mut().for_each(|v| *v /= norm);
                }
            }
        }
        Ok(Self {
            times,
            values,
            width,
            interpolation,
            quaternion,
        })
    }

    /// Number of values the sampler produces.
    pub(crate) fn width(&self) -> usize {
        self.width
    }

    /// Time of the last key.
    pub(crate) fn end(&self) -> f64 {
        self.times[self.times.len() - 1]
    }

    /// The value (not a tangent) of key `k`.
    fn value(&self, k: usize) -> &[f64] {
        let w = self.width;
        match self.interpolation {
            Interpolation::CubicSpline => &self.values[(3 * k + 1) * w..(3 * k + 2) * w],
            _ => &self.values[k * w..(k + 1) * w],
        }
    }

    /// Writes the sampled value at time `t` (finite) into `out` (`width` values).
    pub(crate) fn sample(&self, t: f64, out: &mut [f64]) {
        let n = self.times.len();
        let w = self.width;
        if t <= self.times[0] || n == 1 {
            out.copy_from_slice(self.value(0));
            return;
        }
        if t >= self.times[n - 1] {
            out.copy_from_slice(self.value(n - 1));
            return;
        }
        // times[k] <= t < times[k + 1]
        let k = self.times.partition_point(|&x| x <= t) - 1;
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let dt = t1 - t0;
        let s = (t - t0) / dt;
        match self.interpolation {
            Interpolation::Step => out.copy_from_slice(self.value(k)),
            Interpolation::Linear if self.quaternion => {
                let q = slerp(quat(self.value(k)), quat(self.value(k + 1)), s);
                out.copy_from_slice(&q.to_array());
            }
            Interpolation::Linear => {
                let (a, b) = (self.value(k), self.value(k + 1));
                for c in 0..w {
                    out[c] = a[c] + s * (b[c] - a[c]);
                }
            }
            Interpolation::CubicSpline => {
                let v0 = &self.values[(3 * k + 1) * w..(3 * k + 2) * w];
                let b0 = &self.values[(3 * k + 2) * w..(3 * k + 3) * w];
                let a1 = &self.values[(3 * (k + 1)) * w..(3 * (k + 1) + 1) * w];
                let v1 = &self.values[(3 * (k + 1) + 1) * w..(3 * (k + 1) + 2) * w];
                let (s2, s3) = (s * s, s * s * s);
                let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
                let h10 = s3 - 2.0 * s2 + s;
                let h01 = -2.0 * s3 + 3.0 * s2;
                let h11 = s3 - s2;
                for c in 0..w {
                    out[c] = h00 * v0[c] + h10 * dt * b0[c] + h01 * v1[c] + h11 * dt * a1[c];
                }
                if self.quaternion {
                    let norm = out.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if norm > 0.0 && norm.is_finite() {
                        out.iter_mut().for_each(|v| *v /= norm);
                    } else {
                        // The spline passed through zero: fall back to the nearer key.
                        let near = if s < 0.5 { v0 } else { v1 };
                        let q = quat(near).normalize();
                        out.copy_from_slice(&q.to_array());
                    }
                }
            }
        }
    }
}

/// An `x y z w` slice as a quaternion.
fn quat(v: &[f64]) -> DQuat {
    DQuat::from_xyzw(v[0], v[1], v[2], v[3])
}

/// Spherical linear interpolation of unit quaternions on the shortest path. The angle comes
/// from `atan2(|a - b|, |a + b|)`, accurate for nearly equal and nearly opposite inputs.
pub(crate) fn slerp(a: DQuat, b: DQuat, s: f64) -> DQuat {
    let b = if a.dot(b) < 0.0 { -b } else { b };
    let half = 2.0 * (a - b).length().atan2((a + b).length());
    let sin = half.sin();
    if sin < SLERP_MIN_SIN {
        return (a * (1.0 - s) + b * s).normalize();
    }
    let wa = ((1.0 - s) * half).sin() / sin;
    let wb = (s * half).sin() / sin;
    (a * wa + b * wb).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_clamps_and_interpolates() {
        let s = Sampler::new(
            vec![1.0, 2.0],
            vec![0.0, 10.0],
            1,
            Interpolation::Linear,
            false,
        )
        .expect("valid");
        let mut out = [0.0];
        s.sample(0.0, &mut out);
        assert_eq!(out[0], 0.0);
        s.sample(1.25, &mut out);
        assert!((out[0] - 2.5).abs() < 1e-12);
        s.sample(5.0, &mut out);
        assert_eq!(out[0], 10.0);
    }

    #[test]
    fn step_holds() {
        let s = Sampler::new(
            vec![0.0, 1.0, 2.0],
            vec![1.0, 2.0, 3.0],
            1,
            Interpolation::Step,
            false,
        )
        .expect("valid");
        let mut out = [0.0];
        s.sample(0.999, &mut out);
        assert_eq!(out[0], 1.0);
        s.sample(1.0, &mut out);
        assert_eq!(out[0], 2.0);
    }

    #[test]
    fn cubic_hits_keys_and_uses_scaled_tangents() {
        // f(t) = t^2 on keys 0 and 2: tangents are df/dt = 0 and 4.
        let values = vec![0.0, 0.0, 0.0, 4.0, 4.0, 0.0];
        let s = Sampler::new(vec![0.0, 2.0], values, 1, Interpolation::CubicSpline, false)
            .expect("valid");
        let mut out = [0.0];
        s.sample(1.0, &mut out);
        assert!((out[0] - 1.0).abs() < 1e-12, "{}", out[0]);
        s.sample(2.0, &mut out);
        assert_eq!(out[0], 4.0);
    }

    #[test]
    fn slerp_shortest_path_and_midpoint() {
        let a = DQuat::IDENTITY;
        let b = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let m = slerp(a, -b, 0.5);
        let want = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4);
        assert!(m.dot(want).abs() > 1.0 - 1e-12);
        assert!((slerp(a, a, 0.3).dot(a) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn bad_samplers_are_refused() {
        assert!(Sampler::new(vec![], vec![], 1, Interpolation::Linear, false).is_err());
        assert!(
            Sampler::new(
                vec![1.0, 1.0],
                vec![0.0, 0.0],
                1,
                Interpolation::Linear,
                false
            )
            .is_err()
        );
        assert!(Sampler::new(vec![0.0], vec![0.0, 0.0], 1, Interpolation::Linear, false).is_err());
        let zero = vec![0.0; 4];
        assert!(Sampler::new(vec![0.0], zero, 4, Interpolation::Linear, true).is_err());
        let nan = vec![f64::NAN, 0.0, 0.0, 1.0];
        assert!(Sampler::new(vec![0.0], nan, 4, Interpolation::Linear, true).is_err());
    }
}
