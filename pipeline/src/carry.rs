//! One mesh carried through a track by the template's triangles (docs/conventions.md §10).
//!
//! Each vertex of a key mesh is bound to one template triangle `(a, b, c)` by coordinates
//! `(u, v, w)` in the basis `e1 = b - a`, `e2 = c - a`, `m = n / sqrt(|n|)` with
//! `n = e1 x e2`: `x = a + u e1 + v e2 + w m`. The basis follows the triangle: in its plane
//! affinely (so vertices bound to neighbouring triangles move together along shared edges),
//! along its normal with the square root of its area change (the Gaussians' adaptive scale).
//! At the key frame the rule gives the vertex back (to rounding). The triangle is the one the
//! vertex's nearest Gaussian is bound to, so a vertex made from hair Gaussians centimetres off
//! the skin follows the part of the template those Gaussians follow.
//!
//! How far the carried mesh has drifted from a frame's Gaussians ([`Drift`]): the share of
//! probe Gaussians (those within a mean template edge of the key mesh) whose distance to the
//! key-mesh triangle they were nearest changed by more than a tolerance (they hop off the
//! surface), and the share of the key mesh's area in triangles stretched or shrunk twofold.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::spatial::{PointIndex, SurfaceIndex, closest_point_on_triangle};

/// Probes summed together before the partial sums are added in order ([`CarriedMesh::drift`]).
const DRIFT_CHUNK: usize = 1024;

/// Why a mesh cannot be carried.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CarryError {
    /// No Gaussian to bind the vertices by, or no template triangle with area.
    #[error("{0}")]
    Nothing(String),
    /// A spatial index could not be built (non-finite or huge coordinates).
    #[error("{0}")]
    Index(String),
    /// The carried vertices do not fit the key mesh (a collapsed template gave a non-finite
    /// position).
    #[error("the carried mesh: {0}")]
    Placed(String),
}

/// A template triangle's frame: corner `a` and the basis `(e1, e2, m)`.
fn basis(positions: &[DVec3], t: [u32; 3]) -> (DVec3, [DVec3; 3]) {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    let (e1, e2) = (b - a, c - a);
    let n = e1.cross(e2);
    let len = n.length();
    let m = if len > 0.0 {
        n / len.sqrt()
    } else {
        DVec3::ZERO
    };
    (a, [e1, e2, m])
}

/// Where coordinates `uvw` put a vertex on the triangle with corners `corners`: the rule of
/// [`CarriedMesh::place`] for one vertex.
#[must_use]
pub fn place_on(corners: [DVec3; 3], uvw: DVec3) -> DVec3 {
    let (a, [e1, e2, m]) = basis(&corners, [0, 1, 2]);
    a + uvw.x * e1 + uvw.y * e2 + uvw.z * m
}

/// Whether the triangle has a usable frame: its area is not negligible against its edges.
fn has_area(positions: &[DVec3], t: [u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    let n = (b - a).cross(c - a).length();
    let scale = (b - a)
        .length_squared()
        .max((c - a).length_squared())
        .max((c - b).length_squared());
    n.is_finite() && scale > 0.0 && n > 1e-9 * scale
}

/// A key mesh bound to the template's triangles.
#[derive(Clone, Debug)]
pub struct CarriedMesh {
    /// The key mesh as extracted (its triangles and colours are kept).
    key: TriMesh,
    /// Each key vertex's template triangle.
    triangle: Vec<u32>,
    /// Each key vertex's `(u, v, w)` in that triangle's basis.
    coords: Vec<DVec3>,
    /// Area of each key-mesh triangle at the key frame.
    key_area: Vec<f64>,
    /// Probes: (Gaussian index in the kept means, key-mesh triangle, distance at the key,
    /// position at the key).
    probes: Vec<(u32, u32, f64, Vec3)>,
    /// The largest distance from a key vertex to the Gaussian it was bound by.
    farthest: f64,
}

impl CarriedMesh {
    /// Binds `key` (the mesh of the key frame) to the template at `positions` (welded, local,
    /// `triangles` its triangles): each vertex to the triangle of its nearest Gaussian
    /// (`means`, bound to `gaussian_triangles`), or, when that triangle has no area in this
    /// frame, to the nearest template triangle that has. `probes` are the Gaussians the drift
    /// is measured by (the kept means), those within `reach` of the key mesh.
    ///
    /// # Errors
    /// [`CarryError::Nothing`] without Gaussians or template triangles with area;
    /// [`CarryError::Index`] when an index cannot be built.
    pub fn bind(
        key: TriMesh,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        means: &[Vec3],
        gaussian_triangles: &[u32],
        probes: &[Vec3],
        reach: f64,
    ) -> Result<Self, CarryError> {
        if means.is_empty() || means.len() != gaussian_triangles.len() {
            return Err(CarryError::Nothing(format!(
                "{} Gaussian means for {} bindings: nothing to bind the mesh by",
                means.len(),
                gaussian_triangles.len()
            )));
        }
        let usable: Vec<bool> = triangles.iter().map(|t| has_area(positions, *t)).collect();
        let vertices: Vec<Vec3> = key.positions().iter().map(|p| p.as_vec3()).collect();
        let nearest = if vertices.is_empty() {
            Vec::new()
        } else {
            PointIndex::new(means)
                .and_then(|index| index.nearest_batch(&vertices))
                .map_err(|e| CarryError::Index(format!("the Gaussians: {e}")))?
        };
        let farthest = nearest.iter().map(|n| n.distance).fold(0.0, f64::max);
        let mut triangle: Vec<u32> = nearest
            .iter()
            .map(|n| gaussian_triangles[n.index as usize])
            .collect();
        // Vertices whose Gaussian's triangle has no area here take the nearest one that has.
        let stranded: Vec<usize> = (0..triangle.len())
            .filter(|&i| !usable.get(triangle[i] as usize).copied().unwrap_or(false))
            .collect();
        if !stranded.is_empty() {
            let ids: Vec<u32> = (0..triangles.len() as u32)
                .filter(|&t| usable[t as usize])
                .collect();
            if ids.is_empty() {
                return Err(CarryError::Nothing(
                    "every template triangle is degenerate in the key frame".to_owned(),
                ));
            }
            let kept: Vec<[u32; 3]> = ids.iter().map(|&t| triangles[t as usize]).collect();
            let index = SurfaceIndex::new(positions, &kept)
                .map_err(|e| CarryError::Index(format!("the template: {e}")))?;
            let queries: Vec<Vec3> = stranded.iter().map(|&i| vertices[i]).collect();
            let hits = index
                .closest_batch(&queries)
                .map_err(|e| CarryError::Index(format!("the template: {e}")))?;
            for (&i, hit) in stranded.iter().zip(&hits) {
                triangle[i] = ids[hit.triangle as usize];
            }
        }
        let coords = key
            .positions()
            .par_iter()
            .zip(&triangle)
            .map(|(&x, &t)| {
                let (a, [e1, e2, m]) = basis(positions, triangles[t as usize]);
                let inverse = glam::DMat3::from_cols(e1, e2, m).inverse();
                let uvw = inverse * (x - a);
                if uvw.is_finite() { uvw } else { DVec3::ZERO }
            })
            .collect();
        let key_area = triangle_areas(key.positions(), key.triangles());
        let probes = probes_of(&key, probes, reach)?;
        Ok(Self {
            key,
            triangle,
            coords,
            key_area,
            probes,
            farthest,
        })
    }

    /// Each key vertex's template triangle and its `(u, v, w)` in that triangle's basis (see
    /// the module docs): what a rig moved onto the key mesh interpolates by.
    #[must_use]
    pub fn binding(&self) -> (&[u32], &[DVec3]) {
        (&self.triangle, &self.coords)
    }

    /// The key mesh as extracted.
    #[must_use]
    pub fn key(&self) -> &TriMesh {
        &self.key
    }

    /// The largest distance from a key vertex to the Gaussian it was bound by.
    #[must_use]
    pub fn farthest(&self) -> f64 {
        self.farthest
    }

    /// The carried vertices for the template at `positions` (same triangles as at the key),
    /// into `out`.
    pub fn place(&self, positions: &[DVec3], triangles: &[[u32; 3]], out: &mut Vec<DVec3>) {
        out.clear();
        out.par_extend(self.triangle.par_iter().zip(&self.coords).map(|(&t, uvw)| {
            let (a, [e1, e2, m]) = basis(positions, triangles[t as usize]);
            a + uvw.x * e1 + uvw.y * e2 + uvw.z * m
        }));
    }

    /// The key mesh with its vertices at `vertices` (from [`CarriedMesh::place`]); stored
    /// normals are dropped (they would be the key's).
    ///
    /// # Errors
    /// [`CarryError::Placed`] when `vertices` has another count or a non-finite position.
    pub fn mesh(&self, vertices: Vec<DVec3>) -> Result<TriMesh, CarryError> {
        let mut mesh = self.key.clone();
        mesh.set_positions(vertices)
            .map_err(|e| CarryError::Placed(e.to_string()))?;
        mesh.clear_normals();
        Ok(mesh)
    }

    /// How far the mesh with its vertices at `vertices` has drifted from Gaussians at
    /// `probes` (the kept means, in the order given to [`CarriedMesh::bind`]).
    #[must_use]
    pub fn drift(&self, vertices: &[DVec3], probes: &[Vec3], tolerance: f64) -> Drift {
        let triangles = self.key.triangles();
        // Per probe: whether it hops, how far its distance changed (0 where not finite), and
        // how far it moved since the key. Summed per fixed chunk, then the chunks in order, so
        // that the sums do not depend on the thread count (shards must equal one run).
        let per_probe = |&(g, t, d0, at_key): &(u32, u32, f64, Vec3)| {
            let Some(p) = probes.get(g as usize) else {
                return (1usize, 0.0, 0.0);
            };
            let [a, b, c] = triangles[t as usize].map(|i| vertices[i as usize]);
            let (q, _) = closest_point_on_triangle(p.as_dvec3(), a, b, c);
            let change = ((q - p.as_dvec3()).length() - d0).abs();
            let moved = f64::from((*p - at_key).length());
            // A non-finite distance (a collapsed triangle) counts as a hop.
            if change.is_finite() && moved.is_finite() {
                (usize::from(change > tolerance), change, moved)
            } else {
                (1, 0.0, 0.0)
            }
        };
        let add = |x: (usize, f64, f64), y: (usize, f64, f64)| (x.0 + y.0, x.1 + y.1, x.2 + y.2);
        let (hops, offset, moved) = self
            .probes
            .par_chunks(DRIFT_CHUNK)
            .map(|chunk| chunk.iter().map(per_probe).fold((0, 0.0, 0.0), add))
            .collect::<Vec<_>>()
            .into_iter()
            .fold((0, 0.0, 0.0), add);
        let areas = triangle_areas(vertices, triangles);
        let (stretched, total) =
            self.key_area
                .iter()
                .zip(&areas)
                .fold((0.0, 0.0), |(s, total), (&a0, &a)| {
                    let off = a0 > 0.0 && (a > 2.0 * a0 || 2.0 * a < a0 || !a.is_finite());
                    (if off { s + a0 } else { s }, total + a0)
                });
        Drift {
            hops: if self.probes.is_empty() {
                0.0
            } else {
                hops as f64 / self.probes.len() as f64
            },
            stretched: if total > 0.0 { stretched / total } else { 0.0 },
            offset: if self.probes.is_empty() {
                0.0
            } else {
                offset / self.probes.len() as f64
            },
            moved: if self.probes.is_empty() {
                0.0
            } else {
                moved / self.probes.len() as f64
            },
            probes: self.probes.len(),
        }
    }
}

/// How far a carried mesh has drifted from a frame's Gaussians.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drift {
    /// Share of the probe Gaussians that hop.
    pub hops: f64,
    /// Share of the key mesh's area in triangles stretched or shrunk more than twofold.
    pub stretched: f64,
    /// Mean over the probes of how far (scene units) each one's distance to its carried
    /// triangle changed since the key: how far the surface the Gaussians make has moved off
    /// the carried mesh, however small (a hop is a change past a tolerance).
    pub offset: f64,
    /// Mean distance (scene units) the probes moved since the key: how far the surface has
    /// travelled through space, which a method sampling a grid fixed in space (tsdf) sees as a
    /// new sampling of it even where the carried mesh follows it.
    pub moved: f64,
    /// Number of probe Gaussians.
    pub probes: usize,
}

/// Area of each triangle.
fn triangle_areas(positions: &[DVec3], triangles: &[[u32; 3]]) -> Vec<f64> {
    triangles
        .par_iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .collect()
}

/// The probes of `key`: each point within `reach` of it, with its nearest triangle, distance
/// and position.
fn probes_of(
    key: &TriMesh,
    points: &[Vec3],
    reach: f64,
) -> Result<Vec<(u32, u32, f64, Vec3)>, CarryError> {
    if key.triangle_count() == 0 || points.is_empty() {
        return Ok(Vec::new());
    }
    let index = SurfaceIndex::new(key.positions(), key.triangles())
        .map_err(|e| CarryError::Index(format!("the key mesh: {e}")))?;
    let hits = index
        .closest_batch(points)
        .map_err(|e| CarryError::Index(format!("the key mesh: {e}")))?;
    Ok(hits
        .iter()
        .enumerate()
        .filter(|(_, h)| h.distance <= reach)
        .map(|(g, h)| (g as u32, h.triangle, h.distance, points[g]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 x 4 grid of unit squares in the z = 0 plane, two triangles each.
    fn grid() -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let n = 5u32;
        let positions = (0..n * n)
            .map(|i| DVec3::new(f64::from(i % n), f64::from(i / n), 0.0))
            .collect();
        let mut triangles = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = y * n + x;
                triangles.push([i, i + 1, i + n + 1]);
                triangles.push([i, i + n + 1, i + n]);
            }
        }
        (positions, triangles)
    }

    /// One Gaussian at each triangle's centroid, lifted by `lift`, bound to it.
    fn gaussians(positions: &[DVec3], triangles: &[[u32; 3]], lift: f64) -> (Vec<Vec3>, Vec<u32>) {
        triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let c = tri.iter().map(|&i| positions[i as usize]).sum::<DVec3>() / 3.0;
                ((c + DVec3::Z * lift).as_vec3(), t as u32)
            })
            .unzip()
    }

    /// A small mesh floating 0.3 above the grid, off the triangles' centres.
    fn key_mesh() -> TriMesh {
        TriMesh::new(
            vec![
                DVec3::new(0.7, 0.4, 0.3),
                DVec3::new(2.9, 0.6, 0.3),
                DVec3::new(1.3, 3.1, 0.35),
                DVec3::new(3.6, 3.4, 0.25),
            ],
            vec![[0, 1, 2], [1, 3, 2]],
        )
    }

    fn bound(positions: &[DVec3], triangles: &[[u32; 3]]) -> (CarriedMesh, Vec<Vec3>) {
        let (means, owners) = gaussians(positions, triangles, 0.3);
        let carried = CarriedMesh::bind(
            key_mesh(),
            positions,
            triangles,
            &means,
            &owners,
            &means,
            1.0,
        )
        .expect("bind");
        (carried, means)
    }

    #[test]
    fn the_key_frame_gives_the_key_mesh_back() {
        let (positions, triangles) = grid();
        let (carried, _) = bound(&positions, &triangles);
        let mut out = Vec::new();
        carried.place(&positions, &triangles, &mut out);
        for (a, b) in out.iter().zip(key_mesh().positions()) {
            assert!((*a - *b).length() < 1e-12, "{a} vs {b}");
        }
        assert!(carried.farthest() < 1.0);
    }

    #[test]
    fn a_similarity_of_the_template_carries_the_mesh_exactly() {
        let (positions, triangles) = grid();
        let (carried, means) = bound(&positions, &triangles);
        let turn = glam::DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 0.5).normalize(), 0.9);
        let (scale, shift) = (1.7, DVec3::new(-3.0, 0.5, 10.0));
        let moved = |p: DVec3| turn * (p * scale) + shift;
        let frame: Vec<DVec3> = positions.iter().map(|&p| moved(p)).collect();
        let mut out = Vec::new();
        carried.place(&frame, &triangles, &mut out);
        for (a, b) in out.iter().zip(key_mesh().positions()) {
            assert!((*a - moved(*b)).length() < 1e-9, "{a} vs {}", moved(*b));
        }
        // Turned and shifted (not scaled: drift measures lengths), the Gaussians moved alike:
        // nothing hops, nothing stretches.
        let rigid = |p: DVec3| turn * p + shift;
        let frame: Vec<DVec3> = positions.iter().map(|&p| rigid(p)).collect();
        carried.place(&frame, &triangles, &mut out);
        let probes: Vec<Vec3> = means
            .iter()
            .map(|m| rigid(m.as_dvec3()).as_vec3())
            .collect();
        let drift = carried.drift(&out, &probes, 1e-5);
        assert!(drift.probes > 0);
        assert_eq!((drift.hops, drift.stretched), (0.0, 0.0), "{drift:?}");
    }

    #[test]
    fn an_in_plane_stretch_moves_points_on_the_surface_affinely() {
        let (positions, triangles) = grid();
        let (means, owners) = gaussians(&positions, &triangles, 0.0);
        let flat = TriMesh::new(
            vec![
                DVec3::new(0.5, 0.5, 0.0),
                DVec3::new(3.5, 0.2, 0.0),
                DVec3::new(2.0, 3.9, 0.0),
            ],
            vec![[0, 1, 2]],
        );
        let carried = CarriedMesh::bind(
            flat.clone(),
            &positions,
            &triangles,
            &means,
            &owners,
            &means,
            1.0,
        )
        .expect("bind");
        let shear = |p: DVec3| DVec3::new(2.0 * p.x + 0.5 * p.y, p.y, p.z);
        let frame: Vec<DVec3> = positions.iter().map(|&p| shear(p)).collect();
        let mut out = Vec::new();
        carried.place(&frame, &triangles, &mut out);
        for (a, b) in out.iter().zip(flat.positions()) {
            assert!((*a - shear(*b)).length() < 1e-12);
        }
        // Doubled in x: every carried triangle's area doubled, at the limit, not past it.
        let drift = carried.drift(&out, &[], 1.0);
        assert_eq!(drift.stretched, 0.0);
        let wider: Vec<DVec3> = positions
            .iter()
            .map(|&p| DVec3::new(2.5 * p.x, p.y, p.z))
            .collect();
        carried.place(&wider, &triangles, &mut out);
        assert_eq!(carried.drift(&out, &[], 1.0).stretched, 1.0);
    }

    #[test]
    fn gaussians_that_leave_the_surface_hop() {
        let (positions, triangles) = grid();
        let (carried, means) = bound(&positions, &triangles);
        let mut out = Vec::new();
        carried.place(&positions, &triangles, &mut out);
        let half = means.len() / 2;
        let probes: Vec<Vec3> = means
            .iter()
            .enumerate()
            .map(|(i, m)| if i < half { *m + Vec3::Z * 0.5 } else { *m })
            .collect();
        let drift = carried.drift(&out, &probes, 0.1);
        let hopped = carried
            .probes
            .iter()
            .filter(|p| (p.0 as usize) < half)
            .count();
        assert_eq!(drift.hops, hopped as f64 / drift.probes as f64);
        assert!(drift.hops > 0.0 && drift.hops < 1.0, "{drift:?}");
    }

    #[test]
    fn the_offset_is_the_mean_change_of_the_probes_distances() {
        let (positions, triangles) = grid();
        let (means, owners) = gaussians(&positions, &triangles, 0.0);
        // A flat key mesh 0.3 above the grid, over every Gaussian.
        let lid = TriMesh::new(
            vec![
                DVec3::new(-1.0, -1.0, 0.3),
                DVec3::new(5.0, -1.0, 0.3),
                DVec3::new(5.0, 5.0, 0.3),
                DVec3::new(-1.0, 5.0, 0.3),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let carried = CarriedMesh::bind(lid, &positions, &triangles, &means, &owners, &means, 1.0)
            .expect("bind");
        let mut out = Vec::new();
        carried.place(&positions, &triangles, &mut out);
        let drift = carried.drift(&out, &means, 0.1);
        assert_eq!((drift.probes, drift.offset), (means.len(), 0.0));
        // Every third Gaussian 0.02 farther from the key mesh: below the hop tolerance, so
        // nothing hops, yet the offset is their share of 0.02.
        let probes: Vec<Vec3> = means
            .iter()
            .enumerate()
            .map(|(i, m)| if i % 3 == 0 { *m - Vec3::Z * 0.02 } else { *m })
            .collect();
        let drift = carried.drift(&out, &probes, 0.1);
        assert_eq!(drift.hops, 0.0);
        let moved = means.len().div_ceil(3);
        let expected = 0.02 * moved as f64 / means.len() as f64;
        assert!(
            (drift.offset - expected).abs() < 1e-6,
            "{drift:?} vs {expected}"
        );
    }

    #[test]
    fn a_degenerate_key_triangle_hands_its_vertices_to_one_with_area() {
        let (mut positions, triangles) = grid();
        let (means, _) = gaussians(&positions, &triangles, 0.3);
        // Every Gaussian claims triangle 0, which collapses in the key frame.
        let owners = vec![0u32; means.len()];
        positions[1] = positions[0];
        let carried = CarriedMesh::bind(
            key_mesh(),
            &positions,
            &triangles,
            &means,
            &owners,
            &means,
            1.0,
        )
        .expect("bind");
        assert!(carried.triangle.iter().all(|&t| t != 0));
        let mut out = Vec::new();
        carried.place(&positions, &triangles, &mut out);
        for (a, b) in out.iter().zip(key_mesh().positions()) {
            assert!((*a - *b).length() < 1e-12);
        }
    }

    #[test]
    fn nothing_to_bind_by_is_an_error() {
        let (positions, triangles) = grid();
        let e = CarriedMesh::bind(key_mesh(), &positions, &triangles, &[], &[], &[], 1.0)
            .expect_err("no Gaussians");
        assert!(matches!(e, CarryError::Nothing(_)), "{e}");
        let flat = vec![DVec3::ZERO; positions.len()];
        let (means, owners) = gaussians(&positions, &triangles, 0.3);
        let e = CarriedMesh::bind(key_mesh(), &flat, &triangles, &means, &owners, &means, 1.0)
            .expect_err("every triangle collapsed");
        assert!(e.to_string().contains("degenerate"), "{e}");
    }

    #[test]
    fn a_collapsed_frame_places_finite_vertices() {
        let (positions, triangles) = grid();
        let (carried, _) = bound(&positions, &triangles);
        let flat = vec![DVec3::new(1.0, 2.0, 3.0); positions.len()];
        let mut out = Vec::new();
        carried.place(&flat, &triangles, &mut out);
        assert!(out.iter().all(|p| p.is_finite()));
        assert!(carried.mesh(out).is_ok());
    }
}
