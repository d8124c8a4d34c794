"""References of the Python package's tests (python/tests/), beyond the fixtures other areas
already store (Open3D's TSDF and alpha shapes, scipy/trimesh metrics, trimesh/Open3D mesh
structure), computed with the pinned tools:

  delaunay   scipy.spatial.Delaunay (Qhull) of 200 points drawn uniformly in the unit cube by
             numpy's PCG64 (seed 16), rounded to float32 as trisplat stores points: the
             points and the tetrahedra, each row sorted (Qhull's orientation is arbitrary).
             Points in general position: the Delaunay tetrahedralisation is unique.
  spot       trimesh on Spot (fixtures/data/spot_triangulated.obj, positions and triangles
             as the OBJ's `v` and `f` lines, process=False): area, volume, is_watertight,
             is_winding_consistent, bounds, and the triangle centroids (triangles_center) of
             the first 64 triangles with the mean of all of them.

Output fixtures/data/reference/python/python.json.
"""

import json
import pathlib

import numpy as np
import scipy
import trimesh
from scipy.spatial import Delaunay

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
OBJ = ROOT / "fixtures" / "data" / "spot_triangulated.obj"
OUT = ROOT / "fixtures" / "data" / "reference" / "python"


def load_spot():
    """Spot's positions and triangles from the OBJ's `v` and `f` lines (no vertex splitting)."""
    verts, faces = [], []
    for line in OBJ.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            for k in range(1, len(idx) - 1):
                faces.append([idx[0], idx[k], idx[k + 1]])
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


def delaunay_case():
    rng = np.random.default_rng(16)
    points = rng.random((200, 3)).astype(np.float32)
    tri = Delaunay(points.astype(np.float64))
    tets = np.sort(tri.simplices, axis=1)
    tets = tets[np.lexsort(tets.T[::-1])]
    return {
        "tool": f"scipy {scipy.__version__} spatial.Delaunay (Qhull)",
        "points": points.tolist(),
        "tetrahedra_sorted": tets.tolist(),
    }


def spot_case():
    v, f = load_spot()
    mesh = trimesh.Trimesh(vertices=v, faces=f, process=False)
    centers = mesh.triangles_center
    return {
        "tool": f"trimesh {trimesh.__version__}",
        "vertices": int(len(v)),
        "triangles": int(len(f)),
        "area": float(mesh.area),
        "volume": float(mesh.volume),
        "is_watertight": bool(mesh.is_watertight),
        "is_winding_consistent": bool(mesh.is_winding_consistent),
        "bounds": mesh.bounds.tolist(),
        "triangles_center_first_64": centers[:64].tolist(),
        "triangles_center_mean": centers.mean(axis=0).tolist(),
    }


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    result = {
        "versions": {"numpy": np.__version__, "scipy": scipy.__version__, "trimesh": trimesh.__version__},
        "delaunay": delaunay_case(),
        "spot": spot_case(),
    }
    path = OUT / "python.json"
    path.write_text(json.dumps(result, separators=(",", ":")) + "\n")
    print(f"wrote {path.relative_to(ROOT)} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
