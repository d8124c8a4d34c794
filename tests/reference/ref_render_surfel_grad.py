#!/usr/bin/env python3
"""Reference gradients of the 2DGS surfel renderer's backward pass (docs/conventions.md §5
"Gradients"), by torch autograd on the CPU in float64.

Pinned versions (tests/reference/requirements-gsplat.txt, checked at start):
    torch==2.15.0, gsplat==1.5.3, numpy==2.4.6

gsplat's 2DGS rasterizer needs CUDA, so the forward is written here in torch and differentiated
by autograd. The projection is gsplat 1.5.3's own pure-PyTorch 2DGS projection
(`gsplat.cuda._torch_impl_2dgs._fully_fused_projection_2dgs`: normalised quaternion, scales
exp(log-scales), ray transform M = K [Tu Tv p] with rows Tu, Tv, Tw, the filter centre means2d =
hbb1's computeAABB centre) with K's principal point shifted by -0.5 so that integer pixel
coordinates are pixel centres (trisplat's mapping of hbb1's convention, docs/conventions.md §5);
SH colours are gsplat's `_spherical_harmonics` (colour = max(SH + 0.5, 0), dirs = mean - camera
centre). The rest follows hbb1's diff-surfel-rasterization, as tests/reference/ref_render_surfel.py
does for the forward:

  cull     camera z <= near (0.2) or >= far, opacity < 1/255, empty tile rectangle;
           radius = ceil(3 max(extent_x, extent_y, 0.707106)), 16x16 tiles by getRect; a
           surfel is evaluated at every pixel of the tiles it touches (no gradient: masks);
  normal   camera-space third axis with negative z (world frame: rotated back), sign held fixed;
  pixel    k = x Tw - Tu, l = y Tw - Tv, p = k x l, s = p.xy / p.z; rho3d = |s|^2,
           rho2d = 2 |centre - pixel|^2; rho = min; depth = s.x Tw.x + s.y Tw.y + Tw.z where
           rho3d <= rho2d, else Tw.z; skip depth < near; alpha = min(0.99, o exp(-rho / 2)) (no
           gradient where clamped), skip alpha < 1/255, stop before the surfel that brings T
           below 1e-4 (which surfels contribute is decided without gradient); surfels in
           centre-depth order (float32 key, ties by index); w = alpha T;
  images   rgb = sum w c + T background, alpha = 1 - T, depth = sum w z / max(alpha, 1e-10)
           (0 where alpha = 0), normal = sum w n, distortion = sum_{i<j} w_i w_j (m_i - m_j)^2
           (2DGS's render_dist, explicit pairwise sum here) with m = 100/99.8 (1 - 0.2 / z).

The loss is linear in the images with weights both sides compute from the row-major pixel index
i and channel c:  w_rgb = sin(0.1 i + 0.7 c + 0.3),  w_alpha = cos(0.13 i),
w_depth = 0.2 sin(0.05 i + 1.0),  w_normal = 0.3 cos(0.07 i + 0.5 c),  plus LAMBDA times the
distortion summed over pixels.

Cases (fixtures/data/reference/render_surfel_grad/<case>.json, cameras in cameras.json there):
- `random`: 20 seeded surfels of SH degree 3, a grazing surfel and a needle (second scale
  e^-9), 32x24 camera with an off-centre principal point, background (0.2, 0.4, 0.6), normals
  in the camera frame;
- `random_world`: the same scene and camera, normals in the world frame.
Each file holds the parameters, the images and the gradients with respect to means, log-scales
(three; the third is unused by surfels), raw quaternions [w, x, y, z], opacity logits and SH
coefficients (file order: f_dc_0..2, then f_rest channel-major).

    /work/venv-torch/bin/python tests/reference/ref_render_surfel_grad.py
"""

import json
import math
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent
OUT = ROOT / "fixtures" / "data" / "reference" / "render_surfel_grad"
REQUIREMENTS = HERE / "requirements-gsplat.txt"

NEAR, FAR = 0.2, 1e10
FILTER_SIZE = 0.707106
TILE = 16
DIST_NEAR, DIST_FAR = 0.2, 100.0
LAMBDA = 50.0


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
    c = np.arange(3)[None, :]
    w_rgb = np.sin(0.1 * i[:, None] + 0.7 * c + 0.3)
    w_alpha = np.cos(0.13 * i)
    w_depth = 0.2 * np.sin(0.05 * i + 1.0)
    w_normal = 0.3 * np.cos(0.07 * i[:, None] + 0.5 * c)
    return w_rgb, w_alpha, w_depth, w_normal


def render(params, cam, background, world_normals):
    """Images and gradients of the loss (module documentation), float64."""
    import torch
    from gsplat.cuda._torch_impl import _quat_scale_to_matrix, _spherical_harmonics
    from gsplat.cuda._torch_impl_2dgs import _fully_fused_projection_2dgs

    d = torch.float64
    t = lambda a: torch.tensor(np.asarray(a, np.float64), dtype=d)
    means = t(params["means"]).requires_grad_()
    log_scales = t(params["log_scales"]).requires_grad_()
    quats = t(params["quats"]).requires_grad_()
    logits = t(params["opacity_logits"]).requires_grad_()
    degree = params["degree"]
    sh = t(file_to_torch_sh(params["sh_file"], degree)).requires_grad_()
    n = means.shape[0]

    r = np.asarray(cam["rotation"], np.float64)
    pos = np.asarray(cam["position"], np.float64)
    view = np.eye(4)
    view[:3, :3] = r.T
    view[:3, 3] = -r.T @ pos
    k = np.array([[cam["fx"], 0, cam["cx"] - 0.5], [0, cam["fy"], cam["cy"] - 0.5], [0, 0, 1]])
    w, h = cam["width"], cam["height"]
    scales = torch.cat([torch.exp(log_scales[:, :2]), torch.ones((n, 1), dtype=d)], dim=1)
    _, centre, depths, rows, _ = _fully_fused_projection_2dgs(
        means, quats, scales, t(view)[None], t(k)[None], w, h, near_plane=NEAR, far_plane=FAR)
    centre, depths, rows = centre[0], depths[0], rows[0]  # rows[g] = [Tu; Tv; Tw]
    rot = _quat_scale_to_matrix(quats, torch.ones((n, 3), dtype=d))
    n_cam = torch.einsum("ij,nj->ni", t(r.T), rot[:, :, 2])
    n_cam = torch.where((n_cam[:, 2] < 0)[:, None], n_cam, -n_cam)
    normals = torch.einsum("ij,nj->ni", t(r), n_cam) if world_normals else n_cam
    opac = torch.sigmoid(logits)
    colors = _spherical_harmonics(degree, means - t(pos)[None], sh)
    colors = torch.clamp_min(colors + 0.5, 0.0)

    # Culling and tile rectangles (no gradient).
    with torch.no_grad():
        tw = rows[:, 2]
        sign = t([1.0, 1.0, -1.0])
        dd = (tw * tw * sign).sum(-1)
        f = sign[None] / dd[:, None]
        ext = torch.sqrt(torch.clamp_min(
            centre ** 2 - torch.stack([(f * rows[:, 0] ** 2).sum(-1),
                                       (f * rows[:, 1] ** 2).sum(-1)], -1), 0.0))
        radius = torch.ceil(3.0 * torch.clamp_min(ext.max(-1).values, FILTER_SIZE))
        grid = ((w + TILE - 1) // TILE, (h + TILE - 1) // TILE)
        cnp, rnp = centre.numpy(), radius.numpy()
        rects = []
        for g in range(n):
            cx, cy = float(np.float32(cnp[g, 0])), float(np.float32(cnp[g, 1]))
            rr = float(np.float32(rnp[g]))
            lo = [min(grid[a], max(0, int((c - rr) / TILE))) for a, c in ((0, cx), (1, cy))]
            hi = [min(grid[a], max(0, int((c + rr + TILE - 1) / TILE))) for a, c in ((0, cx), (1, cy))]
            rects.append((lo, hi))
        z = depths.numpy()
        visible = [g for g in range(n)
                   if NEAR < z[g] < FAR and dd[g] != 0 and opac[g] >= 1.0 / 255.0
                   and (rects[g][1][0] - rects[g][0][0]) * (rects[g][1][1] - rects[g][0][1]) > 0]
    order = sorted(visible, key=lambda g: (np.float32(z[g]), g))
    idx = torch.tensor(order, dtype=torch.long)
    ii, jj = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    px_np, py_np = jj.reshape(-1).astype(np.float64), ii.reshape(-1).astype(np.float64)
    in_tile = np.zeros((h * w, len(order)), bool)
    for a, g in enumerate(order):
        (x0, y0), (x1, y1) = rects[g]
        in_tile[:, a] = ((px_np // TILE >= x0) & (px_np // TILE < x1)
                         & (py_np // TILE >= y0) & (py_np // TILE < y1))
    px, py = t(px_np)[:, None], t(py_np)[:, None]
    R = rows[idx]  # [G, 3, 3]
    tu, tv, tw = R[None, :, 0], R[None, :, 1], R[None, :, 2]  # [1, G, 3]
    kk = px[..., None] * tw - tu
    ll = py[..., None] * tw - tv
    p = torch.cross(kk, ll, dim=-1)  # [P, G, 3]
    with torch.no_grad():
        hits = p[..., 2] != 0
    pz = torch.where(hits, p[..., 2], torch.ones_like(p[..., 2]))
    su, sv = p[..., 0] / pz, p[..., 1] / pz
    rho3d = su * su + sv * sv
    dc = centre[idx][None] - torch.stack([px, py], -1).squeeze(-2)[:, None, :]
    rho2d = 2.0 * (dc * dc).sum(-1)
    with torch.no_grad():
        on_disc = rho3d <= rho2d
    rho = torch.where(on_disc, rho3d, rho2d)
    depth_px = torch.where(on_disc, su * tw[..., 0] + sv * tw[..., 1] + tw[..., 2],
                           tw[..., 2].expand_as(su))
    alpha = torch.clamp(opac[idx][None] * torch.exp(-0.5 * torch.where(hits, rho, 0.0)), max=0.99)
    with torch.no_grad():
        valid = hits & torch.tensor(in_tile) & (depth_px >= NEAR) & (alpha >= 1.0 / 255.0) \
            & torch.isfinite(rho)
        pixels, g_n = alpha.shape
        T = torch.ones(pixels, dtype=d)
        alive = torch.ones(pixels, dtype=torch.bool)
        use = torch.zeros((pixels, g_n), dtype=torch.bool)
        for g in range(g_n):
            v = valid[:, g] & alive
            nt = T * (1.0 - alpha[:, g])
            stop = v & (nt < 1e-4)
            alive &= ~stop
            acc = v & ~stop
            use[:, g] = acc
            T = torch.where(acc, nt, T)
    a_used = torch.where(use, alpha, torch.zeros_like(alpha))
    cum = torch.cumprod(1.0 - a_used, dim=1)
    t_excl = torch.cat([torch.ones((pixels, 1), dtype=d), cum[:, :-1]], dim=1)
    wgt = a_used * t_excl
    t_final = cum[:, -1] if g_n else torch.ones(pixels, dtype=d)
    zsafe = torch.where(use, depth_px, torch.ones_like(depth_px))
    rgb = wgt @ colors[idx] + t_final[:, None] * t(background)[None, :]
    acc_alpha = 1.0 - t_final
    dsum = (wgt * zsafe).sum(1)
    depth = torch.where(acc_alpha > 0, dsum / torch.clamp(acc_alpha, min=1e-10),
                        torch.zeros_like(dsum))
    normal = wgt @ normals[idx]
    m = DIST_FAR / (DIST_FAR - DIST_NEAR) * (1.0 - DIST_NEAR / zsafe)
    diff = m[:, :, None] - m[:, None, :]
    upper = torch.triu(torch.ones((g_n, g_n), dtype=torch.bool), diagonal=1)
    distortion = (wgt[:, :, None] * wgt[:, None, :] * diff * diff * upper[None]).sum((1, 2))

    w_rgb, w_alpha, w_depth, w_normal = loss_weights(pixels)
    loss = (rgb * t(w_rgb)).sum() + (acc_alpha * t(w_alpha)).sum() + (depth * t(w_depth)).sum() \
        + (normal * t(w_normal)).sum() + LAMBDA * distortion.sum()
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
        normal=normal.detach().numpy().reshape(-1),
        distortion=distortion.detach().numpy(),
    )
    return images, grads, len(order)


def random_scene(n, degree, seed):
    rng = np.random.default_rng(seed)
    k = 3 * (degree + 1) ** 2
    sh = rng.uniform(-0.3, 0.3, (n + 2, k))
    sh[:, :3] = rng.uniform(-1.0, 1.0, (n + 2, 3))
    means = rng.uniform([-0.6, -0.45, -0.5], [0.6, 0.45, 0.5], (n + 2, 3))
    log_scales = rng.uniform([-1.9, -1.9, -3.0], [-1.0, -1.0, -1.0], (n + 2, 3))
    quats = rng.uniform(-1.0, 1.0, (n + 2, 4))
    logits = rng.uniform(-1.0, 2.0, n + 2)
    # Grazing: third axis 87 degrees from the view axis; needle: second scale e^-9.
    half = math.radians(87.0) / 2
    quats[n] = [math.cos(half), 0.0, math.sin(half), 0.0]
    means[n] = [0.1, 0.05, 0.0]
    log_scales[n] = [-1.4, -1.6, -5.0]
    logits[n] = 2.0
    means[n + 1] = [-0.2, 0.1, -0.2]
    log_scales[n + 1] = [-1.5, -9.0, -5.0]
    logits[n + 1] = 1.5
    f32 = lambda a: np.asarray(a, np.float32).astype(np.float64)
    return dict(means=f32(means), log_scales=f32(log_scales), quats=f32(quats),
                opacity_logits=f32(logits), sh_file=f32(sh), degree=degree)


def short(values):
    """Float64 values to 14 significant digits (relative 1e-14, far below every tolerance)."""
    return [float(f"{v:.14g}") for v in np.asarray(values, np.float64).reshape(-1)]


def main():
    check_pinned_versions()
    OUT.mkdir(parents=True, exist_ok=True)
    cam = look_at("surfel_grad", [0.3, -0.2, -3.0], [0, 0, 0], [0, -1, 0], (32, 24), 40.0,
                  principal=(17.3, 11.6))
    scene = random_scene(20, 3, 2025)
    bg = [float(np.float32(b)) for b in (0.2, 0.4, 0.6)]
    for name, world in (("random", False), ("random_world", True)):
        images, grads, visible = render(scene, cam, bg, world)
        doc = dict(
            case=name,
            camera=cam["img_name"],
            background=bg,
            near=NEAR,
            normal_frame="world" if world else "camera",
            distortion_weight=LAMBDA,
            visible=visible,
            params=dict(
                sh_degree=scene["degree"],
                means=scene["means"].tolist(),
                log_scales=scene["log_scales"].tolist(),
                rotations=scene["quats"].tolist(),
                opacity_logits=scene["opacity_logits"].tolist(),
                sh=scene["sh_file"].reshape(-1).tolist(),
            ),
            images={key: short(val) for key, val in images.items()},
            grads={key: short(val) for key, val in grads.items()},
        )
        (OUT / f"{name}.json").write_text(json.dumps(doc, separators=(",", ":")) + "\n")
        print(f"{name}: {len(scene['means'])} surfels, {visible} visible, "
              f"covered {(images['alpha'] > 0).sum()} px, distortion {images['distortion'].sum():.3e}, "
              f"|grad means|max {np.abs(grads['means']).max():.3e}")
    (OUT / "cameras.json").write_text(json.dumps([cam], indent=1) + "\n")


if __name__ == "__main__":
    main()
