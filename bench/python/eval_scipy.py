"""scipy/trimesh side of `trisplat-bench eval`: docs/conventions.md §8 metrics on two point files.

Usage:
    eval_scipy.py points PRED.ply GT.ply TAU [TAU ...]
    eval_scipy.py surface POINTS.ply MESH.ply N

`points`: cKDTree(workers=-1) both ways, then accuracy, completeness, chamfer L1/L2, normal
consistency/angle and precision/recall/F-score per tau (the same definitions as trisplat).
Timed: tree builds, queries and metric arithmetic; not file loading (Open3D's reader, or
plyfile's where Open3D does not import, else numpy's for binary PLYs).

`surface`: trimesh.proximity.closest_point for the first N points against the mesh (exact
point-to-triangle distances). Timed: the call, including trimesh's lazy acceleration structure.

The last stdout line is JSON: {"seconds": ..., "cpu_seconds": ..., "chamfer_l1": ...} (CPU
seconds of all threads, user + sys, for comparisons on a loaded machine) or {"seconds": ...,
"mean_distance": ...}.
"""

import json
import sys
import time

import numpy as np


def read_points(path):
    """Positions and normals (or None) as float64, by Open3D, else by plyfile, else by numpy
    (binary PLYs of scalar vertex properties only)."""
    try:
        import open3d as o3d
    except ImportError:
        try:
            return read_points_plyfile(path)
        except ImportError:
            return read_points_numpy(path)
    pcd = o3d.io.read_point_cloud(path)
    pts = np.asarray(pcd.points, dtype=np.float64)
    nrm = np.asarray(pcd.normals, dtype=np.float64) if pcd.has_normals() else None
    return pts, nrm


def positions_and_normals(v):
    """x y z (and nx ny nz, or None) of a structured vertex array, as float64."""
    names = v.dtype.names
    pts = np.stack([v[c] for c in ("x", "y", "z")], axis=1).astype(np.float64)
    nrm = None
    if all(c in names for c in ("nx", "ny", "nz")):
        nrm = np.stack([v[c] for c in ("nx", "ny", "nz")], axis=1).astype(np.float64)
    return pts, nrm


def read_points_plyfile(path):
    """The vertex element's x y z (and nx ny nz) of a PLY, for machines without Open3D."""
    from plyfile import PlyData

    v = PlyData.read(path)["vertex"].data
    return positions_and_normals(v)


PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_points_numpy(path):
    """The vertex element of a binary PLY whose first element is `vertex` with scalar
    properties only (what `trisplat sample` writes), by numpy."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    lines = data[:end].decode("ascii").split("\n")
    order = "<" if "binary_little_endian" in lines[1] else ">"
    if "ascii" in lines[1]:
        sys.exit(f"{path}: the numpy reader reads binary PLYs only")
    fields, count, in_vertex = [], 0, False
    for line in lines:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count, in_vertex = int(words[2]), True
        elif words[:1] == ["element"] and not fields and count == 0 and int(words[2]) > 0:
            sys.exit(f"{path}: the numpy reader needs the vertex element first")
        elif words[:1] == ["element"]:
            in_vertex = False
        elif in_vertex and words[:1] == ["property"]:
            if words[1] == "list":
                sys.exit(f"{path}: the numpy reader reads scalar vertex properties only")
            fields.append((words[2], order + PLY_TYPES[words[1]]))
    v = np.frombuffer(data, dtype=np.dtype(fields), count=count, offset=end)
    return positions_and_normals(v)


def unit(v):
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def point_metrics(pred, pred_n, gt, gt_n, taus):
    from scipy.spatial import cKDTree

    d_p, i_p = cKDTree(gt).query(pred, k=1, workers=-1)
    d_g, i_g = cKDTree(pred).query(gt, k=1, workers=-1)
    acc, comp = float(np.mean(d_p)), float(np.mean(d_g))
    out = {
        "accuracy": acc,
        "completeness": comp,
        "chamfer_l1": (acc + comp) / 2,
        "chamfer_l2": float((np.mean(d_p**2) + np.mean(d_g**2)) / 2),
    }
    if pred_n is not None and gt_n is not None:
        pn, gn = unit(pred_n), unit(gt_n)
        cos_p = np.minimum(np.abs(np.sum(pn * gn[i_p], axis=1)), 1.0)
        cos_g = np.minimum(np.abs(np.sum(gn * pn[i_g], axis=1)), 1.0)
        out["normal_consistency"] = float((cos_p.mean() + cos_g.mean()) / 2)
        out["normal_angle_deg"] = float(
            np.degrees((np.arccos(cos_p).mean() + np.arccos(cos_g).mean()) / 2)
        )
    thresholds = []
    for tau in taus:
        p, r = float(np.mean(d_p < tau)), float(np.mean(d_g < tau))
        thresholds.append(
            {"tau": tau, "precision": p, "recall": r, "fscore": 2 * p * r / (p + r) if p + r > 0 else 0.0}
        )
    out["thresholds"] = thresholds
    return out


def main():
    mode, *rest = sys.argv[1:]
    if mode == "points":
        pred, pred_n = read_points(rest[0])
        gt, gt_n = read_points(rest[1])
        taus = [float(t) for t in rest[2:]]
        t0, c0 = time.perf_counter(), time.process_time()
        result = point_metrics(pred, pred_n, gt, gt_n, taus)
        result["seconds"] = time.perf_counter() - t0
        result["cpu_seconds"] = time.process_time() - c0
    elif mode == "surface":
        import trimesh

        pts, _ = read_points(rest[0])
        pts = pts[: int(rest[2])]
        mesh = trimesh.load(rest[1], process=False)
        t0 = time.perf_counter()
        _, dist, _ = trimesh.proximity.closest_point(mesh, pts)
        result = {"seconds": time.perf_counter() - t0, "mean_distance": float(np.mean(dist))}
    else:
        sys.exit(f"unknown mode {mode!r}")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
