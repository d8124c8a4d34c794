#!/usr/bin/env python3
"""The stiff-case suite (docs/numerics.md): inputs that make floating point hard, with references
computed by mpmath at 50 significant digits (more where a case cancels), and the error of a naive
float32 implementation of each operation next to them.

Writes fixtures/data/reference/stiff/{frames,covariance,w2,alpha,tsdf,collapse}.json. Each file
holds `groups`: one per (operation, case), each with its `instances` (inputs and references) and
`naive_f32`: the worst error, per quantity, of the textbook formula evaluated in numpy float32
(inputs rounded to float32) against the same reference, measured exactly as the Rust test
`tests/tests/numerics_stiff.rs` measures trisplat.

Conventions of the files:
- inputs are decimal strings that are exactly the float64 (or float32, where the Rust function
  takes float32: Gaussian parameters, template vertices of the deformers, depth maps) values used;
- references are decimal strings with 25 significant digits of the mpmath value;
- matrices are 9 numbers in column-major order (glam's `from_cols_array`), quaternions `[w, x, y, z]`.

Errors (the same definitions in the Rust test):
- `rel`: |x - r| / |r|;
- matrices and vectors: max |X_ij - R_ij| / max |R_ij| (relative to the largest entry);
- scales: max_i |s_i - r_i| / r_i over the nonzero reference scales, and |s_i| / r_0 for a zero one;
- TSDF: |tsdf - tsdf_ref| (tsdf is in units of the truncation), 1 when the voxel is skipped;
  zero crossings along z (marching cubes' vertex on that edge): |n . (x - p0)| / voxel, the
  distance to the exact plane, NaN when the two voxels do not straddle zero;
- a NaN makes the error NaN; NaNs are counted.

Collapse sequences carry no numeric reference: the policy (every output finite, the frame
flagged degenerate exactly at zero area) is the reference.

Usage (numpy and mpmath pinned in requirements.txt; the other pins are not needed here):

    venv/bin/python tests/reference/ref_stiff.py
"""

import json
import pathlib
import sys
from importlib.metadata import PackageNotFoundError, version

import numpy as np
import mpmath
from mpmath import mp

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
OUT = ROOT / "fixtures" / "data" / "reference" / "stiff"
REQUIREMENTS = HERE / "requirements.txt"
SEED = 1802
DPS = 50
DIGITS = 25
F32 = np.float32

# trisplat constants the references reproduce (splat/src/frames.rs, FrameOptions::default()).
DEGENERATE_TOL = 1e-12
MIN_SCALE = 1e-12


def check_pinned_versions(names):
    """Refuses to run with other versions of the packages this script uses."""
    pins = {}
    for line in REQUIREMENTS.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            name, want = line.split("==")
            pins[name] = want
    bad = []
    for name in names:
        try:
            have = version(name)
        except PackageNotFoundError:
            have = None
        if have != pins.get(name):
            bad.append(f"{name}: want {pins.get(name)}, have {have}")
    if bad:
        sys.exit("pinned versions differ:\n  " + "\n  ".join(bad))


# ---------------------------------------------------------------- number formatting


def s64(x):
    """A float64 input as the shortest decimal that round-trips."""
    x = float(x)
    assert np.isfinite(x)
    return repr(x)


def s32(x):
    """A float32 input as the shortest decimal that round-trips in float32."""
    x = F32(x)
    assert np.isfinite(x)
    return np.format_float_positional(x, unique=True, trim="-") if x != 0 else "0"


def sref(x):
    """A reference value, 25 significant digits."""
    return mp.nstr(mp.mpf(x), DIGITS, min_fixed=-3, max_fixed=6)


def vec_s(v, fmt=s64):
    return [fmt(t) for t in v]


def mat_s(m, fmt=s64):
    """Column-major strings of a 3x3 (numpy array or mp rows)."""
    return [fmt(m[r][c]) for c in range(3) for r in range(3)]


# ---------------------------------------------------------------- exact 3-vectors and matrices


def mv(v):
    return [mp.mpf(float(t)) for t in v]


def mm(m):
    """mp rows from a numpy 3x3 (exact)."""
    return [[mp.mpf(float(m[r][c])) for c in range(3)] for r in range(3)]


def add(a, b):
    return [x + y for x, y in zip(a, b)]


def sub(a, b):
    return [x - y for x, y in zip(a, b)]


def scl(a, s):
    return [x * s for x in a]


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    return mp.sqrt(dot(a, a))


def normalize(a):
    n = norm(a)
    return [x / n for x in a]


def cols(c0, c1, c2):
    return [[c0[r], c1[r], c2[r]] for r in range(3)]


def col(m, c):
    return [m[r][c] for r in range(3)]


def matmul(a, b):
    return [[sum(a[r][k] * b[k][c] for k in range(3)) for c in range(3)] for r in range(3)]


def matvec(a, v):
    return [sum(a[r][k] * v[k] for k in range(3)) for r in range(3)]


def transpose(a):
    return [[a[c][r] for c in range(3)] for r in range(3)]


def det(a):
    return dot(col(a, 0), cross(col(a, 1), col(a, 2)))


def cofactor(a):
    """cof(A) = det(A) A^-T: columns c1 x c2, c2 x c0, c0 x c1."""
    c = [col(a, k) for k in range(3)]
    return cols(cross(c[1], c[2]), cross(c[2], c[0]), cross(c[0], c[1]))


def inverse(a):
    return [[x / det(a) for x in row] for row in transpose(cofactor(a))]


def diag(d):
    return [[d[r] if r == c else mp.mpf(0) for c in range(3)] for r in range(3)]


def mpmat(a):
    return mp.matrix([[a[r][c] for c in range(3)] for r in range(3)])


def rows_of(m):
    return [[m[r, c] for c in range(3)] for r in range(3)]


def svd(a):
    """Singular values (descending) and U, V rows with A = U diag(s) V^T."""
    u, s, vt = mp.svd_r(mpmat(a))
    order = sorted(range(3), key=lambda k: -s[k])
    sv = [s[k] for k in order]
    u = rows_of(u)
    vt = rows_of(vt)
    uu = cols(*[col(u, k) for k in order])
    vv = cols(*[vt[k] for k in order])
    return sv, uu, vv


def quat_matrix(q):
    """Rotation of a raw [w, x, y, z] quaternion (normalised exactly)."""
    w, x, y, z = normalize(mv(q))
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


# ---------------------------------------------------------------- errors


def rel(x, r):
    if x is None or not np.isfinite(float(x)):
        return mp.nan
    return abs(mp.mpf(float(x)) - r) / abs(r)


def arr_rel(x, r):
    """max |x - r| / max |r| over flattened arrays (x float, r mp)."""
    x = np.asarray(x, dtype=np.float64).ravel()
    r = list(r)
    if not np.all(np.isfinite(x)):
        return mp.nan
    big = max(abs(t) for t in r)
    return max(abs(mp.mpf(float(a)) - b) for a, b in zip(x, r)) / big


def scales_rel(x, r):
    """Scales: relative per nonzero reference, |x| / r_0 for a zero reference."""
    x = [float(t) for t in x]
    if not all(np.isfinite(x)):
        return mp.nan
    out = mp.mpf(0)
    for a, b in zip(x, r):
        if b > 0:
            out = max(out, abs(mp.mpf(a) - b) / b)
        else:
            out = max(out, abs(mp.mpf(a)) / r[0])
    return out


def flat_rows(m):
    return [m[r][c] for c in range(3) for r in range(3)]


class Worst:
    """Worst error per quantity of the naive implementation over a group."""

    def __init__(self):
        self.worst = {}
        self.nan = {}
        self.count = {}

    def add(self, quantity, err):
        self.count[quantity] = self.count.get(quantity, 0) + 1
        self.nan.setdefault(quantity, 0)
        self.worst.setdefault(quantity, mp.mpf(0))
        if mp.isnan(err):
            self.nan[quantity] += 1
        else:
            self.worst[quantity] = max(self.worst[quantity], err)

    def json(self):
        return {
            q: {"worst": mp.nstr(self.worst[q], 3), "nan": self.nan[q], "count": self.count[q]}
            for q in self.worst
        }


def group(op, case, instances, naive, note=None):
    g = {"op": op, "case": case, "instances": instances, "naive_f32": naive.json()}
    if note:
        g["note"] = note
    return g


# ---------------------------------------------------------------- random inputs (float64)


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def place(rng, local, offset=0.0, size=1.0):
    """Local triangle corners rotated randomly, scaled and moved (float64 results are the input)."""
    r = random_rotation(rng)
    t = rng.normal(size=3) * 0.3 + offset
    return [r @ (np.asarray(p, dtype=np.float64) * size) + t for p in local]


# ================================================================= triangle frames


def edge_and_normal(v):
    """frames.rs `edge_and_normal`, exactly."""
    tol = mp.mpf(DEGENERATE_TOL)
    e1, e2, e3 = sub(v[1], v[0]), sub(v[2], v[0]), sub(v[2], v[1])
    l1, l2, l3 = norm(e1), norm(e2), norm(e3)
    longest = max(l1, l2, l3)
    n = cross(e1, e2)
    n_len = norm(n)
    if longest > 0 and l1 > tol * longest and n_len > tol * longest * longest:
        a0 = scl(e1, 1 / l1)
        return a0, normalize(cross(a0, e2)), False, l1, longest
    if longest > 0 and l1 > tol * longest:
        a0 = scl(e1, 1 / l1)
    elif longest > 0:
        e = e2 if l2 >= l3 else e3
        a0 = normalize(e)
    else:
        a0 = [mp.mpf(1), mp.mpf(0), mp.mpf(0)]
    return a0, orthogonal_unit(a0), True, l1, longest


def orthogonal_unit(a):
    ax = [abs(t) for t in a]
    if ax[0] <= ax[1] and ax[0] <= ax[2]:
        axis = [1, 0, 0]
    elif ax[1] <= ax[2]:
        axis = [0, 1, 0]
    else:
        axis = [0, 0, 1]
    return normalize(cross(a, [mp.mpf(t) for t in axis]))


def frame_scale(l1, in_plane, e2, longest, degenerate):
    k = (l1 + abs(dot(in_plane, e2))) / 2
    if degenerate:
        k = max(k, longest / 2)
    return max(k, mp.mpf(MIN_SCALE))


def ref_frame(v, convention):
    """(rotation rows, scale, origin, degenerate) of frames.rs `gaussian_avatars_frame` /
    `surfhead_frame`."""
    v = [mv(p) for p in v]
    a0, a1, degenerate, l1, longest = edge_and_normal(v)
    e2 = sub(v[2], v[0])
    origin = scl(add(add(v[0], v[1]), v[2]), mp.mpf(1) / 3)
    if convention == "gaussian_avatars":
        a2 = scl(normalize(cross(a1, a0)), -1)
        rot = cols(a0, a1, a2)
        k = frame_scale(l1, a2, e2, longest, degenerate)
    else:
        b1 = cross(a1, a0)
        rot = cols(a0, b1, a1)
        k = frame_scale(l1, b1, e2, longest, degenerate)
    return rot, k, origin, degenerate


def naive_frame(v, convention):
    """The published formulas in float32, no degenerate fallback."""
    v = [np.asarray(p, dtype=F32) for p in v]
    e1, e2 = v[1] - v[0], v[2] - v[0]
    a0 = e1 / np.linalg.norm(e1)
    a1 = np.cross(a0, e2)
    a1 = a1 / np.linalg.norm(a1)
    origin = (v[0] + v[1] + v[2]) / F32(3)
    if convention == "gaussian_avatars":
        a2 = -np.cross(a1, a0)
        a2 = a2 / np.linalg.norm(a2)
        rot = np.stack([a0, a1, a2], axis=1)
        k = (np.linalg.norm(e1) + abs(np.dot(a2, e2))) / F32(2)
    else:
        b1 = np.cross(a1, a0)
        rot = np.stack([a0, b1, a1], axis=1)
        k = (np.linalg.norm(e1) + abs(np.dot(b1, e2))) / F32(2)
    return rot, k, origin


def frame_error(rot, k, origin, ref):
    r_rot, r_k, r_origin, _ = ref
    errs = [arr_rel(np.asarray(rot).T.ravel(), flat_rows(r_rot)), rel(k, r_k), arr_rel(origin, r_origin)]
    return mp.nan if any(mp.isnan(e) for e in errs) else max(errs)


def edge_matrix(v):
    e1, e2 = sub(v[1], v[0]), sub(v[2], v[0])
    n = cross(e1, e2)
    length = norm(n)
    third = scl(n, 1 / mp.sqrt(length)) if length > 0 else [mp.mpf(0)] * 3
    return cols(e1, e2, third)


def naive_inv(m):
    """float32 inverse; NaN for a matrix LAPACK finds singular."""
    try:
        return np.linalg.inv(m)
    except np.linalg.LinAlgError:
        return np.full((3, 3), np.nan, dtype=F32)


def naive_edge_matrix(v):
    v = [np.asarray(p, dtype=F32) for p in v]
    e1, e2 = v[1] - v[0], v[2] - v[0]
    n = np.cross(e1, e2)
    return np.stack([e1, e2, n / np.sqrt(np.linalg.norm(n))], axis=1)


def ref_gradient(c, d):
    """frames.rs `deformation_gradient`, exactly: (J rows, degenerate)."""
    c, d = [mv(p) for p in c], [mv(p) for p in d]
    _, _, degenerate, _, _ = edge_and_normal(c)
    if not degenerate:
        return matmul(edge_matrix(d), inverse(edge_matrix(c))), False
    fc, fd = ref_frame_mp(c), ref_frame_mp(d)
    m = matmul(fd[0], transpose(fc[0]))
    return [[x * fd[1] / fc[1] for x in row] for row in m], True


def ref_frame_mp(v):
    """surfhead frame of mp corners."""
    a0, a1, degenerate, l1, longest = edge_and_normal(v)
    b1 = cross(a1, a0)
    return cols(a0, b1, a1), frame_scale(l1, b1, sub(v[2], v[0]), longest, degenerate)


def frame_cases(rng):
    """Triangle shapes: (case, local corners or None, offset, size, count)."""
    cases = [
        ("regular", lambda: [[0, 0, 0], [1, 0, 0], [0.3, 0.9, 0]], 0.0, 1.0),
        ("sliver h/L=1e-3", lambda: [[0, 0, 0], [1, 0, 0], [rng.uniform(0.2, 0.8), 1e-3, 0]], 0.0, 1.0),
        ("sliver h/L=1e-6", lambda: [[0, 0, 0], [1, 0, 0], [rng.uniform(0.2, 0.8), 1e-6, 0]], 0.0, 1.0),
        ("sliver h/L=1e-9 (beyond 1e6)", lambda: [[0, 0, 0], [1, 0, 0], [rng.uniform(0.2, 0.8), 1e-9, 0]], 0.0, 1.0),
        ("needle, first edge 1e-6 L", lambda: [[0, 0, 0], [1e-6, 0.3e-6, 0], [1, 0.1, 0]], 0.0, 1.0),
        ("needle, second edge 1e-6 L", lambda: [[0, 0, 0], [1, 0.1, 0], [0.4e-6, 0.8e-6, 0]], 0.0, 1.0),
        ("needle, last edge 1e-6 L", lambda: [[0, 0, 0], [1, 0, 0], [1 + 0.4e-6, 0.8e-6, 0]], 0.0, 1.0),
        ("size 1e-3 at 1e3 from the origin", lambda: [[0, 0, 0], [1, 0, 0], [0.3, 0.9, 0]], 1e3, 1e-3),
        ("sliver h/L=1e-6, size 1e-3 at 1e3", lambda: [[0, 0, 0], [1, 0, 0], [rng.uniform(0.2, 0.8), 1e-6, 0]], 1e3, 1e-3),
    ]
    return cases


def collapsed_triangles():
    """Exactly zero-area triangles (binary fractions, exact in float64 and float32)."""
    v0 = np.array([0.375, -1.25, 2.5])
    e = np.array([0.25, -0.125, 0.5])
    return [
        ("collinear", [v0, v0 + e, v0 + 2.5 * e]),
        ("collinear, v2 between v0 and v1", [v0, v0 + 4 * e, v0 + e]),
        ("v0 = v1", [v0, v0, v0 + e]),
        ("v1 = v2", [v0, v0 + e, v0 + e]),
        ("a point", [v0, v0, v0]),
    ]


def frames_groups(rng):
    groups = []
    per = 6
    for conv in ["gaussian_avatars", "surfhead"]:
        op = f"frame_{conv}"
        for case, local, offset, size in frame_cases(rng):
            naive = Worst()
            inst = []
            for _ in range(per):
                v = place(rng, local(), offset, size)
                ref = ref_frame(v, conv)
                inst.append(
                    {
                        "v": [vec_s(p) for p in v],
                        "ref": {
                            "rotation": [sref(x) for x in flat_rows(ref[0])],
                            "scale": sref(ref[1]),
                            "origin": [sref(x) for x in ref[2]],
                            "degenerate": ref[3],
                        },
                    }
                )
                with np.errstate(all="ignore"):
                    naive.add("frame", frame_error(*naive_frame(v, conv), ref))
            groups.append(group(op, case, inst, naive))
        # Exactly collapsed triangles: the reference is the documented fallback.
        naive = Worst()
        inst = []
        for case, v in collapsed_triangles():
            ref = ref_frame(v, conv)
            assert ref[3]
            inst.append(
                {
                    "name": case,
                    "v": [vec_s(p) for p in v],
                    "ref": {
                        "rotation": [sref(x) for x in flat_rows(ref[0])],
                        "scale": sref(ref[1]),
                        "origin": [sref(x) for x in ref[2]],
                        "degenerate": True,
                    },
                }
            )
            with np.errstate(all="ignore"):
                naive.add("frame", frame_error(*naive_frame(v, conv), ref))
        groups.append(group(op, "zero area (fallback frame)", inst, naive))

    # edge_matrix E(v) = [v1 - v0 | v2 - v0 | n / sqrt|n|] on the same shapes.
    for case, local, offset, size in frame_cases(rng):
        naive = Worst()
        inst = []
        for _ in range(per):
            v = place(rng, local(), offset, size)
            e = edge_matrix([mv(p) for p in v])
            inst.append({"v": [vec_s(p) for p in v], "ref": {"e": [sref(x) for x in flat_rows(e)]}})
            with np.errstate(all="ignore"):
                naive.add("e", arr_rel(naive_edge_matrix(v).T.ravel(), flat_rows(e)))
        groups.append(group("edge_matrix", case, inst, naive))

    groups += gradient_groups(rng)
    groups += normal_groups(rng)
    return groups


def gradient_groups(rng):
    """J = E(deformed) E(canonical)^-1 (deformation_gradient and CanonicalTriangle::gradient)."""
    regular = [[0, 0, 0], [1, 0, 0], [0.3, 0.9, 0]]
    sliver = [[0, 0, 0], [1, 0, 0], [0.5, 1e-3, 0]]

    def near_identity(delta, local):
        def make():
            c = place(rng, local)
            d = [p + rng.normal(size=3) * delta for p in c]
            return c, d

        return make

    def stretched():
        c = place(rng, regular)
        a = random_rotation(rng) @ np.diag([1e3, 1.0, 1e-3]) @ random_rotation(rng)
        return c, [a @ p + 1.0 for p in c]

    def near_collapse(eps):
        def make():
            c = place(rng, regular)
            local = [[0, 0, 0], [1.2, 0, 0], [0.7, eps, 0]]
            return c, place(rng, local)

        return make

    def flipped():
        # The deformed triangle mirrored through a plane (its normal reverses): J is then a
        # proper rotation composed with the mirror's in-plane action, det J > 0.
        c = place(rng, regular)
        h = rng.normal(size=3)
        h /= np.linalg.norm(h)
        m = np.eye(3) - 2 * np.outer(h, h)
        return c, [m @ p for p in c]

    def collapsed_deformed():
        c = place(rng, regular)
        return c, collapsed_triangles()[0][1]

    def collapsed_canonical():
        v = collapsed_triangles()[0][1]
        return v, place(rng, regular)

    cases = [
        ("near identity, perturbation 1e-9", near_identity(1e-9, regular)),
        ("near identity on a sliver (h/L=1e-3), perturbation 1e-9", near_identity(1e-9, sliver)),
        ("stretch 1e3 / 1e-3", stretched),
        ("deformed near collapse (h/L=1e-6)", near_collapse(1e-6)),
        ("deformed mirrored (normal reversed)", flipped),
        ("deformed collapsed (zero area)", collapsed_deformed),
        ("canonical collapsed (similarity fallback)", collapsed_canonical),
    ]
    groups = []
    for case, make in cases:
        naive = Worst()
        inst = []
        for _ in range(6):
            c, d = make()
            j, degenerate = ref_gradient(c, d)
            inst.append(
                {
                    "canonical": [vec_s(p) for p in c],
                    "deformed": [vec_s(p) for p in d],
                    "ref": {"j": [sref(x) for x in flat_rows(j)], "degenerate": degenerate},
                }
            )
            with np.errstate(all="ignore"):
                nj = naive_edge_matrix(d) @ naive_inv(naive_edge_matrix(c))
                naive.add("j", arr_rel(nj.T.ravel(), flat_rows(j)))
        groups.append(group("deformation_gradient", case, inst, naive))
    return groups


def normal_groups(rng):
    """transform_normal(J, n) = normalize(sign(det J) cof(J) n); naive: normalize(inv(J)^T n)."""

    def j_of(sv, flip=False):
        def make():
            u, v = random_rotation(rng), random_rotation(rng)
            d = np.array(sv, dtype=np.float64)
            if flip:
                d[2] = -d[2]
            return u @ np.diag(d) @ v

        return make

    cases = [
        ("near identity (I + 1e-9 noise)", lambda: np.eye(3) + rng.normal(size=(3, 3)) * 1e-9),
        ("scale ratio 1e8", j_of([1.0, 1e-4, 1e-8])),
        ("nearly singular (sigma_min = 1e-12)", j_of([1.0, 0.7, 1e-12])),
        ("rank 2 (sigma_min = 0)", j_of([1.0, 0.7, 0.0])),
        ("near reflection (det < 0, sigma_min = 1e-9)", j_of([1.0, 0.5, 1e-9], flip=True)),
    ]
    groups = []
    for case, make in cases:
        naive = Worst()
        inst = []
        # For a J singular to rounding (det ~ 1e-17) the computed sign of det J is noise, and
        # with it the orientation of the moved normal: compared up to sign.
        sign_free = case.startswith("rank 2")
        for _ in range(6):
            j = make()
            n = rng.normal(size=3)
            jm, nm = mm(j), mv(n)
            m = matvec(cofactor(jm), nm)
            if det(jm) < 0:
                m = scl(m, -1)
            want = normalize(m)
            inst.append({"j": mat_s(j), "n": vec_s(n), "ref": {"normal": [sref(x) for x in want]}})
            with np.errstate(all="ignore"):
                j32 = j.astype(F32)
                got = naive_inv(j32).T @ n.astype(F32)
                got = got / np.linalg.norm(got)
            err = arr_rel(got, want) if np.all(np.isfinite(got)) else mp.nan
            if sign_free and not mp.isnan(err):
                err = min(err, arr_rel(-got, want))
            naive.add("normal", err)
        g = group("transform_normal", case, inst, naive)
        g["sign_free"] = sign_free
        groups.append(g)
    return groups


# ================================================================= covariances


def log_scale_cases():
    """(case, log-scales); exp of the float32 values is the scale."""
    return [
        ("scales within 1e2", [-1.0, -2.5, -5.0]),
        ("scale ratio 1e4", [-1.0, -5.6, -10.2]),
        ("scale ratio 1e8", [-2.0, -11.2, -20.4]),
        ("log-scales down to -23", [-5.0, -14.0, -23.0]),
        ("two equal scales, third 1e-8", [-3.0, -3.0, -21.4]),
    ]


def factor_cases(rng):
    """L = J R S for rotation_and_scales: (case, J maker, log-scales, surfel)."""

    def near_id():
        return np.eye(3) + rng.normal(size=(3, 3)) * 1e-9

    def general():
        return random_rotation(rng) @ np.diag([1.7, 1.1, 0.6]) @ random_rotation(rng)

    def near_reflection():
        return random_rotation(rng) @ np.diag([1.0, 1.0, -1.0]) + rng.normal(size=(3, 3)) * 1e-9

    def near_singular(s):
        def make():
            return random_rotation(rng) @ np.diag([1.3, 0.8, s]) @ random_rotation(rng)

        return make

    out = []
    for name, ls in log_scale_cases():
        out.append((f"J near identity, {name}", near_id, ls, False))
        out.append((f"J general, {name}", general, ls, False))
    out.append(("J near reflection (det ~ -1), scale ratio 1e8", near_reflection, [-2.0, -11.2, -20.4], False))
    out.append(("J nearly singular (+1e-9), scale ratio 1e4", near_singular(1e-9), [-1.0, -5.6, -10.2], False))
    out.append(("J nearly singular (-1e-9, reflecting)", near_singular(-1e-9), [-1.0, -5.6, -10.2], False))
    out.append(("surfel (third scale 0), J general", general, [-1.0, -6.0, 0.0], True))
    out.append(("surfel (third scale 0), scale ratio 1e8", near_id, [-2.0, -20.4, 0.0], True))
    return out


def ref_factor(l):
    """Singular values (descending), L L^T, and the normal of a rank-2 L."""
    sv, u, _ = svd(l)
    cov = matmul(l, transpose(l))
    return sv, cov, col(u, 2)


def naive_factor(l):
    """Textbook: eigen-decomposition of the float32 covariance L L^T, sigma = sqrt(lambda)."""
    l32 = np.asarray(l, dtype=F32)
    c = l32 @ l32.T
    lam, vec = np.linalg.eigh(c)
    order = np.argsort(-lam)
    lam, vec = lam[order], vec[:, order]
    with np.errstate(invalid="ignore"):
        sigma = np.sqrt(lam)
    back = (vec * lam) @ vec.T
    return sigma, back, vec[:, 2]


def normal_error(got, want):
    """|sin| of the angle between two unit axes (sign-free)."""
    g = [mp.mpf(float(t)) for t in got]
    if not all(mp.isfinite(t) for t in g):
        return mp.nan
    return norm(cross(normalize(g), want))


def covariance_groups(rng):
    groups = []
    for case, make_j, ls, surfel in factor_cases(rng):
        naive = Worst()
        inst = []
        for _ in range(6):
            j = make_j()
            r = random_rotation(rng)
            s = np.exp(np.asarray(ls, dtype=np.float64))
            if surfel:
                s[2] = 0.0
            l = j @ r @ np.diag(s)
            sv, cov, nrm = ref_factor(mm(l))
            ref = {"sigma": [sref(x) for x in sv], "cov": [sref(x) for x in flat_rows(cov)]}
            if surfel:
                ref["normal"] = [sref(x) for x in nrm]
            inst.append({"l": mat_s(l), "ref": ref})
            sigma, back, n32 = naive_factor(l)
            naive.add("sigma", scales_rel(sigma, sv))
            naive.add("cov", arr_rel(back.T.ravel(), flat_rows(cov)))
            if surfel:
                naive.add("normal", normal_error(n32, nrm))
        groups.append(group("rotation_and_scales", case, inst, naive))
    groups += polar_groups(rng)
    groups += deformer_groups(rng)
    return groups


def polar_groups(rng):
    """lbs.rs polar_rotation: Q of A = Q H; None for det A <= 0 (and near-singular blends)."""

    def svd_a(sv):
        def make():
            return random_rotation(rng) @ np.diag(sv) @ random_rotation(rng)

        return make

    cases = [
        ("near identity (I + 1e-9 noise)", lambda: np.eye(3) + rng.normal(size=(3, 3)) * 1e-9),
        ("general", svd_a([1.5, 1.0, 0.5])),
        ("condition 1e6", svd_a([1.0, 1e-3, 1e-6])),
        ("nearly singular (sigma = 1, 1, 1e-9)", svd_a([1.0, 1.0, 1e-9])),
        ("near reflection (sigma_3 = -1e-6): None", svd_a([1.0, 1.0, -1e-6])),
    ]
    groups = []
    for case, make in cases:
        naive = Worst()
        inst = []
        for _ in range(8):
            a = make()
            am = mm(a)
            if det(am) <= 0:
                inst.append({"a": mat_s(a), "ref": {"q": None}})
                # the textbook formula does not check: it returns a reflection (error 1)
                naive.add("q", mp.mpf(1))
                continue
            sv, u, v = svd(am)
            q = matmul(u, transpose(v))
            inst.append({"a": mat_s(a), "ref": {"q": [sref(x) for x in flat_rows(q)]}})
            a32 = a.astype(F32)
            lam, vec = np.linalg.eigh(a32.T @ a32)
            with np.errstate(all="ignore"):
                h_inv = (vec / np.sqrt(lam)) @ vec.T
            naive.add("q", arr_rel((a32 @ h_inv).T.ravel(), flat_rows(q)))
        groups.append(group("polar_rotation", case, inst, naive))
    return groups


# ---------------------------------------------------------------- the deformers (end to end)


def f32_triangle(rng, local, offset=0.0, size=1.0):
    return [np.asarray(p, dtype=F32).astype(np.float64) for p in place(rng, local, offset, size)]


def gaussians(rng, ls, surfel, n=4):
    out = []
    for _ in range(n):
        q = rng.normal(size=4).astype(F32)
        mean = (rng.normal(size=3) * 0.5).astype(F32)
        jitter = rng.normal(size=3) * 0.1
        lsv = (np.asarray(ls) + jitter).astype(F32)
        if surfel:
            lsv[2] = F32(0.0)
        out.append({"mean": mean, "rot": q, "log_scale": lsv})
    return out


def binding_ref(tri, g, surfel):
    """GaussianAvatars binding: mu = k R_f mu + c, Sigma = k^2 R_f R S^2 R^T R_f^T, s = k e^ls."""
    rot, k, origin, _ = ref_frame(tri, "gaussian_avatars")
    rl = quat_matrix(g["rot"])
    s = [mp.exp(mp.mpf(float(x))) for x in g["log_scale"]]
    if surfel:
        s[2] = mp.mpf(0)
    a = matmul(rot, matmul(rl, diag(s)))
    cov = [[x * k * k for x in row] for row in matmul(a, transpose(a))]
    mean = add(scl(matvec(rot, mv(g["mean"])), k), origin)
    return mean, cov, [x * k for x in s]


def naive_binding(tri, g, surfel):
    rot, k, origin = naive_frame(tri, "gaussian_avatars")
    w, x, y, z = g["rot"].astype(F32) / np.linalg.norm(g["rot"].astype(F32))
    rl = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ],
        dtype=F32,
    )
    s = np.exp(g["log_scale"].astype(F32))
    if surfel:
        s[2] = F32(0)
    a = rot @ rl @ np.diag(s)
    cov = (a @ a.T) * (k * k)
    mean = rot @ g["mean"] * k + origin
    return mean, cov, s * k


def jacobian_ref(can, tri, g, surfel):
    """Jacobian mode: M = J k_c R_c, mu = M mu + centroid, Sigma = M R S^2 R^T M^T, s = svd(M R S)."""
    j, _ = ref_gradient(can, tri)
    rot_c, k_c = ref_frame_mp([mv(p) for p in can])
    m = [[x * k_c for x in row] for row in matmul(j, rot_c)]
    rl = quat_matrix(g["rot"])
    s = [mp.exp(mp.mpf(float(x))) for x in g["log_scale"]]
    if surfel:
        s[2] = mp.mpf(0)
    l = matmul(m, matmul(rl, diag(s)))
    sv, _, _ = svd(l)
    d = [mv(p) for p in tri]
    centroid = scl(add(add(d[0], d[1]), d[2]), mp.mpf(1) / 3)
    mean = add(matvec(m, mv(g["mean"])), centroid)
    return mean, matmul(l, transpose(l)), sv


def naive_jacobian(can, tri, g, surfel):
    j = naive_edge_matrix(tri) @ naive_inv(naive_edge_matrix(can))
    rot_c, k_c, _ = naive_frame(can, "surfhead")
    m = j @ rot_c * k_c
    w, x, y, z = g["rot"].astype(F32) / np.linalg.norm(g["rot"].astype(F32))
    rl = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ],
        dtype=F32,
    )
    s = np.exp(g["log_scale"].astype(F32))
    if surfel:
        s[2] = F32(0)
    sig_local = rl @ np.diag(s * s) @ rl.T
    cov = m @ sig_local @ m.T
    lam = np.sort(np.linalg.eigh(cov)[0])[::-1]
    with np.errstate(invalid="ignore"):
        sigma = np.sqrt(lam)
    centroid = (tri[0].astype(F32) + tri[1].astype(F32) + tri[2].astype(F32)) / F32(3)
    return m @ g["mean"] + centroid, cov, sigma


def deformer_groups(rng):
    regular = [[0, 0, 0], [1, 0, 0], [0.3, 0.9, 0]]
    groups = []
    # Binding mode: the posed triangle's frame carries the Gaussian; the canonical shape is unused.
    shapes = [
        ("regular triangle", regular, 0.0, 1.0),
        ("sliver triangle (h/L=1e-3)", [[0, 0, 0], [1, 0, 0], [0.4, 1e-3, 0]], 0.0, 1.0),
        ("sliver triangle (h/L=1e-6)", [[0, 0, 0], [1, 0, 0], [0.4, 1e-6, 0]], 0.0, 1.0),
        ("size 1e-3 at 1e3", regular, 1e3, 1e-3),
    ]
    scale_sets = [
        ("scale ratio 1e8", [-2.0, -11.2, -20.4], False),
        ("log-scales down to -23", [-5.0, -14.0, -23.0], False),
        ("surfel", [-3.0, -12.0, 0.0], True),
    ]
    for mode in ["binding", "jacobian"]:
        for shape, local, offset, size in shapes:
            for sname, ls, surfel in scale_sets:
                naive = Worst()
                inst = []
                for _ in range(2):
                    if mode == "binding":
                        can = f32_triangle(rng, regular)
                        tri = f32_triangle(rng, local, offset, size)
                    else:
                        can = f32_triangle(rng, regular, offset, size)
                        # deformed: the canonical shape moved by a near-rigid motion plus the
                        # case's shape change
                        tri = f32_triangle(rng, local, offset, size)
                    gs = gaussians(rng, ls, surfel)
                    refs = []
                    for g in gs:
                        if mode == "binding":
                            mean, cov, sig = binding_ref(tri, g, surfel)
                            with np.errstate(all="ignore"):
                                nm, nc, ns = naive_binding(tri, g, surfel)
                            nsig = ns
                        else:
                            mean, cov, sig = jacobian_ref(can, tri, g, surfel)
                            with np.errstate(all="ignore"):
                                nm, nc, nsig = naive_jacobian(can, tri, g, surfel)
                        refs.append(
                            {
                                "mean": [sref(x) for x in mean],
                                "cov": [sref(x) for x in flat_rows(cov)],
                                "sigma": [sref(x) for x in sig],
                            }
                        )
                        naive.add("mean", arr_rel(nm, mean))
                        naive.add("cov", arr_rel(np.asarray(nc).T.ravel(), flat_rows(cov)))
                        if surfel:
                            # the flat axis is 0 in both; compare the two others
                            naive.add("sigma", scales_rel(list(nsig)[:2], sig[:2]))
                        else:
                            naive.add("sigma", scales_rel(nsig, sig))
                    inst.append(
                        {
                            "canonical": [vec_s(p, s32) for p in can],
                            "deformed": [vec_s(p, s32) for p in tri],
                            "surfel": surfel,
                            "gaussians": [
                                {
                                    "mean": vec_s(g["mean"], s32),
                                    "rot": vec_s(g["rot"], s32),
                                    "log_scale": vec_s(g["log_scale"], s32),
                                }
                                for g in gs
                            ],
                            "ref": refs,
                        }
                    )
                groups.append(group(f"deform_{mode}", f"{shape}, {sname}", inst, naive))
    return groups


# ================================================================= W2 gate


def bures_ref(l1, l2):
    """B^2 = |L1|^2 + |L2|^2 - 2 |L2^T L1|_* (nuclear norm), exact identity, at 100 digits."""
    with mp.workdps(100):
        a, b = mm(l1), mm(l2)
        k = matmul(transpose(b), a)
        sv, _, _ = svd(k)
        f = sum(x * x for row in a for x in row) + sum(x * x for row in b for x in row)
        return f - 2 * sum(sv)


def naive_bures(l1, l2):
    """Textbook trace form tr S1 + tr S2 - 2 tr sqrt(S1^1/2 S2 S1^1/2) in float32 (eigh roots)."""
    a, b = l1.astype(F32), l2.astype(F32)
    s1, s2 = a @ a.T, b @ b.T
    lam, vec = np.linalg.eigh(s1)
    with np.errstate(invalid="ignore"):
        root = (vec * np.sqrt(lam)) @ vec.T
        c = root @ s2 @ root
        try:
            mu = np.linalg.eigvalsh((c + c.T) / F32(2))
        except np.linalg.LinAlgError:
            return F32(np.nan)
        return np.trace(s1) + np.trace(s2) - F32(2) * np.sum(np.sqrt(mu))


def w2_groups(rng):
    def axes(r, s):
        return r @ np.diag(s)

    def pair_generic():
        return axes(random_rotation(rng), np.exp(rng.uniform(-3, 0, 3))), axes(
            random_rotation(rng), np.exp(rng.uniform(-3, 0, 3))
        )

    def near_equal(delta, s):
        def make():
            r = random_rotation(rng)
            k = rng.normal(size=(3, 3)) * delta
            skew = (k - k.T) / 2
            # rotation exp(skew) to second order is enough: the perturbed pair is the input
            r2 = r @ (np.eye(3) + skew + skew @ skew / 2)
            sv = np.asarray(s, dtype=np.float64)
            s2 = sv * (1 + rng.normal(size=3) * delta)
            return axes(r, sv), axes(r2, s2)

        return make

    def near_singular():
        s1 = np.array([1.0, 1e-4, 1e-8])
        s2 = np.array([0.8, 2e-4, 3e-8])
        return axes(random_rotation(rng), s1), axes(random_rotation(rng), s2)

    cases = [
        ("unrelated pair", pair_generic),
        ("nearly equal, delta = 1e-4", near_equal(1e-4, [1.0, 0.5, 0.2])),
        ("nearly equal, delta = 1e-8", near_equal(1e-8, [1.0, 0.5, 0.2])),
        ("nearly equal, delta = 1e-12", near_equal(1e-12, [1.0, 0.5, 0.2])),
        ("nearly singular (scales 1, 1e-4, 1e-8), unrelated", near_singular),
        ("nearly singular (ratio 1e8) and nearly equal, delta = 1e-6", near_equal(1e-6, [1.0, 1e-4, 1e-8])),
        ("singular (surfel, scale 0) and nearly equal, delta = 1e-6", near_equal(1e-6, [1.0, 0.3, 0.0])),
    ]
    groups = []
    for case, make in cases:
        naive = Worst()
        inst = []
        for _ in range(8):
            l1, l2 = make()
            mu1 = rng.normal(size=3) * 0.1
            mu2 = mu1 + rng.normal(size=3) * 1e-3
            b = bures_ref(l1, l2)
            with mp.workdps(100):
                w = sum((mp.mpf(float(x)) - mp.mpf(float(y))) ** 2 for x, y in zip(mu1, mu2)) + b
            inst.append(
                {
                    "mu1": vec_s(mu1),
                    "l1": mat_s(l1),
                    "mu2": vec_s(mu2),
                    "l2": mat_s(l2),
                    "ref": {"bures_sq": sref(b), "w2_sq": sref(w)},
                }
            )
            with np.errstate(all="ignore"):
                nb = naive_bures(l1, l2)
                nw = np.sum((mu1.astype(F32) - mu2.astype(F32)) ** 2) + nb
            naive.add("bures_sq", rel(nb, b))
            naive.add("w2_sq", rel(nw, w))
        groups.append(group("w2", case, inst, naive))
    return groups


# ================================================================= alpha shapes and Delaunay


def circumradius_mp(p):
    """Exact circumradius of a tetrahedron (p: 4 mp points)."""
    b, c, d = sub(p[1], p[0]), sub(p[2], p[0]), sub(p[3], p[0])
    n = add(add(scl(cross(c, d), dot(b, b)), scl(cross(d, b), dot(c, c))), scl(cross(b, c), dot(d, d)))
    den = 2 * dot(b, cross(c, d))
    return norm(n) / abs(den) if den != 0 else mp.inf


def circumradius_f32(p):
    """The same formula in float32 (relative to the first vertex; inputs rounded to float32)."""
    p = [np.asarray(x, dtype=F32) for x in p]
    b, c, d = p[1] - p[0], p[2] - p[0], p[3] - p[0]
    n = np.dot(b, b) * np.cross(c, d) + np.dot(c, c) * np.cross(d, b) + np.dot(d, d) * np.cross(b, c)
    den = F32(2) * np.dot(b, np.cross(c, d))
    with np.errstate(all="ignore"):
        return np.linalg.norm(n) / abs(den)


def pythagorean_sphere():
    """The 30 integer points at distance 3 from the origin: (+-1, +-2, +-2) permuted, (+-3, 0, 0)."""
    pts = set()
    for perm in [(1, 2, 2), (2, 1, 2), (2, 2, 1)]:
        for sx in (1, -1):
            for sy in (1, -1):
                for sz in (1, -1):
                    pts.add((sx * perm[0], sy * perm[1], sz * perm[2]))
    for axis in range(3):
        for sgn in (3, -3):
            p = [0, 0, 0]
            p[axis] = sgn
            pts.add(tuple(p))
    return sorted(pts)


def circumradius_groups(rng):
    def sphere_points(n, flat=None):
        """Points on the unit sphere (float64 rounded); with `flat`, the fourth one lies at
        height `flat` above the plane of the first three (a sliver with all four co-spherical)."""
        pts = []
        for _ in range(n):
            v = rng.normal(size=3)
            pts.append(v / np.linalg.norm(v))
        if flat is not None:
            a, b, c = [np.asarray(p) for p in pts[:3]]
            nrm = np.cross(b - a, c - a)
            nrm /= np.linalg.norm(nrm)
            h = float(np.dot(a, nrm))
            # a point on the circle of a, b, c, lifted by `flat` along the normal, on the sphere
            centre = h * nrm
            rad = np.sqrt(max(1 - h * h, 0.0))
            u = (a - centre) / np.linalg.norm(a - centre)
            w = np.cross(nrm, u)
            t = rng.uniform(0.5, 2.5)
            q = centre + rad * (np.cos(t) * u + np.sin(t) * w)
            q = q + nrm * flat
            pts[3] = q / np.linalg.norm(q)
        return pts

    sphere = pythagorean_sphere()

    def cospherical(offset, scale):
        def make():
            while True:
                idx = rng.choice(len(sphere), 4, replace=False)
                a, b, c, d = [np.asarray(sphere[i]) for i in idx]
                if round(np.linalg.det(np.stack([b - a, c - a, d - a]))) != 0:  # integers: exact
                    return [np.asarray(sphere[i], dtype=np.float64) * scale + offset for i in idx]

        return make

    cases = [
        ("random tetrahedra on the unit sphere", lambda: sphere_points(4)),
        ("co-spherical integer points (R = 3/64, exact)", cospherical(0.0, 2.0**-6)),
        ("co-spherical points x 0.01 at offset 1000 (rounded)", cospherical(1000.0, 0.01)),
        ("sliver: 4th point 1e-3 off the circle of 3", lambda: sphere_points(4, 1e-3)),
        ("sliver: 4th point 1e-6 off the circle of 3", lambda: sphere_points(4, 1e-6)),
        ("sliver 1e-6 at offset 1e3", lambda: [p + 1e3 for p in sphere_points(4, 1e-6)]),
    ]
    groups = []
    for case, make in cases:
        naive = Worst()
        inst = []
        for _ in range(8):
            p = make()
            r = circumradius_mp([mv(x) for x in p])
            inst.append({"p": [vec_s(x) for x in p], "ref": {"r": sref(r)}})
            naive.add("r", rel(circumradius_f32(p), r))
        groups.append(group("circumradius", case, inst, naive))
    return groups


def lattice(n, h, offset):
    return [
        [offset + x * h, offset + y * h, offset + z * h] for z in range(n) for y in range(n) for x in range(n)
    ]


def delaunay_groups(rng):
    """Combinatorial references for point sets full of co-spherical / co-circular subsets."""
    sets = []
    s = 2.0**-6
    sphere = [[c * s for c in p] for p in pythagorean_sphere()]
    r_sphere = 3 * mp.mpf(s)
    # every tetrahedron of a co-spherical set is inscribed in the sphere
    sets.append(
        {
            "name": "30 co-spherical integer points (radius 3/64)",
            "points": sphere,
            "radius": r_sphere,
            "hull_faces": 2 * 30 - 4,
            "volume": None,
            "tets": [[sphere[i] for i in rng.choice(30, 4, replace=False)] for _ in range(2000)],
        }
    )
    off = [[c + 1000.0 for c in p] for p in sphere]
    sets.append(
        {
            "name": "the same at offset 1000",
            "points": off,
            "radius": r_sphere,
            "hull_faces": 56,
            "volume": None,
            "tets": [[off[i] for i in rng.choice(30, 4, replace=False)] for _ in range(2000)],
        }
    )
    h = 2.0**-3
    grid = lattice(4, h, 1000.0)
    # every Delaunay tetrahedron of a lattice lies in a cube: circumradius sqrt(3)/2 h
    cube = [[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    cube_tets = []
    for _ in range(2000):
        o = rng.integers(0, 3, 3)
        idx = rng.choice(8, 4, replace=False)
        cube_tets.append([[1000.0 + (o[k] + cube[i][k]) * h for k in range(3)] for i in idx])
    sets.append(
        {
            "name": "4x4x4 lattice (spacing 1/8) at offset 1000",
            "points": grid,
            "radius": mp.sqrt(3) / 2 * mp.mpf(h),
            # 6 faces x 3 x 3 squares x 2 triangles
            "hull_faces": 108,
            "volume": (3 * mp.mpf(h)) ** 3,
            "tets": cube_tets,
        }
    )
    # 12 co-circular integer points on x^2 + y^2 = 25 in z = 0 and two apexes (0, 0, +-2)
    circle = [
        [5, 0], [4, 3], [3, 4], [0, 5], [-3, 4], [-4, 3], [-5, 0], [-4, -3], [-3, -4], [0, -5], [3, -4], [4, -3],
    ]
    ring = [[x * 0.125, y * 0.125, 0.0] for x, y in circle] + [[0.0, 0.0, 0.25], [0.0, 0.0, -0.25]]
    area = sum(
        mp.mpf(circle[i][0]) * circle[(i + 1) % 12][1] - mp.mpf(circle[(i + 1) % 12][0]) * circle[i][1]
        for i in range(12)
    ) / 2 * mp.mpf(0.125) ** 2
    sets.append(
        {
            "name": "12 co-circular points and two apexes (double cone)",
            "points": ring,
            "radius": None,
            "hull_faces": 24,
            "volume": area * mp.mpf(0.5) / 3,
            "tets": None,
        }
    )
    # nearly co-spherical: random unit vectors rounded to float64
    pts = []
    for _ in range(200):
        v = rng.normal(size=3)
        pts.append(list(v / np.linalg.norm(v)))
    sets.append(
        {
            "name": "200 points on the unit sphere (rounded: nearly co-spherical)",
            "points": pts,
            "radius": None,
            "hull_faces": 2 * 200 - 4,
            "volume": None,
            "tets": None,
        }
    )
    # a planar grid: dimension 2, no tetrahedra
    plane = [[x * 0.25, y * 0.25, 0.5] for y in range(5) for x in range(5)]
    sets.append(
        {
            "name": "5x5 planar grid (coplanar: no tetrahedra)",
            "points": plane,
            "radius": None,
            "hull_faces": 0,
            "volume": None,
            "tets": None,
        }
    )
    inst = []
    naive = Worst()
    for st in sets:
        entry = {
            "name": st["name"],
            "points": [vec_s(p) for p in st["points"]],
            "hull_faces": st["hull_faces"],
        }
        if st["radius"] is not None:
            entry["radius"] = sref(st["radius"])
            for t in st["tets"]:
                r = circumradius_mp([mv(x) for x in t])
                if r > 1e10:  # coplanar subset: not a tetrahedron
                    continue
                assert abs(r - st["radius"]) < mp.mpf(10) ** -40 * st["radius"], (st["name"], r)
                naive.add("circumradius", rel(circumradius_f32(t), st["radius"]))
        if st["volume"] is not None:
            entry["volume"] = sref(st["volume"])
        inst.append(entry)
    return [group("delaunay_alpha", "co-spherical / co-circular sets", inst, naive)]


# ================================================================= TSDF at grazing angles


TSDF_W, TSDF_H = 24, 16
TSDF_F = 20000.0
TSDF_D = 2.0
TSDF_VOXEL = 2.0**-12  # 2.44e-4, about 2.4 pixel footprints at depth 2
TSDF_TRUNC = 4 * TSDF_VOXEL


TSDF_CELL_SPREAD_PIXELS = 8.0  # extract/src/tsdf: MAX_CELL_SPREAD_PIXELS


def tsdf_rule(g, cam, depth, exact=True):
    """The per-voxel rule of extract/src/tsdf (Open3D's legacy integrator with the depth read
    between pixel centres, docs/conventions.md section 6) for an identity-rotation camera:
    returns tsdf, or None when the voxel is skipped; with exact=True in mpmath (and 'ambiguous'
    when a decision lies within 1e-9 of its threshold), else in float32.

    The depth at (u, v) is the bilinear interpolation of the four pixel centres around it
    (centres at j + 1/2) when all four are valid and differ by at most
    max(trunc, 8 * nearest / f), else the nearest pixel's; sdf = (d - q.z) * |q| / q.z."""
    c, fx, cx, cy = cam["c"], cam["f"], cam["cx"], cam["cy"]
    if exact:
        v = mp.mpf(TSDF_VOXEL)
        p = [(mp.mpf(int(k)) + mp.mpf(0.5)) * v for k in g]
        q = sub(p, mv(c))
        if q[2] <= 0:
            return None
        u = fx * q[0] / q[2] + cx
        w = fx * q[1] / q[2] + cy
        margin = mp.mpf(1e-4)
        if not (margin <= u < TSDF_W - margin and margin <= w < TSDF_H - margin):
            return None
        tiny = mp.mpf(1e-9)
        trunc = mp.mpf(TSDF_TRUNC)
        # the nearest pixel changes at integers, the cell at half-integers
        if min(abs(u - mp.nint(u)), abs(w - mp.nint(w))) < tiny:
            return "ambiguous"
        if min(abs(u - 0.5 - mp.nint(u - 0.5)), abs(w - 0.5 - mp.nint(w - 0.5))) < tiny:
            return "ambiguous"
        x, y = u - mp.mpf(0.5), w - mp.mpf(0.5)
        d = None
        if x >= 0 and y >= 0:
            j0, i0 = int(mp.floor(x)), int(mp.floor(y))
            if j0 + 1 < TSDF_W and i0 + 1 < TSDF_H:
                cell = [mp.mpf(float(depth[i0 + a][j0 + b])) for a in (0, 1) for b in (0, 1)]
                lo, hi = min(cell), max(cell)
                if lo > 0:
                    limit = max(trunc, lo * mp.mpf(TSDF_CELL_SPREAD_PIXELS) / fx)
                    if abs((hi - lo) - limit) < tiny * limit:
                        return "ambiguous"
                    if hi - lo <= limit:
                        tx, ty = x - j0, y - i0
                        top = cell[0] + tx * (cell[1] - cell[0])
                        bottom = cell[2] + tx * (cell[3] - cell[2])
                        d = top + ty * (bottom - top)
        if d is None:
            j, i = int(mp.floor(u)), int(mp.floor(w))
            d = mp.mpf(float(depth[i][j]))
        if d <= 0:
            return None
        dz = d - q[2]
        factor = mp.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2) / q[2]
        sdf = dz * factor
        if abs(sdf + trunc) < tiny * trunc or abs(dz + trunc) < tiny * trunc:
            return "ambiguous"
        if dz <= -trunc or sdf <= -trunc:
            return None
        return min(mp.mpf(1), sdf / trunc)
    v = F32(TSDF_VOXEL)
    p = (np.asarray(g, dtype=F32) + F32(0.5)) * v
    q = p - np.asarray(c, dtype=F32)
    if q[2] <= 0:
        return None
    u = F32(fx) * q[0] / q[2] + F32(cx)
    w = F32(fx) * q[1] / q[2] + F32(cy)
    if not (F32(1e-4) <= u < F32(TSDF_W - 1e-4) and F32(1e-4) <= w < F32(TSDF_H - 1e-4)):
        return None
    trunc = F32(TSDF_TRUNC)
    x, y = u - F32(0.5), w - F32(0.5)
    d = None
    if x >= 0 and y >= 0:
        j0, i0 = int(np.floor(x)), int(np.floor(y))
        if j0 + 1 < TSDF_W and i0 + 1 < TSDF_H:
            cell = [F32(depth[i0 + a][j0 + b]) for a in (0, 1) for b in (0, 1)]
            lo, hi = min(cell), max(cell)
            if lo > 0 and hi - lo <= max(trunc, lo * F32(TSDF_CELL_SPREAD_PIXELS) / F32(fx)):
                tx, ty = x - F32(j0), y - F32(i0)
                top = cell[0] + tx * (cell[1] - cell[0])
                bottom = cell[2] + tx * (cell[3] - cell[2])
                d = top + ty * (bottom - top)
    if d is None:
        j, i = int(np.floor(u)), int(np.floor(w))
        d = F32(depth[i][j])
    if d <= 0:
        return None
    dz = d - q[2]
    factor = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]) / q[2]
    sdf = dz * factor
    if sdf <= -trunc:
        return None
    return min(F32(1), sdf / trunc)


def tsdf_groups(rng):
    cases = [
        ("plane facing the camera (0 deg)", 0.0, [0.0, 0.0, 0.0], 0.5),
        ("plane at 60 deg", 60.0, [0.0, 0.0, 0.0], 0.5),
        ("plane at 85 deg", 85.0, [0.0, 0.0, 0.0], 0.5),
        ("plane at 89 deg", 89.0, [0.0, 0.0, 0.0], 0.5),
        ("plane at 89.9 deg", 89.9, [0.0, 0.0, 0.0], 0.1),
        ("plane at 89.9 deg, camera at (1000.5, -250.25, 3000.125)", 89.9, [1000.5, -250.25, 3000.125], 0.1),
    ]
    groups = []
    for case, theta, c, window in cases:
        th = mp.radians(mp.mpf(theta))
        n = [mp.mpf(0), mp.sin(th), -mp.cos(th)]
        cm = mv(c)
        p0 = add(cm, [mp.mpf(0), mp.mpf(0), mp.mpf(TSDF_D)])
        cam = {"c": c, "f": TSDF_F, "cx": TSDF_W / 2, "cy": TSDF_H / 2}
        depth = np.zeros((TSDF_H, TSDF_W), dtype=F32)
        for i in range(TSDF_H):
            for j in range(TSDF_W):
                d = [(j + mp.mpf(0.5) - cam["cx"]) / TSDF_F, (i + mp.mpf(0.5) - cam["cy"]) / TSDF_F, mp.mpf(1)]
                nd = dot(n, d)
                if nd == 0:
                    continue
                t = dot(n, sub(p0, cm)) / nd
                if t > 0 and abs(t - TSDF_D) <= window * TSDF_D:
                    depth[i, j] = F32(float(t))
        # sample voxels near the plane: random pixels, random depth offsets within the band
        voxels, pairs = [], []
        naive = Worst()
        tries = 0
        while (len(voxels) < 120 or len(pairs) < 40) and tries < 200000:
            tries += 1
            i, j = rng.integers(0, TSDF_H), rng.integers(0, TSDF_W)
            if depth[i, j] <= 0:
                continue
            x = (j + rng.uniform(0, 1) - cam["cx"]) / TSDF_F
            y = (i + rng.uniform(0, 1) - cam["cy"]) / TSDF_F
            t = float(depth[i, j]) + rng.uniform(-1.2, 1.2) * TSDF_TRUNC
            pt = np.asarray(c) + t * np.array([x, y, 1.0])
            g = [int(np.floor(pt[k] / TSDF_VOXEL - 0.5 + rng.uniform(0, 1))) for k in range(3)]
            ref = tsdf_rule(g, cam, depth)
            if ref is None or isinstance(ref, str) or abs(ref) >= 1:
                continue
            if len(voxels) < 120:
                voxels.append({"g": g, "tsdf": sref(ref)})
                got = tsdf_rule(g, cam, depth, exact=False)
                naive.add("tsdf", mp.mpf(1) if got is None else abs(mp.mpf(float(got)) - ref))
            # a zero crossing along z: the next voxel's sign differs
            if len(pairs) < 40:
                g2 = [g[0], g[1], g[2] + (1 if ref > 0 else -1)]
                ref2 = tsdf_rule(g2, cam, depth)
                if ref2 is None or isinstance(ref2, str) or (ref2 > 0) == (ref > 0) or abs(ref2) >= 1:
                    continue
                lo, hi = (g, g2) if g[2] < g2[2] else (g2, g)
                vlo, vhi = (ref, ref2) if g[2] < g2[2] else (ref2, ref)
                # linear interpolation of the exact rule's values (marching cubes' vertex)
                z = (mp.mpf(lo[2]) + mp.mpf(0.5) + vlo / (vlo - vhi)) * TSDF_VOXEL
                pt = [(mp.mpf(lo[0]) + mp.mpf(0.5)) * TSDF_VOXEL, (mp.mpf(lo[1]) + mp.mpf(0.5)) * TSDF_VOXEL, z]
                rule_err = abs(dot(n, sub(pt, p0))) / TSDF_VOXEL
                pairs.append({"lo": lo, "rule_crossing_error": sref(rule_err)})
                a = tsdf_rule(lo, cam, depth, exact=False)
                b = tsdf_rule(hi, cam, depth, exact=False)
                if a is None or b is None or (a > 0) == (b > 0):
                    naive.add("crossing", mp.nan)
                else:
                    zf = (mp.mpf(lo[2]) + mp.mpf(0.5) + mp.mpf(float(a)) / (mp.mpf(float(a)) - mp.mpf(float(b)))) * TSDF_VOXEL
                    ptf = [pt[0], pt[1], zf]
                    naive.add("crossing", abs(dot(n, sub(ptf, p0))) / TSDF_VOXEL)
        assert len(voxels) == 120 and len(pairs) == 40, (case, len(voxels), len(pairs))
        inst = [
            {
                "camera": {
                    "position": vec_s(c),
                    "f": s64(TSDF_F),
                    "cx": s64(cam["cx"]),
                    "cy": s64(cam["cy"]),
                    "width": TSDF_W,
                    "height": TSDF_H,
                },
                "voxel": s64(TSDF_VOXEL),
                "trunc": s64(TSDF_TRUNC),
                "depth": [s32(x) for x in depth.ravel()],
                "plane": {"normal": [sref(x) for x in n], "point": [sref(x) for x in p0]},
                "voxels": voxels,
                "crossings": pairs,
                "rule_crossing_error_worst": sref(max(mp.mpf(p["rule_crossing_error"]) for p in pairs)),
            }
        ]
        groups.append(group("tsdf", case, inst, naive))
    return groups


# ================================================================= collapse to zero area


def collapse_groups(rng):
    """A triangle collapsing over frames (v2 onto the edge v0 v1, v1 onto v0, all to a point) and
    inverting past it; the reference is the policy: every output finite, the frame flagged
    degenerate exactly at zero area. The naive column counts NaNs of the naive frame."""
    v0 = np.array([0.25, 0.5, -0.75])
    v1 = np.array([1.25, 0.0, -0.25])
    v2 = np.array([0.5, 1.0, 0.25])
    mid = (v0 + v1) / 2  # exact
    ts = [0.0, 0.5, 0.9, 0.999, 1 - 1e-4, 1.0, 1 + 1e-4, 1.5]
    seqs = []
    for name, target_index, target in [
        ("v2 onto the midpoint of v0 v1", 2, mid),
        ("v1 onto v0", 1, v0),
    ]:
        frames = []
        for t in ts:
            tri = [v0.copy(), v1.copy(), v2.copy()]
            start = tri[target_index]
            tri[target_index] = (start + t * (target - start)).astype(F32).astype(np.float64)
            if t == 1.0:
                tri[target_index] = target.copy()
            frames.append(tri)
        seqs.append((name, frames))
    seqs.append(("all three onto one point", [[((1 - t) * p + t * mid).astype(F32).astype(np.float64) if t != 1.0 else mid.copy() for p in (v0, v1, v2)] for t in ts]))
    naive = Worst()
    inst = []
    g = gaussians(rng, [-2.0, -4.0, -20.0], False, n=3)
    for name, frames in seqs:
        flags = []
        for tri in frames:
            ref = ref_frame(tri, "gaussian_avatars")
            flags.append(bool(ref[3]))
            with np.errstate(all="ignore"):
                rot, k, origin = naive_frame(tri, "gaussian_avatars")
            bad = not (np.all(np.isfinite(rot)) and np.isfinite(k))
            naive.add("nan", mp.nan if bad else mp.mpf(0))
        inst.append(
            {
                "name": name,
                "canonical": [vec_s(p, s32) for p in frames[0]],
                "frames": [[vec_s(p, s32) for p in tri] for tri in frames],
                "t": [s64(t) for t in ts],
                "degenerate": flags,
                "gaussians": [
                    {"mean": vec_s(x["mean"], s32), "rot": vec_s(x["rot"], s32), "log_scale": vec_s(x["log_scale"], s32)}
                    for x in g
                ],
            }
        )
    return [group("collapse", "triangle collapsing to zero area and inverting", inst, naive)]


# ================================================================= main


def write(name, groups):
    OUT.mkdir(parents=True, exist_ok=True)
    doc = {
        "generator": "tests/reference/ref_stiff.py",
        "versions": {"mpmath": mpmath.__version__, "numpy": np.__version__},
        "digits": DPS,
        "seed": SEED,
        "groups": groups,
    }
    path = OUT / f"{name}.json"
    path.write_text(json.dumps(doc, separators=(",", ":")) + "\n")
    return path.stat().st_size


def main():
    check_pinned_versions(["numpy", "mpmath"])
    mp.dps = DPS
    rng = np.random.default_rng(SEED)
    total = 0
    for name, make in [
        ("frames", frames_groups),
        ("covariance", covariance_groups),
        ("w2", w2_groups),
        ("alpha", lambda r: circumradius_groups(r) + delaunay_groups(r)),
        ("tsdf", tsdf_groups),
        ("collapse", collapse_groups),
    ]:
        groups = make(rng)
        size = write(name, groups)
        total += size
        print(f"{name}: {len(groups)} groups, {size / 1024:.0f} KiB")
        for g in groups:
            worst = ", ".join(f"{q} {v['worst']} ({v['nan']} NaN)" for q, v in g["naive_f32"].items())
            if g["op"] == "tsdf":
                worst += f", exact rule's crossing {g['instances'][0]['rule_crossing_error_worst'][:8]}"
            print(f"  {g['op']:<22} {g['case']:<60} naive f32: {worst}")
    print(f"total {total / 1024:.0f} KiB in {OUT}")
    assert total < 1 << 20


if __name__ == "__main__":
    main()
