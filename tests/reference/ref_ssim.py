"""SSIM and L1 references for the fitter's image losses (docs/conventions.md §5 "Fitting"), by
scikit-image and scipy (pinned in requirements.txt: scikit-image==0.25.2, scipy==1.17.1,
numpy==2.4.6).

Cases (seeded numpy images in 0..1, float64; the prediction is the target plus uniform noise of
the given spread, clipped to 0..1):
  rgb    24 x 20, 3 channels, spread 0.3 (seed 7)
  grey   16 x 16, 1 channel,  spread 1.0 (seed 8)

Per case, in fixtures/data/reference/fit_loss/ssim.json:
  pred, target     the images, [H, W, C] row-major, flattened
  l1               numpy mean |pred - target|
  skimage_mssim    skimage.metrics.structural_similarity(target, pred, gaussian_weights=True,
                   sigma=1.5, use_sample_covariance=False, data_range=1.0, channel_axis=2):
                   the mean of the SSIM map over the pixels at least 5 from the border (skimage
                   crops (win_size - 1) / 2 = 5 after filtering with reflect padding)
  skimage_map      its full SSIM map (full=True), [H, W, C]; only pixels at least 5 from the
                   border are independent of the padding
  zero_pad_mssim   3DGS's ssim(): the same moments with scipy.ndimage.correlate1d
                   (mode='constant', cval=0: torch conv2d's zero padding) on the 11-tap window
                   exp(-x^2 / (2 * 1.5^2)), x = -5..5, normalised, averaged over every pixel
                   and channel
"""

import json
import pathlib

import numpy as np
import scipy.ndimage as ndi
import skimage
from skimage.metrics import structural_similarity

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
OUT = ROOT / "fixtures" / "data" / "reference" / "fit_loss"

C1 = 0.01**2
C2 = 0.03**2


def window():
    x = np.arange(11, dtype=np.float64) - 5.0
    w = np.exp(-(x * x) / (2.0 * 1.5 * 1.5))
    return w / w.sum()


def zero_pad_ssim(pred, target):
    w = window()

    def f(a):
        a = ndi.correlate1d(a, w, axis=0, mode="constant", cval=0.0)
        return ndi.correlate1d(a, w, axis=1, mode="constant", cval=0.0)

    maps = []
    for c in range(pred.shape[2]):
        x, y = pred[:, :, c], target[:, :, c]
        mx, my = f(x), f(y)
        sxx = f(x * x) - mx * mx
        syy = f(y * y) - my * my
        sxy = f(x * y) - mx * my
        maps.append(((2 * mx * my + C1) * (2 * sxy + C2)) / ((mx * mx + my * my + C1) * (sxx + syy + C2)))
    return float(np.mean(np.stack(maps, axis=2)))


def case(name, h, w, c, spread, seed):
    rng = np.random.default_rng(seed)
    target = rng.random((h, w, c))
    pred = np.clip(target + spread * (rng.random((h, w, c)) - 0.5), 0.0, 1.0)
    mssim, smap = structural_similarity(
        target,
        pred,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=1.0,
        channel_axis=2,
        full=True,
    )
    return {
        "name": name,
        "height": h,
        "width": w,
        "channels": c,
        "pred": pred.ravel().tolist(),
        "target": target.ravel().tolist(),
        "l1": float(np.mean(np.abs(pred - target))),
        "skimage_mssim": float(mssim),
        "skimage_map": np.asarray(smap).ravel().tolist(),
        "zero_pad_mssim": zero_pad_ssim(pred, target),
    }


def main():
    assert skimage.__version__ == "0.25.2", skimage.__version__
    OUT.mkdir(parents=True, exist_ok=True)
    cases = [case("rgb", 24, 20, 3, 0.3, 7), case("grey", 16, 16, 1, 1.0, 8)]
    doc = {"generator": "tests/reference/ref_ssim.py", "skimage": skimage.__version__, "cases": cases}
    (OUT / "ssim.json").write_text(json.dumps(doc) + "\n")
    for c in cases:
        print(c["name"], c["l1"], c["skimage_mssim"], c["zero_pad_mssim"])


if __name__ == "__main__":
    main()
