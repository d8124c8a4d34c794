//! Mesh decimation through meshoptimizer's simplifier (`meshopt::simplify`), and what it cost.
//!
//! [`simplify`] collapses edges of a triangle mesh until it has at most a target number of
//! triangles ([`SimplifyTarget::Faces`]) or until the next collapse would move the surface by
//! more than a share of the mesh's extent ([`SimplifyTarget::Error`], meshoptimizer's relative
//! error: the share of the largest side of the mesh's bounding box). The simplifier keeps a
//! subset of the original vertices in place (no vertex moves), so per-vertex attributes
//! (normals, uvs, colours) of the kept vertices stay theirs; the kept vertices are renumbered in
//! their original order, which makes the result deterministic.
//!
//! Rules:
//! - **Borders** (edges of one triangle) stay where the mesh had them with
//!   [`SimplifyOptions::lock_border`] (meshoptimizer's `LockBorder`): an open mesh keeps its rim
//!   exactly, at the price of fewer collapses near it; without it meshoptimizer still collapses
//!   border vertices only along the border, so holes neither open nor close.
//! - **Seams**: vertices that share a position but not an index (a mesh split at uv or normal
//!   seams) are collapsed together by meshoptimizer, so a seam never opens a crack.
//! - Triangles with a repeated index carry no surface and are dropped before simplifying.
//! - A face target at or above the mesh's triangle count gives the mesh back unchanged (error
//!   0); meshoptimizer may stop above a face target where no collapse keeps the topology
//!   (borders, non-manifold edges), and [`Simplified::faces_after`] says where it stopped.
//!
//! What it cost ([`Simplified`]): meshoptimizer's own error estimate converted to model units
//! (its relative error times its scale, the largest bounding-box side), and a measured error:
//! the exact point-to-surface distance (spatial's BVH) from every original vertex and every
//! original triangle's centroid to the simplified mesh, as a maximum (one-sided Hausdorff over
//! those points) and a mean (one-sided Chamfer-L1).

use glam::{DVec3, Vec3};
use meshopt::SimplifyOptions as Flags;

use crate::mesh::TriMesh;
use crate::spatial::surface::SurfaceIndex;

/// What the simplifier aims at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SimplifyTarget {
    /// At most this many triangles (at least 1).
    Faces(usize),
    /// Collapse while the error stays within this share of the mesh's extent (finite, >= 0;
    /// meshoptimizer's relative `target_error`).
    Error(f64),
}

/// How [`simplify`] simplifies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimplifyOptions {
    /// The target.
    pub target: SimplifyTarget,
    /// Keep border vertices (edges of one triangle) in place.
    pub lock_border: bool,
}

/// Why a mesh cannot be simplified.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SimplifyError {
    /// A target out of range: no faces, or an error that is negative or not finite.
    #[error("{option} {value}: {expected}")]
    BadTarget {
        /// The option (`faces` or `simplify-error`).
        option: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// The mesh has no triangle with three distinct vertices.
    #[error("the mesh has no triangle to simplify ({vertices} vertices, {triangles} triangles)")]
    Empty {
        /// Vertex count.
        vertices: usize,
        /// Triangle count (repeated-index ones included).
        triangles: usize,
    },
    /// The simplified mesh could not be indexed to measure its error (non-finite or huge
    /// coordinates).
    #[error("measuring the simplified mesh: {0}")]
    Measure(String),
}

/// A simplified mesh and what the simplification cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Simplified {
    /// The simplified mesh (kept vertices in their original order, with their attributes).
    pub mesh: TriMesh,
    /// Triangles before (repeated-index ones included).
    pub faces_before: usize,
    /// Triangles after.
    pub faces_after: usize,
    /// meshoptimizer's error estimate in model units (its relative error times its scale).
    pub error: f64,
    /// The largest exact distance from an original vertex or triangle centroid to the
    /// simplified surface, model units.
    pub hausdorff: f64,
    /// The mean of those distances (one-sided Chamfer-L1), model units.
    pub mean_distance: f64,
}

impl SimplifyTarget {
    /// Checks the target: faces at least 1; an error finite and not negative.
    ///
    /// # Errors
    /// [`SimplifyError::BadTarget`] naming the option.
    pub fn check(self) -> Result<(), SimplifyError> {
        match self {
            Self::Faces(0) => Err(SimplifyError::BadTarget {
                option: "faces",
                value: 0.0,
                expected: "a face count of at least 1",
            }),
            Self::Error(e) if !(e.is_finite() && e >= 0.0) => Err(SimplifyError::BadTarget {
                option: "simplify-error",
                value: e,
                expected: "a finite share of the mesh's extent, 0 or more (0.01 = 1%)",
            }),
            _ => Ok(()),
        }
    }
}

/// `mesh` simplified as `options` asks, with what it cost (see the module's rules).
///
/// # Errors
/// [`SimplifyError::BadTarget`] for a target out of range; [`SimplifyError::Empty`] for a
/// mesh without a triangle of three distinct vertices; [`SimplifyError::Measure`] when the
/// result cannot be indexed.
pub fn simplify(mesh: &TriMesh, options: &SimplifyOptions) -> Result<Simplified, SimplifyError> {
    options.target.check()?;
    let faces_before = mesh.triangle_count();
    let proper: Vec<u32> = mesh
        .triangles()
        .iter()
        .filter(|&&[a, b, c]| a != b && b != c && a != c)
        .flatten()
        .copied()
        .collect();
    if proper.is_empty() {
        return Err(SimplifyError::Empty {
            vertices: mesh.vertex_count(),
            triangles: faces_before,
        });
    }
    if let SimplifyTarget::Faces(n) = options.target
        && n >= faces_before
    {
        return Ok(Simplified {
            mesh: mesh.clone(),
            faces_before,
            faces_after: faces_before,
            error: 0.0,
            hausdorff: 0.0,
            mean_distance: 0.0,
        });
    }
    // meshoptimizer reads f32 positions: relative to the box's centre, so that a mesh far from
    // the origin keeps its precision.
    let centre = mesh.bounds().map_or(DVec3::ZERO, |b| b.center());
    let local: Vec<[f32; 3]> = mesh
        .positions()
        .iter()
        .map(|p| (*p - centre).as_vec3().to_array())
        .collect();
    let (target_count, target_error) = match options.target {
        SimplifyTarget::Faces(n) => (3 * n, f32::MAX),
        SimplifyTarget::Error(e) => (0, e as f32),
    };
    let flags = if options.lock_border {
        Flags::LockBorder
    } else {
        Flags::None
    };
    let mut relative = 0.0f32;
    let indices = meshopt::simplify_decoder(
        &proper,
        &local,
        target_count,
        target_error,
        flags,
        Some(&mut relative),
    );
    let scale = f64::from(meshopt::simplify_scale_decoder(&local));
    let simplified = compact(mesh, &indices);
    let (hausdorff, mean_distance) = distance_to(mesh, &simplified)?;
    Ok(Simplified {
        faces_after: simplified.triangle_count(),
        mesh: simplified,
        faces_before,
        error: f64::from(relative) * scale,
        hausdorff,
        mean_distance,
    })
}

/// `mesh`'s vertices that `indices` use, renumbered in their original order, with their
/// attributes, and the triangles of `indices`.
fn compact(mesh: &TriMesh, indices: &[u32]) -> TriMesh {
    let mut map = vec![u32::MAX; mesh.vertex_count()];
    for &i in indices {
        map[i as usize] = 0;
    }
    let mut kept = Vec::new();
    for (i, m) in map.iter_mut().enumerate() {
        if *m == 0 {
            *m = kept.len() as u32;
            kept.push(i);
        }
    }
    let positions: Vec<DVec3> = kept.iter().map(|&i| mesh.positions()[i]).collect();
    let triangles: Vec<[u32; 3]> = indices
        .chunks_exact(3)
        .map(|t| [map[t[0] as usize], map[t[1] as usize], map[t[2] as usize]])
        .collect();
    let mut out = TriMesh::new_unchecked(positions, triangles);
    let pick = |i: &usize| *i;
    if let Some(n) = mesh.normals() {
        out = out
            .with_normals(kept.iter().map(|i| n[pick(i)]).collect())
            .unwrap_or_else(|_| unreachable!("one normal per kept vertex"));
    }
    if let Some(uv) = mesh.uvs() {
        out = out
            .with_uvs(kept.iter().map(|i| uv[pick(i)]).collect())
            .unwrap_or_else(|_| unreachable!("one uv per kept vertex"));
    }
    if let Some(c) = mesh.colors() {
        out = out
            .with_colors(kept.iter().map(|i| c[pick(i)]).collect())
            .unwrap_or_else(|_| unreachable!("one colour per kept vertex"));
    }
    out
}

/// The largest and the mean exact distance from `original`'s vertices and triangle centroids
/// to `simplified`'s surface.
fn distance_to(original: &TriMesh, simplified: &TriMesh) -> Result<(f64, f64), SimplifyError> {
    if simplified.triangle_count() == 0 {
        return Ok((f64::INFINITY, f64::INFINITY));
    }
    let index = SurfaceIndex::new(simplified.positions(), simplified.triangles())
        .map_err(|e| SimplifyError::Measure(e.to_string()))?;
    let mut queries: Vec<Vec3> = original.positions_f32();
    queries.extend(original.triangles().iter().map(|t| {
        (t.iter()
            .map(|&i| original.positions()[i as usize])
            .sum::<DVec3>()
            / 3.0)
            .as_vec3()
    }));
    let hits = index
        .closest_batch(&queries)
        .map_err(|e| SimplifyError::Measure(e.to_string()))?;
    let (max, sum) = hits.iter().fold((0.0f64, 0.0f64), |(m, s), h| {
        (m.max(h.distance), s + h.distance)
    });
    Ok((max, sum / hits.len().max(1) as f64))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topology::boundary_edges;

    /// A unit sphere: the octahedron subdivided `levels` times (8 * 4^levels triangles).
    fn sphere(levels: usize) -> TriMesh {
        let octa = TriMesh::new(
            vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z],
            crate::test_meshes::OCTAHEDRON_TRIANGLES.to_vec(),
        );
        let fine = crate::subdivide::midpoint(&octa, levels).expect("subdivide");
        let positions = fine.positions().iter().map(|p| p.normalize()).collect();
        TriMesh::new(positions, fine.triangles().to_vec())
    }

    /// An `n` x `n` grid of squares in z = 0 with a bump, two triangles each (open).
    fn sheet(n: u32) -> TriMesh {
        let positions = (0..(n + 1) * (n + 1))
            .map(|i| {
                let (x, y) = (f64::from(i % (n + 1)), f64::from(i / (n + 1)));
                DVec3::new(x, y, 0.1 * (x * 0.3).sin() * (y * 0.2).cos())
            })
            .collect();
        let mut triangles = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let i = y * (n + 1) + x;
                triangles.push([i, i + 1, i + n + 2]);
                triangles.push([i, i + n + 2, i + n + 1]);
            }
        }
        TriMesh::new(positions, triangles)
    }

    fn faces(n: usize) -> SimplifyOptions {
        SimplifyOptions {
            target: SimplifyTarget::Faces(n),
            lock_border: true,
        }
    }

    #[test]
    fn a_closed_sphere_reaches_the_face_target_and_stays_closed() {
        let mesh = sphere(4);
        assert_eq!(mesh.triangle_count(), 2048);
        let s = simplify(&mesh, &faces(500)).expect("simplify");
        assert_eq!(s.faces_before, 2048);
        assert_eq!(s.faces_after, s.mesh.triangle_count());
        // meshoptimizer stops at or just below the target on a closed manifold.
        assert!((450..=500).contains(&s.faces_after), "{}", s.faces_after);
        assert!(boundary_edges(s.mesh.triangles()).is_empty());
        // Every kept vertex is an original one, unmoved.
        for p in s.mesh.positions() {
            assert!(mesh.positions().contains(p));
        }
        // The estimate and the measurement agree in scale, and both are small on a sphere.
        assert!(s.error > 0.0 && s.error < 0.05, "{}", s.error);
        assert!(s.hausdorff > 0.0 && s.hausdorff < 0.05, "{}", s.hausdorff);
        assert!(s.mean_distance <= s.hausdorff);
        assert_eq!(simplify(&mesh, &faces(500)).expect("again"), s);
    }

    #[test]
    fn an_error_target_bounds_meshoptimizers_estimate() {
        let mesh = sphere(4);
        let s = simplify(
            &mesh,
            &SimplifyOptions {
                target: SimplifyTarget::Error(0.01),
                lock_border: true,
            },
        )
        .expect("simplify");
        assert!(s.faces_after < 2048, "{}", s.faces_after);
        // Relative to the largest side of the box (2 for the unit sphere).
        assert!(s.error <= 0.01 * 2.0 + 1e-6, "{}", s.error);
        let exact = simplify(
            &mesh,
            &SimplifyOptions {
                target: SimplifyTarget::Error(0.0),
                lock_border: true,
            },
        )
        .expect("simplify");
        assert_eq!(exact.faces_after, 2048);
    }

    #[test]
    fn a_locked_border_stays_where_it_was() {
        let mesh = sheet(20);
        let border: Vec<u32> = boundary_edges(mesh.triangles())
            .iter()
            .flat_map(|e| [e.0, e.1])
            .collect();
        let s = simplify(&mesh, &faces(100)).expect("simplify");
        assert!(s.faces_after < mesh.triangle_count());
        for v in border {
            let p = mesh.positions()[v as usize];
            assert!(s.mesh.positions().contains(&p), "border vertex {v} moved");
        }
        let free = simplify(
            &mesh,
            &SimplifyOptions {
                target: SimplifyTarget::Faces(100),
                lock_border: false,
            },
        )
        .expect("simplify");
        assert!(free.faces_after <= s.faces_after);
    }

    #[test]
    fn attributes_follow_their_vertices() {
        let mesh = sphere(3);
        let colors: Vec<crate::Rgba> = mesh
            .positions()
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32, 1.0])
            .collect();
        let mesh = mesh.with_colors(colors).expect("colours");
        let s = simplify(&mesh, &faces(100)).expect("simplify");
        let kept = s.mesh.colors().expect("colours kept");
        for (p, c) in s.mesh.positions().iter().zip(kept) {
            assert_eq!(*c, [p.x as f32, p.y as f32, p.z as f32, 1.0]);
        }
    }

    #[test]
    fn a_target_above_the_mesh_gives_it_back() {
        let mesh = sphere(2);
        let s = simplify(&mesh, &faces(10_000)).expect("simplify");
        assert_eq!(s.mesh, mesh);
        assert_eq!((s.faces_before, s.faces_after, s.error), (128, 128, 0.0));
    }

    #[test]
    fn bad_targets_and_empty_meshes_are_refused() {
        let mesh = sphere(1);
        let e = simplify(&mesh, &faces(0)).expect_err("no faces");
        assert!(e.to_string().starts_with("faces 0"), "{e}");
        for bad in [-0.1, f64::NAN, f64::INFINITY] {
            let e = simplify(
                &mesh,
                &SimplifyOptions {
                    target: SimplifyTarget::Error(bad),
                    lock_border: true,
                },
            )
            .expect_err("bad error");
            assert!(e.to_string().starts_with("simplify-error"), "{e}");
        }
        let empty = TriMesh::new(vec![DVec3::ZERO, DVec3::X], vec![[0, 0, 1]]);
        let e = simplify(&empty, &faces(1)).expect_err("empty");
        assert!(
            matches!(e, SimplifyError::Empty { triangles: 1, .. }),
            "{e}"
        );
        assert!(simplify(&TriMesh::default(), &faces(1)).is_err());
    }
}
