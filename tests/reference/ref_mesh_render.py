"""Mesh rendering reference: z-depth and hit-triangle maps of Spot by Open3D's RaycastingScene.

Open3D and trisplat read the same positions-only PLY (`reference/smoothing/spot.ply`, written by
ref_smoothing.py from the OBJ's `v`/`f` lines). Cameras use trisplat's conventions (docs/conventions.md §2):
3DGS `cameras.json` layout, OpenCV axes, pixel (i, j) sampled at (j + 0.5, i + 0.5). Rays are
built here (not with `create_rays_pinhole`) from those conventions, with unit directions, and
Open3D's `t_hit` (distance along the unit ray) is turned into z-depth: z = t_hit * (d . z_cam).

Outputs in fixtures/data/reference/render_mesh/:

  cameras.json      the views (3 around the cow, 1 close and oblique, 1 inside the body)
  depth.npy         float32 [N, H, W] z-depth, 0 where the ray misses
  triangle.npy      float32 [N, H, W] Open3D primitive id of the hit, -1 where it misses
  normal0.npy       float32 [H, W, 3] Open3D primitive normal of view 0, turned to face the
                    camera (0 where it misses)
  render_mesh.json  versions, sizes, hit counts
"""

import json
import pathlib

import numpy as np
import open3d as o3d

ROOT = pathlib.Path(__file__).resolve().parents[2]
PLY = ROOT / "fixtures" / "data" / "reference" / "smoothing" / "spot.ply"
OUT = ROOT / "fixtures" / "data" / "reference" / "render_mesh"

WIDTH, HEIGHT = 96, 72


def look_at(name, cid, eye, target, fov_y_deg, up=(0.0, 1.0, 0.0)):
    """A camera of trisplat's cameras.json layout (camera-to-world rotation, row-major)."""
    eye, target, up = (np.asarray(x, dtype=np.float64) for x in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward], axis=1)  # columns: camera x, y, z in world
    focal = 0.5 * HEIGHT / np.tan(0.5 * np.radians(fov_y_deg))
    return {
        "id": cid,
        "img_name": name,
        "width": WIDTH,
        "height": HEIGHT,
        "position": eye.tolist(),
        "rotation": rotation.tolist(),
        "fx": focal,
        "fy": focal,
        "cx": 0.5 * WIDTH,
        "cy": 0.5 * HEIGHT,
    }


CAMERAS = [
    look_at("front", 0, (0.35, 0.4, 2.1), (0.0, 0.1, 0.15), 50.0),
    look_at("side", 1, (2.4, 0.3, 0.2), (0.0, 0.1, 0.15), 45.0),
    look_at("above_back", 2, (-0.6, 1.5, -1.1), (0.0, 0.1, 0.15), 55.0),
    # Close and oblique: wide field of view, rays grazing the flank.
    look_at("close_oblique", 3, (0.6, 0.05, -0.9), (0.0, 0.15, 0.6), 90.0),
    # Inside the body, looking at the head: every ray hits a back face.
    look_at("inside", 4, (0.0, 0.0, 0.0), (0.0, 0.3, 0.8), 70.0),
]


def rays(cam):
    """Unit rays (origin, direction) of every pixel in row-major order, float64."""
    j, i = np.meshgrid(np.arange(cam["width"]), np.arange(cam["height"]))
    d_cam = np.stack(
        [
            (j + 0.5 - cam["cx"]) / cam["fx"],
            (i + 0.5 - cam["cy"]) / cam["fy"],
            np.ones(j.shape),
        ],
        axis=-1,
    ).reshape(-1, 3)
    rot = np.asarray(cam["rotation"])
    d_world = d_cam @ rot.T
    d_world /= np.linalg.norm(d_world, axis=1, keepdims=True)
    origin = np.broadcast_to(np.asarray(cam["position"]), d_world.shape)
    return origin, d_world, rot[:, 2]


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    mesh = o3d.t.io.read_triangle_mesh(str(PLY))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(mesh)
    depths, triangles, hits = [], [], []
    normal0 = None
    for k, cam in enumerate(CAMERAS):
        origin, direction, z_axis = rays(cam)
        r = np.concatenate([origin, direction], axis=1).astype(np.float32)
        ans = scene.cast_rays(o3d.core.Tensor(r))
        t_hit = ans["t_hit"].numpy().astype(np.float64)
        prim = ans["primitive_ids"].numpy().astype(np.int64)
        hit = np.isfinite(t_hit)
        # z-depth = distance along the unit ray times the cosine to the optical axis.
        z = np.where(hit, t_hit * (direction @ z_axis), 0.0)
        depths.append(z.reshape(HEIGHT, WIDTH))
        triangles.append(np.where(hit, prim, -1).reshape(HEIGHT, WIDTH))
        hits.append(int(hit.sum()))
        if k == 0:
            n = ans["primitive_normals"].numpy().astype(np.float64)
            flip = np.sum(n * direction, axis=1) > 0
            n[flip] *= -1
            n[~hit] = 0
            normal0 = n.reshape(HEIGHT, WIDTH, 3)
    (OUT / "cameras.json").write_text(json.dumps(CAMERAS, indent=1) + "\n")
    np.save(OUT / "depth.npy", np.stack(depths).astype(np.float32))
    np.save(OUT / "triangle.npy", np.stack(triangles).astype(np.float32))
    np.save(OUT / "normal0.npy", normal0.astype(np.float32))
    meta = {
        "tool": "open3d.t.geometry.RaycastingScene.cast_rays",
        "open3d": o3d.__version__,
        "numpy": np.__version__,
        "mesh": "fixtures/data/reference/smoothing/spot.ply",
        "width": WIDTH,
        "height": HEIGHT,
        "cameras": [c["img_name"] for c in CAMERAS],
        "hits": hits,
    }
    (OUT / "render_mesh.json").write_text(json.dumps(meta, indent=1) + "\n")
    print(json.dumps(meta))


if __name__ == "__main__":
    main()
