"""2DGS surfel reference: a float64 numpy re-implementation of hbb1's diff-surfel-rasterization
forward pass (cuda_rasterizer/forward.cu and auxiliary.h of hbb1/diff-surfel-rasterization):

  preprocess  cull camera z <= near (0.2); T = K [Tu Tv p] (rows Tu, Tv, Tw); computeAABB:
              d = Tw.x^2 + Tw.y^2 - Tw.z^2, f = (1, 1, -1) / d, centre = (f.(Tu*Tw), f.(Tv*Tw)),
              extent = sqrt(max(0, centre^2 - (f.(Tu*Tu), f.(Tv*Tv)))),
              radius = ceil(3 max(extent.x, extent.y, FilterSize = 0.707106)); getRect on 16x16
              tiles; normal = camera-space third axis with negative z (DUAL_VISIABLE)
  render      per pixel of every touched tile, surfels in centre-depth order:
              k = -Tu + x Tw, l = -Tv + y Tw, p = k x l (skip p.z == 0), s = p.xy / p.z,
              rho3d = |s|^2, rho2d = 2 |centre - pixel|^2, rho = min, depth = intersection z
              if rho3d <= rho2d else centre z (skip depth < near), alpha = min(0.99, o exp(-rho/2)),
              skip alpha < 1/255, stop if T (1 - alpha) < 1e-4; colour/depth/normal += alpha T;
              median depth = depth of the last surfel met while T > 0.5

hbb1 samples integer pixel centres with the principal point at (W - 1)/2; trisplat samples pixel
(i, j) at (j + 0.5, i + 0.5) with principal point cx: the same rays when the principal point is
shifted by -0.5 and pixels are integer points, which is what this script does.

Inputs are rounded to float32 as trisplat stores them (means, quaternions, log-scales, opacity
logits, SH DC); scale = exp(log-scale) in float32 and opacity = sigmoid(logit) rounded to float32,
as trisplat activates them. Outputs in fixtures/data/reference/render_surfel/:

  scene.json            surfels (mean, rotation wxyz, log_scale[2], opacity_logit, f_dc[3]),
                        near plane, background
  cameras.json          the cameras (trisplat cameras.json layout)
  <camera>_alpha.npy    float32 [H, W]      1 - T
  <camera>_depth.npy    float32 [H, W]      sum(w z) / sum(w), 0 where alpha = 0
  <camera>_median.npy   float32 [H, W]      median depth
  <camera>_normal.npy   float32 [H, W, 3]   sum(w n), camera frame
  <camera>_rgb.npy      float32 [H, W, 3]   sum(w c) + T * background
"""

import json
import math
import pathlib

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT = ROOT / "fixtures" / "data" / "reference" / "render_surfel"

FILTER_SIZE = 0.707106
FILTER_INV_SQUARE = 2.0
NEAR = 0.2
TILE = 16
SH_C0 = 0.28209479177387814
BACKGROUND = np.array([0.1, 0.2, 0.3])


def look_at(name, cid, eye, target, size, fov_y_deg, fx_scale=1.0, principal=None):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rot = np.stack([right, down, forward], axis=1)
    w, h = size
    focal = 0.5 * h / math.tan(0.5 * math.radians(fov_y_deg))
    cx, cy = principal if principal else (0.5 * w, 0.5 * h)
    return {
        "id": cid, "img_name": name, "width": w, "height": h,
        "position": eye.tolist(), "rotation": rot.tolist(),
        "fx": focal * fx_scale, "fy": focal, "cx": cx, "cy": cy,
    }


CAMERAS = [
    look_at("front", 0, (0.0, 0.0, -3.0), (0.0, 0.0, 0.0), (64, 48), 50.0),
    look_at("oblique", 1, (1.6, 0.9, -2.2), (0.05, 0.0, 0.1), (56, 40), 58.0,
            fx_scale=1.15, principal=(30.3, 18.6)),
]


def make_surfels():
    rng = np.random.default_rng(20240605)
    surfels = []
    for _ in range(16):
        q = rng.normal(size=4)
        surfels.append({
            "mean": rng.uniform(-0.6, 0.6, size=3).tolist(),
            "rotation": q.tolist(),
            "log_scale": np.log(rng.uniform(0.05, 0.35, size=2)).tolist(),
            "opacity_logit": float(rng.uniform(-1.0, 3.0)),
            "f_dc": rng.uniform(-1.5, 1.5, size=3).tolist(),
        })
    # Edge-on to the front camera (normal along x), a sub-pixel one (log-scale -29, drawn by the
    # low-pass filter only), an invisible one (opacity < 1/255), one inside the near plane of
    # the front camera, one behind it, and a large one covering much of the image.
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    surfels += [
        {"mean": [0.3, -0.2, -0.3], "rotation": [c, 0.0, s, 0.0], "log_scale": [-1.5, -2.0],
         "opacity_logit": 2.0, "f_dc": [1.0, -1.0, 0.5]},
        {"mean": [-0.1, 0.15, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0], "log_scale": [-29.0, -29.0],
         "opacity_logit": 4.0, "f_dc": [0.2, 0.8, -0.4]},
        {"mean": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0], "log_scale": [-1.0, -1.0],
         "opacity_logit": -8.0, "f_dc": [1.0, 1.0, 1.0]},
        {"mean": [0.0, 0.0, -2.9], "rotation": [1.0, 0.0, 0.0, 0.0], "log_scale": [-2.0, -2.0],
         "opacity_logit": 2.0, "f_dc": [1.0, 1.0, 1.0]},
        {"mean": [0.0, 0.0, -4.0], "rotation": [1.0, 0.0, 0.0, 0.0], "log_scale": [0.0, 0.0],
         "opacity_logit": 2.0, "f_dc": [1.0, 1.0, 1.0]},
        {"mean": [0.1, 0.0, 0.9], "rotation": [0.95, 0.2, -0.1, 0.05], "log_scale": [0.3, 0.1],
         "opacity_logit": 0.5, "f_dc": [-0.5, 0.3, 1.2]},
    ]
    # Round to float32 as stored.
    for g in surfels:
        for key in ("mean", "rotation", "log_scale", "f_dc"):
            g[key] = [float(np.float32(v)) for v in g[key]]
        g["opacity_logit"] = float(np.float32(g["opacity_logit"]))
    return surfels


def quat_to_mat(q):
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def activate(g):
    scale = np.exp(np.asarray(g["log_scale"], dtype=np.float32)).astype(np.float64)
    logit = float(g["opacity_logit"])
    opacity = float(np.float32(1.0 / (1.0 + math.exp(-logit)))) if logit >= 0 else float(
        np.float32(math.exp(logit) / (1.0 + math.exp(logit))))
    color = np.maximum(SH_C0 * np.asarray(g["f_dc"], float) + 0.5, 0.0)
    color = color.astype(np.float32).astype(np.float64)
    return quat_to_mat(g["rotation"]), scale, opacity, color


def preprocess(g, cam):
    rot_c2w = np.asarray(cam["rotation"])
    w2c = rot_c2w.T
    mean = np.asarray(g["mean"], float)
    t = w2c @ (mean - np.asarray(cam["position"]))
    if not t[2] > NEAR:
        return None
    R, scale, opacity, color = activate(g)
    K = np.array([[cam["fx"], 0, cam["cx"] - 0.5], [0, cam["fy"], cam["cy"] - 0.5], [0, 0, 1]])
    M = K @ np.stack([w2c @ R[:, 0] * scale[0], w2c @ R[:, 1] * scale[1], t], axis=1)
    Tu, Tv, Tw = M[0], M[1], M[2]
    sign = np.array([1.0, 1.0, -1.0])
    d = np.dot(sign, Tw * Tw)
    if d == 0.0:
        return None
    f = sign / d
    centre = np.array([np.dot(f, Tu * Tw), np.dot(f, Tv * Tw)])
    h0 = centre * centre - np.array([np.dot(f, Tu * Tu), np.dot(f, Tv * Tv)])
    extent = np.sqrt(np.maximum(0.0, h0))
    radius = math.ceil(3.0 * max(extent[0], extent[1], FILTER_SIZE))
    grid = ((cam["width"] + TILE - 1) // TILE, (cam["height"] + TILE - 1) // TILE)
    rect_min = [min(grid[a], max(0, int((centre[a] - radius) / TILE))) for a in (0, 1)]
    rect_max = [min(grid[a], max(0, int((centre[a] + radius + TILE - 1) / TILE))) for a in (0, 1)]
    if (rect_max[0] - rect_min[0]) * (rect_max[1] - rect_min[1]) == 0:
        return None
    n = w2c @ R[:, 2]
    n = n if n[2] < 0 else -n
    return {
        "Tu": Tu, "Tv": Tv, "Tw": Tw, "centre": centre, "depth": t[2], "opacity": opacity,
        "color": color, "normal": n, "rect": (rect_min, rect_max),
    }


def render(surfels, cam):
    W, H = cam["width"], cam["height"]
    splats = [(i, p) for i, g in enumerate(surfels) if (p := preprocess(g, cam)) is not None]
    # Sort by float32 centre depth, ties by index (trisplat's and hbb1's stable key order).
    splats.sort(key=lambda ip: (np.float32(ip[1]["depth"]), ip[0]))
    alpha = np.zeros((H, W))
    depth = np.zeros((H, W))
    median = np.zeros((H, W))
    normal = np.zeros((H, W, 3))
    rgb = np.zeros((H, W, 3))
    for y in range(H):
        for x in range(W):
            tx, ty = x // TILE, y // TILE
            T = 1.0
            C = np.zeros(3)
            D = 0.0
            N = np.zeros(3)
            med = 0.0
            for _, p in splats:
                (x0, y0), (x1, y1) = p["rect"]
                if not (x0 <= tx < x1 and y0 <= ty < y1):
                    continue
                k = -p["Tu"] + x * p["Tw"]
                l = -p["Tv"] + y * p["Tw"]
                h = np.cross(k, l)
                if h[2] == 0.0:
                    continue
                s = h[:2] / h[2]
                rho3d = float(s @ s)
                dd = p["centre"] - np.array([x, y], float)
                rho2d = FILTER_INV_SQUARE * float(dd @ dd)
                rho = min(rho3d, rho2d)
                z = s[0] * p["Tw"][0] + s[1] * p["Tw"][1] + p["Tw"][2] if rho3d <= rho2d else p["Tw"][2]
                if z < NEAR:
                    continue
                a = min(0.99, p["opacity"] * math.exp(-0.5 * rho))
                if a < 1.0 / 255.0:
                    continue
                test_T = T * (1.0 - a)
                if test_T < 1e-4:
                    break
                w = a * T
                if T > 0.5:
                    med = z
                C += w * p["color"]
                D += w * z
                N += w * p["normal"]
                T = test_T
            acc = 1.0 - T
            alpha[y, x] = acc
            depth[y, x] = D / acc if acc > 0 else 0.0
            median[y, x] = med
            normal[y, x] = N
            rgb[y, x] = C + T * BACKGROUND
    return alpha, depth, median, normal, rgb


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    surfels = make_surfels()
    maps = [render(surfels, cam) for cam in CAMERAS]
    names = ["alpha", "depth", "median", "normal", "rgb"]
    for k, name in enumerate(names):
        for c, m in zip(CAMERAS, maps):
            np.save(OUT / f"{c['img_name']}_{name}.npy", m[k].astype(np.float32))
    (OUT / "cameras.json").write_text(json.dumps(CAMERAS, indent=1) + "\n")
    scene = {
        "rules": "hbb1/diff-surfel-rasterization forward pass, float64",
        "near": NEAR, "background": BACKGROUND.tolist(), "numpy": np.__version__,
        "surfels": surfels,
    }
    (OUT / "scene.json").write_text(json.dumps(scene, indent=1) + "\n")
    for c, m in zip(CAMERAS, maps):
        print(c["img_name"], "covered", int((m[0] > 0).sum()), "max alpha", float(m[0].max()))


if __name__ == "__main__":
    main()
