"""Render consistency of any meshes against a frame's own Gaussians, as
bench/python/render_consistency.py measures it (16-view sphere rig of 384x384 around a
reference mesh; silhouette IoU of the mesh against the Gaussians' alpha > 0.5; |mesh depth -
the Gaussians' median depth| in mm over the pixels both cover, median and 90th percentile).

    python3 mesh_consistency.py TRISPLAT GAUSSIANS.ply REFERENCE_MESH.ply WORK_DIR MESH...
"""
import json
import os
import subprocess
import sys

import numpy as np

trisplat, gaussians, reference, work = sys.argv[1:5]
meshes = sys.argv[5:]
os.makedirs(work, exist_ok=True)


def run(*args):
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)


cams = os.path.join(work, "cams.json")
run(trisplat, "cameras", reference, "-o", cams, "--rig", "sphere", "--views", "16", "--size",
    "384x384")
views = [c["img_name"] for c in json.load(open(cams))]
gr = os.path.join(work, "gaussians")
run(trisplat, "render", gaussians, "--cameras", cams, "-o", gr, "--outputs", "alpha,median_depth",
    "-q")
print("| mesh | IoU | median depth error (mm) | 90th percentile (mm) |")
print("|---|---:|---:|---:|")
for k, mesh in enumerate(meshes):
    pictures = os.path.join(work, f"mesh{k}")
    run(trisplat, "render", "--mesh", mesh, "--cameras", cams, "-o", pictures, "-q")
    inter = union = 0
    errors = []
    for v in views:
        seen = np.load(f"{gr}/{v}_alpha.npy") > 0.5
        depth = np.load(f"{gr}/{v}_median_depth.npy")
        mesh_depth = np.load(f"{pictures}/{v}_depth.npy")
        covered = mesh_depth > 0
        inter += (seen & covered).sum()
        union += (seen | covered).sum()
        both = seen & covered
        errors.append(np.abs(mesh_depth[both] - depth[both]))
    e = np.concatenate(errors) * 1000.0
    print(f"| {mesh} | {inter / union:.3f} | {np.median(e):.1f} | {np.percentile(e, 90):.1f} |")
