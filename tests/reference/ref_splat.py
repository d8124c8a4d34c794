"""Reference values for the splat area: 2-Wasserstein distances between 3D Gaussians computed
with scipy.linalg.sqrtm (the textbook trace form, in float64).

Writes fixtures/data/reference/splat/w2_sqrtm.json: a list of pairs, each with the means,
w-first unit quaternions and scales of both Gaussians and `w2_sq`. Pairs range from unrelated
Gaussians to ones differing by 1e-3 relative (below that the trace form itself loses digits in
float64, which is the point of trisplat's residual form).
"""

import json
import pathlib

import numpy as np
import scipy.linalg

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent
OUT = ROOT / "fixtures" / "data" / "reference" / "splat"


def rotation(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def covariance(q, s):
    r = rotation(q)
    return r @ np.diag(s * s) @ r.T


def w2_sq(mu1, c1, mu2, c2):
    r1 = scipy.linalg.sqrtm(c1)
    cross = scipy.linalg.sqrtm(r1 @ c2 @ r1)
    bures = np.trace(c1) + np.trace(c2) - 2.0 * np.trace(np.real(cross))
    return float(np.sum((mu1 - mu2) ** 2) + bures)


def main():
    rng = np.random.default_rng(20240611)
    pairs = []
    for i in range(60):
        q1 = rng.normal(size=4)
        q1 /= np.linalg.norm(q1)
        s1 = np.exp(rng.uniform(-3.0, 0.0, size=3))
        mu1 = rng.normal(size=3) * 0.1
        if i < 30:
            q2 = rng.normal(size=4)
            s2 = np.exp(rng.uniform(-3.0, 0.0, size=3))
            mu2 = rng.normal(size=3) * 0.1
        else:
            eps = 10.0 ** rng.uniform(-3.0, -1.0)
            q2 = q1 + rng.normal(size=4) * eps
            s2 = s1 * (1.0 + rng.normal(size=3) * eps)
            mu2 = mu1 + rng.normal(size=3) * eps * 0.01
        q2 = q2 / np.linalg.norm(q2)
        c1, c2 = covariance(q1, s1), covariance(q2, s2)
        pairs.append(
            {
                "mu1": mu1.tolist(), "q1": q1.tolist(), "s1": s1.tolist(),
                "mu2": mu2.tolist(), "q2": q2.tolist(), "s2": s2.tolist(),
                "w2_sq": w2_sq(mu1, c1, mu2, c2),
            }
        )
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "w2_sqrtm.json").write_text(json.dumps({"scipy": scipy.__version__, "pairs": pairs}, indent=1))
    print(f"wrote {len(pairs)} pairs to {OUT / 'w2_sqrtm.json'}")


if __name__ == "__main__":
    main()
