//! Mesh depth/normal/mask maps against Open3D 0.20.0 `RaycastingScene` on Spot.
//!
//! Reference: `tests/reference/ref_mesh_render.py` → `fixtures/data/reference/render_mesh/`
//! (five 96×72 views: three around the cow, one close and oblique at 90° field of view, one
//! from inside the body). Open3D and this test read the same positions-only `spot.ply`; the
//! script turns Open3D's ray distance into z-depth.

use glam::Vec3;
use trisplat_geometry::io::{read_mesh, read_npy};
use trisplat_geometry::mesh_render::{
    MeshRenderOptions, MeshRenderer, NO_TRIANGLE, NormalFrame, NormalSource,
};
use trisplat_geometry::read_cameras_json;

/// The bound: z-depth within 1e-5 relative of Open3D where both hit.
const MAX_DEPTH_RELATIVE_ERROR: f64 = 1e-5;
/// Pixels whose hit/miss differs from Open3D's (exactly this many are expected). Embree (f32) and our f64 Möller-Trumbore
/// disagree only for rays within rounding of a silhouette edge; none occur in these views.
const MAX_MASK_MISMATCHES: usize = 0;
/// Pixels whose hit triangle differs (a ray within rounding of a shared edge could pick either
/// neighbour, both right); none occur in these views.
const MAX_TRIANGLE_MISMATCHES: usize = 0;
/// Unit length of normals, and agreement of a face normal with Open3D's (cosine).
const NORMAL_TOLERANCE: f32 = 1e-5;

fn dir() -> std::path::PathBuf {
    trisplat_fixtures::path("reference/render_mesh")
}

#[test]
fn spot_depth_mask_and_normals_match_open3d() {
    let mesh = read_mesh(&trisplat_fixtures::path("reference/smoothing/spot.ply")).expect("spot");
    let cameras = read_cameras_json(&dir().join("cameras.json")).expect("cameras");
    let depth = read_npy(&dir().join("depth.npy")).expect("depth");
    let triangle = read_npy(&dir().join("triangle.npy")).expect("triangle");
    let normal0 = read_npy(&dir().join("normal0.npy")).expect("normal0");
    assert_eq!(cameras.len(), 5);
    let (h, w) = (cameras[0].height as usize, cameras[0].width as usize);
    assert_eq!(depth.shape, vec![cameras.len(), h, w]);
    assert_eq!(normal0.shape, vec![h, w, 3]);

    let renderer = MeshRenderer::new(&mesh, MeshRenderOptions::default()).expect("bvh");
    let face_normals = mesh.face_normals();
    let mut worst = 0.0f64;
    let (mut mask_mismatch, mut tri_mismatch, mut both) = (0, 0, 0);
    for (k, cam) in cameras.iter().enumerate() {
        let maps = renderer.render(cam);
        for p in 0..h * w {
            let want = f64::from(depth.data[k * h * w + p]);
            let want_tri = triangle.data[k * h * w + p];
            let got = f64::from(maps.depth[p]);
            let hit = maps.triangle[p] != NO_TRIANGLE;
            assert_eq!(maps.mask[p], if hit { 1.0 } else { 0.0 });
            if hit != (want_tri >= 0.0) {
                mask_mismatch += 1;
                continue;
            }
            if !hit {
                assert_eq!(got, 0.0);
                assert_eq!(maps.normal[p], [0.0; 3]);
                continue;
            }
            both += 1;
            worst = worst.max((got - want).abs() / want);
            if maps.triangle[p] as f32 != want_tri {
                tri_mismatch += 1;
            }
            // Unit, the hit triangle's face normal, facing the camera.
            let n = Vec3::from_array(maps.normal[p]);
            assert!((n.length() - 1.0).abs() < NORMAL_TOLERANCE, "{n}");
            let face = face_normals[maps.triangle[p] as usize];
            assert!(n.dot(face).abs() > 1.0 - NORMAL_TOLERANCE);
            let (row, col) = ((p / w) as u32, (p % w) as u32);
            let (_, ray) = cam.pixel_ray(row, col);
            assert!(n.dot(ray.as_vec3()) <= 0.0, "view {k} pixel {p} faces away");
            if k == 0 && maps.triangle[p] as f32 == want_tri {
                let o3d = Vec3::from_slice(&normal0.data[3 * p..3 * p + 3]);
                assert!(n.dot(o3d) > 1.0 - NORMAL_TOLERANCE, "{n} vs {o3d}");
            }
        }
    }
    println!(
        "{both} pixels hit in both: max relative depth error {worst:.2e}; \
         mask mismatches {mask_mismatch}, triangle mismatches {tri_mismatch}"
    );
    assert!(both > 10_000, "too few hits: {both}");
    assert!(worst <= MAX_DEPTH_RELATIVE_ERROR, "depth error {worst:.2e}");
    assert!(
        mask_mismatch == MAX_MASK_MISMATCHES,
        "{mask_mismatch} mask mismatches"
    );
    assert!(
        tri_mismatch == MAX_TRIANGLE_MISMATCHES,
        "{tri_mismatch} triangle mismatches"
    );
}

#[test]
fn interpolated_camera_frame_normals_are_unit_and_face_the_camera() {
    let mesh = read_mesh(&trisplat_fixtures::path("reference/smoothing/spot.ply")).expect("spot");
    let cameras = read_cameras_json(&dir().join("cameras.json")).expect("cameras");
    let renderer = MeshRenderer::new(
        &mesh,
        MeshRenderOptions {
            normals: NormalSource::Interpolated,
            frame: NormalFrame::Camera,
        },
    )
    .expect("bvh");
    for cam in &cameras {
        let maps = renderer.render(cam);
        for (p, n) in maps.normal.iter().enumerate() {
            let n = Vec3::from_array(*n);
            if maps.mask[p] == 0.0 {
                assert_eq!(n, Vec3::ZERO);
                continue;
            }
            assert!((n.length() - 1.0).abs() < NORMAL_TOLERANCE);
            // In the camera frame the ray through the pixel is (u', v', 1).
            let (row, col) = (
                (p / cam.width as usize) as u32,
                (p % cam.width as usize) as u32,
            );
            let ray = cam.unproject(f64::from(col) + 0.5, f64::from(row) + 0.5);
            assert!(f64::from(n.dot(ray.as_vec3())) <= 0.0);
        }
    }
}
