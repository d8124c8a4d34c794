use glam::DVec3;
use trisplat_geometry::sphere_rig;
use trisplat_geometry::topology::{boundary_edges, non_manifold_edges};

use super::*;
use crate::marching_cubes::marching_cubes_dense;
use crate::tsdf::{MAX_CELL_SPREAD_PIXELS, TsdfOptions, fuse, scene_radius};

const RADIUS: f64 = 0.3;
const VOXEL: f64 = 0.02;

/// Analytic z-depth of a sphere of `RADIUS` at the origin, 0 where the ray misses.
fn sphere_depth(cam: &Camera) -> DepthImage {
    let mut data = Vec::new();
    for i in 0..cam.height {
        for j in 0..cam.width {
            let d = cam.rotation() * cam.unproject(f64::from(j) + 0.5, f64::from(i) + 0.5);
            let o = cam.position();
            // |o + t d|² = r²
            let (a, b, c) = (d.dot(d), 2.0 * o.dot(d), o.dot(o) - RADIUS * RADIUS);
            let disc = b * b - 4.0 * a * c;
            let t = if disc >= 0.0 {
                (-b - disc.sqrt()) / (2.0 * a)
            } else {
                0.0
            };
            // The camera-space z of d is 1, so t is the z-depth.
            data.push(t.max(0.0) as f32);
        }
    }
    DepthImage::try_new(cam.width, cam.height, data).unwrap()
}

fn rig() -> Vec<Camera> {
    sphere_rig(DVec3::ZERO, RADIUS, 7, (40, 32), 50.0).unwrap()
}

fn params() -> TsdfParams {
    TsdfParams {
        voxel: VOXEL,
        trunc: 4.0 * VOXEL,
        depth_trunc: f64::INFINITY,
    }
}

/// The depth at image point `(u, v)`, written plainly: bilinear over the four pixel centres
/// around it when they are valid (within the depth truncation) and differ by at most
/// `MAX_CELL_SPREAD_PIXELS` footprints at the nearest of them (or the truncation), else the
/// pixel whose centre is nearest.
fn plain_depth(cam: &Camera, depth: &DepthImage, u: f64, v: f64, p: TsdfParams) -> f64 {
    let at = |col: i64, row: i64| -> f64 {
        let d = f64::from(depth.data()[(row * i64::from(cam.width) + col) as usize]);
        if d.is_finite() && d > 0.0 && d <= p.depth_trunc {
            d
        } else {
            0.0
        }
    };
    let (x, y) = (u - 0.5, v - 0.5);
    let (j, i) = (x.floor() as i64, y.floor() as i64);
    if j >= 0 && i >= 0 && j + 1 < i64::from(cam.width) && i + 1 < i64::from(cam.height) {
        let c = [at(j, i), at(j + 1, i), at(j, i + 1), at(j + 1, i + 1)];
        let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = c.iter().copied().fold(0.0, f64::max);
        let limit = (lo * MAX_CELL_SPREAD_PIXELS / cam.fx.min(cam.fy)).max(p.trunc);
        if lo > 0.0 && hi - lo <= limit {
            let (tx, ty) = (x - j as f64, y - i as f64);
            let top = c[0] + tx * (c[1] - c[0]);
            let bottom = c[2] + tx * (c[3] - c[2]);
            return top + ty * (bottom - top);
        }
    }
    at(u.floor() as i64, v.floor() as i64)
}

/// The fusion rule, written plainly over every voxel of a dense box: Open3D's legacy
/// integrator with the depth read by [`plain_depth`] and the sdf measured along the voxel's
/// own ray.
fn dense_reference(
    cams: &[Camera],
    depths: &[DepthImage],
    p: TsdfParams,
    half: i32,
) -> Vec<(f32, f32)> {
    let n = (2 * half) as usize;
    let mut out = vec![(0.0f32, 0.0f32); n * n * n];
    for z in -half..half {
        for y in -half..half {
            for x in -half..half {
                let centre = (DVec3::new(f64::from(x), f64::from(y), f64::from(z)) + 0.5) * p.voxel;
                let slot = &mut out
                    [((x + half) + 2 * half * ((y + half) + 2 * half * (z + half))) as usize];
                for (cam, depth) in cams.iter().zip(depths) {
                    let q = cam.world_to_camera(centre);
                    if q.z <= 0.0 {
                        continue;
                    }
                    let uv = cam.project(q);
                    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
                    if !(uv.x >= 1e-4 && uv.x < w - 1e-4 && uv.y >= 1e-4 && uv.y < h - 1e-4) {
                        continue;
                    }
                    let d = plain_depth(cam, depth, uv.x, uv.y, p);
                    if d <= 0.0 || d > p.depth_trunc {
                        continue;
                    }
                    let sdf = (d - q.z) * q.length() / q.z;
                    if sdf > -p.trunc {
                        let tsdf = (sdf / p.trunc).min(1.0);
                        let w0 = f64::from(slot.1);
                        slot.0 = ((f64::from(slot.0) * w0 + tsdf) / (w0 + 1.0)) as f32;
                        slot.1 += 1.0;
                    }
                }
            }
        }
    }
    out
}

#[test]
fn sparse_volume_matches_dense_open3d_rule() {
    // Coarse voxels (a block spans many pixels: the blocks are culled by tiles).
    check_against_dense(&rig(), VOXEL, 24);
}

#[test]
fn fine_voxels_match_dense_open3d_rule() {
    // Fine voxels on larger images: a block spans a few pixels, so most blocks are judged
    // from their exact pixel rectangle, and many are wholly in free space or behind the
    // surface for a view.
    let cams = sphere_rig(DVec3::ZERO, RADIUS, 9, (160, 128), 50.0).unwrap();
    check_against_dense(&cams, 0.5 * VOXEL, 40);
}

/// Integrates the sphere's depth maps seen by `cams` (with invalid pixels and a depth
/// truncation) into a sparse volume of voxel `voxel` and checks every voxel of the dense box
/// `[-half, half)³` against [`dense_reference`], and the two meshes.
fn check_against_dense(cams: &[Camera], voxel: f64, half: i32) {
    let cams = cams.to_vec();
    let mut depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    // A few invalid pixels and a depth truncation that cuts some of the far side.
    let mut raw = depths[2].data().to_vec();
    for v in raw.iter_mut().step_by(37) {
        *v = f32::NAN;
    }
    depths[2] = DepthImage::try_new(cams[2].width, cams[2].height, raw).unwrap();
    assert!(depths[2].invalid_count() > 0);
    let mut p = params();
    p.voxel = voxel;
    p.trunc = 4.0 * voxel;
    let nearest = depths
        .iter()
        .flat_map(|d| d.data().iter().copied())
        .filter(|&d| d > 0.0)
        .fold(f32::INFINITY, f32::min);
    p.depth_trunc = f64::from(nearest) + 0.1;
    let frames: Vec<Frame<'_>> = cams
        .iter()
        .zip(&depths)
        .map(|(camera, depth)| Frame {
            camera,
            depth,
            color: None,
        })
        .collect();
    let mut volume = TsdfVolume::new(p, false).unwrap();
    volume.integrate(&frames).unwrap();
    let grid = volume.grid();
    assert!(grid.block_count() > 0);

    let dense = dense_reference(&cams, &depths, p, half);
    let n = (2 * half) as usize;
    let mut compared = 0;
    for z in -half..half {
        for y in -half..half {
            for x in -half..half {
                let (value, weight) =
                    dense[((x + half) + 2 * half * ((y + half) + 2 * half * (z + half))) as usize];
                let g = IVec3::new(x, y, z);
                match grid.voxel_value(g) {
                    Some((v, w)) => {
                        assert_eq!(w, weight, "weight at {g}");
                        assert!((v - value).abs() <= 1e-5, "value at {g}: {v} vs {value}");
                        compared += 1;
                    }
                    // Unallocated voxels must not be near a surface.
                    None => assert!(
                        weight == 0.0 || value >= 1.0 - 1e-6,
                        "{g}: {value} {weight}"
                    ),
                }
            }
        }
    }
    assert!(compared > 10_000);

    // The same surface from both.
    let values: Vec<f32> = dense
        .iter()
        .map(|&(v, w)| if w > 0.0 { v } else { f32::NAN })
        .collect();
    let origin = DVec3::splat((-f64::from(half) + 0.5) * voxel);
    let reference = marching_cubes_dense(&values, [n; 3], origin, voxel).unwrap();
    let ours = volume.extract_mesh();
    assert!(ours.triangle_count() > 100);
    assert_eq!(ours.triangle_count(), reference.triangle_count());
    assert_eq!(ours.vertex_count(), reference.vertex_count());
    let sorted = |m: &TriMesh| {
        let mut p: Vec<[f64; 3]> = m.positions().iter().map(|v| v.to_array()).collect();
        p.sort_by(|a, b| a.partial_cmp(b).unwrap());
        p
    };
    for (a, b) in sorted(&ours).iter().zip(sorted(&reference)) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-5, "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn closed_sphere_is_watertight_and_outward() {
    let cams = sphere_rig(DVec3::ZERO, RADIUS, 14, (48, 48), 40.0).unwrap();
    let depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    let options = TsdfOptions {
        voxel: Some(VOXEL),
        ..TsdfOptions::default()
    };
    let fused = fuse(&cams, &depths, None, &options).unwrap();
    let mesh = &fused.mesh;
    assert!(boundary_edges(mesh.triangles()).is_empty());
    assert!(non_manifold_edges(mesh.triangles()).is_empty());
    let exact = 4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3);
    assert!((mesh.signed_volume() - exact).abs() < 0.05 * exact);
    // Near silhouettes a pixel's depth reaches voxels at a grazing angle: errors stay below
    // 1.5 voxels here (pixels are 0.7 voxel wide at the sphere).
    for v in mesh.positions() {
        assert!((v.length() - RADIUS).abs() < 1.5 * VOXEL, "{v}");
    }
    // Defaults as 2DGS: the scene radius is the camera distance (the axes meet at the centre).
    let (center, radius) = scene_radius(&cams).unwrap();
    assert!(center.length() < 1e-9);
    assert!((radius - cams[0].position().length()).abs() < 1e-9);
    assert_eq!(fused.params.trunc, 5.0 * VOXEL);
    assert_eq!(fused.params.depth_trunc, 2.0 * radius);
}

#[test]
fn result_does_not_depend_on_thread_count() {
    let cams = rig();
    let depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    let options = TsdfOptions {
        voxel: Some(VOXEL / 2.0),
        ..TsdfOptions::default()
    };
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| fuse(&cams, &depths, None, &options).unwrap().mesh)
    };
    let one = run(1);
    let three = run(3);
    assert!(one.triangle_count() > 0);
    assert_eq!(one.positions(), three.positions());
    assert_eq!(one.triangles(), three.triangles());
}

#[test]
fn colours_are_averaged_onto_vertices() {
    let cams = rig();
    let depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    let colors: Vec<ColorImage> = cams
        .iter()
        .map(|c| {
            ColorImage::try_new(
                c.width,
                c.height,
                vec![[0.25, 0.5, 1.0]; (c.width * c.height) as usize],
            )
            .unwrap()
        })
        .collect();
    let options = TsdfOptions {
        voxel: Some(VOXEL),
        ..TsdfOptions::default()
    };
    let mesh = fuse(&cams, &depths, Some(&colors), &options).unwrap().mesh;
    let vertex_colors = mesh.colors().unwrap();
    assert_eq!(vertex_colors.len(), mesh.vertex_count());
    for c in vertex_colors {
        assert!(
            (c[0] - 0.25).abs() < 1e-5 && (c[1] - 0.5).abs() < 1e-5 && (c[2] - 1.0).abs() < 1e-5
        );
    }
    // A coloured volume refuses a frame without colour.
    let mut volume = TsdfVolume::new(params(), true).unwrap();
    let frame = Frame {
        camera: &cams[0],
        depth: &depths[0],
        color: None,
    };
    assert!(matches!(
        volume.integrate(&[frame]),
        Err(TsdfError::NoColor { .. })
    ));
}

#[test]
fn degenerate_inputs() {
    let cams = rig();
    let options = TsdfOptions {
        voxel: Some(VOXEL),
        ..TsdfOptions::default()
    };
    // Empty (all-zero) depth maps: an empty mesh by design, and no block.
    let empty: Vec<DepthImage> = cams
        .iter()
        .map(|c| {
            DepthImage::try_new(c.width, c.height, vec![0.0; (c.width * c.height) as usize])
                .unwrap()
        })
        .collect();
    let fused = fuse(&cams, &empty, None, &options).unwrap();
    assert_eq!(fused.mesh.triangle_count(), 0);
    assert_eq!(fused.blocks, 0);
    // All NaN: the same, with every pixel counted invalid.
    let nan = DepthImage::try_new(
        4,
        2,
        vec![f32::NAN, f32::INFINITY, -1.0, 0.0, 1.0, 2.0, 3.0, 4.0],
    )
    .unwrap();
    assert_eq!(nan.invalid_count(), 3);
    assert_eq!(&nan.data()[..4], &[0.0; 4]);
    // Allocated blocks that no frame reaches have weight 0 everywhere: nothing is extracted.
    let mut volume = TsdfVolume::new(params(), false).unwrap();
    let depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    let frames: Vec<Frame<'_>> = cams
        .iter()
        .zip(&depths)
        .map(|(camera, depth)| Frame {
            camera,
            depth,
            color: None,
        })
        .collect();
    volume.allocate(&frames).unwrap();
    assert!(volume.grid().block_count() > 0);
    assert_eq!(volume.grid().observed_voxels(), 0);
    assert_eq!(volume.extract_mesh().triangle_count(), 0);
    // Wrong sizes and counts.
    let small = DepthImage::try_new(3, 3, vec![1.0; 9]).unwrap();
    let frame = Frame {
        camera: &cams[0],
        depth: &small,
        color: None,
    };
    let err = volume.integrate(&[frame]).unwrap_err();
    assert!(matches!(err, TsdfError::ImageSize { .. }), "{err}");
    assert!(err.to_string().contains("view_000"), "{err}");
    assert!(DepthImage::try_new(3, 3, vec![1.0; 8]).is_err());
    assert!(matches!(
        fuse(&cams, &depths[..2], None, &options),
        Err(TsdfError::FrameCount { .. })
    ));
    // Bad parameters.
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let o = TsdfOptions {
            voxel: Some(bad),
            ..TsdfOptions::default()
        };
        assert!(matches!(
            o.resolve(&cams),
            Err(TsdfError::Parameter { name: "voxel", .. })
        ));
    }
    // One camera: no default scale without a voxel; with one, no depth truncation.
    assert!(matches!(
        TsdfOptions::default().resolve(&cams[..1]),
        Err(TsdfError::NoScale { cameras: 1 })
    ));
    let p = options.resolve(&cams[..1]).unwrap();
    assert_eq!(p.depth_trunc, f64::INFINITY);
    // A voxel far too small for the scene is refused, not allocated.
    let mut tiny = TsdfVolume::new(params(), false)
        .unwrap()
        .with_max_blocks(10);
    assert!(matches!(
        tiny.integrate(&frames),
        Err(TsdfError::TooManyBlocks { .. })
    ));
    // Points beyond 2^30 voxels from the origin.
    let far = TsdfParams {
        voxel: 1e-12,
        trunc: 1e-11,
        depth_trunc: f64::INFINITY,
    };
    let mut volume = TsdfVolume::new(far, false).unwrap();
    assert!(matches!(
        volume.integrate(&frames),
        Err(TsdfError::OutOfRange { .. })
    ));
}

#[test]
fn dense_and_hashed_allocation_agree() {
    let cams = rig();
    let depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    let frames: Vec<Frame<'_>> = cams
        .iter()
        .zip(&depths)
        .map(|(camera, depth)| Frame {
            camera,
            depth,
            color: None,
        })
        .collect();
    let volume = TsdfVolume::new(params(), false).unwrap();
    let prepared = volume.prepare(&frames).unwrap();
    let origin = volume.grid().origin();
    let dense = frame_blocks(&prepared, params(), origin, 1 << 20, DENSE_MARK_CELLS).unwrap();
    let hashed = frame_blocks(&prepared, params(), origin, 1 << 20, 0).unwrap();
    assert!(!dense.is_empty());
    assert_eq!(dense, hashed);
    assert!(matches!(
        frame_blocks(&prepared, params(), origin, 10, 0),
        Err(TsdfError::TooManyBlocks { .. })
    ));
}

#[test]
fn views_streamed_in_batches_give_the_volume_of_all_at_once() {
    let cams = sphere_rig(DVec3::ZERO, RADIUS, 9, (48, 40), 50.0).unwrap();
    let depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    let frames: Vec<Frame<'_>> = cams
        .iter()
        .zip(&depths)
        .map(|(camera, depth)| Frame {
            camera,
            depth,
            color: None,
        })
        .collect();
    let mut all = TsdfVolume::new(params(), false).unwrap();
    all.integrate(&frames).unwrap();
    for batch in [1, 2, 4, 9] {
        let loads = std::sync::atomic::AtomicUsize::new(0);
        let mut streamed = TsdfVolume::new(params(), false).unwrap();
        streamed
            .integrate_in_batches(
                &cams,
                |i| {
                    loads.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    Ok((depths[i].clone(), None))
                },
                batch,
            )
            .unwrap();
        // Each view read twice (allocation, integration), once when they all fit in one
        // batch; the same blocks, in the same order, with the same values.
        let reads = if batch >= cams.len() { 1 } else { 2 };
        assert_eq!(loads.into_inner(), reads * cams.len(), "batch {batch}");
        assert_eq!(streamed.grid().keys(), all.grid().keys(), "batch {batch}");
        assert_eq!(streamed.grid().value, all.grid().value, "batch {batch}");
        assert_eq!(streamed.grid().weight, all.grid().weight, "batch {batch}");
    }
    // A failing view stops the fusion with its error.
    let mut failing = TsdfVolume::new(params(), false).unwrap();
    let err = failing
        .integrate_in_batches(
            &cams,
            |i| {
                if i == 5 {
                    Err(TsdfError::MissingImage {
                        path: "view_5_depth.npy".into(),
                        camera: cams[i].name.clone(),
                    })
                } else {
                    Ok((depths[i].clone(), None))
                }
            },
            2,
        )
        .unwrap_err();
    assert!(err.to_string().contains("view_5_depth.npy"), "{err}");
}

/// Issue #15, item 4: the same views with the cameras moved by 1e6 (a whole number of voxels,
/// so the grid moves with them) give the same mesh moved by 1e6: voxel centres, camera
/// positions and the marching-cubes vertices are f64, so nothing is lost far from the origin.
#[test]
fn far_from_the_origin_the_mesh_moves_with_the_cameras() {
    let voxel = 1.0 / 64.0;
    let offset = DVec3::new(1e6, -1e6, 1e6);
    let here = sphere_rig(DVec3::ZERO, RADIUS, 7, (40, 32), 50.0).unwrap();
    let there = sphere_rig(offset, RADIUS, 7, (40, 32), 50.0).unwrap();
    // The views are the same relative to the sphere: one set of depth images serves both.
    let depths: Vec<DepthImage> = here.iter().map(sphere_depth).collect();
    let options = TsdfOptions {
        voxel: Some(voxel),
        trunc: Some(4.0 * voxel),
        depth_trunc: Some(10.0),
        ..TsdfOptions::default()
    };
    let a = fuse(&here, &depths, None, &options).unwrap().mesh;
    let b = fuse(&there, &depths, None, &options).unwrap().mesh;
    assert!(a.triangle_count() > 500);
    assert_eq!(a.triangle_count(), b.triangle_count());
    let sorted = |m: &TriMesh, o: DVec3| {
        let mut p: Vec<[f64; 3]> = m.positions().iter().map(|v| (*v - o).to_array()).collect();
        p.sort_by(|x, y| x.partial_cmp(y).unwrap());
        p
    };
    let worst = sorted(&a, DVec3::ZERO)
        .iter()
        .zip(sorted(&b, offset))
        .map(|(p, q)| (DVec3::from(*p) - DVec3::from(q)).length())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-6 * voxel, "{worst:e}");
}

/// Mean distance of the mesh's vertices to the sphere of `RADIUS` and their mean signed offset.
fn sphere_errors(mesh: &TriMesh) -> (f64, f64) {
    let n = mesh.vertex_count() as f64;
    let offsets = mesh.positions().iter().map(|p| p.length() - RADIUS);
    let (abs, signed) = offsets.fold((0.0, 0.0), |(a, s), e| (a + e.abs(), s + e));
    (abs / n, signed / n)
}

#[test]
fn error_falls_with_the_voxel_below_the_pixel_footprint() {
    // Issue #34: reading each voxel's depth at the nearest pixel centre shrank convex shapes
    // by a part of a pixel footprint that no voxel removed (the error stopped falling, then
    // rose, once voxels were smaller than the footprint at truncation 4 voxels). The depth
    // now follows the surface between pixel centres, so the error keeps falling with the
    // voxel, here from about 2 voxels per footprint (~0.012) to about 4 per footprint.
    let cams = sphere_rig(DVec3::ZERO, RADIUS, 24, (64, 64), 50.0).unwrap();
    let depths: Vec<DepthImage> = cams.iter().map(sphere_depth).collect();
    let errors: Vec<(f64, f64)> = [0.012, 0.006, 0.003]
        .iter()
        .map(|&voxel| {
            let options = TsdfOptions {
                voxel: Some(voxel),
                trunc: Some(4.0 * voxel),
                depth_trunc: Some(10.0),
                ..TsdfOptions::default()
            };
            sphere_errors(&fuse(&cams, &depths, None, &options).unwrap().mesh)
        })
        .collect();
    for pair in errors.windows(2) {
        assert!(
            pair[1].0 < 0.8 * pair[0].0,
            "mean distance to the sphere does not fall with the voxel: {errors:?}"
        );
    }
    let (finest, bias) = errors[2];
    assert!(bias.abs() < 0.5 * finest + 1e-5, "{errors:?}");
}

/// A view with front depths marks free space only in front of them: a voxel between a
/// pixel's front depth and its depth keeps what other views said (here nothing), while
/// without front depths the same view carves it (the free-space block path and the voxel
/// path both, since the block lies wholly in front of the surface).
#[test]
fn front_depths_end_the_free_space() {
    let cam = Camera::look_at("c", DVec3::ZERO, DVec3::Z, DVec3::NEG_Y, (16, 16), 40.0).unwrap();
    let plane = |z: f32| DepthImage::try_new(16, 16, vec![z; 256]).unwrap();
    let (near, far) = (plane(0.75), plane(1.0));
    let fronted = plane(1.0).with_front(vec![0.5; 256]).unwrap();
    fn frame<'a>(camera: &'a Camera, depth: &'a DepthImage) -> Frame<'a> {
        Frame {
            camera,
            depth,
            color: None,
        }
    }
    // The voxel on the axis at z = 0.75 and one near the surface at z = 0.99.
    let (between, surface) = (IVec3::new(0, 0, 37), IVec3::new(0, 0, 49));
    let run = |depth: &DepthImage, lookup| {
        let mut volume = TsdfVolume::new(params(), false)
            .unwrap()
            .with_depth_lookup(lookup);
        volume
            .allocate(&[frame(&cam, &near), frame(&cam, &far)])
            .unwrap();
        volume.integrate_allocated(&[frame(&cam, depth)]).unwrap();
        let grid = volume.grid();
        (
            grid.voxel_value(between).unwrap(),
            grid.voxel_value(surface).unwrap(),
        )
    };
    for lookup in [DepthLookup::Bilinear, DepthLookup::Nearest] {
        let (carved, plain_surface) = run(&far, lookup);
        assert_eq!(carved, (1.0, 1.0), "{lookup:?}");
        let (kept, surface) = run(&fronted, lookup);
        assert_eq!(kept.1, 0.0, "{lookup:?}: the view says nothing between");
        assert_eq!(
            surface, plain_surface,
            "{lookup:?}: the surface is the same"
        );
        assert_eq!(surface.1, 1.0);
    }
    // Front depths of the wrong size are refused.
    assert!(plane(1.0).with_front(vec![0.5; 255]).is_err());
}
