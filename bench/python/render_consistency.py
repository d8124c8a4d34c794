"""Render consistency of each method's LAM mesh against the avatar's own Gaussians (called by
bench/lam_check.sh in its output folder): per frame f in 0, 450, 900, a 16-view sphere rig of
384x384 around the new build's tsdf mesh (directions the 24-view extraction rig did not use);
silhouette IoU of the mesh against the Gaussians' alpha > 0.5, and |mesh depth - the
Gaussians' median depth| (mm) over the pixels both cover, median and 90th percentile.

    python3 render_consistency.py TRISPLAT_BINARY FOLDER
"""
import glob
import json
import os
import subprocess
import sys

import numpy as np

trisplat, folder = sys.argv[1], sys.argv[2]
os.chdir(folder)


def run(*args):
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)


print("| frame | build | method | IoU | median depth error (mm) | 90th percentile (mm) |")
print("|---:|---|---|---:|---:|---:|")
for f in [0, 450, 900]:
    cams = f"cams{f}.json"
    run(trisplat, "cameras", f"new/f{f}/tsdf/frame_{f:06d}.ply", "-o", cams, "--rig", "sphere",
        "--views", "16", "--size", "384x384")
    views = [c["img_name"] for c in json.load(open(cams))]
    gaussians = glob.glob(f"g{f}/*.ply")[0]
    run(trisplat, "render", gaussians, "--cameras", cams, "-o", f"gr{f}", "--outputs",
        "alpha,median_depth", "-q")
    for build in ["base", "new"]:
        for method in ["tsdf", "delaunay", "alpha"]:
            pictures = f"mr_{build}_{method}_{f}"
            run(trisplat, "render", "--mesh", f"{build}/f{f}/{method}/frame_{f:06d}.ply",
                "--cameras", cams, "-o", pictures, "-q")
            inter = union = 0
            errors = []
            for v in views:
                seen = np.load(f"gr{f}/{v}_alpha.npy") > 0.5
                depth = np.load(f"gr{f}/{v}_median_depth.npy")
                mesh_depth = np.load(f"{pictures}/{v}_depth.npy")
                covered = mesh_depth > 0
                inter += (seen & covered).sum()
                union += (seen | covered).sum()
                both = seen & covered
                errors.append(np.abs(mesh_depth[both] - depth[both]))
            e = np.concatenate(errors) * 1000.0
            print(f"| {f} | {build} | {method} | {inter / union:.3f} | {np.median(e):.1f} "
                  f"| {np.percentile(e, 90):.1f} |")
