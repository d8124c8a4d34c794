"""Torch reference of relit shading and its backward pass (docs/conventions.md §5
"Relighting", "Relit gradients"): split sum written again in torch (float64) from the
definitions, and differentiated by autograd, independently of the Rust code and of
ref_relight.py's numpy.

Pinned (tests/reference/requirements-relight.txt): torch==2.15.0 (CPU; no CUDA needed),
numpy==2.4.6, opencv-python-headless==4.14.0.94.
    python -m venv /tmp/venv-brdf
    /tmp/venv-brdf/bin/pip install -r tests/reference/requirements-relight.txt
    /tmp/venv-brdf/bin/python tests/reference/ref_relight_torch.py

Input: fixtures/data/relight/esplanade_64x32.hdr (CC0, see its README; written by
ref_relight.py), read by OpenCV, scaled by INTENSITY and turned by ROTATION_DEG about +Y.

Per record, one Gaussian: raw quaternion q, log-scales, mean mu, seen from one EYE. The normal is
column k of R(q/|q|), k = argmin of the log-scales (first on ties), turned to face the eye; the
view v = (eye - mu)/|eye - mu|; then the split sum: E/pi from 9 SH coefficients of the map
(downsampled to at most 128 wide), the GGX-prefiltered chain (5 levels, exact weighted sums),
the 32x32 BRDF table (1024 Hammersley samples), bilinear lookups (u wraps, v clamps; floor
indices constant), colour = (1 - ks) albedo E/pi + ks L_spec, ks = F0 A + B.

Loss = sum_i g_i . colour_i with seeded weights g; autograd gives d loss / d (albedo, roughness,
F0, q, mu). Written to fixtures/data/relight/split_sum_torch.json.

The same loss's gradient with respect to the map's texels (as read, before INTENSITY; through the
downsampling, the SH projection, the prefiltered chain and the bilinear lookups, all linear in the
texels): fixtures/data/relight/split_sum_env_torch.json, 9 significant digits, row-major [H, W, 3].
"""

import json
import math
import pathlib

import cv2
import numpy as np
import torch

torch.set_default_dtype(torch.float64)

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
DATA = ROOT / "fixtures" / "data" / "relight"
ROTATION_DEG = -40.0
INTENSITY = 0.8
LEVELS = 5
LEVEL_WIDTHS = [512, 64, 32, 32, 32]
SOURCE_WIDTHS = [512, 128, 64, 32, 32]
IRRADIANCE_WIDTH = 128
TABLE_SIZE = 32
TABLE_SAMPLES = 1024
EYE = [0.3, 0.2, 2.5]
RECORDS = 64


def solid_angles(h, w):
    t = math.pi * torch.arange(h + 1) / h
    return 2 * math.pi / w * (torch.cos(t[:-1]) - torch.cos(t[1:]))


def downsample(img, nw):
    """Each new texel: the solid-angle weighted mean of the texels whose centres it contains."""
    h, w, _ = img.shape
    nw = min(nw, w)
    if nw == w:
        return img.clone()
    nh = nw // 2
    om = solid_angles(h, w)
    tj = ((2 * torch.arange(h) + 1) * nh) // (2 * h)
    ti = ((2 * torch.arange(w) + 1) * nw) // (2 * w)
    idx = (tj[:, None] * nw + ti[None, :]).reshape(-1)
    s = torch.zeros(nh * nw, 3).index_add_(0, idx, (img * om[:, None, None]).reshape(-1, 3))
    wt = torch.zeros(nh * nw).index_add_(0, idx, om[:, None].expand(h, w).reshape(-1))
    return (s / wt[:, None]).reshape(nh, nw, 3)


def directions(h, w):
    theta = math.pi * (torch.arange(h) + 0.5) / h
    phi = 2 * math.pi * ((torch.arange(w) + 0.5) / w - 0.5)
    st, ct = torch.sin(theta)[:, None], torch.cos(theta)[:, None]
    return torch.stack(
        [st * torch.sin(phi), ct.expand(h, w), -st * torch.cos(phi)], dim=-1
    )


def sh9(d):
    """A real orthonormal SH basis of bands 0..2 (any sign convention: projected and evaluated
    with the same one)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    c1 = math.sqrt(3 / (4 * math.pi))
    c2 = 0.5 * math.sqrt(15 / math.pi)
    return torch.stack(
        [
            torch.full_like(x, 0.5 / math.sqrt(math.pi)),
            c1 * x,
            c1 * y,
            c1 * z,
            c2 * x * y,
            c2 * y * z,
            c2 * x * z,
            0.25 * math.sqrt(5 / math.pi) * (3 * y * y - 1),
            0.25 * math.sqrt(15 / math.pi) * (x * x - z * z),
        ],
        dim=-1,
    )


def irradiance_coeffs(img):
    h, w, _ = img.shape
    y = sh9(directions(h, w)) * solid_angles(h, w)[:, None, None]
    coeffs = torch.einsum("hwk,hwc->kc", y, img)
    band = torch.tensor([1.0] + [2.0 / 3.0] * 3 + [0.25] * 5)
    return coeffs * band[:, None]


def prefilter(src, width, r):
    a2 = r**4
    sh_, sw, _ = src.shape
    om = solid_angles(sh_, sw)[:, None].expand(sh_, sw).reshape(-1)
    l = directions(sh_, sw).reshape(-1, 3)
    rd = directions(width // 2, width).reshape(-1, 3)
    c = rd @ l.T
    x2 = 0.5 * (1 + c)
    d = a2 / (math.pi * ((a2 - 1) * x2 + 1) ** 2)
    wgt = torch.where(c > 0, d * c, torch.zeros_like(c)) * om[None, :]
    return ((wgt @ src.reshape(-1, 3)) / wgt.sum(1, keepdim=True)).reshape(width // 2, width, 3)


def brdf_table():
    k = torch.arange(TABLE_SAMPLES)
    xi1 = k / TABLE_SAMPLES
    xi2 = torch.tensor(
        [int(f"{int(i):032b}"[::-1], 2) / 2.0**32 for i in k.tolist()]
    )
    phi = 2 * math.pi * xi1
    table = torch.zeros(TABLE_SIZE, TABLE_SIZE, 2)
    for j in range(TABLE_SIZE):
        r = (j + 0.5) / TABLE_SIZE
        a2 = r**4
        kk = r * r / 2
        ct = torch.sqrt((1 - xi2) / (1 + (a2 - 1) * xi2))
        st = torch.sqrt(torch.clamp(1 - ct * ct, min=0))
        hx, hz = st * torch.cos(phi), ct
        nv = (torch.arange(TABLE_SIZE) + 0.5) / TABLE_SIZE
        vx = torch.sqrt(1 - nv * nv)
        vh = vx[:, None] * hx[None, :] + nv[:, None] * hz[None, :]
        nl = 2 * vh * hz[None, :] - nv[:, None]
        ok = nl > 0
        g1 = lambda x: x / (x * (1 - kk) + kk)
        gvis = g1(nv)[:, None] * g1(torch.where(ok, nl, torch.ones_like(nl))) * vh.clamp(min=0)
        gvis = gvis / (hz[None, :] * nv[:, None])
        fc = (1 - vh.clamp(min=0)) ** 5
        zero = torch.zeros_like(gvis)
        table[j, :, 0] = torch.where(ok, (1 - fc) * gvis, zero).sum(1) / TABLE_SAMPLES
        table[j, :, 1] = torch.where(ok, fc * gvis, zero).sum(1) / TABLE_SAMPLES
    return table


def grid_coord(x, size):
    """Clamped bilinear coordinate between centres: (i0 as long, weight, differentiable)."""
    t = torch.clamp(torch.clamp(x, 0.0, 1.0) * size - 0.5, 0.0, size - 1)
    i0 = torch.clamp(torch.floor(t.detach()), max=size - 2).long()
    return i0, t - i0


def table_lookup(table, nv, r):
    i0, fx = grid_coord(nv, TABLE_SIZE)
    j0, fy = grid_coord(r, TABLE_SIZE)
    fx, fy = fx[:, None], fy[:, None]
    top = table[j0, i0] * (1 - fx) + table[j0, i0 + 1] * fx
    bot = table[j0 + 1, i0] * (1 - fx) + table[j0 + 1, i0 + 1] * fx
    out = top * (1 - fy) + bot * fy
    return out[:, 0], out[:, 1]


def bilinear(img, d):
    h, w, _ = img.shape
    d = d / torch.linalg.norm(d, dim=-1, keepdim=True)
    u = torch.remainder(torch.atan2(d[:, 0], -d[:, 2]) / (2 * math.pi) + 0.5, 1.0)
    v = torch.acos(torch.clamp(d[:, 1], -1.0, 1.0)) / math.pi
    x = u * w - 0.5
    y = torch.clamp(v * h - 0.5, 0.0, h - 1)
    x0, y0 = torch.floor(x.detach()), torch.floor(y.detach())
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    i0 = torch.remainder(x0.long(), w)
    i1 = torch.remainder(i0 + 1, w)
    j0 = y0.long()
    j1 = torch.clamp(j0 + 1, max=h - 1)
    top = img[j0, i0] * (1 - fx) + img[j0, i1] * fx
    bot = img[j1, i0] * (1 - fx) + img[j1, i1] * fx
    return top * (1 - fy) + bot * fy


def quat_to_matrix(q):
    w, x, y, z = (q / torch.linalg.norm(q, dim=-1, keepdim=True)).unbind(-1)
    return torch.stack(
        [
            torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def main():
    img = cv2.imread(str(DATA / "esplanade_64x32.hdr"), cv2.IMREAD_UNCHANGED)
    assert img is not None and img.dtype == np.float32
    texels = torch.from_numpy(img[:, :, ::-1].astype(np.float64).copy()).requires_grad_()
    env = texels * INTENSITY
    coeffs = irradiance_coeffs(downsample(env, IRRADIANCE_WIDTH))
    levels = [downsample(env, LEVEL_WIDTHS[0])]
    for k in range(1, LEVELS):
        src = downsample(env, SOURCE_WIDTHS[k])
        levels.append(prefilter(src, min(LEVEL_WIDTHS[k], src.shape[1]), k / (LEVELS - 1)))
    table = brdf_table()
    t = math.radians(-ROTATION_DEG)
    to_map = torch.tensor(
        [[math.cos(t), 0, math.sin(t)], [0, 1, 0], [-math.sin(t), 0, math.cos(t)]]
    )

    gen = np.random.default_rng(3333)
    f32 = lambda a: torch.from_numpy(np.asarray(a, np.float32).astype(np.float64))
    q = f32(gen.normal(size=(RECORDS, 4))).requires_grad_()
    log_scales = f32(np.log(gen.uniform(0.01, 0.1, size=(RECORDS, 3))))
    mu = f32(gen.uniform(-0.5, 0.5, size=(RECORDS, 3))).requires_grad_()
    albedo = f32(gen.uniform(0, 1, size=(RECORDS, 3))).requires_grad_()
    rough = f32(gen.uniform(0.02, 0.98, size=RECORDS)).requires_grad_()
    f0 = f32(gen.uniform(0, 1, size=RECORDS)).requires_grad_()
    g = f32(gen.uniform(-1, 1, size=(RECORDS, 3)))
    eye = torch.tensor(EYE)

    rot = quat_to_matrix(q)
    k = torch.argmin(log_scales, dim=1)
    axis = rot[torch.arange(RECORDS), :, k]
    to_eye = eye[None, :] - mu
    v = to_eye / torch.linalg.norm(to_eye, dim=-1, keepdim=True)
    sign = torch.where((axis * v).sum(-1) < 0, -1.0, 1.0).detach()
    n = axis * sign[:, None]
    nv = torch.clamp((n * v).sum(-1), 0.0, 1.0)
    refl = 2 * nv[:, None] * n - v
    a, b = table_lookup(table, nv, rough)
    ks = f0 * a + b
    e = torch.clamp(sh9(n @ to_map.T) @ coeffs, min=0.0)
    tr = torch.clamp(rough, 0.0, 1.0) * (LEVELS - 1)
    k0 = torch.clamp(torch.floor(tr.detach()), max=LEVELS - 2).long()
    fr = (tr - k0)[:, None]
    rmap = refl @ to_map.T
    lspec = torch.zeros(RECORDS, 3)
    for lev in range(LEVELS - 1):
        sel = (k0 == lev)[:, None]
        lo, hi = bilinear(levels[lev], rmap), bilinear(levels[lev + 1], rmap)
        lspec = lspec + torch.where(sel, lo * (1 - fr) + hi * fr, torch.zeros_like(lo))
    color = (1 - ks)[:, None] * albedo * e + ks[:, None] * lspec
    loss = (g * color).sum()
    loss.backward()

    records = []
    for i in range(RECORDS):
        records.append(
            {
                "rotation": q[i].tolist(),
                "log_scales": log_scales[i].tolist(),
                "mean": mu[i].tolist(),
                "albedo": albedo[i].tolist(),
                "roughness": float(rough[i].detach()),
                "f0": float(f0[i].detach()),
                "g": g[i].tolist(),
                "color": color[i].tolist(),
                "d_albedo": albedo.grad[i].tolist(),
                "d_roughness": float(rough.grad[i]),
                "d_f0": float(f0.grad[i]),
                "d_rotation": q.grad[i].tolist(),
                "d_mean": mu.grad[i].tolist(),
            }
        )
    doc = {
        "generator": "tests/reference/ref_relight_torch.py",
        "torch": torch.__version__,
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "map": "esplanade_64x32.hdr",
        "rotation_deg": ROTATION_DEG,
        "intensity": INTENSITY,
        "eye": EYE,
        "records": records,
    }
    out = DATA / "split_sum_torch.json"
    out.write_text(json.dumps(doc))
    print(f"wrote {out} ({RECORDS} records, loss {float(loss):.6f})")
    d_env = texels.grad.reshape(-1)
    env_doc = {
        "generator": "tests/reference/ref_relight_torch.py",
        "torch": torch.__version__,
        "numpy": np.__version__,
        "records": "split_sum_torch.json",
        "map": "esplanade_64x32.hdr",
        "shape": list(texels.shape),
        "loss": float(loss),
        "d_texels": [float(f"{x:.9g}") for x in d_env.tolist()],
    }
    out = DATA / "split_sum_env_torch.json"
    out.write_text(json.dumps(env_doc))
    print(f"wrote {out} (max |d texel| {float(d_env.abs().max()):.6f})")


if __name__ == "__main__":
    main()
