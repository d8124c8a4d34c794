"""Alpha-shape references: Open3D's `TriangleMesh.create_from_point_cloud_alpha_shape` on generic
point sets, and what Open3D does on degenerate ones (cube corners, a grid, a plane).

Inputs are written here as float32 binary PLY files (x y z), so Open3D (float64) and trisplat
(f32 -> f64) see exactly the same coordinates:

  spot_samples.ply    2000 area-uniform samples of Spot (numpy default_rng(7)), public domain
  ball.ply            1000 uniform points in the unit ball (numpy default_rng(8))

Output fixtures/data/reference/alpha/alpha.json:

  cases:      one per (input, alpha): `triangles` is the boundary as a flat list of sorted
              input-point index triples (i < j < k), sorted; Open3D's vertices are mapped back to
              input indices by exact coordinates. Also Open3D's triangle count, watertightness
              and signed volume (its faces are not consistently oriented).
  degenerate: per degenerate input, Open3D's outcome (the exception text or the triangle
              count, watertightness and the number of "invalid tetra" flat tetrahedra is not
              observable from Python: the triangle count says enough).
"""

import json
import pathlib

import numpy as np
import open3d as o3d

ROOT = pathlib.Path(__file__).resolve().parents[2]
OBJ = ROOT / "fixtures" / "data" / "spot_triangulated.obj"
OUT = ROOT / "fixtures" / "data" / "reference" / "alpha"

SPOT_SAMPLES = 2000
BALL_POINTS = 1000
CASES = [
    ("spot_samples.ply", 0.05),
    ("spot_samples.ply", 0.1),
    ("spot_samples.ply", 0.3),
    ("ball.ply", 0.15),
    ("ball.ply", 0.4),
]


def read_obj(path):
    """Positions and triangles from `v` and `f` lines (first index of each corner, fans)."""
    verts, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(c.split("/")[0]) for c in parts[1:]]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            for k in range(1, len(idx) - 1):
                faces.append([idx[0], idx[k], idx[k + 1]])
    return np.asarray(verts, dtype=np.float64), np.asarray(faces, dtype=np.int64)


def sample_area_uniform(verts, faces, n, seed):
    rng = np.random.default_rng(seed)
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tri = rng.choice(len(faces), size=n, p=area / area.sum())
    r1 = np.sqrt(rng.random(n))[:, None]
    r2 = rng.random(n)[:, None]
    p = (1 - r1) * a[tri] + r1 * (1 - r2) * b[tri] + r1 * r2 * c[tri]
    return p.astype(np.float32)


def ball_points(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        p = rng.uniform(-1.0, 1.0, size=3)
        if p @ p <= 1.0:
            out.append(p)
    return np.asarray(out, dtype=np.float32)


def write_points_ply(path, pts, comment):
    header = (
        f"ply\nformat binary_little_endian 1.0\ncomment {comment}\n"
        f"element vertex {len(pts)}\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.ascontiguousarray(pts, dtype="<f4").tobytes())


def unique_rows(pts):
    assert len({tuple(p) for p in pts.tolist()}) == len(pts), "inputs must be distinct"


def open3d_alpha(pts64, alpha):
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts64))
    return o3d.geometry.TriangleMesh.create_from_point_cloud_alpha_shape(pcd, alpha)


def boundary_as_input_indices(mesh, pts64):
    lookup = {tuple(p): i for i, p in enumerate(pts64.tolist())}
    verts = np.asarray(mesh.vertices)
    ids = np.array([lookup[tuple(v)] for v in verts.tolist()], dtype=np.int64)
    tris = np.sort(ids[np.asarray(mesh.triangles)], axis=1)
    tris = np.unique(tris, axis=0)
    return tris


def degenerate_inputs():
    cube = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.float64)
    g = np.arange(10, dtype=np.float64)
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    plane = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1)
    return [
        ("cube_corners", cube, 2.0),
        ("grid_10x10x10", grid, 2.0),
        ("plane_10x10", plane, 2.0),
    ]


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    verts, faces = read_obj(OBJ)
    inputs = {
        "spot_samples.ply": sample_area_uniform(verts, faces, SPOT_SAMPLES, 7),
        "ball.ply": ball_points(BALL_POINTS, 8),
    }
    comments = {
        "spot_samples.ply": "2000 area-uniform samples of Spot (public domain), float32",
        "ball.ply": "1000 uniform random points in the unit ball, float32",
    }
    for name, pts in inputs.items():
        unique_rows(pts)
        write_points_ply(OUT / name, pts, comments[name])

    cases = []
    for name, alpha in CASES:
        pts64 = inputs[name].astype(np.float64)
        mesh = open3d_alpha(pts64, alpha)
        tris = boundary_as_input_indices(mesh, pts64)
        cases.append(
            {
                "input": name,
                "alpha": alpha,
                "open3d_triangles": len(mesh.triangles),
                "open3d_watertight": bool(mesh.is_watertight()),
                "open3d_signed_volume": float(signed_volume(mesh)),
                "triangles": tris.ravel().tolist(),
            }
        )
        print(f"{name} alpha {alpha}: {len(tris)} triangles", flush=True)

    degenerate = []
    for name, pts, alpha in degenerate_inputs():
        try:
            mesh = open3d_alpha(pts, alpha)
            outcome = {
                "error": None,
                "triangles": len(mesh.triangles),
                "watertight": bool(mesh.is_watertight()),
            }
        except RuntimeError as e:
            outcome = {"error": str(e).splitlines()[0][:160], "triangles": 0, "watertight": False}
        degenerate.append({"name": name, "points": len(pts), "alpha": alpha, **outcome})
        print(f"{name}: {outcome}", flush=True)

    doc = {
        "tool": "open3d.geometry.TriangleMesh.create_from_point_cloud_alpha_shape",
        "versions": {"open3d": o3d.__version__, "numpy": np.__version__},
        "cases": cases,
        "degenerate": degenerate,
    }
    (OUT / "alpha.json").write_text(json.dumps(doc, separators=(",", ":")) + "\n")


def signed_volume(mesh):
    v = np.asarray(mesh.vertices)
    t = np.asarray(mesh.triangles)
    if len(t) == 0:
        return 0.0
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    return np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0


if __name__ == "__main__":
    main()
