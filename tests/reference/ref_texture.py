"""Reference for the base-colour texture lookup (docs/conventions.md §5 "Fitting", "Textured
targets"): CesiumMan's JPEG texture decoded by Pillow and sampled bilinearly with REPEAT by
scipy (pinned in requirements.txt: pillow==13.0.0, which bundles libjpeg-turbo; scipy==1.17.1,
numpy==2.4.6).

The image is the bytes of `images[0]`'s buffer view in fixtures/data/anim/CesiumMan.glb (the
GLB read with the standard library: header, JSON chunk, BIN chunk), decoded with
`PIL.Image.open(...).convert("RGBA")` (8-bit values, / 255 here).

Sample points (numpy default_rng(14), rounded to float32 first: the Rust side stores uvs as
f32, so both sides sample exactly the same point):
  120 uniform in [0, 1)^2
   40 uniform in [-3, 4)^2            (outside 0..1: REPEAT)
   40 near the edges and corners      (u or v within half a texel of 0 or 1, and exactly 0, 1)

Bilinear lookup: texel (i, j) has its centre at ((i + 1/2) / W, (j + 1/2) / H), v down the
image (glTF); the value at uv is scipy.ndimage.map_coordinates(channel, [[v H - 1/2],
[u W - 1/2]], order=1, mode="grid-wrap") per channel: linear interpolation between the four
texels around the point, indices wrapped with period W (H), which is REPEAT.

Written to fixtures/data/reference/texture/cesium_man.json:
  width, height          the decoded image size
  uv                     [N][2] sample points (float32 values)
  rgba                   [N][4] the scipy lookup on Pillow's texels, in 0..1
  texel_ij, texel_rgba   200 seeded texels (column, row) and Pillow's values / 255, to measure
                         the JPEG decoders' difference without any filtering
"""

import io
import json
import pathlib
import struct

import numpy as np
import PIL
import scipy
import scipy.ndimage as ndi
from PIL import Image

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
GLB = ROOT / "fixtures" / "data" / "anim" / "CesiumMan.glb"
OUT = ROOT / "fixtures" / "data" / "reference" / "texture"


def glb_image_bytes(path, image_index=0):
    data = path.read_bytes()
    json_len = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + json_len])
    bin_start = 20 + json_len + 8
    view = doc["bufferViews"][doc["images"][image_index]["bufferView"]]
    start = bin_start + view.get("byteOffset", 0)
    return data[start : start + view["byteLength"]]


def sample_points(rng, width, height):
    inside = rng.random((120, 2))
    outside = rng.random((40, 2)) * 7.0 - 3.0
    edges = []
    for k in range(40):
        # Alternately near 0 and near 1, on u then on v; every tenth exactly on the edge,
        # the last four at the corners.
        axis = (k // 2) % 2
        size = width if axis == 0 else height
        near = float(k % 2) + (0.0 if k % 10 == 0 else (rng.random() - 0.5) / size)
        other = rng.random() if k < 36 else float(k % 2)
        edges.append([near, other] if axis == 0 else [other, near])
    uv = np.concatenate([inside, outside, np.array(edges)])
    return uv.astype(np.float32).astype(np.float64)


def main():
    rgba = np.asarray(Image.open(io.BytesIO(glb_image_bytes(GLB))).convert("RGBA"))
    height, width = rgba.shape[:2]
    texels = rgba.astype(np.float64) / 255.0
    rng = np.random.default_rng(14)
    uv = sample_points(rng, width, height)
    rows = uv[:, 1] * height - 0.5
    cols = uv[:, 0] * width - 0.5
    values = np.stack(
        [
            ndi.map_coordinates(texels[:, :, c], [rows, cols], order=1, mode="grid-wrap")
            for c in range(4)
        ],
        axis=1,
    )
    ij = np.stack([rng.integers(0, width, 200), rng.integers(0, height, 200)], axis=1)
    texel_rgba = texels[ij[:, 1], ij[:, 0]]
    OUT.mkdir(parents=True, exist_ok=True)
    doc = {
        "source": "fixtures/data/anim/CesiumMan.glb images[0]",
        "tools": {"pillow": PIL.__version__, "scipy": scipy.__version__, "numpy": np.__version__},
        "width": int(width),
        "height": int(height),
        "uv": uv.tolist(),
        "rgba": values.tolist(),
        "texel_ij": ij.tolist(),
        "texel_rgba": texel_rgba.tolist(),
    }
    (OUT / "cesium_man.json").write_text(json.dumps(doc) + "\n")
    print(f"texture: {width}x{height}, {len(uv)} samples, {len(ij)} texels")


if __name__ == "__main__":
    main()
