"""Mesh structure references (docs/conventions.md §8, `geometry::mesh_stats`): trimesh's area,
bodies (`split(only_watertight=False)`), boundary and non-manifold edges, `is_watertight` and
`is_winding_consistent`, and Open3D's `cluster_connected_triangles`, on Spot and edited copies
of it.

No mesh file is written: each case is Spot (fixtures/data/spot_triangulated.obj, positions and
triangles as the OBJ's `v` and `f` lines, float32 as trisplat stores them) or nothing, edited
by a recipe stored with the results, so the fixture stays a few KB:

  flip_faces      indices (into the base's faces) whose first two corners are swapped
  remove_faces    indices (into the base's faces) removed (after flipping)
  add_vertices    float32-exact positions appended to the base's vertices
  add_faces       triangles appended (indices into the combined vertices)

Cases: spot; spot_holes (12 faces removed); spot_piece (plus a detached tetrahedron);
spot_fin (plus one triangle on a Spot edge: a non-manifold edge); book (three triangles on one
edge, alone); spot_flipped (5 faces reversed); spot_degenerate (plus a zero-area triangle of
three distinct collinear vertices, a triangle [a, a, b] on a Spot edge, a triangle [c, c, c]);
empty.

Output fixtures/data/reference/mesh_stats/mesh_stats.json, per case:

  trimesh   area (float64 from the float32 coordinates), bodies = len(split(only_watertight=False,
            repair=False)), largest_body_area_fraction, boundary_edges = len(group_rows(edges_sorted,
            require_count=1)), non_manifold_edges = edges of edges_sorted used more than twice,
            is_watertight, is_winding_consistent
  open3d    clusters = number of cluster_connected_triangles clusters, largest_cluster_area_
            fraction (cluster area / total area)

trimesh's bodies and Open3D's clusters differ where an edge has more than two triangles:
trimesh's face adjacency ignores such edges. trisplat's `components` follows Open3D.
"""

import json
import pathlib
import sys

import numpy as np
import open3d as o3d
import trimesh
from trimesh import grouping

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
OBJ = ROOT / "fixtures" / "data" / "spot_triangulated.obj"
OUT = ROOT / "fixtures" / "data" / "reference" / "mesh_stats"


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
    return np.asarray(verts, np.float32), np.asarray(faces, np.int64)


def f32(points):
    """Positions rounded to float32, as lists of the float64 of those float32 (exact in JSON)."""
    return [[float(x) for x in p] for p in np.asarray(points, np.float32)]


def edge_of(faces, k):
    """The first side (a, b) of face k."""
    return int(faces[k][0]), int(faces[k][1])


def recipes(spot_v, spot_f):
    n_v, n_f = len(spot_v), len(spot_f)
    rng = np.random.default_rng(3)
    holes = sorted(int(k) for k in rng.choice(n_f, 12, replace=False))
    flips = sorted(int(k) for k in rng.choice(n_f, 5, replace=False))
    lo, hi = spot_v.min(0), spot_v.max(0)
    # A small tetrahedron beside Spot (outward winding), touching nothing.
    o = hi + np.float32(0.5)
    tet = f32([o, o + [0.1, 0, 0], o + [0, 0.1, 0], o + [0, 0, 0.1]])
    tet_faces = [[n_v + a, n_v + b, n_v + c] for a, b, c in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]]
    # A fin on the first side of face 100.
    a, b = edge_of(spot_f, 100)
    fin_apex = f32([(spot_v[a] + spot_v[b]) / 2 + (hi - lo) * np.float32(0.05)])
    # Degenerate: three distinct collinear vertices (zero area), [a, a, b] on a Spot edge, [c, c, c].
    d0 = lo - np.float32(0.25)
    line = f32([d0, d0 + [0.25, 0, 0], d0 + [0.5, 0, 0]])
    da, db = edge_of(spot_f, 2000)
    dc = int(spot_f[3000][2])
    return [
        {"name": "spot", "base": "spot"},
        {"name": "spot_holes", "base": "spot", "remove_faces": holes},
        {"name": "spot_piece", "base": "spot", "add_vertices": tet, "add_faces": tet_faces},
        {"name": "spot_fin", "base": "spot", "add_vertices": fin_apex, "add_faces": [[b, a, n_v]]},
        {
            "name": "book",
            "base": None,
            "add_vertices": f32([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]]),
            "add_faces": [[0, 1, 2], [1, 0, 3], [0, 1, 4]],
        },
        {"name": "spot_flipped", "base": "spot", "flip_faces": flips},
        {
            "name": "spot_degenerate",
            "base": "spot",
            "add_vertices": line,
            "add_faces": [[n_v, n_v + 1, n_v + 2], [da, da, db], [dc, dc, dc]],
        },
        {"name": "empty", "base": None},
    ]


def build(case, spot_v, spot_f):
    if case["base"] == "spot":
        v, f = spot_v.astype(np.float64), spot_f.copy()
    else:
        v, f = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    for k in case.get("flip_faces", []):
        f[k, [0, 1]] = f[k, [1, 0]]
    f = np.delete(f, case.get("remove_faces", []), axis=0)
    add_v = np.asarray(case.get("add_vertices", []), np.float64).reshape(-1, 3)
    add_f = np.asarray(case.get("add_faces", []), np.int64).reshape(-1, 3)
    return np.concatenate([v, add_v]), np.concatenate([f, add_f])


def trimesh_stats(v, f):
    mesh = trimesh.Trimesh(vertices=v, faces=f, process=False, validate=False)
    area = float(mesh.area)
    bodies = mesh.split(only_watertight=False, repair=False) if len(f) else []
    body_areas = [float(b.area) for b in bodies]
    edges = mesh.edges_sorted
    if len(edges):
        _, counts = np.unique(edges, axis=0, return_counts=True)
    else:
        counts = np.zeros(0, np.int64)
    return {
        "area": area,
        "bodies": len(bodies),
        "largest_body_area_fraction": max(body_areas) / area if area > 0 else None,
        "boundary_edges": int(len(grouping.group_rows(edges, require_count=1))) if len(edges) else 0,
        "non_manifold_edges": int(np.sum(counts > 2)),
        "is_watertight": bool(mesh.is_watertight),
        "is_winding_consistent": bool(mesh.is_winding_consistent),
    }


def open3d_stats(v, f):
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f.astype(np.int32)))
    if len(f) == 0:
        return {"clusters": 0, "largest_cluster_area_fraction": None}
    _, _, areas = mesh.cluster_connected_triangles()
    areas = np.asarray(areas)
    total = float(mesh.get_surface_area())
    return {
        "clusters": int(len(areas)),
        "largest_cluster_area_fraction": float(areas.max() / total) if total > 0 else None,
    }


def main():
    sys.path.insert(0, str(HERE))
    from make_reference import check_pinned_versions

    check_pinned_versions()
    OUT.mkdir(parents=True, exist_ok=True)
    spot_v, spot_f = load_spot()
    cases = []
    for case in recipes(spot_v, spot_f):
        v, f = build(case, spot_v, spot_f)
        case["trimesh"] = trimesh_stats(v, f)
        case["open3d"] = open3d_stats(v, f)
        cases.append(case)
        t, o = case["trimesh"], case["open3d"]
        print(
            f"mesh_stats {case['name']}: area {t['area']:.6g}, bodies {t['bodies']}, clusters "
            f"{o['clusters']}, boundary {t['boundary_edges']}, non-manifold {t['non_manifold_edges']}, "
            f"watertight {t['is_watertight']}, winding {t['is_winding_consistent']}"
        )
    result = {
        "versions": {"numpy": np.__version__, "trimesh": trimesh.__version__, "open3d": o3d.__version__},
        "base": "fixtures/data/spot_triangulated.obj",
        "cases": cases,
    }
    (OUT / "mesh_stats.json").write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
