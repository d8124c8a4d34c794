"""scipy/trimesh side of `trisplat-bench eval`: docs/conventions.md §8 metrics on two point files.

Usage:
    eval_scipy.py points PRED.ply GT.ply TAU [TAU ...]
    eval_scipy.py surface POINTS.ply MESH.ply N

`points`: cKDTree(workers=-1) both ways, then accuracy, completeness, chamfer L1/L2, normal
consistency/angle and precision/recall/F-score per tau (the same definitions as trisplat).
Timed: tree builds, queries and metric arithmetic; not file loading (Open3D's reader, or
plyfile's where Open3D does not import).

`surface`: trimesh.proximity.closest_point for the first N points against the mesh (exact
point-to-triangle distances). Timed: the call, including trimesh's lazy acceleration structure.

The last stdout line is JSON: {"seconds": ..., "chamfer_l1": ...} or {"seconds": ...,
"mean_distance": ...}.
"""

import json
import sys
import time

import numpy as np


def read_points(path):
    """Positions and normals (or None) as float64, by Open3D, else by plyfile (PLY only)."""
    try:
        import open3d as o3d
    except ImportError:
        return read_points_plyfile(path)
    pcd = o3d.io.read_point_cloud(path)
    pts = np.asarray(pcd.points, dtype=np.float64)
    nrm = np.asarray(pcd.normals, dtype=np.float64) if pcd.has_normals() else None
    return pts, nrm


def read_points_plyfile(path):
    """The vertex element's x y z (and nx ny nz) of a PLY, for machines without Open3D."""
    from plyfile import PlyData

    v = PlyData.read(path)["vertex"].data
    names = v.dtype.names
    pts = np.stack([v[c] for c in ("x", "y", "z")], axis=1).astype(np.float64)
    nrm = None
    if all(c in names for c in ("nx", "ny", "nz")):
        nrm = np.stack([v[c] for c in ("nx", "ny", "nz")], axis=1).astype(np.float64)
    return pts, nrm


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
        t0 = time.perf_counter()
        result = point_metrics(pred, pred_n, gt, gt_n, taus)
        result["seconds"] = time.perf_counter() - t0
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
