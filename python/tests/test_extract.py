"""Surfaces against Open3D and scipy: TSDF (Open3D 0.20's UniformTSDFVolume, tests/reference/
ref_tsdf.py), alpha shapes (Open3D's create_from_point_cloud_alpha_shape, ref_alpha.py), 3D
Delaunay (scipy/Qhull, ref_python.py). Tolerances as the Rust tests of the same fixtures
(tests/tests/extract_tsdf.rs, extract_alpha.rs)."""

import json

import numpy as np
import pytest
import trisplat
from conftest import DATA, REFERENCE

TSDF = REFERENCE / "tsdf"


def test_tsdf_matches_open3d():
    ref = json.loads((TSDF / "open3d.json").read_text())
    cameras = trisplat.read_cameras(TSDF / "cameras.json")
    assert len(cameras) == ref["views"]
    depths = [np.load(TSDF / f"{c.name}_depth.npy") for c in cameras]
    mesh = trisplat.tsdf(cameras, depths, voxel=ref["voxel"], trunc=ref["trunc"])
    # Open3D's rules but for the depth read between pixel centres (docs/conventions.md §6):
    # counts within 5% and volume within 1%, as tests/tests/extract_tsdf.rs.
    assert mesh.vertex_count == pytest.approx(ref["vertices"], rel=5e-2)
    assert mesh.triangle_count == pytest.approx(ref["triangles"], rel=5e-2)
    assert mesh.volume() == pytest.approx(ref["signed_volume"], rel=1e-2)
    stats = mesh.stats()
    assert stats["boundary_edges"] == 0 and stats["non_manifold_edges"] == 0
    # Chamfer to Spot no more than 5% above Open3D's (surface mode, as the reference).
    spot = trisplat.read_mesh(REFERENCE / "smoothing" / "spot.ply")
    ours = trisplat.eval(mesh, spot, surface=True)["chamfer_l1"]
    assert ours <= 1.05 * ref["chamfer"]["chamfer_l1"]


def test_tsdf_checks_image_sizes():
    cameras = trisplat.read_cameras(TSDF / "cameras.json")[:2]
    with pytest.raises(ValueError, match=r"depths\[1\]: shape"):
        trisplat.tsdf(cameras, [np.zeros((48, 48), np.float32), np.zeros((4, 4), np.float32)])


def sorted_triples(mesh, index):
    """The mesh's triangles as sorted triples of input point indices."""
    ids = np.array([index[tuple(v)] for v in mesh.vertices.astype(np.float32).tolist()])
    return {tuple(sorted(t)) for t in ids[mesh.triangles].tolist()}


@pytest.mark.parametrize("case", range(5))
def test_alpha_shape_matches_open3d(case):
    ref = json.loads((REFERENCE / "alpha" / "alpha.json").read_text())["cases"][case]
    points = trisplat.read_points(REFERENCE / "alpha" / ref["input"]).points
    index = {tuple(p): i for i, p in enumerate(points.tolist())}
    mesh = trisplat.alpha_shape(points, ref["alpha"])
    theirs = {tuple(sorted(t)) for t in np.reshape(ref["triangles"], (-1, 3)).tolist()}
    # Open3D's set exactly (no tetrahedron's circumradius ties with α on these inputs).
    assert sorted_triples(mesh, index) == theirs
    assert mesh.triangle_count == ref["open3d_triangles"]


def test_delaunay_matches_scipy():
    ref = json.loads((REFERENCE / "python" / "python.json").read_text())["delaunay"]
    points = np.array(ref["points"], dtype=np.float32)
    tets = trisplat.delaunay(points)
    assert tets.dtype == np.uint32 and tets.shape[1] == 4
    ours = {tuple(t) for t in np.sort(tets, axis=1).tolist()}
    assert ours == {tuple(t) for t in ref["tetrahedra_sorted"]}
    # Positive in Shewchuk's orient3d convention: (p1 - p0) x (p2 - p0) . (p3 - p0) < 0.
    p = points.astype(np.float64)[tets]
    volumes = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    assert (volumes < 0).all()


def test_degenerate_points_give_empty_results():
    plane = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    assert trisplat.delaunay(plane).shape == (0, 4)
    assert trisplat.alpha_shape(plane, 10.0).triangle_count == 0
    with pytest.raises(trisplat.TrisplatError, match="point 1"):
        trisplat.delaunay([[0, 0, 0], [np.nan, 0, 0], [0, 1, 0], [0, 0, 1]])
