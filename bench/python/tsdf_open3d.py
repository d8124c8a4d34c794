"""Open3D side of `trisplat-bench tsdf`: VoxelBlockGrid (CPU) fusion of a folder of depth maps.

Usage:
    tsdf_open3d.py DIR VOXEL TRUNC_VOXELS DEPTH_TRUNC OUT.ply [BLOCK_RESOLUTION]

DIR holds cameras.json (3DGS layout, trisplat's pixel centres at j + 0.5: Open3D's principal
point is cx - 0.5) and <img_name>_depth.npy (float32 z-depth, metres). Loading is not timed;
timed: per frame compute_unique_block_coordinates + integrate, then extract_triangle_mesh
(default weight threshold 3). BLOCK_RESOLUTION defaults to 16 (Open3D's default). Writes the mesh to OUT.ply; the last stdout line is JSON:
{"seconds": ..., "integrate_seconds": ..., "vertices": ..., "triangles": ...}.
"""

import json
import pathlib
import sys
import time

import numpy as np
import open3d as o3d
import open3d.core as o3c


def main():
    folder, voxel, trunc_voxels, depth_trunc, out = sys.argv[1:6]
    block_resolution = int(sys.argv[6]) if len(sys.argv) > 6 else 16
    folder = pathlib.Path(folder)
    voxel, trunc_voxels, depth_trunc = float(voxel), float(trunc_voxels), float(depth_trunc)
    device = o3c.Device("CPU:0")
    cams = json.loads((folder / "cameras.json").read_text())
    frames = []
    for cam in cams:
        depth = np.load(folder / f"{cam['img_name']}_depth.npy").astype(np.float32)
        intrinsic = np.array(
            [[cam["fx"], 0, cam["cx"] - 0.5], [0, cam["fy"], cam["cy"] - 0.5], [0, 0, 1]],
            dtype=np.float64,
        )
        rotation = np.asarray(cam["rotation"], dtype=np.float64)
        extrinsic = np.eye(4)
        extrinsic[:3, :3] = rotation.T
        extrinsic[:3, 3] = -rotation.T @ np.asarray(cam["position"], dtype=np.float64)
        frames.append(
            (
                o3d.t.geometry.Image(o3c.Tensor(depth)).to(device),
                o3c.Tensor(intrinsic),
                o3c.Tensor(extrinsic),
            )
        )
    t0 = time.perf_counter()
    vbg = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight"),
        attr_dtypes=(o3c.float32, o3c.float32),
        attr_channels=((1), (1)),
        voxel_size=voxel,
        block_resolution=block_resolution,
        block_count=50000,
        device=device,
    )
    for depth, intrinsic, extrinsic in frames:
        blocks = vbg.compute_unique_block_coordinates(
            depth, intrinsic, extrinsic, 1.0, depth_trunc, trunc_voxels
        )
        vbg.integrate(blocks, depth, intrinsic, extrinsic, 1.0, depth_trunc, trunc_voxels)
    t1 = time.perf_counter()
    mesh = vbg.extract_triangle_mesh()
    t2 = time.perf_counter()
    legacy = mesh.to_legacy()
    o3d.io.write_triangle_mesh(out, legacy)
    print(
        json.dumps(
            {
                "seconds": t2 - t0,
                "integrate_seconds": t1 - t0,
                "vertices": len(legacy.vertices),
                "triangles": len(legacy.triangles),
            }
        )
    )


if __name__ == "__main__":
    main()
