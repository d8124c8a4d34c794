"""Open3D side of `trisplat-bench smooth`: times one Open3D operation on a mesh file.

Usage:
    smooth_open3d.py MESH laplacian ITERATIONS LAMBDA OUT.npy
    smooth_open3d.py MESH taubin ITERATIONS LAMBDA MU OUT.npy
    smooth_open3d.py MESH uniform N
    smooth_open3d.py MESH poisson N

Loading is not timed. Smoothing writes the smoothed vertices (float64 [V, 3]) to OUT.npy.
The last stdout line is JSON: {"seconds": ..., "points": ...}.
"""

import json
import sys
import time

import numpy as np
import open3d as o3d


def main():
    path, op, *rest = sys.argv[1:]
    mesh = o3d.io.read_triangle_mesh(path)
    result = {}
    if op == "laplacian":
        iterations, lam, out = int(rest[0]), float(rest[1]), rest[2]
        t0 = time.perf_counter()
        smoothed = mesh.filter_smooth_laplacian(iterations, lam)
        result["seconds"] = time.perf_counter() - t0
        np.save(out, np.asarray(smoothed.vertices, dtype=np.float64))
    elif op == "taubin":
        iterations, lam, mu, out = int(rest[0]), float(rest[1]), float(rest[2]), rest[3]
        t0 = time.perf_counter()
        smoothed = mesh.filter_smooth_taubin(iterations, lam, mu)
        result["seconds"] = time.perf_counter() - t0
        np.save(out, np.asarray(smoothed.vertices, dtype=np.float64))
    elif op == "uniform":
        n = int(rest[0])
        t0 = time.perf_counter()
        pcd = mesh.sample_points_uniformly(n, use_triangle_normal=True)
        result["seconds"] = time.perf_counter() - t0
        result["points"] = len(pcd.points)
    elif op == "poisson":
        n = int(rest[0])
        t0 = time.perf_counter()
        pcd = mesh.sample_points_poisson_disk(n, use_triangle_normal=True)
        result["seconds"] = time.perf_counter() - t0
        result["points"] = len(pcd.points)
    else:
        sys.exit(f"unknown operation {op}")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
