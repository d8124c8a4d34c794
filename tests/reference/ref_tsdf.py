"""TSDF references (docs/conventions.md §6): Open3D 0.20's legacy UniformTSDFVolume on depth maps of Spot.

Spot (positions-only `fixtures/data/reference/smoothing/spot.ply`, closed, about 1.8 units
tall) is seen by 30 cameras of 48 x 48 pixels on a sphere (the Fibonacci lattice of trisplat's
`camera::sphere_rig`: centre = the bounding-box centre, radius = the largest vertex distance to
it, vertical field of view 40 degrees, distance 1.1 r / sin(20 deg), world up +y). Depth maps
are rendered with Open3D's RaycastingScene through the pixel centres (j + 0.5, i + 0.5) as
z-depth (0 where the ray misses).

Open3D's volume uses the same voxel centres as trisplat: its origin is a multiple of the voxel,
so its voxel (i + 1/2) * voxel + origin is trisplat's voxel g + 1/2 with g = i + origin / voxel.
Its pixel centres are at integers, so its principal point is (cx - 1/2, cy - 1/2). The mesh is
post-processed as 2DGS does (clusters at least as large as the largest, unreferenced vertices,
degenerate triangles).

Chamfer (docs/conventions.md §8, surface mode, like `trisplat eval --surface`): N_SAMPLES area-uniform samples
on each mesh (numpy, seed 0), d(x, S) the exact distance to the other mesh's triangles
(RaycastingScene.compute_distance), chamfer_l1 = (mean d(p, GT) + mean d(g, P)) / 2.

Outputs in fixtures/data/reference/tsdf/:

  cameras.json            the 30 cameras, 3DGS layout (trisplat's `read_cameras_json`)
  view_XXX_depth.npy      float32 [48, 48] z-depth maps
  open3d.json             parameters, 2DGS scene radius, Open3D mesh counts, boundary edges,
                          Open3D's is_watertight (which also needs no self-intersection),
                          signed volume, and Chamfer to Spot

With 20 views of 64 x 64 the top of the head had unobserved cells (20 boundary edges in Open3D's
mesh); 30 views of 48 x 48 observe every cell of the surface.
"""

import json
import pathlib

import numpy as np
import open3d as o3d

ROOT = pathlib.Path(__file__).resolve().parents[2]
SPOT = ROOT / "fixtures" / "data" / "reference" / "smoothing" / "spot.ply"
OUT = ROOT / "fixtures" / "data" / "reference" / "tsdf"

VIEWS = 30
SIZE = 48
FOV_Y_DEG = 40.0
VOXEL = 0.02
TRUNC = 5 * VOXEL
N_SAMPLES = 100_000


def look_at(eye, target, up, width, height, fov_y_deg):
    """trisplat's Camera::look_at: (rotation camera-to-world with columns right, down,
    forward; fx = fy; principal point at the image centre)."""
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    focal = 0.5 * height / np.tan(0.5 * np.radians(fov_y_deg))
    rotation = np.stack([right, down, forward], axis=1)
    return rotation, focal, 0.5 * width, 0.5 * height


def sphere_rig(center, radius, count, width, height, fov_y_deg):
    """trisplat's camera::sphere_rig (Fibonacci lattice)."""
    distance = 1.1 * radius / np.sin(0.5 * np.radians(fov_y_deg))
    golden = np.pi * (3.0 - np.sqrt(5.0))
    cams = []
    for i in range(count):
        y = 1.0 - 2.0 * (i + 0.5) / count
        r = np.sqrt(max(1.0 - y * y, 0.0))
        phi = golden * i
        direction = np.array([r * np.cos(phi), y, r * np.sin(phi)])
        eye = center + direction * distance
        rotation, focal, cx, cy = look_at(eye, center, np.array([0.0, 1.0, 0.0]), width, height, fov_y_deg)
        cams.append(
            {
                "id": i,
                "img_name": f"view_{i:03d}",
                "width": width,
                "height": height,
                "position": eye.tolist(),
                "rotation": rotation.tolist(),
                "fx": focal,
                "fy": focal,
                "cx": cx,
                "cy": cy,
            }
        )
    return cams


def render_depth(scene, cam):
    """z-depth through the pixel centres; the ray direction has camera z = 1, so t is z."""
    w, h = cam["width"], cam["height"]
    jj, ii = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    d_cam = np.stack(
        [(jj - cam["cx"]) / cam["fx"], (ii - cam["cy"]) / cam["fy"], np.ones_like(jj)], axis=-1
    )
    rotation = np.asarray(cam["rotation"])
    d_world = d_cam @ rotation.T
    origin = np.broadcast_to(np.asarray(cam["position"]), d_world.shape)
    rays = np.concatenate([origin, d_world], axis=-1).astype(np.float32)
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    return np.where(np.isfinite(t), t, 0.0).astype(np.float32)


def focus_radius(cams):
    """2DGS estimate_bounding_sphere: point nearest all optical axes, smallest camera distance."""
    dirs = np.array([np.asarray(c["rotation"])[:, 2] for c in cams])
    origins = np.array([c["position"] for c in cams])
    m = np.eye(3)[None] - dirs[:, :, None] * dirs[:, None, :]
    mt_m = np.transpose(m, [0, 2, 1]) @ m
    focus = np.linalg.inv(mt_m.mean(0)) @ (mt_m @ origins[:, :, None]).mean(0)[:, 0]
    radius = np.linalg.norm(origins - focus, axis=-1).min()
    return focus, float(radius)


def post_process(mesh, keep=1):
    """2DGS post_process_mesh without its 50-triangle floor (k-th largest cluster kept)."""
    clusters, n_tri, _ = mesh.cluster_connected_triangles()
    clusters, n_tri = np.asarray(clusters), np.asarray(n_tri)
    if len(n_tri) == 0:
        return mesh
    threshold = np.sort(n_tri)[-keep] if keep <= len(n_tri) else 0
    mesh.remove_triangles_by_mask(n_tri[clusters] < threshold)
    mesh.remove_unreferenced_vertices()
    mesh.remove_degenerate_triangles()
    return mesh


def sample(verts, tris, n, rng):
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    t = rng.choice(len(tris), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    return w[:, :1] * a[t] + w[:, 1:2] * b[t] + w[:, 2:] * c[t]


def surface_distances(points, verts, tris):
    scene = o3d.t.geometry.RaycastingScene()
    mesh = o3d.t.geometry.TriangleMesh()
    mesh.vertex.positions = o3d.core.Tensor(verts.astype(np.float32))
    mesh.triangle.indices = o3d.core.Tensor(tris.astype(np.int32))
    scene.add_triangles(mesh)
    return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy().astype(np.float64)


def chamfer(pred_v, pred_t, gt_v, gt_t):
    rng = np.random.default_rng(0)
    p = sample(pred_v, pred_t, N_SAMPLES, rng)
    g = sample(gt_v, gt_t, N_SAMPLES, rng)
    accuracy = surface_distances(p, gt_v, gt_t).mean()
    completeness = surface_distances(g, pred_v, pred_t).mean()
    return {
        "accuracy": accuracy,
        "completeness": completeness,
        "chamfer_l1": 0.5 * (accuracy + completeness),
        "samples": N_SAMPLES,
    }


def boundary_edge_count(tris):
    """Edges used by exactly one triangle."""
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int((counts == 1).sum())


def signed_volume(verts, tris):
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    spot = o3d.io.read_triangle_mesh(str(SPOT))
    gt_v = np.asarray(spot.vertices, dtype=np.float64)
    gt_t = np.asarray(spot.triangles, dtype=np.int64)
    lo, hi = gt_v.min(0), gt_v.max(0)
    center = 0.5 * (lo + hi)
    radius = float(np.linalg.norm(gt_v - center, axis=1).max())
    cams = sphere_rig(center, radius, VIEWS, SIZE, SIZE, FOV_Y_DEG)
    (OUT / "cameras.json").write_text(json.dumps(cams, indent=1) + "\n")

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(spot))
    depths = [render_depth(scene, c) for c in cams]
    for cam, depth in zip(cams, depths):
        np.save(OUT / f"{cam['img_name']}_depth.npy", depth)

    focus, radius_2dgs = focus_radius(cams)
    depth_trunc = 2.0 * radius_2dgs

    margin = TRUNC + 2 * VOXEL
    origin = np.floor((lo - margin) / VOXEL) * VOXEL
    resolution = int(np.ceil((hi + margin - origin).max() / VOXEL))
    volume = o3d.pipelines.integration.UniformTSDFVolume(
        length=resolution * VOXEL,
        resolution=resolution,
        sdf_trunc=TRUNC,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.NoColor,
        origin=origin,
    )
    for cam, depth in zip(cams, depths):
        w, h = cam["width"], cam["height"]
        color = o3d.geometry.Image(np.zeros((h, w, 3), np.uint8))
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            color,
            o3d.geometry.Image(depth),
            depth_scale=1.0,
            depth_trunc=depth_trunc,
            convert_rgb_to_intensity=False,
        )
        intrinsic = o3d.camera.PinholeCameraIntrinsic(
            w, h, cam["fx"], cam["fy"], cam["cx"] - 0.5, cam["cy"] - 0.5
        )
        rotation = np.asarray(cam["rotation"])
        extrinsic = np.eye(4)
        extrinsic[:3, :3] = rotation.T
        extrinsic[:3, 3] = -rotation.T @ np.asarray(cam["position"])
        volume.integrate(rgbd, intrinsic, extrinsic)
    raw = volume.extract_triangle_mesh()
    raw_counts = (len(raw.vertices), len(raw.triangles))
    mesh = post_process(raw, keep=1)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles, dtype=np.int64)
    result = {
        "tool": f"open3d {o3d.__version__} UniformTSDFVolume",
        "views": VIEWS,
        "size": SIZE,
        "voxel": VOXEL,
        "trunc": TRUNC,
        "depth_trunc": depth_trunc,
        "radius_2dgs": radius_2dgs,
        "focus_2dgs": focus.tolist(),
        "volume_origin": origin.tolist(),
        "volume_resolution": resolution,
        "raw_vertices": raw_counts[0],
        "raw_triangles": raw_counts[1],
        "vertices": len(v),
        "triangles": len(t),
        "boundary_edges": boundary_edge_count(t),
        "watertight_open3d": bool(mesh.is_watertight()),
        "edge_manifold": bool(mesh.is_edge_manifold()),
        "signed_volume": signed_volume(v, t),
        "gt_volume": signed_volume(gt_v, gt_t),
        "chamfer": chamfer(v, t, gt_v, gt_t),
    }
    (OUT / "open3d.json").write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
