"""Reference for relighting (docs/conventions.md §5 "Relighting"): the Radiance reader against
OpenCV, and split-sum shading written again from its definition in numpy (float64), not from
the Rust code.

Pinned (tests/reference/requirements-relight.txt): numpy==2.4.6,
opencv-python-headless==4.14.0.94.
    python -m venv /tmp/venv-relight
    /tmp/venv-relight/bin/pip install -r tests/reference/requirements-relight.txt
    /tmp/venv-relight/bin/python tests/reference/ref_relight.py ../shared/data/envmaps/royal_esplanade_1k.hdr

1. The fixture map: Poly Haven's "Royal Esplanade" (CC0) read by cv2.imread(IMREAD_UNCHANGED)
   (BGR float32 -> RGB), downsampled to 64x32 (each new texel the solid-angle weighted mean of
   the source texels whose centres it contains), written here as a run-length encoded Radiance
   file fixtures/data/relight/esplanade_64x32.hdr (our own RGBE encoder: frexp, mantissa * 256 /
   2^e truncated), then read back by OpenCV: those texels are what both sides shade with.
2. Shading of 96 seeded records (normal, view, albedo, roughness, F0) under that map turned by
   ROTATION_DEG about +Y and scaled by INTENSITY, as conventions §5 defines it:
   - irradiance: SH projection (of the map downsampled to at most 128 wide) to bands 0..2 (a real orthonormal basis written here) with each
     texel's exact solid angle, E(n)/pi = sum_l (A_l / pi) L_lm Y_lm(n), A = (pi, 2pi/3, pi/4);
   - specular chain: level 0 the map itself (at most 512 wide), level k = 1..4 (roughness
     k/4) a map LEVEL_WIDTHS[k] wide whose texel towards R is the D(R.h) max(R.l, 0) dOmega
     weighted mean of the map downsampled to SOURCE_WIDTHS[k] (widths capped at the map's);
     lookup bilinear between texel centres (u wraps, v clamps), linear between levels;
   - BRDF table: 32x32, 1024 Hammersley samples, Schlick-Smith k = alpha/2, bilinear lookup
     between centres, clamped;
   - colour = (1 - ks) albedo E/pi + ks L_spec, ks = F0 A + B.
   Written to fixtures/data/relight/split_sum.json with the OpenCV texels of the fixture.
"""

import json
import math
import pathlib
import sys

import cv2
import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
OUT = ROOT / "fixtures" / "data" / "relight"
WIDTH = 64
ROTATION_DEG = 30.0
INTENSITY = 1.5
LEVELS = 5
LEVEL_WIDTHS = [512, 64, 32, 32, 32]
SOURCE_WIDTHS = [512, 128, 64, 32, 32]
TABLE_SIZE = 32
IRRADIANCE_WIDTH = 128
TABLE_SAMPLES = 1024


def read_hdr(path):
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None and img.dtype == np.float32, path
    return img[:, :, ::-1].astype(np.float64)


def row_solid_angles(h, w):
    t = np.pi * np.arange(h + 1) / h
    return 2 * np.pi / w * (np.cos(t[:-1]) - np.cos(t[1:]))


def downsample(img, nw):
    h, w, _ = img.shape
    nw = min(nw, w)
    if nw == w:
        return img.copy()
    nh = nw // 2
    omega = row_solid_angles(h, w)
    tj = ((2 * np.arange(h) + 1) * nh) // (2 * h)
    ti = ((2 * np.arange(w) + 1) * nw) // (2 * w)
    s = np.zeros((nh, nw, 3))
    wt = np.zeros((nh, nw))
    for j in range(h):
        np.add.at(s[tj[j]], ti, img[j] * omega[j])
        np.add.at(wt[tj[j]], ti, omega[j])
    return s / wt[:, :, None]


def write_rle_hdr(path, img):
    h, w, _ = img.shape
    m = img.max(axis=2)
    mant, exp = np.frexp(m)
    scale = np.where(m > 1e-32, mant * 256.0 / np.where(m > 0, m, 1), 0.0)
    rgbe = np.zeros((h, w, 4), np.uint8)
    rgbe[:, :, :3] = np.floor(img * scale[:, :, None]).clip(0, 255).astype(np.uint8)
    rgbe[:, :, 3] = np.where(m > 1e-32, exp + 128, 0).astype(np.uint8)
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
    for j in range(h):
        out += bytes([2, 2, w >> 8, w & 255])
        for c in range(4):
            row = rgbe[j, :, c]
            x = 0
            while x < w:
                run = 1
                while x + run < w and run < 127 and row[x + run] == row[x]:
                    run += 1
                if run >= 3:
                    out += bytes([128 + run, int(row[x])])
                    x += run
                else:
                    n = 1
                    while x + n < w and n < 128:
                        if x + n + 2 < w and row[x + n] == row[x + n + 1] == row[x + n + 2]:
                            break
                        n += 1
                    out += bytes([n]) + bytes(int(v) for v in row[x : x + n])
                    x += n
    path.write_bytes(bytes(out))


def directions(h, w):
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (u - 0.5)
    theta = np.pi * v
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    return np.stack(
        [st * np.sin(phi)[None, :], np.broadcast_to(ct, (h, w)), -st * np.cos(phi)[None, :]],
        axis=-1,
    )


def sh9(d):
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack(
        [
            0.5 * np.sqrt(1 / np.pi) * np.ones_like(x),
            np.sqrt(3 / (4 * np.pi)) * y,
            np.sqrt(3 / (4 * np.pi)) * z,
            np.sqrt(3 / (4 * np.pi)) * x,
            0.5 * np.sqrt(15 / np.pi) * x * y,
            0.5 * np.sqrt(15 / np.pi) * y * z,
            0.25 * np.sqrt(5 / np.pi) * (3 * z * z - 1),
            0.5 * np.sqrt(15 / np.pi) * x * z,
            0.25 * np.sqrt(15 / np.pi) * (x * x - y * y),
        ],
        axis=-1,
    )


def irradiance_coeffs(img):
    h, w, _ = img.shape
    y = sh9(directions(h, w))
    omega = row_solid_angles(h, w)[:, None, None]
    coeffs = np.einsum("hwk,hwc->kc", y * omega, img)
    band = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5) / np.pi
    return coeffs * band[:, None]


def prefilter(src, width, r):
    a2 = r**4
    sh, sw, _ = src.shape
    l = directions(sh, sw).reshape(-1, 3)
    lw = (src * row_solid_angles(sh, sw)[:, None, None]).reshape(-1, 3)
    om = np.repeat(row_solid_angles(sh, sw), sw)
    rd = directions(width // 2, width).reshape(-1, 3)
    c = rd @ l.T
    x2 = 0.5 * (1 + c)
    d = a2 / (np.pi * ((a2 - 1) * x2 + 1) ** 2)
    wgt = np.where(c > 0, d * c, 0.0)
    num = wgt @ lw
    den = wgt @ om
    return (num / den[:, None]).reshape(width // 2, width, 3)


def bilinear(img, d):
    h, w, _ = img.shape
    d = d / np.linalg.norm(d)
    u = (math.atan2(d[0], -d[2]) / (2 * np.pi) + 0.5) % 1.0
    v = math.acos(max(-1.0, min(1.0, d[1]))) / np.pi
    x = u * w - 0.5
    y = min(max(v * h - 0.5, 0.0), h - 1)
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    i0 = x0 % w
    i1 = (i0 + 1) % w
    j0 = int(y0)
    j1 = min(j0 + 1, h - 1)
    top = img[j0, i0] * (1 - fx) + img[j0, i1] * fx
    bot = img[j1, i0] * (1 - fx) + img[j1, i1] * fx
    return top * (1 - fy) + bot * fy


def radical_inverse(k):
    return int(f"{k:032b}"[::-1], 2) / 2.0**32


def brdf_table():
    k = np.arange(TABLE_SAMPLES)
    xi1 = k / TABLE_SAMPLES
    xi2 = np.array([radical_inverse(int(i)) for i in k])
    table = np.zeros((TABLE_SIZE, TABLE_SIZE, 2))
    for j in range(TABLE_SIZE):
        r = (j + 0.5) / TABLE_SIZE
        a = r * r
        a2 = a * a
        kk = a / 2
        g1 = lambda x: x / (x * (1 - kk) + kk)
        phi = 2 * np.pi * xi1
        ct = np.sqrt((1 - xi2) / (1 + (a2 - 1) * xi2))
        st = np.sqrt(np.maximum(1 - ct * ct, 0))
        hv = np.stack([st * np.cos(phi), st * np.sin(phi), ct], axis=-1)
        for i in range(TABLE_SIZE):
            nv = (i + 0.5) / TABLE_SIZE
            v = np.array([math.sqrt(max(1 - nv * nv, 0)), 0.0, nv])
            vh = hv @ v
            nl = 2 * vh * hv[:, 2] - v[2]
            ok = nl > 0
            vh = np.maximum(vh, 0)
            g = g1(nv) * g1(np.where(ok, nl, 1.0))
            gv = g * vh / (hv[:, 2] * nv)
            fc = (1 - vh) ** 5
            table[j, i, 0] = np.sum(np.where(ok, (1 - fc) * gv, 0)) / TABLE_SAMPLES
            table[j, i, 1] = np.sum(np.where(ok, fc * gv, 0)) / TABLE_SAMPLES
    return table


def table_lookup(table, nv, r):
    s = TABLE_SIZE

    def coord(x):
        t = min(max(min(max(x, 0.0), 1.0) * s - 0.5, 0.0), s - 1)
        i0 = min(int(t), s - 2)
        return i0, t - i0

    i0, fx = coord(nv)
    j0, fy = coord(r)
    top = table[j0, i0] * (1 - fx) + table[j0, i0 + 1] * fx
    bot = table[j0 + 1, i0] * (1 - fx) + table[j0 + 1, i0 + 1] * fx
    return top * (1 - fy) + bot * fy


def rot_y(deg):
    t = math.radians(deg)
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def main():
    source = pathlib.Path(sys.argv[1])
    OUT.mkdir(parents=True, exist_ok=True)
    small = downsample(read_hdr(source), WIDTH)
    hdr_path = OUT / f"esplanade_{WIDTH}x{WIDTH // 2}.hdr"
    write_rle_hdr(hdr_path, small)
    texels = read_hdr(hdr_path)
    env = texels * INTENSITY
    coeffs = irradiance_coeffs(downsample(env, IRRADIANCE_WIDTH))
    levels = [downsample(env, LEVEL_WIDTHS[0])]
    for k in range(1, LEVELS):
        src = downsample(env, SOURCE_WIDTHS[k])
        levels.append(prefilter(src, min(LEVEL_WIDTHS[k], src.shape[1]), k / (LEVELS - 1)))
    table = brdf_table()
    to_map = rot_y(-ROTATION_DEG)
    rng = np.random.default_rng(33)
    records = []
    for idx in range(96):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if n @ v < 0:
            v = -v
        n, v = n.astype(np.float32).astype(np.float64), v.astype(np.float32).astype(np.float64)
        albedo = rng.random(3).astype(np.float32)
        roughness = np.float32([0.0, 1.0, 0.25, 0.5][idx] if idx < 4 else rng.random())
        f0 = np.float32(rng.random() if idx % 3 else 0.04)
        nv = min(max(float(n @ v), 0.0), 1.0)
        r = 2 * nv * n - v
        a, b = table_lookup(table, nv, float(roughness))
        ks = float(f0) * a + b
        e = np.maximum(sh9(to_map @ n) @ coeffs, 0)
        t = float(roughness) * (LEVELS - 1)
        k0 = min(int(t), LEVELS - 2)
        f = t - k0
        spec_l = bilinear(levels[k0], to_map @ r)
        if f > 0:
            spec_l = spec_l * (1 - f) + bilinear(levels[k0 + 1], to_map @ r) * f
        spec = ks * spec_l
        color = (1 - ks) * albedo * e + spec
        records.append(
            {
                "normal": n.tolist(),
                "view": v.tolist(),
                "albedo": albedo.astype(float).tolist(),
                "roughness": float(roughness),
                "f0": float(f0),
                "ab": [a, b],
                "irradiance": e.tolist(),
                "color": color.tolist(),
                "specular": spec.tolist(),
            }
        )
    doc = {
        "generator": "tests/reference/ref_relight.py",
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "map": hdr_path.name,
        "width": int(texels.shape[1]),
        "height": int(texels.shape[0]),
        "texels_opencv": texels.reshape(-1, 3).astype(np.float32).astype(float).tolist(),
        "rotation_deg": ROTATION_DEG,
        "intensity": INTENSITY,
        "records": records,
    }
    (OUT / "split_sum.json").write_text(json.dumps(doc))
    print(f"wrote {hdr_path} and split_sum.json ({len(records)} records)")


if __name__ == "__main__":
    main()
