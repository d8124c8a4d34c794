#!/usr/bin/env python3
"""Reference gradients of the 3DGS renderer's backward pass (docs/conventions.md §5 "Gradients"),
by torch autograd on the CPU in float64.

Pinned versions (tests/reference/requirements-gsplat.txt, checked at start):
    torch==2.15.0, gsplat==1.5.3, numpy==2.4.6

The forward is gsplat 1.5.3's own pure-PyTorch projection and SH, differentiated by autograd:
`gsplat.cuda._torch_impl._quat_scale_to_covar_preci` (normalised quaternion, scales = exp(log
scales)), `_fully_fused_projection` (EWA Jacobian with the widened-frustum clamp, +0.3 dilation,
near/far and det culling, compensation when antialiased) and `_spherical_harmonics` (colour =
max(SH + 0.5, 0), dirs = mean - camera centre). gsplat's rasterizer needs CUDA (its torch
`_rasterize_to_pixels` calls a CUDA kernel), so compositing is written here in torch, dense over
(pixel, Gaussian) pairs, following its CUDA kernel: pixel centres (j + 0.5, i + 0.5), Gaussians
in depth order (ties by index), sigma = 0.5 (a dx^2 + c dy^2) + b dx dy with d = mean - pixel,
alpha = min(0.999, opacity exp(-sigma)) (no gradient where clamped), skip sigma < 0 or
alpha < 1/255, stop before the Gaussian that brings T to <= 1e-4 (which Gaussians contribute is
decided without gradient, as in the kernel), w = alpha T, rgb = sum w c + T background,
alpha = 1 - T, expected depth = sum w z / max(alpha, 1e-10) (0 where alpha = 0). Pixels outside a
Gaussian's 3.33-sigma box, which gsplat never evaluates, have alpha < 1/255, so no tile mask is
needed.

The loss is linear in the images with weights both sides compute from the row-major pixel index
i and channel c:  w_rgb = sin(0.1 i + 0.7 c + 0.3),  w_alpha = cos(0.13 i),
w_depth = 0.2 sin(0.05 i + 1.0).

Cases (fixtures/data/reference/render_grad/<case>.json, cameras in cameras.json there):
- `random`: 24 seeded Gaussians, SH degree 3, 40x32 camera with an off-centre principal point,
  background (0.2, 0.4, 0.6), gsplat rules;
- `random_aa`: the same scene, antialiased;
- `deg3_fixture`: the Gaussians of fixtures/data/render/random_deg3.ply (degree 3) whose centres
  project into the first 64x48 camera of random_cameras.json (at most 96, in file order), seen
  by that camera, black background.
Each file holds the parameters in float64 (the PLY case: its float32 values), the images and the
gradients with respect to means, log-scales, raw quaternions [w, x, y, z], opacity logits and SH
coefficients (file order: f_dc_0..2, then f_rest channel-major).

    python -m venv /work/venv-torch
    /work/venv-torch/bin/pip install -r tests/reference/requirements-gsplat.txt
    /work/venv-torch/bin/python tests/reference/ref_render_grad.py
"""

import json
import math
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
DATA = ROOT / "fixtures" / "data"
OUT = DATA / "reference" / "render_grad"
REQUIREMENTS = HERE / "requirements-gsplat.txt"


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


def read_ply(path):
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    lines = raw[:end].decode().splitlines()
    n = int(next(l for l in lines if l.startswith("element vertex")).split()[-1])
    props = [l.split()[-1] for l in lines if l.startswith("property")]
    a = np.frombuffer(raw[end:], dtype="<f4").reshape(n, len(props)).astype(np.float64)
    col = {p: a[:, i] for i, p in enumerate(props)}
    rest = sorted((p for p in props if p.startswith("f_rest_")), key=lambda p: int(p[7:]))
    k1 = len(rest) // 3
    sh_file = np.concatenate(
        [np.stack([col[f"f_dc_{c}"] for c in range(3)], 1)]
        + ([np.stack([col[p] for p in rest], 1)] if k1 else []),
        axis=1,
    )
    return dict(
        means=np.stack([col["x"], col["y"], col["z"]], 1),
        log_scales=np.stack([col[f"scale_{i}"] for i in range(3)], 1),
        quats=np.stack([col[f"rot_{i}"] for i in range(4)], 1),
        opacity_logits=col["opacity"],
        sh_file=sh_file,
        degree={0: 0, 3: 1, 8: 2, 15: 3}[k1],
    )


def look_at(name, eye, target, up, size, fov_y_deg, principal=None):
    """A camera in the 3DGS cameras.json layout (OpenCV axes), like trisplat's Camera::look_at."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    rot = np.stack([right, down, f], 1)
    w, h = size
    focal = 0.5 * h / np.tan(0.5 * np.radians(fov_y_deg))
    cx, cy = principal if principal is not None else (0.5 * w, 0.5 * h)
    return dict(id=0, img_name=name, width=w, height=h, position=eye.tolist(),
                rotation=rot.tolist(), fx=focal, fy=focal, cx=cx, cy=cy)


def file_to_torch_sh(sh_file, degree):
    """[N, 3K] file order -> gsplat's [N, K, 3]."""
    n = sh_file.shape[0]
    k = (degree + 1) ** 2
    out = np.zeros((n, k, 3))
    out[:, 0, :] = sh_file[:, :3]
    if k > 1:
        out[:, 1:, :] = sh_file[:, 3:].reshape(n, 3, k - 1).transpose(0, 2, 1)
    return out


def torch_to_file_sh(sh, degree):
    n = sh.shape[0]
    k = (degree + 1) ** 2
    dc = sh[:, 0, :]
    rest = sh[:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1))
    return np.concatenate([dc, rest], axis=1)


def loss_weights(pixels):
    i = np.arange(pixels, dtype=np.float64)
    w_rgb = np.sin(0.1 * i[:, None] + 0.7 * np.arange(3)[None, :] + 0.3)
    w_alpha = np.cos(0.13 * i)
    w_depth = 0.2 * np.sin(0.05 * i + 1.0)
    return w_rgb, w_alpha, w_depth


def render(params, cam, background, antialiased):
    """Images and gradients of the linear loss (module documentation), float64."""
    import torch
    from gsplat.cuda._torch_impl import (
        _fully_fused_projection,
        _quat_scale_to_covar_preci,
        _spherical_harmonics,
    )

    d = torch.float64
    t = lambda a: torch.tensor(np.asarray(a, np.float64), dtype=d)
    means = t(params["means"]).requires_grad_()
    log_scales = t(params["log_scales"]).requires_grad_()
    quats = t(params["quats"]).requires_grad_()
    logits = t(params["opacity_logits"]).requires_grad_()
    degree = params["degree"]
    sh = t(file_to_torch_sh(params["sh_file"], degree)).requires_grad_()

    covars, _ = _quat_scale_to_covar_preci(
        quats, torch.exp(log_scales), compute_covar=True, compute_preci=False)
    r = np.asarray(cam["rotation"], np.float64)
    pos = np.asarray(cam["position"], np.float64)
    view = np.eye(4)
    view[:3, :3] = r.T
    view[:3, 3] = -r.T @ pos
    k = np.array([[cam["fx"], 0, cam["cx"]], [0, cam["fy"], cam["cy"]], [0, 0, 1]])
    w, h = cam["width"], cam["height"]
    radii, means2d, depths, conics, comp = _fully_fused_projection(
        means, covars, t(view)[None], t(k)[None], w, h, eps2d=0.3, near_plane=0.01,
        far_plane=1e10, calc_compensations=antialiased)
    radii, means2d, depths, conics = radii[0], means2d[0], depths[0], conics[0]
    opac = torch.sigmoid(logits)
    if antialiased:
        opac = opac * comp[0]
    colors = _spherical_harmonics(degree, means - t(pos)[None], sh)
    colors = torch.clamp_min(colors + 0.5, 0.0)

    visible = ((radii[:, 0] > 0) | (radii[:, 1] > 0)).numpy()
    dnp = depths.detach().numpy()
    order = [g for g in np.lexsort((np.arange(len(dnp)), dnp)) if visible[g]]
    idx = torch.tensor(order, dtype=torch.long)
    m, con, op, col, z = means2d[idx], conics[idx], opac[idx], colors[idx], depths[idx]
    ii, jj = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    px = t(jj.reshape(-1) + 0.5)
    py = t(ii.reshape(-1) + 0.5)
    dx = m[None, :, 0] - px[:, None]
    dy = m[None, :, 1] - py[:, None]
    sigma = 0.5 * (con[None, :, 0] * dx * dx + con[None, :, 2] * dy * dy) \
        + con[None, :, 1] * dx * dy
    alpha = torch.clamp(op[None, :] * torch.exp(-sigma), max=0.999)
    with torch.no_grad():
        valid = (sigma >= 0) & (alpha >= 1.0 / 255.0)
        pixels, n = alpha.shape
        T = torch.ones(pixels, dtype=d)
        alive = torch.ones(pixels, dtype=torch.bool)
        use = torch.zeros((pixels, n), dtype=torch.bool)
        for g in range(n):
            v = valid[:, g] & alive
            nt = T * (1.0 - alpha[:, g])
            stop = v & (nt <= 1e-4)
            alive &= ~stop
            acc = v & ~stop
            use[:, g] = acc
            T = torch.where(acc, nt, T)
    a_used = torch.where(use, alpha, torch.zeros_like(alpha))
    one_minus = 1.0 - a_used
    cum = torch.cumprod(one_minus, dim=1)
    t_excl = torch.cat([torch.ones((pixels, 1), dtype=d), cum[:, :-1]], dim=1)
    wgt = a_used * t_excl
    t_final = cum[:, -1] if n else torch.ones(pixels, dtype=d)
    rgb = wgt @ col + t_final[:, None] * t(background)[None, :]
    acc_alpha = 1.0 - t_final
    dsum = wgt @ z
    depth = torch.where(acc_alpha > 0, dsum / torch.clamp(acc_alpha, min=1e-10),
                        torch.zeros_like(dsum))

    w_rgb, w_alpha, w_depth = loss_weights(pixels)
    loss = (rgb * t(w_rgb)).sum() + (acc_alpha * t(w_alpha)).sum() + (depth * t(w_depth)).sum()
    loss.backward()
    grads = dict(
        means=means.grad.numpy(),
        log_scales=log_scales.grad.numpy(),
        rotations=quats.grad.numpy(),
        opacity_logits=logits.grad.numpy(),
        sh=torch_to_file_sh(sh.grad.numpy(), degree),
    )
    images = dict(
        rgb=rgb.detach().numpy().reshape(-1),
        alpha=acc_alpha.detach().numpy(),
        depth=depth.detach().numpy(),
    )
    return images, grads, len(order)


def random_scene(n, degree, seed):
    rng = np.random.default_rng(seed)
    k = 3 * (degree + 1) ** 2
    f32 = lambda a: np.asarray(a, np.float32).astype(np.float64)  # exact in a PLY too
    sh = rng.uniform(-0.3, 0.3, (n, k))
    sh[:, :3] = rng.uniform(-1.0, 1.0, (n, 3))
    return dict(
        means=f32(rng.uniform([-0.6, -0.45, -0.5], [0.6, 0.45, 0.5], (n, 3))),
        log_scales=f32(rng.uniform(-2.6, -1.4, (n, 3))),
        quats=f32(rng.uniform(-1.0, 1.0, (n, 4))),
        opacity_logits=f32(rng.uniform(-1.0, 2.5, n)),
        sh_file=f32(sh),
        degree=degree,
    )


def fixture_subset(cam, limit):
    scene = read_ply(DATA / "render" / "random_deg3.ply")
    r = np.asarray(cam["rotation"], np.float64)
    pos = np.asarray(cam["position"], np.float64)
    tc = (scene["means"] - pos) @ r
    z = tc[:, 2]
    u = cam["fx"] * tc[:, 0] / np.maximum(z, 1e-9) + cam["cx"]
    v = cam["fy"] * tc[:, 1] / np.maximum(z, 1e-9) + cam["cy"]
    inside = (z > 0.01) & (u >= 0) & (u < cam["width"]) & (v >= 0) & (v < cam["height"])
    idx = np.nonzero(inside)[0][:limit]
    sub = {key: (val[idx] if isinstance(val, np.ndarray) else val) for key, val in scene.items()}
    return sub, idx


def short(values):
    """Float64 values to 14 significant digits (relative 1e-14, far below every tolerance)."""
    return [float(f"{v:.14g}") for v in np.asarray(values, np.float64).reshape(-1)]


def main():
    check_pinned_versions()
    OUT.mkdir(parents=True, exist_ok=True)
    cams_in = json.loads((DATA / "render" / "random_cameras.json").read_text())
    cam_rand = look_at("grad_random", [0.3, -0.2, -3.0], [0, 0, 0], [0, -1, 0], (40, 32), 40.0,
                       principal=(21.5, 15.0))
    cam_fix = dict(cams_in[0])
    cam_fix["img_name"] = "grad_deg3_fixture"
    scene = random_scene(24, 3, 2024)
    sub, idx = fixture_subset(cams_in[0], 96)
    cases = [
        ("random", scene, cam_rand, [0.2, 0.4, 0.6], False, None),
        ("random_aa", scene, cam_rand, [0.2, 0.4, 0.6], True, None),
        ("deg3_fixture", sub, cam_fix, [0.0, 0.0, 0.0], False, idx),
    ]
    cameras = []
    for name, params, cam, bg, aa, indices in cases:
        bg = [float(np.float32(b)) for b in bg]  # trisplat's background is float32
        images, grads, visible = render(params, cam, bg, aa)
        if cam not in cameras:
            cameras.append(cam)
        doc = dict(
            case=name,
            camera=cam["img_name"],
            background=bg,
            antialiased=aa,
            ply_indices=None if indices is None else [int(i) for i in indices],
            visible=visible,
            params=dict(
                sh_degree=params["degree"],
                means=params["means"].tolist(),
                log_scales=params["log_scales"].tolist(),
                rotations=params["quats"].tolist(),
                opacity_logits=params["opacity_logits"].tolist(),
                sh=params["sh_file"].reshape(-1).tolist(),
            ),
            images={key: short(val) for key, val in images.items()},
            grads={key: short(val) for key, val in grads.items()},
        )
        (OUT / f"{name}.json").write_text(json.dumps(doc, separators=(",", ":")) + "\n")
        print(f"{name}: {len(params['means'])} Gaussians, {visible} visible, "
              f"|grad means|max {np.abs(grads['means']).max():.3e}")
    (OUT / "cameras.json").write_text(json.dumps(cameras, indent=1) + "\n")


if __name__ == "__main__":
    main()
