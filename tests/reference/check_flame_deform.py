#!/usr/bin/env python3
"""Float64 check of `trisplat deform --mode binding` on the FLAME template (issue 3).

FLAME is not redistributable, so nothing is committed: the ignored Rust test
`flame_binding_matches_float64_gaussian_avatars` (cli/tests/cli_splat.rs) writes the bound
Gaussians and trisplat's output frame into a folder; this script recomputes the world-space
Gaussians from the bound file and the registered scan with the GaussianAvatars formulas in numpy
float64 (independently of the Rust code) and prints the largest relative differences as JSON.

    TRISPLAT_SHARED_DATA=$PWD/../shared/data cargo test -p trisplat-cli --test cli_splat \
        flame -- --ignored --nocapture
    python tests/reference/check_flame_deform.py target/tmp/flame_check \
        ../shared/data/faces/flame/flame_registered_scan.ply

Needs numpy and trimesh (tests/reference/requirements.txt).
"""

import json
import pathlib
import sys

import numpy as np
import trimesh

TOLERANCE = 1e-5


def read_vertex_floats(path):
    """The `vertex` element of a binary little-endian PLY whose vertex properties are floats."""
    data = pathlib.Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    lines = data[:end].decode("ascii").splitlines()
    assert "format binary_little_endian 1.0" in lines, "binary little-endian PLY expected"
    names, count, in_vertex = [], 0, False
    for line in lines:
        words = line.split()
        if words[:1] == ["element"]:
            in_vertex = words[1] == "vertex"
            if in_vertex:
                count = int(words[2])
        elif words[:1] == ["property"] and in_vertex:
            assert words[1] == "float", line
            names.append(words[2])
    body = np.frombuffer(data, dtype="<f4", count=count * len(names), offset=end)
    table = body.reshape(count, len(names)).astype(np.float64)
    return {name: table[:, i] for i, name in enumerate(names)}


def quat_to_matrix(q):
    """[N, 4] (w, x, y, z), not necessarily unit -> [N, 3, 3]."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def gaussian_avatars_frames(vertices, faces):
    """GaussianAvatars' per-face rotation [F, 3, 3] (columns a0, a1, a2), centroid, scale k."""
    v0, v1, v2 = (vertices[faces[:, i]] for i in range(3))
    e1, e2 = v1 - v0, v2 - v0
    a0 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    a1 = np.cross(a0, e2)
    a1 /= np.linalg.norm(a1, axis=1, keepdims=True)
    a2 = np.cross(a1, a0)
    a2 = -a2 / np.linalg.norm(a2, axis=1, keepdims=True)
    rotation = np.stack([a0, a1, a2], axis=-1)
    k = (np.linalg.norm(e1, axis=1) + np.abs(np.sum(a2 * e2, axis=1))) / 2
    return rotation, (v0 + v1 + v2) / 3, k


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    folder, scan_path = pathlib.Path(argv[0]), argv[1]
    scan = trimesh.load(scan_path, process=False)
    vertices = np.asarray(scan.vertices, dtype=np.float64)
    faces = np.asarray(scan.faces, dtype=np.int64)
    bound = read_vertex_floats(folder / "bound.ply")
    world = read_vertex_floats(folder / "frames" / "frame_000000.ply")
    tri = bound["binding_0"].astype(np.int64)
    rotation, centroid, k = gaussian_avatars_frames(vertices, faces)
    r, c, kk = rotation[tri], centroid[tri], k[tri]
    mu_local = np.stack([bound[n] for n in ("x", "y", "z")], axis=1)
    mu = kk[:, None] * np.einsum("nij,nj->ni", r, mu_local) + c
    q_local = np.stack([bound[f"rot_{i}"] for i in range(4)], axis=1)
    rot = r @ quat_to_matrix(q_local)
    scale = kk[:, None] * np.exp(np.stack([bound[f"scale_{i}"] for i in range(3)], axis=1))

    got_mu = np.stack([world[n] for n in ("x", "y", "z")], axis=1)
    got_rot = quat_to_matrix(np.stack([world[f"rot_{i}"] for i in range(4)], axis=1))
    got_scale = np.exp(np.stack([world[f"scale_{i}"] for i in range(3)], axis=1))
    diag = np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))
    length = np.maximum(np.linalg.norm(mu, axis=1), 1e-3 * diag)
    result = {
        "gaussians": int(len(tri)),
        "mean_rel": float(np.max(np.linalg.norm(got_mu - mu, axis=1) / length)),
        "rotation_abs": float(np.max(np.abs(got_rot - rot))),
        "scale_rel": float(np.max(np.abs(got_scale - scale) / scale)),
        "tolerance": TOLERANCE,
    }
    result["ok"] = all(result[k] < TOLERANCE for k in ("mean_rel", "rotation_abs", "scale_rel"))
    print(json.dumps(result))
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
