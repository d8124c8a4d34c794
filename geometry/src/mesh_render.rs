//! Depth, normal and mask maps of a triangle mesh seen by a [`Camera`], by ray casting through a
//! [`TriangleBvh`] (ground-truth supervision for the splatting renderer, docs/conventions.md §2 and §5).
//!
//! Conventions are the renderer's: pixel (row i, column j) is sampled at (j + 0.5, i + 0.5);
//! depth is z-depth (distance along the camera's +z axis, not along the ray), 0 where no triangle
//! is hit; the mask is 1 where a triangle is hit and 0 elsewhere; normals are unit vectors turned
//! to face the camera (`n · ray ≤ 0`), zero where nothing is hit, in the world frame or the
//! camera's (OpenCV axes) as [`NormalFrame`] says.
//!
//! Each pixel casts one ray whose direction is `R (u − cx)/fx, (v − cy)/fy, 1)` — the camera's
//! z component is exactly 1 — so the hit parameter *is* the z-depth, with no division by the
//! ray length. Rows are rendered in parallel; every pixel is computed on its own, so the maps do
//! not depend on the thread count.
//!
//! Both faces of every triangle count (a camera inside a closed mesh sees its inside), there is
//! no near plane (a surface through the camera centre has depth 0 and mask 1), and rays parallel
//! to a triangle never hit it (grazing views give finite maps).

use glam::{DMat3, DVec3, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::mesh::TriMesh;
use crate::spatial::bvh::TriangleBvh;
use crate::spatial::error::SpatialError;

/// Triangle id stored in [`MeshMaps::triangle`] for pixels that hit nothing.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// Which normal a hit reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum NormalSource {
    /// The hit triangle's geometric normal (flat shading): what a depth map's gradient shows.
    #[default]
    Face,
    /// Vertex normals interpolated with the hit's barycentric weights and normalised (the mesh's
    /// own normals when it has them, else area-weighted vertex normals). Falls back to the face
    /// normal where the interpolated normal vanishes.
    Interpolated,
}

/// The frame normal maps are expressed in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum NormalFrame {
    /// World coordinates.
    #[default]
    World,
    /// The camera's coordinates (OpenCV axes: x right, y down, z forward); a surface facing the
    /// camera head-on has normal (0, 0, −1).
    Camera,
}

/// Options of [`MeshRenderer`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshRenderOptions {
    /// Face or interpolated vertex normals.
    pub normals: NormalSource,
    /// World or camera frame for normals.
    pub frame: NormalFrame,
}

/// The maps of one view, row-major (`index = row * width + col`).
#[derive(Clone, Debug, PartialEq)]
pub struct MeshMaps {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// z-depth per pixel, 0 where nothing is hit (`[H, W]`).
    pub depth: Vec<f32>,
    /// Unit normal per pixel facing the camera, zero where nothing is hit (`[H, W, 3]`).
    pub normal: Vec<[f32; 3]>,
    /// 1 where a triangle is hit, 0 elsewhere (`[H, W]`).
    pub mask: Vec<f32>,
    /// Id of the triangle hit per pixel, [`NO_TRIANGLE`] where nothing is hit (`[H, W]`).
    pub triangle: Vec<u32>,
}

impl MeshMaps {
    /// The normal map flattened to `[H, W, 3]` floats (for `.npy` output).
    #[must_use]
    pub fn normal_flat(&self) -> Vec<f32> {
        self.normal.iter().flatten().copied().collect()
    }

    /// Number of pixels that hit a triangle.
    #[must_use]
    pub fn hit_count(&self) -> usize {
        self.triangle.iter().filter(|&&t| t != NO_TRIANGLE).count()
    }
}

/// Renders depth, normal and mask maps of one mesh from any number of cameras (the BVH is built
/// once).
#[derive(Debug)]
pub struct MeshRenderer {
    bvh: TriangleBvh,
    /// Per-vertex normals for [`NormalSource::Interpolated`] (empty otherwise).
    vertex_normals: Vec<Vec3>,
    /// Triangles (vertex indices), for interpolation.
    triangles: Vec<[u32; 3]>,
    options: MeshRenderOptions,
}

impl MeshRenderer {
    /// Builds the BVH of `mesh`.
    ///
    /// # Errors
    /// [`SpatialError`] when the mesh cannot be indexed (coordinates beyond
    /// [`crate::spatial::MAX_COORDINATE`], too many triangles). An empty mesh is fine: its maps
    /// are empty.
    pub fn new(mesh: &TriMesh, options: MeshRenderOptions) -> Result<Self, SpatialError> {
        let bvh = TriangleBvh::new(mesh)?;
        let vertex_normals = match options.normals {
            NormalSource::Face => Vec::new(),
            NormalSource::Interpolated => mesh
                .normals()
                .map_or_else(|| mesh.vertex_normals(), <[Vec3]>::to_vec),
        };
        Ok(Self {
            bvh,
            vertex_normals,
            triangles: mesh.triangles().to_vec(),
            options,
        })
    }

    /// The options this renderer was built with.
    #[must_use]
    pub fn options(&self) -> MeshRenderOptions {
        self.options
    }

    /// Renders the maps seen by `camera`.
    #[must_use]
    pub fn render(&self, camera: &Camera) -> MeshMaps {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let rotation = camera.rotation();
        let origin = camera.position().as_vec3();
        let mut depth = vec![0.0f32; w * h];
        let mut normal = vec![[0.0f32; 3]; w * h];
        let mut triangle = vec![NO_TRIANGLE; w * h];
        depth
            .par_chunks_mut(w.max(1))
            .zip(normal.par_chunks_mut(w.max(1)))
            .zip(triangle.par_chunks_mut(w.max(1)))
            .enumerate()
            .for_each(|(row, ((depth, normal), triangle))| {
                let v = row as f64 + 0.5;
                for col in 0..w {
                    let u = col as f64 + 0.5;
                    // Camera-space direction with z = 1: the hit parameter is the z-depth.
                    let dir = rotation * camera.unproject(u, v);
                    let Some(hit) = self.bvh.cast_ray(origin, dir.as_vec3(), f64::INFINITY) else {
                        continue;
                    };
                    depth[col] = hit.t as f32;
                    triangle[col] = hit.triangle;
                    normal[col] = self.hit_normal(hit.triangle, hit.barycentric, dir, rotation);
                }
            });
        let mask = triangle
            .iter()
            .map(|&t| if t == NO_TRIANGLE { 0.0 } else { 1.0 })
            .collect();
        MeshMaps {
            width: camera.width,
            height: camera.height,
            depth,
            normal,
            mask,
            triangle,
        }
    }

    /// The unit normal of a hit, facing the ray's origin, in the requested frame.
    fn hit_normal(
        &self,
        tri: u32,
        barycentric: [f64; 3],
        dir: DVec3,
        camera_to_world: DMat3,
    ) -> [f32; 3] {
        let Some([a, b, c]) = self.bvh.corners(tri as usize) else {
            return [0.0; 3];
        };
        let mut n = (b - a).cross(c - a).normalize_or_zero();
        if self.options.normals == NormalSource::Interpolated
            && let Some(&[i, j, k]) = self.triangles.get(tri as usize)
        {
            let at = |v: u32| {
                self.vertex_normals
                    .get(v as usize)
                    .map_or(DVec3::ZERO, |n| n.as_dvec3())
            };
            let interp = (at(i) * barycentric[0] + at(j) * barycentric[1] + at(k) * barycentric[2])
                .normalize_or_zero();
            if interp != DVec3::ZERO {
                n = interp;
            }
        }
        if n == DVec3::ZERO {
            // Cannot happen for a hit (degenerate triangles are never hit); face the camera.
            n = -dir.normalize_or_zero();
        }
        if n.dot(dir) > 0.0 {
            n = -n;
        }
        if self.options.frame == NormalFrame::Camera {
            n = camera_to_world.transpose() * n;
        }
        n.as_vec3().to_array()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square of side 20 in the plane z = `z`, centred on the z axis.
    fn square(z: f32) -> TriMesh {
        TriMesh::new(
            vec![
                Vec3::new(-10.0, -10.0, z),
                Vec3::new(10.0, -10.0, z),
                Vec3::new(10.0, 10.0, z),
                Vec3::new(-10.0, 10.0, z),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    fn camera(eye: DVec3, target: DVec3, size: (u32, u32), fov: f64) -> Camera {
        Camera::look_at("c", eye, target, DVec3::Y, size, fov).expect("valid camera")
    }

    #[test]
    fn plane_depth_is_z_depth_everywhere() {
        let mesh = square(0.0);
        let r = MeshRenderer::new(&mesh, MeshRenderOptions::default()).expect("bvh");
        // Looking down −z from z = 3 at the origin: every pixel of a fronto-parallel plane
        // has the same z-depth 3, also at the wide corners of the image.
        let cam = camera(DVec3::new(0.0, 0.0, 3.0), DVec3::ZERO, (33, 21), 30.0);
        let maps = r.render(&cam);
        assert_eq!(maps.hit_count(), 33 * 21);
        for (d, n) in maps.depth.iter().zip(&maps.normal) {
            assert!((d - 3.0).abs() < 1e-6, "{d}");
            assert_eq!(*n, [0.0, 0.0, 1.0], "faces the camera");
        }
        let cam_frame = MeshRenderer::new(
            &mesh,
            MeshRenderOptions {
                frame: NormalFrame::Camera,
                ..MeshRenderOptions::default()
            },
        )
        .expect("bvh")
        .render(&cam);
        for n in &cam_frame.normal {
            assert!(
                (Vec3::from_array(*n) - Vec3::NEG_Z).length() < 1e-6,
                "{n:?}"
            );
        }
    }

    #[test]
    fn tilted_plane_matches_analytic_depth() {
        // The plane z = 0.3 x seen from (0, 0, 4) looking at the origin.
        let mut mesh = square(0.0);
        let positions: Vec<DVec3> = mesh
            .positions()
            .iter()
            .map(|p| DVec3::new(p.x, p.y, 0.3 * p.x))
            .collect();
        mesh.set_positions(positions).expect("finite");
        let cam = camera(DVec3::new(0.0, 0.0, 4.0), DVec3::ZERO, (40, 30), 60.0);
        let maps = MeshRenderer::new(&mesh, MeshRenderOptions::default())
            .expect("bvh")
            .render(&cam);
        for row in 0..30u32 {
            for col in 0..40u32 {
                let (o, d) = cam.pixel_ray(row, col);
                // o + t d on z = 0.3 x: o.z + t d.z = 0.3 (o.x + t d.x).
                let t = (0.3 * o.x - o.z) / (d.z - 0.3 * d.x);
                let z = cam.world_to_camera(o + d * t).z;
                let got = f64::from(maps.depth[(row * 40 + col) as usize]);
                assert!((got - z).abs() < 1e-6 * z, "{row} {col}: {got} vs {z}");
            }
        }
    }

    #[test]
    fn misses_inside_and_grazing_views_are_finite() {
        let mesh = square(0.0);
        let r = MeshRenderer::new(&mesh, MeshRenderOptions::default()).expect("bvh");
        // Looking away: nothing.
        let away = camera(
            DVec3::new(0.0, 0.0, 3.0),
            DVec3::new(0.0, 0.0, 6.0),
            (8, 8),
            40.0,
        );
        let maps = r.render(&away);
        assert_eq!(maps.hit_count(), 0);
        assert!(maps.depth.iter().all(|&d| d == 0.0) && maps.mask.iter().all(|&m| m == 0.0));
        // Camera in the plane of the square, looking along it: rays through the middle row are
        // parallel to it; every value stays finite and every normal is unit or zero.
        let grazing = camera(DVec3::new(-30.0, 0.0, 0.0), DVec3::ZERO, (16, 15), 40.0);
        let maps = r.render(&grazing);
        for (d, n) in maps.depth.iter().zip(&maps.normal) {
            assert!(d.is_finite() && *d >= 0.0);
            let len = Vec3::from_array(*n).length();
            assert!(len == 0.0 || (len - 1.0).abs() < 1e-6);
        }
        // Empty mesh.
        let empty = TriMesh::default();
        let maps = MeshRenderer::new(&empty, MeshRenderOptions::default())
            .expect("empty is fine")
            .render(&grazing);
        assert_eq!(maps.hit_count(), 0);
    }

    #[test]
    fn back_faces_are_seen_and_normals_face_the_camera() {
        // Seen from below, the square's stored normal (+z) points away: it is flipped.
        let mesh = square(0.0);
        let cam = camera(DVec3::new(0.0, 0.0, -2.0), DVec3::ZERO, (9, 9), 40.0);
        for normals in [NormalSource::Face, NormalSource::Interpolated] {
            let maps = MeshRenderer::new(
                &mesh,
                MeshRenderOptions {
                    normals,
                    ..MeshRenderOptions::default()
                },
            )
            .expect("bvh")
            .render(&cam);
            assert_eq!(maps.hit_count(), 81);
            assert!(maps.normal.iter().all(|n| *n == [0.0, 0.0, -1.0]));
        }
    }

    /// A closed cube of side 1 centred on the origin, outward normals.
    fn cube() -> TriMesh {
        let p = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .map(|v| v - Vec3::splat(0.5))
            .collect();
        let t = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        TriMesh::new(p, t)
    }

    #[test]
    fn inside_a_closed_mesh() {
        // From the centre of the cube every ray hits a face at z-depth 0.5 straight ahead.
        let r = MeshRenderer::new(&cube(), MeshRenderOptions::default()).expect("bvh");
        let cam = camera(DVec3::ZERO, DVec3::Z, (11, 11), 60.0);
        let maps = r.render(&cam);
        assert_eq!(maps.hit_count(), 121);
        let centre = maps.depth[5 * 11 + 5];
        assert!((centre - 0.5).abs() < 1e-6, "{centre}");
        assert!(
            maps.depth
                .iter()
                .all(|d| d.is_finite() && *d > 0.0 && *d <= 0.5 + 1e-6)
        );
        assert!(
            maps.normal
                .iter()
                .all(|n| (Vec3::from_array(*n).length() - 1.0).abs() < 1e-6)
        );
    }

    #[test]
    fn independent_of_thread_count() {
        let mesh = crate::subdivide::midpoint(&cube(), 3).expect("valid");
        let cam = camera(DVec3::new(0.3, 0.2, 2.5), DVec3::ZERO, (48, 40), 50.0);
        let r = MeshRenderer::new(
            &mesh,
            MeshRenderOptions {
                normals: NormalSource::Interpolated,
                frame: NormalFrame::Camera,
            },
        )
        .expect("bvh");
        let many = r.render(&cam);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| r.render(&cam));
        assert_eq!(many, one);
        assert!(many.hit_count() > 300);
    }
}
