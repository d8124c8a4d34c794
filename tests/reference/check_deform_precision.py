#!/usr/bin/env python3
"""Precision of `trisplat deform` against a float64 reference on the files' own decimal values.

Issue #18, item 1: mesh vertices are kept in f64 from the file to the triangle frames, so the
deformed Gaussians are limited by their own f32 storage, not by f32 storage of the mesh. This
script builds a stiff case from Spot (CC0, `fixtures/data/spot_triangulated.obj`), runs the
`trisplat` binary on it and compares every deformed Gaussian with numpy float64 formulas written
out here from docs/conventions.md §4 (no shared code with the Rust side):

- template: Spot scaled by 1.37 and moved by (0.123456789, -2.718281828, 31.4159265) in f64,
  with slivers: 4% of the vertices pulled to 1e-5 .. 1e-3 of an edge length from the line of the
  opposite edge of one of their triangles (aspect ratios up to 1e5), written as OBJ with 17
  significant digits (values that f32 cannot hold);
- 9 poses: rotations of up to 170 degrees, a bend, a twist, a non-uniform stretch (0.6 .. 1.5)
  and a translation, each in f64, written the same way;
- 3 Gaussians per triangle with random local means, random rotations and log-scales
  N(-1, 0.3), bound in the GaussianAvatars convention (binding mode) and the SurFhead one
  (jacobian mode), written as float PLY (their f32 values are the reference's inputs).

Reports, per mode, the worst covariance error `|Σ - Σ_ref|_F / |Σ_ref|_F` and the worst mean
error relative to the template's bounding-box diagonal, as JSON. `--f32-vertices` rounds every
vertex to f32 before writing (the case where f32 storage of the mesh was already exact).

    cargo build --release
    python tests/reference/check_deform_precision.py [--trisplat target/release/trisplat] \
        [--f32-vertices] [--work DIR]

Needs numpy and plyfile (tests/reference/requirements.txt).
"""

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile

import numpy as np
from plyfile import PlyData, PlyElement

ROOT = pathlib.Path(__file__).resolve().parents[2]
SPOT = ROOT / "fixtures" / "data" / "spot_triangulated.obj"
POSES = 9
PER_TRIANGLE = 3


def read_obj(path):
    """Vertices (float64 from the decimals) and triangles of a triangulated OBJ."""
    vertices, faces = [], []
    for line in pathlib.Path(path).read_text().splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "v":
            vertices.append([float(w) for w in words[1:4]])
        elif words[0] == "f":
            faces.append([int(w.split("/")[0]) - 1 for w in words[1:4]])
    return np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int64)


def write_obj(path, vertices, faces):
    lines = ["# check_deform_precision.py"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces.tolist()]
    pathlib.Path(path).write_text("\n".join(lines) + "\n")


def stiff_template(rng):
    v, f = read_obj(SPOT)
    v = v * 1.37 + np.array([0.123456789, -2.718281828, 31.4159265])
    chosen = rng.choice(len(f), size=len(v) // 25, replace=False)
    moved = set()
    for t in chosen:
        a, b, c = f[t]
        if a in moved:
            continue
        # Pull a towards the line through b and c: height = r * |c - b|.
        e = v[c] - v[b]
        s = np.dot(v[a] - v[b], e) / np.dot(e, e)
        foot = v[b] + np.clip(s, 0.2, 0.8) * e
        off = v[a] - foot
        ratio = 10.0 ** rng.uniform(-5, -3)
        v[a] = foot + off / np.linalg.norm(off) * ratio * np.linalg.norm(e)
        moved.add(a)
    return v, f


def rotation(axis, angle):
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def pose(v, rng, i):
    c = v.mean(axis=0)
    h = np.ptp(v[:, 1])
    p = v - c
    bend = rng.uniform(-1.2, 1.2) * np.clip(p[:, 1:2] / h + 0.5, 0, 1)
    twist = rng.uniform(-0.8, 0.8) * p[:, 1] / h
    out = np.empty_like(p)
    for k in range(len(p)):
        r = rotation(np.array([1.0, 0, 0]), bend[k, 0]) @ rotation(np.array([0, 1.0, 0]), twist[k])
        out[k] = r @ p[k]
    out *= rng.uniform(0.6, 1.5, size=3)
    angle = np.deg2rad(20 * i - 10 + rng.uniform(-5, 5)) if i < 8 else np.deg2rad(170)
    out = out @ rotation(rng.normal(size=3), angle).T
    return out + c + rng.normal(size=3) * 0.3


def unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def ga_frames(v, f):
    """GaussianAvatars: R_f = [a0 | a1 | a2], centroid, k (docs/conventions.md §4)."""
    v0, v1, v2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    a0 = unit(v1 - v0)
    a1 = unit(np.cross(a0, v2 - v0))
    a2 = -unit(np.cross(a1, a0))
    r = np.stack([a0, a1, a2], axis=-1)
    k = (np.linalg.norm(v1 - v0, axis=-1) + np.abs(np.sum(a2 * (v2 - v0), axis=-1))) / 2
    return r, (v0 + v1 + v2) / 3, k


def surfhead_frames(v, f):
    v0, v1, v2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    b0 = unit(v1 - v0)
    n = np.cross(v1 - v0, v2 - v0)
    b2 = unit(n)
    b1 = np.cross(b2, b0)
    r = np.stack([b0, b1, b2], axis=-1)
    _, c, k = ga_frames(v, f)
    return r, c, k


def edge_matrix(v, f):
    v0, v1, v2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    n = np.cross(v1 - v0, v2 - v0)
    n = n / np.sqrt(np.linalg.norm(n, axis=-1, keepdims=True))
    return np.stack([v1 - v0, v2 - v0, n], axis=-1)


def quat_to_matrix(q):
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


def write_bound(path, g):
    n = len(g["tri"])
    names = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity"]
    names += ["scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3", "binding_0"]
    rows = np.zeros(n, dtype=[(name, "<f4") for name in names])
    for i, name in enumerate("xyz"):
        rows[name] = g["mu"][:, i]
        rows[f"scale_{i}"] = g["log_s"][:, i]
    for i in range(4):
        rows[f"rot_{i}"] = g["q"][:, i]
    rows["opacity"] = 2.0
    rows["binding_0"] = g["tri"]
    PlyData([PlyElement.describe(rows, "vertex")]).write(str(path))


def read_gaussians(path):
    v = PlyData.read(str(path))["vertex"]
    f64 = lambda name: np.asarray(v[name], dtype=np.float64)  # noqa: E731
    mu = np.stack([f64(n) for n in "xyz"], -1)
    s = np.exp(np.stack([f64(f"scale_{i}") for i in range(3)], -1))
    q = np.stack([f64(f"rot_{i}") for i in range(4)], -1)
    return mu, s, q


def covariances(r, s):
    l = r * s[:, None, :]
    return l @ np.swapaxes(l, 1, 2)


def reference(mode, rest, frame, faces, g):
    """World-space means and covariances of the bound set at `frame`, in float64."""
    tri = g["tri"]
    r_local = quat_to_matrix(g["q"].astype(np.float64))
    s_local = np.exp(g["log_s"].astype(np.float64))
    mu_local = g["mu"].astype(np.float64)
    if mode == "binding":
        r, c, k = ga_frames(frame, faces)
        r, c, k = r[tri], c[tri], k[tri]
        mu = k[:, None] * np.einsum("nij,nj->ni", r, mu_local) + c
        cov = covariances(r @ r_local, k[:, None] * s_local)
        return mu, cov
    rc, _, kc = surfhead_frames(rest, faces)
    j = edge_matrix(frame, faces) @ np.linalg.inv(edge_matrix(rest, faces))
    _, c, _ = ga_frames(frame, faces)
    rc, kc, j, c = rc[tri], kc[tri], j[tri], c[tri]
    mu = np.einsum("nij,nj->ni", j, kc[:, None] * np.einsum("nij,nj->ni", rc, mu_local)) + c
    l = j @ rc @ r_local * (kc[:, None] * s_local)[:, None, :]
    return mu, l @ np.swapaxes(l, 1, 2)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trisplat", default=str(ROOT / "target" / "release" / "trisplat"))
    parser.add_argument("--f32-vertices", action="store_true")
    parser.add_argument("--work", help="folder for the case (default: a temporary one)")
    args = parser.parse_args()
    rng = np.random.default_rng(18)
    rest, faces = stiff_template(rng)
    poses = [pose(rest, rng, i) for i in range(POSES)]
    if args.f32_vertices:
        rest = rest.astype(np.float32).astype(np.float64)
        poses = [p.astype(np.float32).astype(np.float64) for p in poses]
    n = len(faces) * PER_TRIANGLE
    g = {
        "tri": np.repeat(np.arange(len(faces)), PER_TRIANGLE),
        "mu": (rng.uniform(-0.3, 0.3, size=(n, 3)) * [1, 0.1, 1]).astype(np.float32),
        "q": unit(rng.normal(size=(n, 4))).astype(np.float32),
        "log_s": rng.normal(-1.0, 0.3, size=(n, 3)).astype(np.float32),
    }
    with tempfile.TemporaryDirectory() as tmp:
        work = pathlib.Path(args.work or tmp)
        work.mkdir(parents=True, exist_ok=True)
        write_obj(work / "template.obj", rest, faces)
        frames = work / "frames"
        frames.mkdir(exist_ok=True)
        for i, p in enumerate(poses):
            write_obj(frames / f"pose_{i:02d}.obj", p, faces)
        write_bound(work / "bound.ply", g)
        # What trisplat reads is what the reference uses: the decimals in the files.
        rest, faces_read = read_obj(work / "template.obj")
        assert (faces_read == faces).all()
        diag = np.linalg.norm(np.ptp(rest, axis=0))
        result = {"vertices": len(rest), "triangles": len(faces), "gaussians": n,
                  "poses": POSES, "f32_vertices": args.f32_vertices}
        for mode in ["binding", "jacobian"]:
            out = work / f"out_{mode}"
            subprocess.run(
                [args.trisplat, "deform", "--template", str(work / "template.obj"),
                 "--animation", str(frames), "--gaussians", str(work / "bound.ply"),
                 "--mode", mode, "-o", str(out)],
                check=True, stdout=subprocess.DEVNULL,
            )
            worst_cov, worst_mu = 0.0, 0.0
            for i in range(POSES):
                frame, _ = read_obj(frames / f"pose_{i:02d}.obj")
                mu_ref, cov_ref = reference(mode, rest, frame, faces, g)
                mu, s, q = read_gaussians(out / f"frame_{i:06d}.ply")
                cov = covariances(quat_to_matrix(q), s)
                num = np.linalg.norm(cov - cov_ref, axis=(1, 2))
                den = np.linalg.norm(cov_ref, axis=(1, 2))
                worst_cov = max(worst_cov, float(np.max(num / den)))
                worst_mu = max(worst_mu, float(np.max(np.linalg.norm(mu - mu_ref, axis=1))) / diag)
            result[mode] = {"covariance_rel_frobenius_max": worst_cov, "mean_error_over_diag_max": worst_mu}
        json.dump(result, sys.stdout, indent=2)
        print()


if __name__ == "__main__":
    main()
