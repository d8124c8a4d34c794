//! Deformation of triangle-bound Gaussians by a moving template (docs/conventions.md §4), to world space.
//!
//! Input: a [`GaussianSet`] with a [`crate::Binding`] and parameters in local triangle frames
//! ([`ParameterSpace::Local`]), the template's triangles (fixed topology) and the deformed vertex
//! positions of one frame. Output: a world-space set with normalised rotations (`w ≥ 0`),
//! log-scales and no binding, readable by any 3DGS viewer.
//!
//! - [`DeformMode::Binding`] (GaussianAvatars), frame from the posed triangle:
//!   `mu = k R_f mu_local + c_f`, `R = R_f R_local`, `s = k exp(log_s)` (so the output log-scale
//!   is `log_s + ln k`, no `exp` round trip).
//! - [`DeformMode::Jacobian`] (SurFhead/TGA): canonical frame `(R_c, k_c)` from the template's
//!   rest triangle, `J = E(deformed) E(canonical)⁻¹`; `mu = J (k_c R_c mu_local) + c_f(deformed)`,
//!   covariance axes `L = J R_c R_local k_c diag(exp(log_s))`, so `Σ' = L Lᵀ`. The output rotation
//!   and scales come from the SVD `L = U Σ Vᵀ` (`R = U` with `det U = +1`, `s = σ`), so the file
//!   means exactly `Σ'`: one-sided Jacobi, `LANES` (32) Gaussians at a time in `f32` lanes
//!   ([`crate::lanes`]), warm-started by the polar rotation of each triangle's `M`, and
//!   [`rotation_and_scales`] in `f64` for Gaussians on ill-conditioned triangles or with axes
//!   too unequal for `f32`. A singular value of 0 (a
//!   collapsed triangle, or the flat axis of a 2DGS surfel) is stored as [`crate::MIN_OUTPUT_SCALE`]
//!   so the log-scale stays finite; the shortest axis is stored last.
//!
//! SH coefficients, opacities and extra properties are copied unchanged (view-dependent colour is
//! evaluated with world directions, as GaussianAvatars does). Work is split over Gaussians with
//! rayon; every Gaussian is computed independently, so results do not depend on the thread count.

use glam::{DMat3, DQuat, DVec3, Mat3A, Quat, Vec3, Vec3A};
use rayon::prelude::*;
use trisplat_geometry::{TriId, TriMesh};

use crate::frames::{
    CanonicalTriangle, FrameOptions, corners_of, gaussian_avatars_frame, is_degenerate,
    transform_normal,
};
use crate::gaussians::{
    GaussianParts, GaussianSet, ParameterSpace, ScaleDims, normalize_wxyz, quat_from_rotation,
};
use crate::lanes::{LANES, LaneBatch, LaneFactors, TriangleFactor, factor_f64, factor_lanes};

/// Gaussians per rayon task.
const CHUNK: usize = 2048;

/// Deformation modes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DeformMode {
    /// GaussianAvatars: rigid frame plus uniform scale per posed triangle.
    #[default]
    Binding,
    /// SurFhead/TGA: per-triangle deformation gradient (anisotropic stretch).
    Jacobian,
}

/// Errors of deformation.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DeformError {
    /// The set has no binding.
    #[error("the Gaussians are not bound to triangles")]
    NotBound,
    /// The set is bound but its parameters are in world space.
    #[error("the Gaussians' parameters are in world space, not local triangle frames")]
    NotLocal,
    /// A binding names a triangle the template does not have.
    #[error(
        "Gaussian {index}: bound to triangle {triangle}, but the template has {triangle_count}"
    )]
    BindingOutOfRange {
        /// Gaussian index.
        index: usize,
        /// Its triangle.
        triangle: TriId,
        /// Triangles of the template.
        triangle_count: usize,
    },
    /// The frame's vertex count differs from the template's.
    #[error("the frame has {got} vertices, the template {expected}")]
    VertexCount {
        /// Template vertices.
        expected: usize,
        /// Frame vertices.
        got: usize,
    },
    /// A result overflowed `f32` (local parameters or positions so large that the world
    /// values are not representable).
    #[error("Gaussian {index}: deformed parameters overflow f32")]
    NonFiniteOutput {
        /// Gaussian index.
        index: usize,
    },
    /// A deformed vertex is NaN or infinite.
    #[error("deformed vertex {index} is not finite")]
    NonFiniteVertex {
        /// Vertex index.
        index: usize,
    },
}

/// World-space geometry of deformed Gaussians (reusable buffers, see
/// [`Deformer::deform_geometry`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WorldGeometry {
    /// Centres.
    pub means: Vec<Vec3>,
    /// Unit quaternions `[w, x, y, z]`, `w ≥ 0`.
    pub rotations: Vec<[f32; 4]>,
    /// Log-scales (third component 0 for surfels in binding mode).
    pub log_scales: Vec<Vec3>,
}

impl WorldGeometry {
    /// The world-space set of `set`'s Gaussians at this geometry: binding dropped, every other
    /// array copied. The geometry must be finite and as long as `set`: the other arrays are
    /// copies of a valid set, so the set is built unchecked to avoid another pass over the data.
    pub(crate) fn into_set(self, set: &GaussianSet) -> GaussianSet {
        GaussianSet::new_unchecked(GaussianParts {
            means: self.means,
            log_scales: self.log_scales,
            scale_dims: set.scale_dims(),
            rotations: self.rotations,
            opacity_logits: set.opacity_logits().to_vec(),
            sh_degree: set.sh_degree(),
            sh: set.sh().to_vec(),
            binding: None,
            material: set.material().cloned(),
            space: ParameterSpace::World,
            extras: set.extras().to_vec(),
            property_order: set.property_order().map(<[String]>::to_vec),
        })
    }
}

/// Per-triangle data of the binding mode, in `f32` for the per-Gaussian loop.
#[derive(Clone, Copy, Debug)]
struct BindingTri {
    linear: Mat3A,
    rotation: Quat,
    origin: Vec3A,
    ln_k: f32,
    /// The posed triangle is degenerate (its frame is the fallback frame).
    degenerate: bool,
}

/// Per-triangle data of the Jacobian mode: `M = J k_c R_c`, its kernel data and the deformed
/// centroid.
#[derive(Clone, Copy, Debug)]
struct JacobianTri {
    m: DMat3,
    factor: TriangleFactor,
    /// `M` and the centroid in `f32` for the means (as in the binding mode).
    m32: Mat3A,
    origin: Vec3A,
    /// The deformed triangle is degenerate (`J` is singular).
    degenerate: bool,
}

/// Per-triangle data that a [`FrameHold`] can keep: everything but the centroid, which always
/// follows the frame.
trait HeldTriangle: Copy {
    fn degenerate(&self) -> bool;
    fn origin(&self) -> Vec3A;
    fn set_origin(&mut self, origin: Vec3A);
}

impl HeldTriangle for BindingTri {
    fn degenerate(&self) -> bool {
        self.degenerate
    }
    fn origin(&self) -> Vec3A {
        self.origin
    }
    fn set_origin(&mut self, origin: Vec3A) {
        self.origin = origin;
    }
}

impl HeldTriangle for JacobianTri {
    fn degenerate(&self) -> bool {
        self.degenerate
    }
    fn origin(&self) -> Vec3A {
        self.origin
    }
    fn set_origin(&mut self, origin: Vec3A) {
        self.origin = origin;
    }
}

/// The last valid frame of every triangle, kept from frame to frame so that a triangle that
/// collapses (docs/numerics.md, "The degenerate-triangle policy") keeps the rotation and scale
/// (binding mode) or the linear map `M = J k_c R_c` (Jacobian mode) it had in the last frame
/// where it was valid, while its centroid follows the collapsed triangle. A triangle degenerate
/// in every frame seen so far takes the fallback frame. Used by [`Deformer::deform_held`] and
/// [`Deformer::deform_geometry_held`]; frames must come in order (a caller that starts or jumps
/// to a frame fills the hold from earlier frames with [`Deformer::fill_hold`]).
#[derive(Clone, Debug, Default)]
pub struct FrameHold {
    binding: Vec<BindingTri>,
    jacobian: Vec<JacobianTri>,
    /// Per triangle: the kept entry is a valid frame.
    valid: Vec<bool>,
}

impl FrameHold {
    /// An empty hold (no triangle has a kept frame yet).
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of triangles with a kept valid frame.
    #[must_use]
    pub fn kept(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }
}

/// How many triangles of one frame were degenerate, and what they did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Collapsed {
    /// Degenerate triangles that kept their last valid frame.
    pub held: usize,
    /// Degenerate triangles with no valid frame kept, which took the fallback frame.
    pub fallback: usize,
}

impl Collapsed {
    /// All degenerate triangles of the frame.
    #[must_use]
    pub fn total(&self) -> usize {
        self.held + self.fallback
    }
}

/// Keeps the frames of the triangles `missing` that are valid (`one(i)`), sizing `kept` with
/// `all()` first when it does not hold every triangle; returns the still degenerate ones.
fn fill_kept<T: HeldTriangle>(
    kept: &mut Vec<T>,
    valid: &mut [bool],
    missing: Vec<usize>,
    all: impl FnOnce() -> Vec<T>,
    one: impl Fn(usize) -> T,
) -> Vec<usize> {
    if kept.len() != valid.len() {
        *kept = all();
    }
    missing
        .into_iter()
        .filter(|&i| {
            let t = one(i);
            if t.degenerate() {
                return true;
            }
            kept[i] = t;
            valid[i] = true;
            false
        })
        .collect()
}

/// Replaces each degenerate triangle of `tris` by its kept valid frame (centroid from `tris`)
/// and marks which entries of `tris` hold a valid frame: the caller then keeps `tris` itself
/// (moved, not copied) as the next frame's `kept`.
fn apply_hold<T: HeldTriangle>(tris: &mut [T], kept: &[T], valid: &mut Vec<bool>) -> Collapsed {
    if kept.len() != tris.len() || valid.len() != tris.len() {
        valid.clear();
        valid.resize(tris.len(), false);
    }
    let mut collapsed = Collapsed::default();
    for (i, (t, v)) in tris.iter_mut().zip(valid.iter_mut()).enumerate() {
        if !t.degenerate() {
            *v = true;
        } else if *v {
            let origin = t.origin();
            *t = kept[i];
            t.set_origin(origin);
            collapsed.held += 1;
        } else {
            collapsed.fallback += 1;
        }
    }
    collapsed
}

/// Deforms bound Gaussians frame after frame for one template.
#[derive(Clone, Debug)]
pub struct Deformer {
    mode: DeformMode,
    options: FrameOptions,
    triangles: Vec<[u32; 3]>,
    vertex_count: usize,
    canonical: Vec<CanonicalTriangle>,
    /// Adaptive scale (binding mode): per triangle `(ln k_rest, rest area)`; empty when off.
    adaptive: Vec<(f64, f64)>,
}

impl Deformer {
    /// A deformer for `template` (its positions are the canonical/rest shape used by
    /// [`DeformMode::Jacobian`]), with frame options scaled to the template.
    #[must_use]
    pub fn new(template: &TriMesh, mode: DeformMode) -> Self {
        Self::with_options(
            template,
            mode,
            FrameOptions::for_positions(template.positions()),
        )
    }

    /// As [`Deformer::new`] with explicit frame options.
    #[must_use]
    pub fn with_options(template: &TriMesh, mode: DeformMode, options: FrameOptions) -> Self {
        let positions = template.positions();
        let canonical = match mode {
            DeformMode::Binding => Vec::new(),
            DeformMode::Jacobian => template
                .triangles()
                .par_iter()
                .map(|t| CanonicalTriangle::new(corners_of(positions, *t), &options))
                .collect(),
        };
        Self {
            mode,
            options,
            triangles: template.triangles().to_vec(),
            vertex_count: positions.len(),
            canonical,
            adaptive: Vec::new(),
        }
    }

    /// Turns on the adaptive scale of 3DFilmPCA in [`DeformMode::Binding`]: the Gaussians'
    /// scale factor becomes `k_rest √(area / area_rest)` (the rest frame scale times the square
    /// root of the triangle's area ratio to the template's rest shape) instead of the posed
    /// `k`. Means and rotations are unchanged. For a uniform scaling of a triangle both factors
    /// agree; under anisotropic stretch or shear the adaptive one follows the area (GaussianAvatars'
    /// `k` follows the mean of an edge and a height). A triangle with zero rest area keeps the
    /// posed `k`. Off by default. No effect in [`DeformMode::Jacobian`], whose `J` already
    /// carries the area change.
    #[must_use]
    pub fn with_adaptive_scale(mut self, template: &TriMesh) -> Self {
        let positions = template.positions();
        self.adaptive = template
            .triangles()
            .par_iter()
            .map(|t| {
                let v = corners_of(positions, *t);
                let f = gaussian_avatars_frame(v, &self.options);
                (f.scale.ln(), triangle_area(v))
            })
            .collect();
        self
    }

    /// Whether the adaptive scale is on.
    #[must_use]
    pub fn adaptive_scale(&self) -> bool {
        !self.adaptive.is_empty()
    }

    /// The mode.
    #[must_use]
    pub fn mode(&self) -> DeformMode {
        self.mode
    }

    /// Number of template triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Checks that `set` can be deformed with this template.
    ///
    /// # Errors
    /// [`DeformError::NotBound`], [`DeformError::NotLocal`], [`DeformError::BindingOutOfRange`].
    pub fn check(&self, set: &GaussianSet) -> Result<(), DeformError> {
        let binding = set.binding().ok_or(DeformError::NotBound)?;
        if set.space() != ParameterSpace::Local {
            return Err(DeformError::NotLocal);
        }
        let count = self.triangles.len();
        match binding.triangles.iter().position(|t| t.index() >= count) {
            Some(index) => Err(DeformError::BindingOutOfRange {
                index,
                triangle: binding.triangles[index],
                triangle_count: count,
            }),
            None => Ok(()),
        }
    }

    fn check_positions(&self, positions: &[DVec3]) -> Result<(), DeformError> {
        if positions.len() != self.vertex_count {
            return Err(DeformError::VertexCount {
                expected: self.vertex_count,
                got: positions.len(),
            });
        }
        match positions.par_iter().position_first(|p| !p.is_finite()) {
            Some(index) => Err(DeformError::NonFiniteVertex { index }),
            None => Ok(()),
        }
    }

    /// Deforms `set` to the frame `positions` and returns a world-space, viewer-ready set
    /// (SH, opacities and extras copied; no binding).
    ///
    /// # Errors
    /// As [`Deformer::check`], plus [`DeformError::VertexCount`] and
    /// [`DeformError::NonFiniteVertex`].
    pub fn deform(
        &self,
        set: &GaussianSet,
        positions: &[DVec3],
    ) -> Result<GaussianSet, DeformError> {
        self.deform_with(set, positions, None).map(|(set, _)| set)
    }

    /// [`Deformer::deform`] for frames in order: a triangle that is degenerate in this frame
    /// keeps its last valid frame from `hold` (see [`FrameHold`]); returns the set and the
    /// frame's degenerate triangles.
    ///
    /// # Errors
    /// As [`Deformer::deform`].
    pub fn deform_held(
        &self,
        set: &GaussianSet,
        positions: &[DVec3],
        hold: &mut FrameHold,
    ) -> Result<(GaussianSet, Collapsed), DeformError> {
        self.deform_with(set, positions, Some(hold))
    }

    fn deform_with(
        &self,
        set: &GaussianSet,
        positions: &[DVec3],
        hold: Option<&mut FrameHold>,
    ) -> Result<(GaussianSet, Collapsed), DeformError> {
        let mut geometry = WorldGeometry::default();
        let collapsed = self.geometry_with(set, positions, hold, &mut geometry)?;
        // `geometry_with` checked every output is finite.
        Ok((geometry.into_set(set), collapsed))
    }

    /// The world-space means of `set` with the template at `positions`; with the template's
    /// rest positions, the canonical means that incremental Delaunay meshes from.
    ///
    /// # Errors
    /// As [`Deformer::deform`].
    pub fn means(&self, set: &GaussianSet, positions: &[DVec3]) -> Result<Vec<Vec3>, DeformError> {
        let mut geometry = WorldGeometry::default();
        self.deform_geometry(set, positions, &mut geometry)?;
        Ok(geometry.means)
    }

    /// Deforms only the geometry (means, rotations, log-scales) into reusable buffers: the
    /// per-frame hot path.
    ///
    /// # Errors
    /// As [`Deformer::deform`].
    pub fn deform_geometry(
        &self,
        set: &GaussianSet,
        positions: &[DVec3],
        out: &mut WorldGeometry,
    ) -> Result<(), DeformError> {
        self.geometry_with(set, positions, None, out).map(|_| ())
    }

    /// [`Deformer::deform_geometry`] for frames in order, keeping the last valid frame of
    /// degenerate triangles in `hold` (see [`FrameHold`]); returns the frame's degenerate
    /// triangles.
    ///
    /// # Errors
    /// As [`Deformer::deform`].
    pub fn deform_geometry_held(
        &self,
        set: &GaussianSet,
        positions: &[DVec3],
        hold: &mut FrameHold,
        out: &mut WorldGeometry,
    ) -> Result<Collapsed, DeformError> {
        self.geometry_with(set, positions, Some(hold), out)
    }

    /// The indices of the triangles that are degenerate with the template at `positions` (in
    /// the posed frame for the binding mode, the deformed triangle for the Jacobian mode: the
    /// triangles a [`FrameHold`] would hold).
    ///
    /// # Errors
    /// [`DeformError::VertexCount`], [`DeformError::NonFiniteVertex`].
    pub fn degenerate_triangles(&self, positions: &[DVec3]) -> Result<Vec<usize>, DeformError> {
        self.check_positions(positions)?;
        let tol = self.options.degenerate_tol;
        Ok(self
            .triangles
            .par_iter()
            .enumerate()
            .with_min_len(4096)
            .filter(|(_, t)| is_degenerate(corners_of(positions, **t), tol))
            .map(|(i, _)| i)
            .collect())
    }

    /// Fills `hold` for the triangles `wanted` that have no kept frame yet, from the template
    /// at `positions` (an earlier frame) where they are valid there, and returns those still
    /// without one. A run that starts at (or jumps to) frame `s` calls it with frames
    /// `s - 1, s - 2, …` for the triangles degenerate at `s` until none is left (or frame 0),
    /// so its results equal those of a run that went through every frame before `s`.
    ///
    /// # Errors
    /// [`DeformError::VertexCount`], [`DeformError::NonFiniteVertex`].
    pub fn fill_hold(
        &self,
        positions: &[DVec3],
        hold: &mut FrameHold,
        wanted: &[usize],
    ) -> Result<Vec<usize>, DeformError> {
        self.check_positions(positions)?;
        let missing: Vec<usize> = wanted
            .iter()
            .copied()
            .filter(|&i| i < self.triangles.len() && !hold.valid.get(i).copied().unwrap_or(false))
            .collect();
        if missing.is_empty() {
            return Ok(missing);
        }
        let n = self.triangles.len();
        if hold.valid.len() != n {
            hold.valid = vec![false; n];
        }
        Ok(match self.mode {
            DeformMode::Binding => fill_kept(
                &mut hold.binding,
                &mut hold.valid,
                missing,
                || self.binding_triangles(positions),
                |i| self.binding_triangle(i, positions),
            ),
            DeformMode::Jacobian => fill_kept(
                &mut hold.jacobian,
                &mut hold.valid,
                missing,
                || self.jacobian_triangles(positions),
                |i| self.jacobian_triangle(i, positions),
            ),
        })
    }

    fn geometry_with(
        &self,
        set: &GaussianSet,
        positions: &[DVec3],
        mut hold: Option<&mut FrameHold>,
        out: &mut WorldGeometry,
    ) -> Result<Collapsed, DeformError> {
        self.check(set)?;
        self.check_positions(positions)?;
        let n = set.len();
        out.means.resize(n, Vec3::ZERO);
        out.rotations.resize(n, [1.0, 0.0, 0.0, 0.0]);
        out.log_scales.resize(n, Vec3::ZERO);
        // `check` guarantees a binding; an empty slice would only mean no Gaussians.
        let binding = set.binding().map_or(&[][..], |b| b.triangles.as_slice());
        let mut collapsed = Collapsed::default();
        let bad = match self.mode {
            DeformMode::Binding => {
                let mut tris = self.binding_triangles(positions);
                if let Some(h) = hold.as_deref_mut() {
                    collapsed = apply_hold(&mut tris, &h.binding, &mut h.valid);
                }
                let bad = run_chunks(out, |start, means, rots, scales| {
                    for j in 0..means.len() {
                        let i = start + j;
                        let t = &tris[binding[i].index()];
                        let local = Vec3A::from(set.means()[i]);
                        means[j] = Vec3::from(t.linear * local + t.origin);
                        // q_f is unit, so normalising the product normalises q_local too.
                        let q = normalized_product(t.rotation, set.rotations()[i]);
                        rots[j] = [q.w, q.x, q.y, q.z];
                        let ls = set.log_scales()[i] + Vec3::splat(t.ln_k);
                        scales[j] = match set.scale_dims() {
                            ScaleDims::Three => ls,
                            ScaleDims::Two => Vec3::new(ls.x, ls.y, 0.0),
                        };
                    }
                });
                if let Some(h) = hold {
                    h.binding = tris;
                }
                bad
            }
            DeformMode::Jacobian => {
                let mut tris = self.jacobian_triangles(positions);
                if let Some(h) = hold.as_deref_mut() {
                    collapsed = apply_hold(&mut tris, &h.jacobian, &mut h.valid);
                }
                let flat = set.scale_dims() == ScaleDims::Two;
                let (local_rots, local_ls) = (set.rotations(), set.log_scales());
                let bad = run_chunks(out, |start, means, rots, scales| {
                    for (j, mean) in means.iter_mut().enumerate() {
                        let i = start + j;
                        let t = &tris[binding[i].index()];
                        *mean = Vec3::from(t.m32 * Vec3A::from(set.means()[i]) + t.origin);
                    }
                    let mut batch = LaneBatch::default();
                    let mut f = LaneFactors::default();
                    for j0 in (0..means.len()).step_by(LANES) {
                        let lanes = LANES.min(means.len() - j0);
                        for l in 0..lanes {
                            let i = start + j0 + l;
                            let t = &tris[binding[i].index()].factor;
                            batch.set(l, local_rots[i], local_ls[i].to_array(), t);
                        }
                        factor_lanes(&batch, flat, &mut f);
                        // Straight copies first (no per-lane branch), then the f64 lanes.
                        for l in 0..lanes {
                            let j = j0 + l;
                            rots[j] = [
                                f.rotation[0][l],
                                f.rotation[1][l],
                                f.rotation[2][l],
                                f.rotation[3][l],
                            ];
                            scales[j] = Vec3::new(
                                f.log_scale[0][l],
                                f.log_scale[1][l],
                                if flat { 0.0 } else { f.log_scale[2][l] },
                            );
                        }
                        for l in (0..lanes).filter(|&l| f.needs_f64[l]) {
                            let (j, i) = (j0 + l, start + j0 + l);
                            let m = tris[binding[i].index()].m;
                            let (q, ls) =
                                factor_f64(m, local_rots[i], local_ls[i].to_array(), flat);
                            rots[j] = q;
                            scales[j] = Vec3::new(ls[0], ls[1], if flat { 0.0 } else { ls[2] });
                        }
                    }
                });
                if let Some(h) = hold {
                    h.jacobian = tris;
                }
                bad
            }
        };
        // NaN firewall: finite inputs overflow only at extreme magnitudes; say so instead of
        // handing NaN or infinity to a file or a renderer (checked per chunk, in cache).
        match bad {
            Some(index) => Err(DeformError::NonFiniteOutput { index }),
            None => Ok(collapsed),
        }
    }

    /// Each Gaussian's shading normal with the template at `positions` (unit, not turned to
    /// any camera; docs/conventions.md §5 "Relighting"): its shortest local axis `e_k` (`k` the
    /// smallest local log-scale, the first on ties; a surfel's flat third axis) carried to the
    /// world, `R_local` the normalised local rotation:
    ///
    /// - [`DeformMode::Binding`]: `R_f R_local e_k`, the shortest axis of the deformed Gaussian
    ///   (the frame is a rotation times a uniform scale);
    /// - [`DeformMode::Jacobian`]: `normalize(J⁻ᵀ R_c R_local e_k)` ([`transform_normal`] of
    ///   `M = J k_c R_c`, whose inverse transpose differs from `J⁻ᵀ R_c` by the positive factor
    ///   `1 / k_c`): the normal of the Gaussian's tangent plane carried by `J`. The shortest axis
    ///   of the deformed covariance `J Σ Jᵀ` tends to it only as the Gaussian gets flat (it is
    ///   it for a surfel); `J n` is neither. Where `M` is so singular that `cof(M) n` vanishes,
    ///   the deformed covariance's shortest axis is taken.
    ///
    /// Triangles are taken as they are at `positions` (no [`FrameHold`]).
    ///
    /// # Errors
    /// As [`Deformer::deform`].
    pub fn shading_normals(
        &self,
        set: &GaussianSet,
        positions: &[DVec3],
    ) -> Result<Vec<Vec3>, DeformError> {
        self.check(set)?;
        self.check_positions(positions)?;
        let binding = set.binding().map_or(&[][..], |b| b.triangles.as_slice());
        let flat = set.scale_dims() == ScaleDims::Two;
        let local_axis = |i: usize| -> DVec3 {
            let [w, x, y, z] = set.rotations()[i];
            let q = normalize_wxyz([w, x, y, z]).unwrap_or(DQuat::IDENTITY);
            let r = DMat3::from_quat(q);
            let s = set.log_scales()[i];
            if flat {
                r.z_axis
            } else if s.x <= s.y && s.x <= s.z {
                r.x_axis
            } else if s.y <= s.z {
                r.y_axis
            } else {
                r.z_axis
            }
        };
        let normals: Vec<Vec3> = match self.mode {
            DeformMode::Binding => {
                let tris = self.binding_triangles(positions);
                (0..set.len())
                    .into_par_iter()
                    .with_min_len(CHUNK)
                    .map(|i| {
                        let t = &tris[binding[i].index()];
                        (t.rotation.as_dquat() * local_axis(i)).as_vec3()
                    })
                    .collect()
            }
            DeformMode::Jacobian => {
                let tris = self.jacobian_triangles(positions);
                (0..set.len())
                    .into_par_iter()
                    .with_min_len(CHUNK)
                    .map(|i| {
                        let m = tris[binding[i].index()].m;
                        transform_normal(m, local_axis(i)).map_or_else(
                            || {
                                let (q, _) = factor_f64(
                                    m,
                                    set.rotations()[i],
                                    set.log_scales()[i].to_array(),
                                    flat,
                                );
                                let [w, x, y, z] = q;
                                Quat::from_xyzw(x, y, z, w) * Vec3::Z
                            },
                            DVec3::as_vec3,
                        )
                    })
                    .collect()
            }
        };
        match normals.iter().position(|n| !n.is_finite()) {
            Some(index) => Err(DeformError::NonFiniteOutput { index }),
            None => Ok(normals),
        }
    }

    fn binding_triangles(&self, positions: &[DVec3]) -> Vec<BindingTri> {
        (0..self.triangles.len())
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| self.binding_triangle(i, positions))
            .collect()
    }

    fn binding_triangle(&self, i: usize, positions: &[DVec3]) -> BindingTri {
        let v = corners_of(positions, self.triangles[i]);
        let f = gaussian_avatars_frame(v, &self.options);
        let q = quat_from_rotation(f.rotation);
        let ln_k = match self.adaptive.get(i) {
            Some(&(ln_k_rest, area_rest)) if area_rest > 0.0 => {
                let ratio = triangle_area(v) / area_rest;
                ln_k_rest + 0.5 * ratio.max(f64::MIN_POSITIVE).ln()
            }
            _ => f.scale.ln(),
        };
        BindingTri {
            linear: Mat3A::from_cols(
                (f.rotation.x_axis * f.scale).as_vec3().into(),
                (f.rotation.y_axis * f.scale).as_vec3().into(),
                (f.rotation.z_axis * f.scale).as_vec3().into(),
            ),
            rotation: q.as_quat(),
            origin: f.origin.as_vec3().into(),
            ln_k: ln_k as f32,
            degenerate: f.degenerate,
        }
    }

    fn jacobian_triangles(&self, positions: &[DVec3]) -> Vec<JacobianTri> {
        (0..self.triangles.len())
            .into_par_iter()
            .with_min_len(1024)
            .map(|i| self.jacobian_triangle(i, positions))
            .collect()
    }

    fn jacobian_triangle(&self, i: usize, positions: &[DVec3]) -> JacobianTri {
        let c = &self.canonical[i];
        let v = corners_of(positions, self.triangles[i]);
        let j = c.gradient(v, &self.options);
        let m = j * c.frame.rotation * c.frame.scale;
        JacobianTri {
            m,
            factor: TriangleFactor::new(m),
            m32: Mat3A::from_cols(
                m.x_axis.as_vec3().into(),
                m.y_axis.as_vec3().into(),
                m.z_axis.as_vec3().into(),
            ),
            origin: ((v[0] + v[1] + v[2]) / 3.0).as_vec3().into(),
            degenerate: is_degenerate(v, self.options.degenerate_tol),
        }
    }
}

/// Area of the triangle `v`.
fn triangle_area(v: [DVec3; 3]) -> f64 {
    0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length()
}

/// `normalize(q_f ⊗ q_local)` with `w ≥ 0`, for a unit `q_f` and a raw `[w, x, y, z]` local
/// quaternion; products too small or large for `f32` are normalised in `f64` (a zero quaternion,
/// which a checked set cannot hold, gives `q_f`).
fn normalized_product(q_f: Quat, local: [f32; 4]) -> Quat {
    let [w, x, y, z] = local;
    let q = q_f * Quat::from_xyzw(x, y, z, w);
    let len_sq = q.length_squared();
    let q = if len_sq > f32::MIN_POSITIVE && len_sq.is_finite() {
        q * len_sq.sqrt().recip()
    } else {
        let l = normalize_wxyz(local).map_or(DQuat::IDENTITY, |d| d);
        (q_f.as_dquat() * l).normalize().as_quat()
    };
    if q.w < 0.0 { -q } else { q }
}

/// Runs `f(start, means, rotations, log_scales)` over chunks of the output in parallel and
/// checks each chunk while it is in cache; returns the first Gaussian whose output is not
/// finite.
fn run_chunks<F>(out: &mut WorldGeometry, f: F) -> Option<usize>
where
    F: Fn(usize, &mut [Vec3], &mut [[f32; 4]], &mut [Vec3]) + Sync,
{
    out.means
        .par_chunks_mut(CHUNK)
        .zip(out.rotations.par_chunks_mut(CHUNK))
        .zip(out.log_scales.par_chunks_mut(CHUNK))
        .enumerate()
        .filter_map(|(c, ((m, r), s))| {
            f(c * CHUNK, m, r, s);
            (0..m.len())
                .find(|&j| {
                    !(m[j].is_finite() && s[j].is_finite() && r[j].iter().all(|v| v.is_finite()))
                })
                .map(|j| c * CHUNK + j)
        })
        .min()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaussians::{Binding, BindingEncoding};
    use crate::svd::rotation_and_scales;
    use trisplat_geometry::rng::Rng;

    /// A bumpy grid with `side²` vertices and random bound Gaussians.
    fn scene(side: u32, per_tri: usize) -> (TriMesh, GaussianSet, Vec<DVec3>) {
        let mut rng = Rng::new(11);
        let mut positions = Vec::new();
        for y in 0..side {
            for x in 0..side {
                let z = rng.uniform_f32() * 0.1;
                positions.push(Vec3::new(x as f32, y as f32, z).as_dvec3() / f64::from(side));
            }
        }
        let mut triangles = Vec::new();
        for y in 0..side - 1 {
            for x in 0..side - 1 {
                let a = y * side + x;
                triangles.push([a, a + 1, a + side + 1]);
                triangles.push([a, a + side + 1, a + side]);
            }
        }
        let n = triangles.len() * per_tri;
        let mut u = || rng.uniform_f32() - 0.5;
        let set = GaussianSet::try_new(GaussianParts {
            means: (0..n).map(|_| Vec3::new(u(), u(), u())).collect(),
            log_scales: (0..n).map(|_| Vec3::new(u(), u(), u()) * 4.0).collect(),
            rotations: (0..n).map(|_| [u() + 1.0, u(), u(), u()]).collect(),
            opacity_logits: vec![0.0; n],
            sh: vec![0.0; 3 * n],
            binding: Some(Binding {
                triangles: (0..n).map(|i| TriId((i / per_tri) as u32)).collect(),
                encoding: BindingEncoding::Float,
            }),
            space: ParameterSpace::Local,
            ..GaussianParts::default()
        })
        .unwrap_or_else(|e| panic!("{e}"));
        let moved = positions
            .iter()
            .map(|p| DVec3::new(p.x * 1.5 + p.y * 0.2, p.y, p.z + (p.x * 5.0).sin() * 0.1))
            .collect();
        (TriMesh::new(positions, triangles), set, moved)
    }

    #[test]
    fn results_do_not_depend_on_thread_count() {
        let (mesh, set, moved) = scene(40, 3);
        for mode in [DeformMode::Binding, DeformMode::Jacobian] {
            let deformer = Deformer::new(&mesh, mode);
            let run = |threads| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .map(|pool| pool.install(|| deformer.deform(&set, &moved)))
            };
            let one = run(1).unwrap().unwrap();
            let four = run(4).unwrap().unwrap();
            assert_eq!(one, four, "{mode:?}");
        }
    }

    #[test]
    fn adaptive_scale_follows_the_area_ratio() {
        let (bumpy, set, _) = scene(6, 2);
        // Flat, so that stretching x by 4 multiplies every area by exactly 4.
        let flat = bumpy
            .positions()
            .iter()
            .map(|p| DVec3::new(p.x, p.y, 0.0))
            .collect::<Vec<_>>();
        let mesh = TriMesh::new(flat, bumpy.triangles().to_vec());
        let plain = Deformer::new(&mesh, DeformMode::Binding);
        let adaptive = Deformer::new(&mesh, DeformMode::Binding).with_adaptive_scale(&mesh);
        assert!(adaptive.adaptive_scale() && !plain.adaptive_scale());
        // At rest and under a uniform scaling the two agree (k scales like √area).
        for factor in [1.0, 2.0] {
            let moved: Vec<DVec3> = mesh.positions().iter().map(|p| *p * factor).collect();
            let a = adaptive.deform(&set, &moved).unwrap();
            let b = plain.deform(&set, &moved).unwrap();
            for (x, y) in a.log_scales().iter().zip(b.log_scales()) {
                assert!((*x - *y).abs().max_element() < 1e-5, "{x} {y}");
            }
        }
        // Stretching x by 4 multiplies every area by 4: scales are the rest ones times 2.
        let stretched: Vec<DVec3> = mesh
            .positions()
            .iter()
            .map(|p| DVec3::new(4.0 * p.x, p.y, p.z))
            .collect();
        let rest = plain.deform(&set, mesh.positions()).unwrap();
        let a = adaptive.deform(&set, &stretched).unwrap();
        for (x, y) in a.log_scales().iter().zip(rest.log_scales()) {
            let d = *x - *y - Vec3::splat(2f32.ln());
            assert!(d.abs().max_element() < 1e-5, "{x} {y}");
        }
        // Means and rotations do not change with the option.
        let b = plain.deform(&set, &stretched).unwrap();
        assert_eq!(a.means(), b.means());
        assert_eq!(a.rotations(), b.rotations());
    }

    /// A sheared triangle: in Jacobian mode the shading normal is `J⁻ᵀ n` of the rest normal,
    /// `J` written by hand (the shear `x += s y` in the triangle's plane, area kept), which for
    /// Gaussians tilted out of the plane differs from `J n` and from the deformed covariance's
    /// shortest axis; in binding mode it is the deformed Gaussian's shortest axis.
    #[test]
    fn jacobian_normals_move_by_the_inverse_transpose() {
        use crate::densify::shortest_axis;
        let rest = vec![DVec3::ZERO, DVec3::X, DVec3::Y];
        let s = 0.8;
        let moved = vec![DVec3::ZERO, DVec3::X, DVec3::new(s, 1.0, 0.0)];
        let mesh = TriMesh::new(rest.clone(), vec![[0, 1, 2]]);
        let mut rng = Rng::new(7);
        let n = 40;
        let set = GaussianSet::try_new(GaussianParts {
            means: (0..n)
                .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), 0.0) * 0.3)
                .collect(),
            log_scales: (0..n)
                .map(|i| {
                    // No ties; the shortest axis cycles, thickness ratio 0.3 to 0.74.
                    let mut l = [-2.0, -2.3, -2.6 - 0.02 * i as f32];
                    l.rotate_left(i % 3);
                    Vec3::from_array(l)
                })
                .collect(),
            rotations: (0..n)
                .map(|_| {
                    let q = crate::test_util::random_rotation(&mut rng).as_quat();
                    [q.w, q.x, q.y, q.z]
                })
                .collect(),
            opacity_logits: vec![0.0; n],
            sh: vec![0.0; 3 * n],
            binding: Some(Binding {
                triangles: vec![TriId(0); n],
                encoding: BindingEncoding::Float,
            }),
            space: ParameterSpace::Local,
            ..GaussianParts::default()
        })
        .unwrap();
        let j = DMat3::from_cols(DVec3::X, DVec3::new(s, 1.0, 0.0), DVec3::Z);
        let j_inv_t = j.inverse().transpose();
        let deformer = Deformer::new(&mesh, DeformMode::Jacobian);
        let at_rest = deformer.deform(&set, &rest).unwrap();
        let deformed = deformer.deform(&set, &moved).unwrap();
        let normals = deformer.shading_normals(&set, &moved).unwrap();
        let (mut off_jn, mut off_svd) = (0.0f64, 0.0f64);
        for (i, got) in normals.iter().enumerate() {
            let n_rest = shortest_axis(&at_rest, i);
            let want = (j_inv_t * n_rest).normalize();
            let got = got.as_dvec3();
            assert!((got.length() - 1.0).abs() < 1e-6);
            assert!(1.0 - got.dot(want).abs() < 1e-6, "{i}: {got} vs {want}");
            off_jn = off_jn.max(1.0 - (j * n_rest).normalize().dot(want).abs());
            off_svd = off_svd.max(1.0 - shortest_axis(&deformed, i).dot(want).abs());
        }
        // The test tells the three apart.
        assert!(off_jn > 0.05 && off_svd > 1e-3, "{off_jn} {off_svd}");
        // Binding mode: the deformed Gaussian's own shortest axis.
        let binding = Deformer::new(&mesh, DeformMode::Binding);
        let deformed = binding.deform(&set, &moved).unwrap();
        let normals = binding.shading_normals(&set, &moved).unwrap();
        for (i, got) in normals.iter().enumerate() {
            let a = shortest_axis(&deformed, i);
            assert!(1.0 - a.dot(got.as_dvec3()).abs() < 1e-6, "{i}");
        }
        // Bad frames are refused as by `deform`.
        assert!(matches!(
            deformer.shading_normals(&set, &moved[..2]),
            Err(DeformError::VertexCount { .. })
        ));
    }

    /// A 2DGS surfel deformed by a Jacobian `J` (covariance axes `J R diag(s0, s1, 0)`): the
    /// normal of the factorisation (`u_2 = u_0 × u_1`) is the rest normal moved by `J⁻ᵀ`
    /// ([`crate::frames::transform_normal`]), for mirroring `J` too.
    #[test]
    fn a_surfel_normal_moves_by_the_inverse_transpose() {
        let mut rng = Rng::new(21);
        for case in 0..500 {
            let j = crate::test_util::random_matrix(&mut rng)
                + DMat3::IDENTITY * if case % 2 == 0 { 1.0 } else { -1.0 };
            let q = crate::test_util::random_rotation(&mut rng);
            let r = DMat3::from_quat(q);
            let (s0, s1) = (0.1 + rng.uniform_f64(), 0.1 + rng.uniform_f64());
            let l = j * DMat3::from_cols(r.x_axis * s0, r.y_axis * s1, DVec3::ZERO);
            let (u, sig) = rotation_and_scales(l);
            assert!(sig.z.abs() < 1e-12 * sig.x, "{case}: still flat");
            let Some(moved) = crate::frames::transform_normal(j, r.z_axis) else {
                continue;
            };
            let cos = u.z_axis.dot(moved).abs();
            assert!((1.0 - cos) < 1e-12, "{case}: normal off by {}", 1.0 - cos);
        }
    }
}
