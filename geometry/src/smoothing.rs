//! Mesh smoothing with Open3D's and trimesh's semantics (docs/conventions.md §7).
//!
//! Every method is a Jacobi iteration: all vertices move from the previous iterate, never from
//! values updated in the same pass, so the result does not depend on vertex order or thread
//! count. Positions are held in f64 for all iterations and rounded to f32 once at the end.
//!
//! | method | one pass | matches |
//! |---|---|---|
//! | [`SmoothMethod::Laplacian`] | `x' = x + λ (Σ w_j x_j / Σ w_j − x)`, `w_j = 1 / (‖x − x_j‖ + 1e-12)` over the 1-ring | Open3D `filter_smooth_laplacian(iterations, λ)` |
//! | [`SmoothMethod::Taubin`] | the Laplacian pass with λ, then again with μ, per iteration | Open3D `filter_smooth_taubin(iterations, λ, μ)` |
//! | [`SmoothMethod::Uniform`] | `x' = x + λ (Σ_j x_j / c − x)` with umbrella weights, then a rescale about the initial centre of mass that restores the initial volume | trimesh 5.2 `smoothing.filter_laplacian(mesh, λ, iterations)` (explicit, `volume_constraint=True`) |
//! | [`SmoothMethod::Cotangent`] | the Laplacian pass with `w_ij = (max(cot α, 0) + max(cot β, 0)) / 2` | — |
//!
//! Details that differ between the tools, and what trisplat does:
//! - **Zero iterations** return the input unchanged (Open3D 0.20 returns all-zero positions).
//! - **Isolated vertices** (no neighbour, or all weights zero) stay where they are (Open3D
//!   divides 0 by 0 and writes NaN; trimesh pulls an unreferenced vertex towards the origin).
//! - **Uniform (trimesh) neighbours**: trimesh builds its operator from the *directed* face
//!   edges: vertex `v`'s neighbours are the distinct `j` with an edge `v → j` in some triangle,
//!   each weighted `1 / c` where `c` counts those edges with repetition. On a closed manifold
//!   mesh this is the plain 1-ring average; on a boundary a vertex sees only its outgoing
//!   boundary neighbour, and duplicated triangles make the weights sum to less than one. We
//!   reproduce that operator exactly.
//! - **Volume constraint**: the volume and centre of mass are trimesh's (Eberly's polyhedral
//!   mass properties in f64); the rescale by `(V_0 / V)^(1/3)` is skipped when that ratio is not
//!   a finite positive number (trimesh would write NaN or complex values).
//! - **Cotangent weights** use the cotangents of the angles opposite each edge in its incident
//!   triangles, recomputed from the previous iterate on every pass. Each cotangent is clamped at
//!   zero, so obtuse angles never give negative weights (which make the explicit scheme
//!   unstable); degenerate triangles contribute nothing.
//! - **Normals**: Open3D also smooths vertex normals; we recompute area-weighted vertex normals
//!   from the smoothed positions when the input had normals. UVs and colours are kept.
//! - **Self-loops**: a triangle with a repeated vertex gives Open3D a neighbour at distance 0
//!   (weight 1e12, which freezes that vertex); the 1-ring here skips such edges.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::mesh::TriMesh;

/// Default number of iterations (trimesh's default; Open3D's is 1).
pub const DEFAULT_ITERATIONS: usize = 10;
/// Default λ (Open3D's and trimesh's).
pub const DEFAULT_LAMBDA: f64 = 0.5;
/// Default μ of Taubin smoothing (Open3D's).
pub const DEFAULT_MU: f64 = -0.53;
/// Open3D's offset in the inverse-distance weight `1 / (d + ε)`, so coincident neighbours get
/// a large finite weight. It is part of Open3D's definition, so it is absolute, not scaled.
pub const INVERSE_DISTANCE_OFFSET: f64 = 1e-12;

/// Vertices per parallel work item.
const VERTEX_CHUNK: usize = 1024;

/// Which smoothing operator to apply.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum SmoothMethod {
    /// Open3D's Laplacian with inverse-distance weights.
    #[default]
    Laplacian,
    /// Open3D's Taubin (λ pass then μ pass per iteration), which shrinks far less.
    Taubin,
    /// trimesh's uniform-weight Laplacian with the volume constraint.
    Uniform,
    /// Cotangent weights (clamped at zero).
    Cotangent,
}

/// Options of [`smooth`].
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SmoothOptions {
    /// Smoothing operator: laplacian (Open3D), taubin (Open3D), uniform (trimesh, volume
    /// preserving) or cotangent.
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = SmoothMethod::Laplacian))]
    pub method: SmoothMethod,
    /// Number of iterations (0 returns the input unchanged).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = DEFAULT_ITERATIONS))]
    pub iterations: usize,
    /// Step λ of each (first) pass.
    #[cfg_attr(
        feature = "cli",
        arg(long, default_value_t = DEFAULT_LAMBDA, allow_negative_numbers = true)
    )]
    pub lambda: f64,
    /// Step μ of Taubin's second pass (negative: it inflates).
    #[cfg_attr(
        feature = "cli",
        arg(long, default_value_t = DEFAULT_MU, allow_negative_numbers = true)
    )]
    pub mu: f64,
}

impl Default for SmoothOptions {
    fn default() -> Self {
        Self {
            method: SmoothMethod::Laplacian,
            iterations: DEFAULT_ITERATIONS,
            lambda: DEFAULT_LAMBDA,
            mu: DEFAULT_MU,
        }
    }
}

/// Errors of [`smooth`].
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum SmoothError {
    /// λ or μ is NaN or infinite.
    #[error("{name} = {value} is not a finite number")]
    BadParameter {
        /// `"lambda"` or `"mu"`.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// The iteration diverged (a step outside the stable range): a smoothed position is not
    /// finite.
    #[error("smoothing diverged: vertex {vertex} is no longer finite")]
    Diverged {
        /// First vertex whose position is not finite.
        vertex: usize,
    },
}

/// Smooths `mesh` and returns the smoothed copy (same triangles, UVs and colours; vertex
/// normals recomputed when the input had them).
///
/// # Errors
/// [`SmoothError::BadParameter`] for a non-finite λ or μ, [`SmoothError::Diverged`] when a
/// position is no longer finite.
pub fn smooth(mesh: &TriMesh, options: &SmoothOptions) -> Result<TriMesh, SmoothError> {
    let positions = smooth_positions(mesh, options)?;
    let had_normals = mesh.normals().is_some();
    let mut out = mesh.clone();
    out.set_positions(positions)
        .map_err(|_| SmoothError::Diverged { vertex: 0 })?;
    if had_normals {
        let normals = out.vertex_normals();
        // One normal per vertex by construction.
        out = out
            .with_normals(normals)
            .expect("vertex_normals returns one normal per vertex");
    }
    Ok(out)
}

/// The smoothed vertex positions (what [`smooth`] puts in the mesh).
///
/// # Errors
/// As [`smooth`].
pub fn smooth_positions(
    mesh: &TriMesh,
    options: &SmoothOptions,
) -> Result<Vec<DVec3>, SmoothError> {
    check_finite("lambda", options.lambda)?;
    if options.method == SmoothMethod::Taubin {
        check_finite("mu", options.mu)?;
    }
    let mut prev: Vec<DVec3> = mesh.positions().to_vec();
    if options.iterations == 0 || prev.is_empty() {
        return Ok(prev);
    }
    let mut next = vec![DVec3::ZERO; prev.len()];
    let iterations = options.iterations;
    let lambda = options.lambda;
    match options.method {
        SmoothMethod::Laplacian | SmoothMethod::Taubin => {
            let adjacency = OneRing::new(mesh.vertex_count(), mesh.triangles());
            let steps: &[f64] = if options.method == SmoothMethod::Taubin {
                &[lambda, options.mu]
            } else {
                &[lambda]
            };
            for _ in 0..iterations {
                for &step in steps {
                    jacobi_pass(&prev, &mut next, |v, x, prev| {
                        inverse_distance_update(&adjacency, v, x, prev, step)
                    });
                    std::mem::swap(&mut prev, &mut next);
                }
            }
        }
        SmoothMethod::Uniform => {
            let operator = DirectedUmbrella::new(mesh.vertex_count(), mesh.triangles());
            let initial = MassProperties::of(&prev, mesh.triangles());
            for _ in 0..iterations {
                jacobi_pass(&prev, &mut next, |v, x, prev| {
                    operator.update(v, x, prev, lambda)
                });
                std::mem::swap(&mut prev, &mut next);
                let now = MassProperties::of(&prev, mesh.triangles());
                let ratio = initial.volume / now.volume;
                if ratio.is_finite() && ratio > 0.0 {
                    let scale = ratio.cbrt();
                    let center = initial.center_mass;
                    prev.par_iter_mut()
                        .for_each(|p| *p = (*p - center) * scale + center);
                }
            }
        }
        SmoothMethod::Cotangent => {
            let rings = TriangleRings::new(mesh.vertex_count(), mesh.triangles());
            for _ in 0..iterations {
                jacobi_pass(&prev, &mut next, |v, x, prev| {
                    rings.update(v, x, prev, lambda)
                });
                std::mem::swap(&mut prev, &mut next);
            }
        }
    }
    if let Some(vertex) = prev.iter().position(|p| !p.is_finite()) {
        return Err(SmoothError::Diverged { vertex });
    }
    Ok(prev)
}

/// Taubin smoothing by Open3D's rule (as [`smooth_positions`] with [`SmoothMethod::Taubin`]:
/// inverse-distance weights over the 1-rings of `triangles`, a λ then a μ Jacobi step per
/// iteration) that moves only the vertices whose `free` is true; the others are held and still
/// pull their neighbours. A step whose result is not finite leaves that vertex where it was,
/// so the output is finite wherever the input is. Same bits as [`smooth_positions`] for the
/// vertices it moves when every vertex is free.
#[must_use]
pub fn taubin_held(
    positions: Vec<DVec3>,
    triangles: &[[u32; 3]],
    free: &[bool],
    iterations: u32,
    lambda: f64,
    mu: f64,
) -> Vec<DVec3> {
    if iterations == 0 || !free.iter().any(|&f| f) {
        return positions;
    }
    let adjacency = OneRing::new(positions.len(), triangles);
    let mut prev = positions;
    let mut next = vec![DVec3::ZERO; prev.len()];
    for _ in 0..iterations {
        for step in [lambda, mu] {
            jacobi_pass(&prev, &mut next, |v, x, prev| {
                if !free[v] {
                    return x;
                }
                let moved = inverse_distance_update(&adjacency, v, x, prev, step);
                if moved.is_finite() { moved } else { x }
            });
            std::mem::swap(&mut prev, &mut next);
        }
    }
    prev
}

fn check_finite(name: &'static str, value: f64) -> Result<(), SmoothError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(SmoothError::BadParameter { name, value })
    }
}

/// One Jacobi pass: `next[v] = update(v, prev[v], prev)` for every vertex, in parallel.
fn jacobi_pass<F>(prev: &[DVec3], next: &mut [DVec3], update: F)
where
    F: Fn(usize, DVec3, &[DVec3]) -> DVec3 + Sync,
{
    next.par_chunks_mut(VERTEX_CHUNK)
        .enumerate()
        .for_each(|(chunk, out)| {
            let base = chunk * VERTEX_CHUNK;
            for (i, o) in out.iter_mut().enumerate() {
                let v = base + i;
                *o = update(v, prev[v], prev);
            }
        });
}

/// `x + step (Σ w_j x_j / Σ w_j − x)`, or `x` when the weights sum to zero.
#[inline]
fn relax(x: DVec3, weighted_sum: DVec3, weight_total: f64, step: f64) -> DVec3 {
    if weight_total > 0.0 {
        x + step * (weighted_sum / weight_total - x)
    } else {
        x
    }
}

/// Open3D's inverse-distance Laplacian update of vertex `v`.
#[inline]
fn inverse_distance_update(
    adjacency: &OneRing,
    v: usize,
    x: DVec3,
    prev: &[DVec3],
    step: f64,
) -> DVec3 {
    let mut sum = DVec3::ZERO;
    let mut total = 0.0;
    for &j in adjacency.neighbors(v) {
        let xj = prev[j as usize];
        let w = 1.0 / ((x - xj).length() + INVERSE_DISTANCE_OFFSET);
        total += w;
        sum += w * xj;
    }
    relax(x, sum, total, step)
}

/// The 1-ring of every vertex (sorted, unique, no self-loops): the same lists as
/// [`crate::topology::VertexAdjacency`], built with a counting pass and parallel per-vertex
/// sorts instead of one global edge sort.
struct OneRing {
    offsets: Vec<usize>,
    neighbors: Vec<u32>,
}

impl OneRing {
    fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Self {
        let edges =
            |&[a, b, c]: &[u32; 3]| [(a, b), (b, c), (c, a)].into_iter().filter(|(p, q)| p != q);
        let mut raw_offsets = vec![0usize; vertex_count + 1];
        for tri in triangles {
            for (p, q) in edges(tri) {
                raw_offsets[p as usize + 1] += 1;
                raw_offsets[q as usize + 1] += 1;
            }
        }
        for i in 1..raw_offsets.len() {
            raw_offsets[i] += raw_offsets[i - 1];
        }
        let mut fill = raw_offsets.clone();
        let mut raw = vec![0u32; raw_offsets[vertex_count]];
        for tri in triangles {
            for (p, q) in edges(tri) {
                raw[fill[p as usize]] = q;
                fill[p as usize] += 1;
                raw[fill[q as usize]] = p;
                fill[q as usize] += 1;
            }
        }
        // Split into one slice per vertex, sort and dedup each in parallel.
        let mut slices: Vec<&mut [u32]> = Vec::with_capacity(vertex_count);
        let mut rest = raw.as_mut_slice();
        for v in 0..vertex_count {
            let (head, tail) = rest.split_at_mut(raw_offsets[v + 1] - raw_offsets[v]);
            slices.push(head);
            rest = tail;
        }
        let unique: Vec<usize> = slices
            .into_par_iter()
            .map(|list| {
                list.sort_unstable();
                let mut n = 0;
                for i in 0..list.len() {
                    if n == 0 || list[i] != list[n - 1] {
                        list[n] = list[i];
                        n += 1;
                    }
                }
                n
            })
            .collect();
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        offsets.push(0usize);
        let mut neighbors = Vec::with_capacity(unique.iter().sum());
        for (v, &n) in unique.iter().enumerate() {
            neighbors.extend_from_slice(&raw[raw_offsets[v]..raw_offsets[v] + n]);
            offsets.push(neighbors.len());
        }
        Self { offsets, neighbors }
    }

    #[inline]
    fn neighbors(&self, v: usize) -> &[u32] {
        &self.neighbors[self.offsets[v]..self.offsets[v + 1]]
    }
}

/// trimesh's uniform operator: distinct directed-edge neighbours, divisor = edge count.
struct DirectedUmbrella {
    offsets: Vec<usize>,
    neighbors: Vec<u32>,
    divisor: Vec<f64>,
}

impl DirectedUmbrella {
    fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Self {
        let mut divisor = vec![0.0f64; vertex_count];
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(triangles.len() * 3);
        for &[a, b, c] in triangles {
            for (from, to) in [(a, b), (b, c), (c, a)] {
                divisor[from as usize] += 1.0;
                pairs.push((from, to));
            }
        }
        pairs.par_sort_unstable();
        pairs.dedup();
        let mut offsets = vec![0usize; vertex_count + 1];
        for &(from, _) in &pairs {
            offsets[from as usize + 1] += 1;
        }
        for i in 1..offsets.len() {
            offsets[i] += offsets[i - 1];
        }
        let neighbors = pairs.into_iter().map(|(_, to)| to).collect();
        Self {
            offsets,
            neighbors,
            divisor,
        }
    }

    #[inline]
    fn update(&self, v: usize, x: DVec3, prev: &[DVec3], step: f64) -> DVec3 {
        let mut sum = DVec3::ZERO;
        for &j in &self.neighbors[self.offsets[v]..self.offsets[v + 1]] {
            sum += prev[j as usize];
        }
        relax(x, sum, self.divisor[v], step)
    }
}

/// For every vertex, the other two corners of each incident (non-degenerate-index) triangle,
/// in the triangle's winding order.
struct TriangleRings {
    offsets: Vec<usize>,
    others: Vec<[u32; 2]>,
}

impl TriangleRings {
    fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Self {
        let distinct = |&&[a, b, c]: &&[u32; 3]| a != b && b != c && a != c;
        let mut offsets = vec![0usize; vertex_count + 1];
        for tri in triangles.iter().filter(distinct) {
            for &v in tri {
                offsets[v as usize + 1] += 1;
            }
        }
        for i in 1..offsets.len() {
            offsets[i] += offsets[i - 1];
        }
        let mut fill = offsets.clone();
        let mut others = vec![[0u32; 2]; offsets[vertex_count]];
        for &[a, b, c] in triangles.iter().filter(distinct) {
            for (v, p, q) in [(a, b, c), (b, c, a), (c, a, b)] {
                others[fill[v as usize]] = [p, q];
                fill[v as usize] += 1;
            }
        }
        Self { offsets, others }
    }

    #[inline]
    fn update(&self, v: usize, x: DVec3, prev: &[DVec3], step: f64) -> DVec3 {
        let mut sum = DVec3::ZERO;
        let mut total = 0.0;
        for &[p, q] in &self.others[self.offsets[v]..self.offsets[v + 1]] {
            let (xp, xq) = (prev[p as usize], prev[q as usize]);
            // The angle at q is opposite the edge (v, p), the angle at p opposite (v, q).
            let w_p = 0.5 * clamped_cot(x - xq, xp - xq);
            let w_q = 0.5 * clamped_cot(x - xp, xq - xp);
            sum += w_p * xp + w_q * xq;
            total += w_p + w_q;
        }
        relax(x, sum, total, step)
    }
}

/// `max(cot θ, 0)` of the angle between `u` and `w`; 0 when they are parallel or zero.
#[inline]
fn clamped_cot(u: DVec3, w: DVec3) -> f64 {
    let sin_scaled = u.cross(w).length();
    if sin_scaled > 0.0 {
        (u.dot(w) / sin_scaled).max(0.0)
    } else {
        0.0
    }
}

/// Volume and centre of mass as trimesh's `triangles.mass_properties` (Eberly's polyhedral
/// mass properties).
struct MassProperties {
    volume: f64,
    center_mass: DVec3,
}

impl MassProperties {
    fn of(positions: &[DVec3], triangles: &[[u32; 3]]) -> Self {
        // Summed over fixed chunks, then the chunks in order: the same sums whatever the
        // threads (rayon's `reduce` splits where work is stolen, which moves the last bits).
        const CHUNK: usize = 4096;
        let add = |(v0, m0): (f64, DVec3), (v1, m1): (f64, DVec3)| (v0 + v1, m0 + m1);
        let partials: Vec<(f64, DVec3)> = triangles
            .par_chunks(CHUNK)
            .map(|chunk| {
                chunk.iter().fold((0.0, DVec3::ZERO), |acc, &[a, b, c]| {
                    let (p0, p1, p2) = (
                        positions[a as usize],
                        positions[b as usize],
                        positions[c as usize],
                    );
                    let cross = (p1 - p0).cross(p2 - p0);
                    let f1 = p0 + p1 + p2;
                    let f2 = p0 * p0 + p1 * p1 + p0 * p1 + p2 * f1;
                    add(acc, (cross.x * f1.x, cross * f2))
                })
            })
            .collect();
        let (x_integral, first_moments) = partials.into_iter().fold((0.0, DVec3::ZERO), add);
        let volume = x_integral / 6.0;
        Self {
            volume,
            center_mass: first_moments / 24.0 / volume,
        }
    }
}

/// Convenience: f32 positions of a smoothed f64 array (rounded once).
#[must_use]
pub fn to_f32(positions: &[DVec3]) -> Vec<Vec3> {
    positions.iter().map(|p| p.as_vec3()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn octahedron() -> TriMesh {
        let p = vec![
            Vec3::X,
            -Vec3::X,
            Vec3::Y,
            -Vec3::Y,
            Vec3::Z,
            -Vec3::Z * 2.0,
            Vec3::splat(7.0), // isolated
        ];
        TriMesh::new(p, crate::test_meshes::OCTAHEDRON_TRIANGLES.to_vec())
    }

    #[test]
    fn held_taubin_moves_only_free_vertices_and_equals_taubin_when_all_are_free() {
        let m = octahedron();
        let opts = SmoothOptions {
            method: SmoothMethod::Taubin,
            iterations: 3,
            ..SmoothOptions::default()
        };
        let want = smooth_positions(&m, &opts).expect("taubin");
        let start = m.positions().to_vec();
        let all = vec![true; start.len()];
        let got = taubin_held(
            start.clone(),
            m.triangles(),
            &all,
            3,
            DEFAULT_LAMBDA,
            DEFAULT_MU,
        );
        assert_eq!(got, want);
        let mut free = all;
        free[0] = false;
        let held = taubin_held(
            start.clone(),
            m.triangles(),
            &free,
            3,
            DEFAULT_LAMBDA,
            DEFAULT_MU,
        );
        assert_eq!(held[0], start[0]);
        assert_ne!(held[1], want[1], "a held vertex still pulls its neighbours");
    }

    #[test]
    fn one_ring_equals_vertex_adjacency() {
        let mut t = octahedron().triangles().to_vec();
        t.push([0, 0, 1]); // repeated index
        t.push([0, 2, 4]); // duplicate triangle
        let fast = OneRing::new(8, &t);
        let slow = crate::topology::VertexAdjacency::new(8, &t);
        for v in 0..8 {
            assert_eq!(fast.neighbors(v), slow.neighbors(v), "vertex {v}");
        }
    }

    #[test]
    fn zero_iterations_return_input() {
        let m = octahedron();
        for method in [
            SmoothMethod::Laplacian,
            SmoothMethod::Taubin,
            SmoothMethod::Uniform,
            SmoothMethod::Cotangent,
        ] {
            let opts = SmoothOptions {
                method,
                iterations: 0,
                ..SmoothOptions::default()
            };
            assert_eq!(smooth(&m, &opts).unwrap(), m);
        }
    }

    #[test]
    fn isolated_vertex_stays_and_laplacian_matches_hand_computation() {
        let m = octahedron();
        let opts = SmoothOptions {
            iterations: 1,
            ..SmoothOptions::default()
        };
        let out = smooth_positions(&m, &opts).unwrap();
        assert_eq!(out[6], DVec3::splat(7.0));
        // Vertex 4 (0,0,1) has neighbours ±x, ±y at distance sqrt 2: the weighted mean is the
        // origin, so one pass with λ = 0.5 moves it to (0, 0, 0.5).
        assert!((out[4] - DVec3::new(0.0, 0.0, 0.5)).length() < 1e-12);
    }

    #[test]
    fn uniform_preserves_volume_and_cotangent_is_finite() {
        let m = octahedron();
        let v0 = MassProperties::of(m.positions(), m.triangles()).volume;
        let opts = SmoothOptions {
            method: SmoothMethod::Uniform,
            iterations: 5,
            ..SmoothOptions::default()
        };
        let out = smooth_positions(&m, &opts).unwrap();
        let v1 = MassProperties::of(&out, m.triangles()).volume;
        assert!((v1 - v0).abs() < 1e-12 * v0.abs(), "{v0} {v1}");
        let opts = SmoothOptions {
            method: SmoothMethod::Cotangent,
            iterations: 5,
            ..SmoothOptions::default()
        };
        let out = smooth(&m, &opts).unwrap();
        assert!(out.positions().iter().all(|p| p.is_finite()));
    }

    #[test]
    fn bad_parameters_and_divergence_are_errors() {
        let m = octahedron();
        let opts = SmoothOptions {
            lambda: f64::NAN,
            ..SmoothOptions::default()
        };
        assert!(matches!(
            smooth(&m, &opts),
            Err(SmoothError::BadParameter { name: "lambda", .. })
        ));
        let opts = SmoothOptions {
            lambda: -f64::MAX,
            iterations: 3,
            ..SmoothOptions::default()
        };
        let result = smooth(&m, &opts);
        assert!(
            matches!(result, Err(SmoothError::Diverged { .. })),
            "{:?}",
            result.map(|m| m.positions()[0])
        );
    }
}
