"""Reading and writing meshes, point clouds and Gaussians; arrays in and out; errors."""

import json

import numpy as np
import pytest
import trisplat
from conftest import DATA, REFERENCE


def test_spot_matches_trimesh():
    """Spot read from its OBJ against trimesh on the same `v`/`f` lines (ref_python.py)."""
    ref = json.loads((REFERENCE / "python" / "python.json").read_text())["spot"]
    spot = trisplat.read_mesh(DATA / "spot_triangulated.obj")
    assert spot.vertices.dtype == np.float64 and spot.vertices.shape == (ref["vertices"], 3)
    assert spot.triangles.dtype == np.uint32 and spot.triangles.shape == (ref["triangles"], 3)
    np.testing.assert_allclose(
        [spot.vertices.min(0), spot.vertices.max(0)], ref["bounds"], rtol=0, atol=1e-12
    )
    assert spot.area() == pytest.approx(ref["area"], rel=1e-12)
    assert spot.volume() == pytest.approx(ref["volume"], rel=1e-12)
    stats = spot.stats()
    assert stats["watertight"] == ref["is_watertight"]
    assert stats["winding_consistent"] == ref["is_winding_consistent"]


def test_mesh_round_trip(tmp_path):
    spot = trisplat.read_mesh(DATA / "spot_triangulated.obj")
    for name in ["spot.ply", "spot.obj", "spot.glb"]:
        trisplat.write_mesh(tmp_path / name, spot)
        back = trisplat.read_mesh(tmp_path / name)
        np.testing.assert_array_equal(back.triangles, spot.triangles)
        # PLY writes float32 when every coordinate is one, else double; glTF stores float32.
        np.testing.assert_allclose(back.vertices, spot.vertices, rtol=0, atol=1e-6)


def test_mesh_from_numpy_converts_dtypes():
    vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    mesh = trisplat.Mesh(vertices, np.array([[0, 1, 2]], dtype=np.int64))
    assert mesh.vertices.dtype == np.float64 and mesh.triangles.dtype == np.uint32
    assert mesh.area() == pytest.approx(0.5)
    # A float64 C-contiguous array is kept as is (no copy).
    v = np.zeros((3, 3))
    v[1, 0] = v[2, 1] = 1.0
    assert trisplat.Mesh(v, [[0, 1, 2]]).vertices is v


def test_points_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    pts = rng.random((100, 3), dtype=np.float32)
    normals = np.tile(np.array([0, 0, 1], np.float32), (100, 1))
    trisplat.write_points(tmp_path / "p.ply", trisplat.PointCloud(pts, normals))
    back = trisplat.read_points(tmp_path / "p.ply")
    np.testing.assert_array_equal(back.points, pts)
    np.testing.assert_array_equal(back.normals, normals)
    assert len(back) == 100


def test_gaussian_ply_round_trip_is_bit_exact(tmp_path):
    """LAM's Gaussians (with normals, an extra property) written back byte for byte."""
    source = DATA / "splat" / "lam_offset_subset.ply"
    g = trisplat.read_gaussians(source)
    assert len(g) == 500 and g.sh_degree == 0 and g.extra_names == ["nx", "ny", "nz"]
    trisplat.write_gaussians(tmp_path / "g.ply", g)
    assert (tmp_path / "g.ply").read_bytes() == source.read_bytes()


def test_gaussian_formats(tmp_path):
    mesh = trisplat.read_mesh(DATA / "spot_triangulated.obj")
    world = trisplat.deform(mesh, trisplat.bind(mesh, opacity=0.5), mesh.vertices)
    assert not world.local and world.binding is None
    for name in ["w.ply", "w.glb", "w.spz"]:
        trisplat.write_gaussians(tmp_path / name, world)
        back = trisplat.read_gaussians(tmp_path / name)
        assert len(back) == len(world)
        # PLY and glTF floats are lossless; SPZ quantises positions to 1/4096 by default.
        atol = 1e-3 if name.endswith(".spz") else 0
        np.testing.assert_allclose(back.means, world.means, rtol=0, atol=atol)


def test_errors_name_the_file_and_element(tmp_path):
    with pytest.raises(trisplat.TrisplatError, match="missing.ply"):
        trisplat.read_mesh(tmp_path / "missing.ply")
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    with pytest.raises(trisplat.TrisplatError, match="bad.obj.*line 4"):
        trisplat.read_mesh(bad)
    with pytest.raises(trisplat.TrisplatError, match="mesh: .*triangle 0"):
        trisplat.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 5]]).area()
    with pytest.raises(ValueError, match=r"vertices: expected an array of shape \(N, 3\)"):
        trisplat.Mesh(np.zeros((4, 2)), [[0, 1, 2]])
