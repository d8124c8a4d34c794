"""Thread control: set_num_threads/get_num_threads, and results that do not depend on it."""

import numpy as np
import pytest
import trisplat
from conftest import DATA


def test_thread_count_is_set_and_reset():
    default = trisplat.get_num_threads()
    assert default >= 1
    try:
        trisplat.set_num_threads(1)
        assert trisplat.get_num_threads() == 1
        trisplat.set_num_threads(3)
        assert trisplat.get_num_threads() == 3
    finally:
        trisplat.set_num_threads(None)
    assert trisplat.get_num_threads() == default
    trisplat.set_num_threads(0)
    assert trisplat.get_num_threads() == default
    with pytest.raises(ValueError, match="expected 1 to 1024"):
        trisplat.set_num_threads(100_000)
    assert trisplat.get_num_threads() == default


def test_results_do_not_depend_on_the_thread_count():
    spot = trisplat.read_mesh(DATA / "spot_triangulated.obj")
    smooth = trisplat.read_mesh(DATA / "spot_taubin.ply")
    centre = spot.vertices.mean(axis=0)
    radius = float(np.linalg.norm(spot.vertices - centre, axis=1).max())
    camera = trisplat.sphere_rig(centre, radius, 1, 64, 48)[0]
    gaussians = trisplat.bind(spot, per_triangle=2, opacity=0.9)
    world = trisplat.deform(spot, gaussians, spot.vertices)
    results = []
    for n in (1, 2, None):
        trisplat.set_num_threads(n)
        m = trisplat.eval(smooth, spot, samples=3000)
        images = trisplat.render(world, camera)
        results.append((m["chamfer_l1"], m["thresholds"], images["rgb"].copy()))
    trisplat.set_num_threads(None)
    for other in results[1:]:
        assert other[0] == results[0][0] and other[1] == results[0][1]
        np.testing.assert_array_equal(other[2], results[0][2])
