#!/usr/bin/env python3
"""Reference renders of the 3DGS splatting renderer with gsplat 1.5.3 (docs/conventions.md §5).

Projection and colours come from gsplat's own torch functions, which run on the CPU:
`gsplat.cuda._torch_impl._quat_scale_to_covar_preci`, `_fully_fused_projection` (EWA Jacobian
with the widened-frustum clamp, +0.3 dilation, near/far and det culling, per-axis 3.33-sigma radii)
and `_spherical_harmonics` (colour = max(SH + 0.5, 0), as `gsplat.rendering.rasterization`).
gsplat's rasterizer needs CUDA, so compositing is a direct numpy transcription of its CUDA kernel
`RasterizeToPixels3DGSFwd.cu` in float32: 16x16 tiles from `isect_tiles` (floor/ceil of the box in
tile units), each tile's Gaussians sorted by depth (stable: ties keep the index order), per pixel
front to back at (j + 0.5, i + 0.5): sigma = 0.5(a dx^2 + c dy^2) + b dx dy with d = mean - pixel;
alpha = min(0.999, opacity exp(-sigma)); skip if sigma < 0 or alpha < 1/255; stop when
next_T <= 1e-4; expected depth sum(w z) / max(alpha, 1e-10) (gsplat "ED"); median depth = z of the
Gaussian at which T first drops below 0.5 (docs/conventions.md §5; not a gsplat output).

Scenes (written to fixtures/data/render/, references to fixtures/data/reference/render/):
- `random_deg3.ply`: 1000 seeded Gaussians with degree-3 SH in front of three cameras
  (`random_cameras.json`, 64x48, one with an off-centre principal point, one at 90 degrees fov);
  also an antialiased render of the first camera (`*_aa_*`).
- the LAM avatar subset `splat/lam_offset_subset.ply` (500 Gaussians, degree 0, log-scales down to
  -29) seen by three cameras (`lam_cameras.json`, 64x64).

Run with the pinned environment of requirements-gsplat.txt:
    venv-gs/bin/python tests/reference/ref_render_gsplat.py
"""

import json
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
DATA = ROOT / "fixtures" / "data"
SCENES = DATA / "render"
OUT = DATA / "reference" / "render"
REQUIREMENTS = HERE / "requirements-gsplat.txt"
TILE = 16


def check_pinned_versions():
    from importlib.metadata import version

    bad = []
    for line in REQUIREMENTS.read_text().splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        name, want = line.split("==")
        have = version(name)
        if have.split("+")[0] != want:
            bad.append(f"{name}: want {want}, have {have}")
    if bad:
        sys.exit("pinned versions differ:\n  " + "\n  ".join(bad))


# ---------------------------------------------------------------- PLY and cameras


def write_ply(path, means, sh_dc, sh_rest, opacity_logits, log_scales, quats_wxyz):
    """INRIA 3DGS layout, binary little-endian; sh_rest is [N, 3, K-1] (channel-major)."""
    n = means.shape[0]
    k1 = sh_rest.shape[2]
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * k1)]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    cols = [means, np.zeros((n, 3)), sh_dc, sh_rest.reshape(n, 3 * k1), opacity_logits[:, None],
            log_scales, quats_wxyz]
    data = np.concatenate(cols, axis=1).astype("<f4")
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
    header += "".join(f"property float {p}\n" for p in names) + "end_header\n"
    path.write_bytes(header.encode() + data.tobytes())


def read_ply(path):
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    lines = raw[:end].decode().splitlines()
    n = int(next(l for l in lines if l.startswith("element vertex")).split()[-1])
    props = [l.split()[-1] for l in lines if l.startswith("property")]
    a = np.frombuffer(raw[end:], dtype="<f4").reshape(n, len(props)).astype(np.float32)
    col = {p: a[:, i] for i, p in enumerate(props)}
    rest = sorted((p for p in props if p.startswith("f_rest_")), key=lambda p: int(p[7:]))
    k1 = len(rest) // 3
    degree = {0: 0, 3: 1, 8: 2, 15: 3}[k1]
    sh = np.zeros((n, k1 + 1, 3), np.float32)
    sh[:, 0, :] = np.stack([col[f"f_dc_{c}"] for c in range(3)], 1)
    if k1:
        r = np.stack([col[p] for p in rest], 1).reshape(n, 3, k1)
        sh[:, 1:, :] = r.transpose(0, 2, 1)
    return dict(
        means=np.stack([col["x"], col["y"], col["z"]], 1),
        log_scales=np.stack([col[f"scale_{i}"] for i in range(3)], 1),
        quats=np.stack([col[f"rot_{i}"] for i in range(4)], 1),
        opacity_logits=col["opacity"],
        sh=sh,
        degree=degree,
    )


def look_at(name, eye, target, up, size, fov_y_deg, principal=None):
    """A camera in the 3DGS cameras.json layout (OpenCV axes), like trisplat's Camera::look_at."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    rot = np.stack([right, down, f], 1)  # columns: camera axes in world
    w, h = size
    focal = 0.5 * h / np.tan(0.5 * np.radians(fov_y_deg))
    cx, cy = principal if principal is not None else (0.5 * w, 0.5 * h)
    return dict(id=0, img_name=name, width=w, height=h, position=eye.tolist(),
                rotation=rot.tolist(), fx=focal, fy=focal, cx=cx, cy=cy)


# ---------------------------------------------------------------- gsplat projection


def project(scene, cam, antialiased=False):
    import torch
    from gsplat.cuda._torch_impl import (
        _fully_fused_projection,
        _quat_scale_to_covar_preci,
        _spherical_harmonics,
    )

    t = lambda a: torch.tensor(np.asarray(a), dtype=torch.float32)
    means = t(scene["means"])
    quats = t(scene["quats"])
    scales = torch.exp(t(scene["log_scales"]))
    opac = torch.sigmoid(t(scene["opacity_logits"]))
    covars, _ = _quat_scale_to_covar_preci(quats, scales, compute_covar=True, compute_preci=False)
    r = np.asarray(cam["rotation"], np.float64)  # camera-to-world
    pos = np.asarray(cam["position"], np.float64)
    view = np.eye(4)
    view[:3, :3] = r.T
    view[:3, 3] = -r.T @ pos
    k = np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1]])
    radii, means2d, depths, conics, comp = _fully_fused_projection(
        means, covars, t(view)[None], t(k)[None], cam["width"], cam["height"],
        eps2d=0.3, near_plane=0.01, far_plane=1e10, calc_compensations=antialiased)
    dirs = means - t(pos)[None]
    colors = _spherical_harmonics(scene["degree"], dirs, t(scene["sh"]))
    colors = torch.clamp_min(colors + 0.5, 0.0)
    if antialiased:
        opac = opac * comp[0]
    return dict(
        radii=radii[0].numpy().astype(np.int64),
        means2d=means2d[0].numpy().astype(np.float32),
        depths=depths[0].numpy().astype(np.float32),
        conics=conics[0].numpy().astype(np.float32),
        opac=opac.numpy().astype(np.float32),
        colors=colors.numpy().astype(np.float32),
    )


# ---------------------------------------------------------------- compositing (CUDA transcription)


def composite(p, width, height):
    f32 = np.float32
    tiles_x = (width + TILE - 1) // TILE
    tiles_y = (height + TILE - 1) // TILE
    radii = p["radii"]
    # gsplat marks culled Gaussians with radii == 0 (both axes).
    visible = np.nonzero((radii[:, 0] > 0) | (radii[:, 1] > 0))[0]
    m = p["means2d"]
    tile_means = m / f32(TILE)
    tile_r = radii.astype(f32) / f32(TILE)
    tmin = np.clip(np.floor(tile_means - tile_r), 0, [tiles_x, tiles_y]).astype(np.int64)
    tmax = np.clip(np.ceil(tile_means + tile_r), 0, [tiles_x, tiles_y]).astype(np.int64)
    order = np.lexsort((np.arange(len(p["depths"])), p["depths"]))  # depth, then index
    rgb = np.zeros((height, width, 3), f32)
    alpha = np.zeros((height, width), f32)
    depth = np.zeros((height, width), f32)
    median = np.zeros((height, width), f32)
    vis_set = np.zeros(len(p["depths"]), bool)
    vis_set[visible] = True
    for ty in range(tiles_y):
        for tx in range(tiles_x):
            x0, y0 = tx * TILE, ty * TILE
            x1, y1 = min(x0 + TILE, width), min(y0 + TILE, height)
            jj, ii = np.meshgrid(np.arange(x0, x1), np.arange(y0, y1))
            px = jj.astype(f32) + f32(0.5)
            py = ii.astype(f32) + f32(0.5)
            T = np.ones(px.shape, f32)
            done = np.zeros(px.shape, bool)
            c = np.zeros(px.shape + (3,), f32)
            d = np.zeros(px.shape, f32)
            med = np.zeros(px.shape, f32)
            for g in order:
                if not vis_set[g]:
                    continue
                if not (tmin[g, 0] <= tx < tmax[g, 0] and tmin[g, 1] <= ty < tmax[g, 1]):
                    continue
                a, b, cc = p["conics"][g]
                dx = m[g, 0] - px
                dy = m[g, 1] - py
                sigma = f32(0.5) * (a * dx * dx + cc * dy * dy) + b * dx * dy
                al = np.minimum(f32(0.999), p["opac"][g] * np.exp(-sigma).astype(f32))
                use = (~done) & ~((sigma < 0) | (al < f32(1.0 / 255.0)))
                next_T = T * (f32(1) - al)
                stop = use & (next_T <= f32(1e-4))
                done |= stop
                use &= ~stop
                w = np.where(use, al * T, f32(0))
                c += w[..., None] * p["colors"][g][None, None, :]
                d += w * p["depths"][g]
                crossed = use & (T >= f32(0.5)) & (next_T < f32(0.5))
                med = np.where(crossed, p["depths"][g], med)
                T = np.where(use, next_T, T)
                if done.all():
                    break
            rgb[y0:y1, x0:x1] = c  # black background
            acc = f32(1) - T
            alpha[y0:y1, x0:x1] = acc
            depth[y0:y1, x0:x1] = np.where(acc > 0, d / np.maximum(acc, f32(1e-10)), f32(0))
            median[y0:y1, x0:x1] = med
    return rgb, alpha, depth, median


def render_all(scene, cameras, prefix, antialiased_first=False):
    for cam in cameras:
        jobs = [(cam["img_name"], False)]
        if antialiased_first and cam is cameras[0]:
            jobs.append((cam["img_name"] + "_aa", True))
        for name, aa in jobs:
            p = project(scene, cam, antialiased=aa)
            rgb, alpha, depth, median = composite(p, cam["width"], cam["height"])
            for key, arr in [("rgb", rgb), ("alpha", alpha), ("depth", depth),
                             ("median_depth", median)]:
                np.save(OUT / f"{prefix}_{name}_{key}.npy", arr.astype("<f4"))
            print(f"{prefix}_{name}: alpha max {alpha.max():.3f}, covered "
                  f"{(alpha > 0.5).mean():.2f}")


def random_scene():
    rng = np.random.default_rng(20240607)
    n = 1000
    means = rng.uniform([-1.0, -0.8, -0.6], [1.0, 0.8, 0.6], (n, 3))
    log_scales = rng.uniform(-4.0, -1.8, (n, 3))
    log_scales[: n // 10, 2] = rng.uniform(-9.0, -6.0, n // 10)  # flat ones
    quats = rng.normal(size=(n, 4))
    opacity_logits = rng.uniform(-3.0, 4.0, n)
    sh_dc = rng.normal(0.0, 0.8, (n, 3))
    sh_rest = rng.normal(0.0, 0.15, (n, 3, 15))
    path = SCENES / "random_deg3.ply"
    write_ply(path, means, sh_dc, sh_rest, opacity_logits, log_scales, quats)
    cameras = [
        look_at("front", [0.3, -0.2, -3.0], [0, 0, 0], [0, 1, 0], (64, 48), 45.0),
        look_at("side", [2.6, 0.4, -1.2], [0.1, 0, 0], [0, 1, 0], (64, 48), 50.0,
                principal=(35.7, 21.2)),
        look_at("wide", [-0.4, 1.3, -1.1], [0, 0, 0], [0, 1, 0], (64, 48), 90.0),
    ]
    for i, c in enumerate(cameras):
        c["id"] = i
    (SCENES / "random_cameras.json").write_text(json.dumps(cameras, indent=1) + "\n")
    return read_ply(path), cameras


def lam_scene():
    scene = read_ply(DATA / "splat" / "lam_offset_subset.ply")
    center = [0.0, -0.004, 0.019]
    cameras = [
        look_at("front", [0.0, 0.0, 0.24], center, [0, 1, 0], (64, 64), 40.0),
        look_at("left", [0.2, 0.03, 0.1], center, [0, 1, 0], (64, 64), 40.0),
        look_at("top", [-0.07, 0.2, 0.14], center, [0, 1, 0], (64, 64), 40.0),
    ]
    for i, c in enumerate(cameras):
        c["id"] = i
    (SCENES / "lam_cameras.json").write_text(json.dumps(cameras, indent=1) + "\n")
    return scene, cameras


def main():
    check_pinned_versions()
    SCENES.mkdir(parents=True, exist_ok=True)
    OUT.mkdir(parents=True, exist_ok=True)
    scene, cams = random_scene()
    render_all(scene, cams, "random", antialiased_first=True)
    scene, cams = lam_scene()
    render_all(scene, cams, "lam")


if __name__ == "__main__":
    main()
