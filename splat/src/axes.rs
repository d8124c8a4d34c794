//! Named axis conventions and the exact change of axes of a world-space [`GaussianSet`]
//! (docs/conventions.md §3, "Axes").
//!
//! The 16 names are those of Niantic's SPZ library: three letters give the directions of the x,
//! y and z axes, `R`ight/`L`eft, `U`p/`D`own, `B`ack (towards the viewer)/`F`ront. `RDF` is the
//! frame 3DGS trains in (COLMAP / OpenCV cameras: x right, y down, z forward) and so the usual
//! frame of an INRIA PLY; `RUB` is the frame SPZ stores (OpenGL, three.js). The standard family
//! (`LDB` .. `RUF`, ids 1-8) differ from each other by axis sign flips, the rotated family
//! (`LFD` .. `RBU`, ids 9-16) swap y and z (a quarter turn about x) as well.
//!
//! A change of axes is the signed permutation matrix `M` with `p_to = M p_from`:
//! - means `M p` (exact);
//! - rotations: when `M` is diagonal (sign flips) the quaternion keeps `w` and flips each of
//!   `x y z` by the product of the other two axes' signs, `R' = M R Mᵀ` (exact, the SPZ
//!   library's rule); otherwise `R' = M R` (`M R D` with `D = diag(-1, 1, 1)` when `M` mirrors),
//!   computed in f64 and rounded once. Both give the covariance `M Σ Mᵀ` with the scales kept;
//! - SH: band by band, `f'(d) = f(Mᵀ d)` ([`ShChange`]): exact sign flips for diagonal `M`.
//!
//! Only world-space sets are changed (a bound set's local parameters have no world axes).

use std::fmt;
use std::str::FromStr;

use glam::{DMat3, DQuat, DVec3, Vec3};

use crate::gaussians::{
    GaussianParts, GaussianSet, ParameterSpace, quat_from_rotation, sh_coeffs_per_channel,
};
use crate::sh::ShChange;

/// One of the 16 named axis conventions (ids as in the SPZ library's `CoordinateSystem`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Axes {
    /// Left, down, back.
    Ldb,
    /// Right, down, back.
    Rdb,
    /// Left, up, back.
    Lub,
    /// Right, up, back: OpenGL, three.js; what SPZ stores.
    Rub,
    /// Left, down, front.
    Ldf,
    /// Right, down, front: COLMAP / OpenCV, the 3DGS training frame of INRIA PLYs.
    Rdf,
    /// Left, up, front (the SPZ library's name for glTF's frame).
    Luf,
    /// Right, up, front (Unity).
    Ruf,
    /// Left, front, down.
    Lfd,
    /// Right, front, down.
    Rfd,
    /// Left, front, up.
    Lfu,
    /// Right, front, up.
    Rfu,
    /// Left, back, down.
    Lbd,
    /// Right, back, down.
    Rbd,
    /// Left, back, up.
    Lbu,
    /// Right, back, up.
    Rbu,
}

const ALL: [Axes; 16] = [
    Axes::Ldb,
    Axes::Rdb,
    Axes::Lub,
    Axes::Rub,
    Axes::Ldf,
    Axes::Rdf,
    Axes::Luf,
    Axes::Ruf,
    Axes::Lfd,
    Axes::Rfd,
    Axes::Lfu,
    Axes::Rfu,
    Axes::Lbd,
    Axes::Rbd,
    Axes::Lbu,
    Axes::Rbu,
];

impl Axes {
    /// Every convention, in id order.
    #[must_use]
    pub fn all() -> [Axes; 16] {
        ALL
    }

    /// The SPZ library's id (1..=16).
    #[must_use]
    pub fn id(self) -> u32 {
        ALL.iter()
            .position(|&a| a == self)
            .map_or(0, |i| i as u32 + 1)
    }

    /// The convention with SPZ id `id` (1..=16).
    #[must_use]
    pub fn from_id(id: u32) -> Option<Self> {
        let i = usize::try_from(id).ok()?.checked_sub(1)?;
        ALL.get(i).copied()
    }

    /// The three letters, lower case (`"rdf"`).
    #[must_use]
    pub fn name(self) -> &'static str {
        const NAMES: [&str; 16] = [
            "ldb", "rdb", "lub", "rub", "ldf", "rdf", "luf", "ruf", "lfd", "rfd", "lfu", "rfu",
            "lbd", "rbd", "lbu", "rbu",
        ];
        NAMES[self.id() as usize - 1]
    }

    /// The directions of this convention's x, y and z axes in `RUB` coordinates (the columns of
    /// the matrix taking this convention's coordinates to `RUB`'s).
    #[must_use]
    pub fn basis(self) -> DMat3 {
        let dir = |c: u8| match c {
            b'r' => DVec3::X,
            b'l' => -DVec3::X,
            b'u' => DVec3::Y,
            b'd' => -DVec3::Y,
            b'b' => DVec3::Z,
            _ => -DVec3::Z, // 'f'
        };
        let n = self.name().as_bytes();
        DMat3::from_cols(dir(n[0]), dir(n[1]), dir(n[2]))
    }

    /// The matrix `M` with `p_to = M p_from` for coordinates in `self` (from) and `to`.
    #[must_use]
    pub fn to(self, to: Axes) -> DMat3 {
        to.basis().transpose() * self.basis()
    }
}

impl fmt::Display for Axes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Axes {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.to_ascii_lowercase();
        ALL.iter()
            .copied()
            .find(|a| a.name() == lower)
            .ok_or_else(|| {
                format!(
                    "unknown axes {s:?}; expected one of {}",
                    ALL.map(Axes::name).join(", ")
                )
            })
    }
}

/// Whether `m` is diagonal (a change of axes by sign flips only).
fn is_diagonal(m: DMat3) -> bool {
    m.x_axis.y == 0.0
        && m.x_axis.z == 0.0
        && m.y_axis.x == 0.0
        && m.y_axis.z == 0.0
        && m.z_axis.x == 0.0
        && m.z_axis.y == 0.0
}

/// Re-expresses a world-space set in other axes: `m` is a signed permutation matrix with
/// `p_new = m p_old` (see the module docs). Extras, property order and SH degree are kept.
/// The set must be in world space; a bound set is returned unchanged by the callers' checks.
#[must_use]
#[expect(clippy::cast_possible_truncation, reason = "f32 storage of Gaussians")]
pub fn change_axes(set: &GaussianSet, m: DMat3) -> GaussianSet {
    debug_assert_eq!(set.space(), ParameterSpace::World);
    if m == DMat3::IDENTITY {
        return set.clone();
    }
    let mut parts: GaussianParts = set.clone().into_parts();
    let mf = m.as_mat3();
    for p in &mut parts.means {
        // Entries are 0 and ±1: every product and sum is exact.
        *p = Vec3::new(
            mf.x_axis.x * p.x + mf.y_axis.x * p.y + mf.z_axis.x * p.z,
            mf.x_axis.y * p.x + mf.y_axis.y * p.y + mf.z_axis.y * p.z,
            mf.x_axis.z * p.x + mf.y_axis.z * p.y + mf.z_axis.z * p.z,
        );
    }
    if is_diagonal(m) {
        let (sx, sy, sz) = (mf.x_axis.x, mf.y_axis.y, mf.z_axis.z);
        for q in &mut parts.rotations {
            q[1] *= sy * sz;
            q[2] *= sx * sz;
            q[3] *= sx * sy;
        }
    } else {
        let mirror = m.determinant() < 0.0;
        let d = DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0));
        for q in &mut parts.rotations {
            let r = crate::gaussians::normalize_wxyz(*q).unwrap_or(DQuat::IDENTITY);
            let mut rm = m * DMat3::from_quat(r);
            if mirror {
                rm *= d;
            }
            let out = quat_from_rotation(rm);
            *q = [out.w as f32, out.x as f32, out.y as f32, out.z as f32];
        }
    }
    if parts.sh_degree > 0 {
        let change = ShChange::new(parts.sh_degree, m);
        let stride = 3 * sh_coeffs_per_channel(parts.sh_degree);
        for coeffs in parts.sh.chunks_exact_mut(stride) {
            change.apply(coeffs);
        }
    }
    GaussianSet::new_unchecked(parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_names_and_bases() {
        for (i, a) in Axes::all().into_iter().enumerate() {
            assert_eq!(a.id() as usize, i + 1);
            assert_eq!(Axes::from_id(a.id()), Some(a));
            assert_eq!(a.name().parse::<Axes>(), Ok(a));
            let b = a.basis();
            assert_eq!(b.transpose() * b, DMat3::IDENTITY, "{a}");
        }
        assert_eq!(Axes::from_id(0), None);
        assert_eq!(Axes::from_id(17), None);
        assert!("xyz".parse::<Axes>().is_err());
        assert_eq!(Axes::Rub.basis(), DMat3::IDENTITY);
        // RDF -> RUB is the half turn about x.
        assert_eq!(
            Axes::Rdf.to(Axes::Rub),
            DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0))
        );
        // The SPZ library's rotated family: RFU -> RUB maps (x, y, z) to (x, z, -y).
        let m = Axes::Rfu.to(Axes::Rub);
        assert_eq!(m * DVec3::new(1.0, 2.0, 3.0), DVec3::new(1.0, 3.0, -2.0));
        // LBD -> RUB: (-x, -z, y).
        let m = Axes::Lbd.to(Axes::Rub);
        assert_eq!(m * DVec3::new(1.0, 2.0, 3.0), DVec3::new(-1.0, -3.0, 2.0));
    }
}
