"""Statistical outlier removal references (`geometry::outliers`): Open3D 0.20.0's
`PointCloud.remove_statistical_outlier(nb_neighbors, std_ratio)` on seeded clouds.

Clouds (float32, stored as `<f4` .npy of shape (n, 3); Open3D receives their exact float64
values):

  sphere      2,000 points on the unit sphere with radial Gaussian noise (sigma 0.01) and 50
              uniform floaters in the box [-1.5, 1.5]^3, shuffled together (seed 7)
  duplicates  300 noisy sphere points (seed 8) where 20 points get one extra copy and 10
              points five extra copies (six coincident points: their mean distance is 0 for
              nb_neighbors <= 6), plus one far point, shuffled together
  tiny        three points (0,0,0), (1,0,0), (0,2,0): nb_neighbors 20 exceeds the cloud
  pair        two points: equal mean distances, sigma = 0, threshold = mean, so the strict
              comparison removes both

Cases (cloud, nb_neighbors, std_ratio): sphere (20, 2.0), (5, 1.0), (30, 3.0); duplicates
(4, 0.5), (4, 1.0), (10, 2.0); tiny (20, 2.0), (20, 1.25), (20, 0.5); pair (20, 2.0).

Some cases tell the pinned definition from near variants: sphere (5, 1.0) removes another
point when the point itself is not among its neighbours; duplicates (4, 0.5) moves 15 points
across the threshold when the zero means are left out of n; tiny (20, 1.25) keeps the third
point only with the n - 1 denominator; pair only with the strict comparison.

Output fixtures/data/reference/outliers/: `<cloud>.npy` and `outliers.json`, per case:

  removed          indices Open3D removed (the complement of the indices it returned), ascending
  threshold        mu + std_ratio * sigma of the definition below (numpy), for reading
  min_margin       min over points with a_i > 0 of |a_i - threshold| / threshold: how close the
                   nearest point came to the threshold (the Rust test tolerates disagreement
                   only within 1e-9 of it)

The script checks the definition pinned in `geometry/src/outliers.rs` against Open3D before
writing: a_i = mean of the Euclidean distances to the min(k, n) nearest points, the point
itself included (scipy cKDTree in float64); mu = sum of the a_i > 0 over n; sigma = sqrt(sum
over a_i > 0 of (a_i - mu)^2 / (n - 1)); kept iff 0 < a_i < mu + std_ratio * sigma.
"""

import json
import pathlib
import sys

import numpy as np
import open3d as o3d
import scipy
from scipy.spatial import cKDTree

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
OUT = ROOT / "fixtures" / "data" / "reference" / "outliers"


def noisy_sphere(rng, n, sigma):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * (1.0 + sigma * rng.normal(size=(n, 1)))


def sphere_cloud():
    rng = np.random.default_rng(7)
    surface = noisy_sphere(rng, 2000, 0.01)
    floaters = rng.uniform(-1.5, 1.5, size=(50, 3))
    points = np.concatenate([surface, floaters])
    return points[rng.permutation(len(points))].astype(np.float32)


def duplicates_cloud():
    rng = np.random.default_rng(8)
    base = noisy_sphere(rng, 300, 0.01)
    picks = rng.choice(300, 30, replace=False)
    once, five = picks[:20], picks[20:]
    points = np.concatenate([base, base[once], np.repeat(base[five], 5, axis=0), [[3.0, 3.0, 3.0]]])
    return points[rng.permutation(len(points))].astype(np.float32)


def tiny_cloud():
    return np.asarray([[0, 0, 0], [1, 0, 0], [0, 2, 0]], np.float32)


def pair_cloud():
    return np.asarray([[0.25, -1, 2], [1.5, 0.5, 2]], np.float32)


CLOUDS = {"sphere": sphere_cloud, "duplicates": duplicates_cloud, "tiny": tiny_cloud, "pair": pair_cloud}
CASES = [
    ("sphere", 20, 2.0),
    ("sphere", 5, 1.0),
    ("sphere", 30, 3.0),
    ("duplicates", 4, 0.5),
    ("duplicates", 4, 1.0),
    ("duplicates", 10, 2.0),
    ("tiny", 20, 2.0),
    ("tiny", 20, 1.25),
    ("tiny", 20, 0.5),
    ("pair", 20, 2.0),
]


def open3d_removed(points, nb_neighbors, std_ratio):
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    _, kept = cloud.remove_statistical_outlier(nb_neighbors=nb_neighbors, std_ratio=std_ratio)
    removed = np.ones(len(points), bool)
    removed[np.asarray(kept, np.int64)] = False
    return removed


def definition(points, nb_neighbors, std_ratio):
    """The rule as pinned in geometry/src/outliers.rs, in numpy: (removed mask, a_i, threshold)."""
    p = points.astype(np.float64)
    n = len(p)
    k = min(nb_neighbors, n)
    dist, _ = cKDTree(p).query(p, k=k)
    dist = np.asarray(dist).reshape(n, k)
    a = dist.sum(axis=1) / k
    positive = a > 0
    mu = a[positive].sum() / n
    sigma = np.sqrt(((a[positive] - mu) ** 2).sum() / (n - 1))
    threshold = mu + std_ratio * sigma
    removed = ~(positive & (a < threshold))
    return removed, a, threshold


def main():
    sys.path.insert(0, str(HERE))
    from make_reference import check_pinned_versions

    check_pinned_versions()
    OUT.mkdir(parents=True, exist_ok=True)
    clouds = {name: make() for name, make in CLOUDS.items()}
    for name, points in clouds.items():
        np.save(OUT / f"{name}.npy", points)
    cases = []
    for name, nb_neighbors, std_ratio in CASES:
        points = clouds[name]
        removed = open3d_removed(points, nb_neighbors, std_ratio)
        ours, a, threshold = definition(points, nb_neighbors, std_ratio)
        margins = np.abs(a[a > 0] - threshold) / threshold
        min_margin = float(margins.min()) if len(margins) else None
        # The definition must reproduce Open3D except within 1e-9 of the threshold.
        differ = np.flatnonzero(ours != removed)
        close = np.abs(a[differ] - threshold) <= 1e-9 * threshold
        if not close.all():
            sys.exit(f"outliers {name} ({nb_neighbors}, {std_ratio}): the definition disagrees with Open3D at {differ[~close]}")
        cases.append(
            {
                "cloud": name,
                "nb_neighbors": nb_neighbors,
                "std_ratio": std_ratio,
                "removed": [int(i) for i in np.flatnonzero(removed)],
                "threshold": float(threshold),
                "min_margin": min_margin,
            }
        )
        print(
            f"outliers {name} ({nb_neighbors}, {std_ratio}): {int(removed.sum())} of {len(points)} removed, "
            f"threshold {threshold:.9g}, closest point {min_margin:.3g} relative"
        )
    result = {
        "versions": {"numpy": np.__version__, "scipy": scipy.__version__, "open3d": o3d.__version__},
        "clouds": {name: {"file": f"{name}.npy", "points": len(points)} for name, points in clouds.items()},
        "cases": cases,
    }
    (OUT / "outliers.json").write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
