"""Smoothing and sampling references: Open3D's Laplacian/Taubin filters and trimesh's
volume-preserving uniform filter on Spot, and Open3D's Poisson-disk spacing statistics.

Both tools and trisplat read the same positions-only binary PLY (written here from the OBJ's `v`
and `f` lines, so the vertex order is the OBJ's; Open3D's OBJ reader would split vertices at uv
seams). Outputs go to fixtures/data/reference/smoothing/:

  spot.ply                       positions-only Spot (float32 x y z, int vertex_indices)
  <name>.npy                     float64 [V, 3] smoothed positions, one per case in CASES
  smoothing.json                 the cases (tool, function, parameters, file) and versions
  poisson_open3d.json            Open3D sample_points_poisson_disk spacing on spot.ply
"""

import json
import pathlib

import numpy as np
import open3d as o3d
import trimesh
from scipy.spatial import cKDTree

ROOT = pathlib.Path(__file__).resolve().parents[2]
OBJ = ROOT / "fixtures" / "data" / "spot_triangulated.obj"
OUT = ROOT / "fixtures" / "data" / "reference" / "smoothing"

# (name, tool, parameters)
CASES = [
    ("open3d_laplacian_1", "open3d", {"method": "laplacian", "iterations": 1, "lambda": 0.5}),
    ("open3d_laplacian_10", "open3d", {"method": "laplacian", "iterations": 10, "lambda": 0.5}),
    ("open3d_laplacian_5_l0.9", "open3d", {"method": "laplacian", "iterations": 5, "lambda": 0.9}),
    ("open3d_taubin_1", "open3d", {"method": "taubin", "iterations": 1, "lambda": 0.5, "mu": -0.53}),
    ("open3d_taubin_10", "open3d", {"method": "taubin", "iterations": 10, "lambda": 0.5, "mu": -0.53}),
    ("trimesh_uniform_10", "trimesh", {"method": "uniform", "iterations": 10, "lambda": 0.5}),
]


def read_obj_positions(path):
    """Positions and triangles from `v` and `f` lines (first index of each corner, fans)."""
    verts, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(c.split("/")[0]) for c in parts[1:]]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            for k in range(1, len(idx) - 1):
                faces.append([idx[0], idx[k], idx[k + 1]])
    return np.asarray(verts, dtype=np.float32), np.asarray(faces, dtype=np.int32)


def write_ply(path, verts, faces):
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment Spot (public domain), positions only\n"
        f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    face_dtype = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    f = np.empty(len(faces), dtype=face_dtype)
    f["n"] = 3
    f["i"] = faces
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(verts.astype("<f4").tobytes())
        fh.write(f.tobytes())


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    verts, faces = read_obj_positions(OBJ)
    ply = OUT / "spot.ply"
    write_ply(ply, verts, faces)

    mesh = o3d.io.read_triangle_mesh(str(ply))
    assert np.array_equal(np.asarray(mesh.vertices), verts.astype(np.float64)), "Open3D order"
    assert np.array_equal(np.asarray(mesh.triangles), faces), "Open3D faces"
    tm = trimesh.load(str(ply), process=False)
    assert np.array_equal(tm.vertices, verts.astype(np.float64)), "trimesh order"
    assert np.array_equal(tm.faces, faces), "trimesh faces"

    manifest = {
        "mesh": "spot.ply",
        "vertices": len(verts),
        "triangles": len(faces),
        "open3d": o3d.__version__,
        "trimesh": trimesh.__version__,
        "cases": [],
    }
    for name, tool, params in CASES:
        if tool == "open3d":
            if params["method"] == "laplacian":
                out = mesh.filter_smooth_laplacian(params["iterations"], params["lambda"])
            else:
                out = mesh.filter_smooth_taubin(params["iterations"], params["lambda"], params["mu"])
            result = np.asarray(out.vertices, dtype=np.float64)
            call = (f"filter_smooth_{params['method']}({params['iterations']}, "
                    f"{params['lambda']}{', ' + str(params['mu']) if 'mu' in params else ''})")
        else:
            m = trimesh.load(str(ply), process=False)
            trimesh.smoothing.filter_laplacian(m, lamb=params["lambda"],
                                               iterations=params["iterations"])
            result = np.asarray(m.vertices, dtype=np.float64)
            call = (f"trimesh.smoothing.filter_laplacian(mesh, lamb={params['lambda']}, "
                    f"iterations={params['iterations']})")
        assert np.isfinite(result).all()
        np.save(OUT / f"{name}.npy", result)
        manifest["cases"].append({"name": name, "file": f"{name}.npy", "tool": tool,
                                  "call": call, **params})
        print(f"  {name}: max displacement {np.abs(result - verts).max():.3e}")
    (OUT / "smoothing.json").write_text(json.dumps(manifest, indent=1) + "\n")

    # Poisson-disk spacing of Open3D's sample elimination, for the statistical tests.
    area = float(mesh.get_surface_area())
    stats = {"open3d": o3d.__version__, "mesh": "spot.ply", "area": area, "runs": []}
    for n in (1000, 4000):
        d_max = 2.0 * np.sqrt(area / (2.0 * np.sqrt(3.0) * n))
        o3d.utility.random.seed(1)
        pcd = mesh.sample_points_poisson_disk(n)
        pts = np.asarray(pcd.points)
        dist, _ = cKDTree(pts).query(pts, k=2)
        nn = dist[:, 1]
        uni = np.asarray(mesh.sample_points_uniformly(n).points)
        udist, _ = cKDTree(uni).query(uni, k=2)
        stats["runs"].append({
            "n": n,
            "returned": len(pts),
            "d_max": d_max,
            "min_nn_over_d_max": float(nn.min() / d_max),
            "mean_nn_over_d_max": float(nn.mean() / d_max),
            "uniform_min_nn_over_d_max": float(udist[:, 1].min() / d_max),
            "uniform_mean_nn_over_d_max": float(udist[:, 1].mean() / d_max),
        })
        print(f"  poisson n={n}: {stats['runs'][-1]}")
    (OUT / "poisson_open3d.json").write_text(json.dumps(stats, indent=1) + "\n")


if __name__ == "__main__":
    main()
