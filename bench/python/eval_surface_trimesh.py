"""`trisplat eval PRED GT --surface` as a trimesh user writes it, for whole-process timing.

Usage: python eval_surface_trimesh.py PRED GT SAMPLES
Samples SAMPLES points on each mesh (area-uniform, seeded) and takes exact point-to-surface
distances both ways with trimesh.proximity.closest_point; prints Chamfer L1 (mean of the two
mean distances) and the seconds of the computation. Pinned: the reference venv's trimesh
(tests/reference/requirements.txt).
"""
import sys
import time

import numpy as np
import trimesh


def main():
    pred_path, gt_path, samples = sys.argv[1], sys.argv[2], int(sys.argv[3])
    pred = trimesh.load(pred_path, process=False, force="mesh")
    gt = trimesh.load(gt_path, process=False, force="mesh")
    start = time.perf_counter()
    p, _ = trimesh.sample.sample_surface(pred, samples, seed=0)
    g, _ = trimesh.sample.sample_surface(gt, samples, seed=1)
    _, d_pg, _ = trimesh.proximity.closest_point(gt, p)
    _, d_gp, _ = trimesh.proximity.closest_point(pred, g)
    chamfer = 0.5 * (np.mean(d_pg) + np.mean(d_gp))
    print(f"chamfer_l1 {chamfer:.6e} seconds {time.perf_counter() - start:.3f}")


if __name__ == "__main__":
    main()
