"""Render-consistency reference: a mesh against Gaussians, the mesh ray cast by Open3D.

The mesh is the LAM fixture's alpha-shape mesh at frame 0 of its expression track (`trisplat
extract --method alpha`: 760 triangles with holes); the Gaussians are the fixture's per-vertex Gaussians deformed to world
space at frame 5 of its expression track (`trisplat deform --avatar fixtures/data/lam_mini`),
stored as SPZ, so that the rest-pose mesh and the Gaussians differ where the face moves. Their alpha, median
depth and world normals come from `trisplat render` (the renderer's own reference is gsplat,
ref_render_gsplat.py). What is checked independently: the mesh's z-depth and face normals from
Open3D's RaycastingScene, and the statistics (docs/conventions.md §8, "Render consistency"):

  covered by the Gaussians = alpha > 0.5 and median depth > 0
  iou                      = |mesh hit & covered| / |mesh hit | covered|
  depth error              = |mesh z - median z| over pixels both cover: median, 90th percentile
                             (numpy's linear interpolation)
  normal angle             = median over those pixels of the angle between the mesh's face
                             normal and the Gaussians' normalised composited normal, degrees

Outputs in fixtures/data/reference/consistency/: mesh.ply, gaussians.spz, cameras.json (a sphere of views
plus a close grazing one), consistency.json (the numbers, versions).

    python3 tests/reference/ref_consistency.py target/release/trisplat
"""

import json
import pathlib
import subprocess
import sys
import tempfile

import numpy as np
import open3d as o3d

ROOT = pathlib.Path(__file__).resolve().parents[2]
AVATAR = ROOT / "fixtures" / "data" / "lam_mini"
OUT = ROOT / "fixtures" / "data" / "reference" / "consistency"
SIZE = 128


def look_at(name, cid, eye, target, fov_y_deg, up=(0.0, 1.0, 0.0)):
    """A camera of trisplat's cameras.json layout (camera-to-world rotation, OpenCV axes)."""
    eye, target, up = (np.asarray(x, dtype=np.float64) for x in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    focal = 0.5 * SIZE / np.tan(0.5 * np.radians(fov_y_deg))
    return {
        "id": cid,
        "img_name": name,
        "width": SIZE,
        "height": SIZE,
        "position": eye.tolist(),
        "rotation": np.stack([right, down, forward], axis=1).tolist(),
        "fx": focal,
        "fy": focal,
        "cx": 0.5 * SIZE,
        "cy": 0.5 * SIZE,
    }


def cameras(center, radius):
    """Six views on a sphere around the head, and one close view grazing its side."""
    dirs = [(0, 0, 1), (1, 0.2, 0.3), (-1, 0.1, 0.2), (0.2, 1, 0.3), (0.3, -0.4, 1), (0, 0.2, -1)]
    out = []
    for k, d in enumerate(dirs):
        d = np.asarray(d, dtype=np.float64)
        eye = center + 3.2 * radius * d / np.linalg.norm(d)
        out.append(look_at(f"view_{k}", k, eye, center, 40.0))
    eye = center + radius * np.array([1.3, 0.0, 0.25])
    out.append(look_at("grazing", len(dirs), eye, center + radius * np.array([0, 0, 0.9]), 70.0))
    return out


def run(*args):
    subprocess.run([str(a) for a in args], check=True, stdout=subprocess.DEVNULL)


def main():
    trisplat = pathlib.Path(sys.argv[1]).resolve()
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        run(trisplat, "deform", "--avatar", AVATAR, "--animation", AVATAR / "expression.json",
            "--frames", "5", "-o", tmp / "g", "-q")
        world = next((tmp / "g").glob("*.ply"))
        run(trisplat, "convert", world, OUT / "gaussians.spz")
        run(trisplat, "extract", "--avatar", AVATAR, "--animation", AVATAR / "expression.json",
            "--frames", "0", "--method", "alpha", "--targets", "meshes", "-o", tmp / "e", "-q")
        (OUT / "mesh.ply").write_bytes((tmp / "e" / "alpha" / "frame_000000.ply").read_bytes())
        mesh = o3d.t.io.read_triangle_mesh(str(OUT / "mesh.ply"))
        v = mesh.vertex.positions.numpy().astype(np.float64)
        center = 0.5 * (v.min(axis=0) + v.max(axis=0))
        radius = np.linalg.norm(v - center, axis=1).max()
        cams = cameras(center, radius)
        (OUT / "cameras.json").write_text(json.dumps(cams, indent=1) + "\n")
        # `render` reads PLY: the SPZ's decoded values, written exactly.
        run(trisplat, "convert", OUT / "gaussians.spz", tmp / "decoded.ply")
        run(trisplat, "render", tmp / "decoded.ply", "--cameras", OUT / "cameras.json",
            "-o", tmp / "r", "--outputs", "alpha,median_depth,normal", "--normal-frame", "world",
            "-q")
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(mesh)
        errors, angles = [], []
        mesh_px = gauss_px = both_px = 0
        for cam in cams:
            j, i = np.meshgrid(np.arange(SIZE), np.arange(SIZE))
            d_cam = np.stack([(j + 0.5 - cam["cx"]) / cam["fx"], (i + 0.5 - cam["cy"]) / cam["fy"],
                              np.ones(j.shape)], axis=-1).reshape(-1, 3)
            rot = np.asarray(cam["rotation"])
            d = d_cam @ rot.T
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            o = np.broadcast_to(np.asarray(cam["position"]), d.shape)
            ans = scene.cast_rays(o3d.core.Tensor(np.concatenate([o, d], 1).astype(np.float32)))
            t = ans["t_hit"].numpy().astype(np.float64)
            hit = np.isfinite(t)
            z = np.where(hit, t * (d @ rot[:, 2]), 0.0)
            n = ans["primitive_normals"].numpy().astype(np.float64)
            n[np.sum(n * d, axis=1) > 0] *= -1
            name = cam["img_name"]
            alpha = np.load(tmp / "r" / f"{name}_alpha.npy").reshape(-1)
            median = np.load(tmp / "r" / f"{name}_median_depth.npy").reshape(-1).astype(np.float64)
            g_n = np.load(tmp / "r" / f"{name}_normal.npy").reshape(-1, 3).astype(np.float64)
            covered = (alpha > 0.5) & (median > 0)
            both = covered & hit
            mesh_px += int(hit.sum())
            gauss_px += int(covered.sum())
            both_px += int(both.sum())
            errors.append(np.abs(z[both] - median[both]))
            a, b = n[both], g_n[both]
            la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
            ok = (la > 0) & (lb > 0)
            cos = np.clip(np.sum(a[ok] * b[ok], 1) / (la[ok] * lb[ok]), -1, 1)
            angles.append(np.degrees(np.arccos(cos)))
        e, ang = np.concatenate(errors), np.concatenate(angles)
        result = {
            "tool": "open3d.t.geometry.RaycastingScene.cast_rays, numpy statistics",
            "open3d": o3d.__version__,
            "numpy": np.__version__,
            "mesh": "alpha shape of fixtures/data/lam_mini, frame 0",
            "views": len(cams),
            "iou": both_px / (mesh_px + gauss_px - both_px),
            "depth_error_median": float(np.median(e)),
            "depth_error_p90": float(np.percentile(e, 90)),
            "normal_angle_deg": float(np.median(ang)),
            "mesh_pixels": mesh_px,
            "gaussian_pixels": gauss_px,
            "both_pixels": both_px,
        }
        (OUT / "consistency.json").write_text(json.dumps(result, indent=1) + "\n")
        print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
