"""eval against scipy's cKDTree and trimesh (tests/reference/ref_metrics.py), and its keys
against `trisplat eval --json` (docs/conventions.md §10)."""

import json

import numpy as np
import pytest
import trisplat
from conftest import DATA, REFERENCE

METRICS = REFERENCE / "metrics"

# The keys of `trisplat eval --json` (cli/src/commands/eval.rs, docs/conventions.md §10).
EVAL_KEYS = {
    "command", "accuracy", "completeness", "chamfer_l1", "chamfer_l2", "normal_consistency",
    "normal_angle_deg", "n_pred", "n_gt", "thresholds", "seconds", "gt_bbox_diagonal",
    "pred_structure", "gt_structure", "area_ratio", "shared_vertex_fraction", "relation",
}
THRESHOLD_KEYS = {"tau", "tau_fraction", "precision", "recall", "fscore"}
STRUCTURE_KEYS = {
    "vertices", "triangles", "area", "components", "largest_component_area_fraction", "boundary_edges",
    "non_manifold_edges", "watertight", "winding_consistent",
}


def test_point_mode_matches_scipy():
    ref = json.loads((METRICS / "metrics.json").read_text())
    m = trisplat.eval(METRICS / "pred.ply", METRICS / "gt.ply", taus=ref["taus"])
    want = ref["point"]
    assert m["n_pred"] == want["n_pred"] and m["n_gt"] == want["n_gt"]
    # eval moves both clouds to the ground truth's centre (in f64, stored in f32) before
    # measuring, so distances move by float32 rounding of the coordinates: 1e-5 relative.
    for key in ["accuracy", "completeness", "chamfer_l1", "chamfer_l2", "normal_consistency",
                "normal_angle_deg"]:
        assert m[key] == pytest.approx(want[key], rel=1e-5), key
    for ours, theirs in zip(m["thresholds"], want["thresholds"]):
        assert ours["tau"] == theirs["tau"] and ours["tau_fraction"] is None
        for key in ["precision", "recall", "fscore"]:
            assert ours[key] == pytest.approx(theirs[key], abs=2 / want["n_pred"]), key
    assert m["pred_structure"] is None and m["relation"] == "accuracy"


def test_surface_mode_matches_trimesh():
    """Points against Spot's triangles: exact distances, as trimesh's closest points."""
    ref = json.loads((METRICS / "metrics.json").read_text())
    spot = trisplat.read_mesh(DATA / "spot_triangulated.obj")
    # The reference measured against Spot's float32 coordinates.
    spot32 = trisplat.Mesh(spot.vertices.astype(np.float32), spot.triangles)
    pred = trisplat.read_points(METRICS / "pred.ply")
    m = trisplat.eval(pred, spot32, taus=ref["taus"], surface=True, samples=2000)
    assert m["accuracy"] == pytest.approx(ref["surface"]["accuracy"], rel=1e-5)


def test_keys_are_those_of_the_command():
    spot = trisplat.read_mesh(DATA / "spot_triangulated.obj")
    smooth = trisplat.read_mesh(DATA / "spot_taubin.ply")
    m = trisplat.eval(smooth, spot, samples=5000)
    assert set(m) == EVAL_KEYS and m["command"] == "eval"
    assert all(set(t) == THRESHOLD_KEYS for t in m["thresholds"])
    assert set(m["pred_structure"]) == STRUCTURE_KEYS == set(m["gt_structure"])
    assert [t["tau_fraction"] for t in m["thresholds"]] == [0.001, 0.0025, 0.005, 0.01]
    assert 0 < m["chamfer_l1"] < 0.05 and m["relation"] == "accuracy"
    # The same mesh scored against itself is labelled self-consistency.
    assert trisplat.eval(spot, spot, samples=1000)["relation"] == "self-consistency"


def test_eval_errors():
    spot = trisplat.read_mesh(DATA / "spot_triangulated.obj")
    pts = trisplat.read_points(METRICS / "pred.ply")
    with pytest.raises(trisplat.TrisplatError, match="need a mesh input"):
        trisplat.eval(pts, pts, surface=True)
    with pytest.raises(TypeError, match="prediction: expected a path"):
        trisplat.eval(3, spot)
