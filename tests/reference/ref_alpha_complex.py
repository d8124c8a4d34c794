"""Alpha-complex reference (CGAL's Alpha_shape_3 in GENERAL mode, written from its definition):
scipy's Delaunay (Qhull) instead of trisplat's, and the emptiness of each triangle's smallest
circumsphere tested by brute force against *every* input point (trisplat tests only the two
opposite vertices, which the Delaunay property makes sufficient).

At α a Delaunay triangle is output when exactly one adjacent tetrahedron has circumradius <= α
(regular), or when neither has and its smallest circumsphere is empty with radius <= α
(singular). Inputs: the alpha fixtures of ref_alpha.py (spot_samples.ply, ball.ply).

The solid's boundary (trisplat's `Surface::Solid`): a tetrahedron is exterior when a walk from
outside the convex hull reaches it crossing only triangles that are not in the complex into
tetrahedra that are not kept (scipy's neighbour table, breadth first); the output is every
triangle between an exterior tetrahedron (or the outside) and one that is not, oriented so that
its normal points away from the non-exterior one.

Output fixtures/data/reference/alpha/complex.json, per (input, α): the output triangles as
sorted input-index triples (flat, sorted), the edge-connected piece count, the solid's boundary
as oriented triples (each rotated to start at its smallest index; flat, sorted) with its piece
count, and the triangles whose classification is within 1e-9 (relative) of a tie (a radius at
α, or a point on a smallest circumsphere), which the Rust test leaves out on both sides.

    python -m venv venv && venv/bin/pip install -r tests/reference/requirements.txt
    venv/bin/python tests/reference/ref_alpha_complex.py
"""

import json
import pathlib

import numpy as np
import scipy
from scipy.spatial import Delaunay

ROOT = pathlib.Path(__file__).resolve().parents[2]
DIR = ROOT / "fixtures" / "data" / "reference" / "alpha"
CASES = [
    ("spot_samples.ply", 0.02),
    ("spot_samples.ply", 0.04),
    ("spot_samples.ply", 0.08),
    ("ball.ply", 0.1),
]
TIE = 1e-9


def read_points(path):
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    n = int([l for l in data[:end].decode().splitlines() if l.startswith("element vertex")][0].split()[2])
    return np.frombuffer(data[end:], dtype="<f4", count=3 * n).reshape(n, 3).astype(np.float64)


def circumradius_tet(p):
    a = p[:, 0]
    b, c, d = p[:, 1] - a, p[:, 2] - a, p[:, 3] - a
    n = (
        (b * b).sum(1)[:, None] * np.cross(c, d)
        + (c * c).sum(1)[:, None] * np.cross(d, b)
        + (d * d).sum(1)[:, None] * np.cross(b, c)
    )
    den = 2.0 * np.einsum("ij,ij->i", b, np.cross(c, d))
    with np.errstate(divide="ignore"):
        return np.linalg.norm(n, axis=1) / np.abs(den)


def smallest_sphere(p):
    a = p[:, 0]
    u, v = p[:, 1] - a, p[:, 2] - a
    w = np.cross(u, v)
    ww = (w * w).sum(1)
    centre = ((u * u).sum(1)[:, None] * np.cross(v, w) + (v * v).sum(1)[:, None] * np.cross(w, u)) / (
        2.0 * ww[:, None]
    )
    return a + centre, np.linalg.norm(centre, axis=1)


def pieces(tris):
    parent = list(range(len(tris)))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    first = {}
    for t, (i, j, k) in enumerate(tris.tolist()):
        for e in ((i, j), (j, k), (i, k)):
            if e in first:
                parent[find(t)] = find(first[e])
            else:
                first[e] = t
    return len({find(t) for t in range(len(tris))})


def solid_boundary(pts, simp, neighbors, kept, faces, singular_flags):
    """The solid's boundary (module docs) as oriented triples, rotated to start at their
    smallest index, sorted."""
    singular = {f: bool(s) for f, s in zip(faces.keys(), singular_flags)}

    def face(t, i):
        s = simp[t].tolist()
        return tuple(sorted(s[:i] + s[i + 1 :]))

    def open_into(t, i):
        return not kept[t] and not singular[face(t, i)]

    exterior = np.zeros(len(simp), dtype=bool)
    queue = []
    for t in range(len(simp)):
        if any(neighbors[t][i] == -1 and open_into(t, i) for i in range(4)):
            exterior[t] = True
            queue.append(t)
    while queue:
        t = queue.pop()
        for u in neighbors[t]:
            if u == -1 or exterior[u]:
                continue
            i = list(neighbors[u]).index(t)
            if open_into(u, i):
                exterior[u] = True
                queue.append(u)
    out = []
    for t in range(len(simp)):
        if exterior[t]:
            continue
        for i in range(4):
            u = neighbors[t][i]
            if u != -1 and not exterior[u]:
                continue
            s = simp[t].tolist()
            a, b, c = s[:i] + s[i + 1 :]
            # Normal away from the solid tetrahedron's fourth vertex.
            if np.dot(np.cross(pts[b] - pts[a], pts[c] - pts[a]), pts[s[i]] - pts[a]) > 0:
                b, c = c, b
            k = [a, b, c].index(min(a, b, c))
            out.append(tuple([a, b, c][k:] + [a, b, c][:k]))
    return np.array(sorted(out), dtype=np.int64).reshape(-1, 3)


def main():
    cases = []
    for name, alpha in CASES:
        pts = read_points(DIR / name)
        tri = Delaunay(pts)
        simp = tri.simplices
        radius = circumradius_tet(pts[simp])
        # Unique faces with their (one or two) tetrahedra.
        faces = {}
        for t, s in enumerate(simp.tolist()):
            for i in range(4):
                f = tuple(sorted(s[:i] + s[i + 1 :]))
                faces.setdefault(f, []).append(t)
        keys = np.array(list(faces.keys()), dtype=np.int64)
        centre, r = smallest_sphere(pts[keys])
        # Brute-force emptiness: the nearest point to each centre, other than the face's own.
        margin = np.full(len(keys), np.inf)
        for lo in range(0, len(keys), 2000):
            hi = min(lo + 2000, len(keys))
            d = np.linalg.norm(centre[lo:hi, None, :] - pts[None, :, :], axis=2)
            rows = np.arange(hi - lo)[:, None]
            d[rows, keys[lo:hi]] = np.inf
            margin[lo:hi] = d.min(1) - r[lo:hi]
        empty = margin > 0
        out, ties = [], []
        for k, (f, ts) in enumerate(faces.items()):
            rs = [radius[t] for t in ts] + [np.inf] * (2 - len(ts))
            kept = [x <= alpha for x in rs]
            tie = any(abs(x - alpha) <= TIE * alpha for x in rs) or abs(margin[k]) <= TIE * r[k]
            tie = tie or abs(r[k] - alpha) <= TIE * alpha
            if kept[0] != kept[1] or (not any(kept) and empty[k] and r[k] <= alpha):
                out.append(f)
            if tie:
                ties.append(f)
        out = np.array(sorted(out), dtype=np.int64).reshape(-1, 3)
        solid = solid_boundary(pts, simp, tri.neighbors, radius <= alpha, faces, empty & (r <= alpha))
        cases.append(
            {
                "input": name,
                "alpha": alpha,
                "triangles": out.ravel().tolist(),
                "pieces": pieces(out),
                "solid": solid.ravel().tolist(),
                "solid_pieces": pieces(np.sort(solid, axis=1)),
                "ties": np.array(sorted(ties), dtype=np.int64).ravel().tolist(),
            }
        )
        print(
            f"{name} alpha {alpha}: {len(out)} triangles, {cases[-1]['pieces']} pieces; solid "
            f"{len(solid)} triangles, {cases[-1]['solid_pieces']} pieces; {len(ties)} ties"
        )
    doc = {
        "tool": "scipy.spatial.Delaunay + brute-force smallest-circumsphere emptiness (CGAL GENERAL rule)",
        "versions": {"scipy": scipy.__version__, "numpy": np.__version__},
        "cases": cases,
    }
    (DIR / "complex.json").write_text(json.dumps(doc, separators=(",", ":")) + "\n")


if __name__ == "__main__":
    main()
