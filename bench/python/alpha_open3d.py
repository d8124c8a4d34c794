"""Open3D side of `trisplat-bench alpha`: times `create_from_point_cloud_alpha_shape`.

Usage:
    alpha_open3d.py POINTS.ply ALPHA OUT.bin

Loading is not timed. Writes the boundary triangles as sorted input-point index triples
(little-endian uint32 [T, 3], rows sorted; Open3D's vertices are mapped back to the input
points by exact coordinates) to OUT.bin. The last stdout line is JSON:
{"seconds": ..., "triangles": ...}.
"""

import json
import sys
import time

import numpy as np
import open3d as o3d


def main():
    path, alpha, out = sys.argv[1], float(sys.argv[2]), sys.argv[3]
    pcd = o3d.io.read_point_cloud(path)
    pts = np.asarray(pcd.points)
    t0 = time.perf_counter()
    mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_alpha_shape(pcd, alpha)
    seconds = time.perf_counter() - t0
    lookup = {tuple(p): i for i, p in enumerate(pts.tolist())}
    ids = np.array([lookup[tuple(v)] for v in np.asarray(mesh.vertices).tolist()], dtype=np.int64)
    tris = np.sort(ids[np.asarray(mesh.triangles)], axis=1) if len(ids) else np.zeros((0, 3), np.int64)
    tris = np.unique(tris, axis=0).astype("<u4")
    with open(out, "wb") as f:
        f.write(tris.tobytes())
    print(json.dumps({"seconds": seconds, "triangles": int(len(mesh.triangles))}))


if __name__ == "__main__":
    main()
