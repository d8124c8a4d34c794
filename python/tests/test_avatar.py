"""Binding, deformation, rendering (against gsplat, tests/reference/ref_render_gsplat.py) and
the extraction session frame by frame."""

import json

import numpy as np
import pytest
import trisplat
from conftest import DATA, REFERENCE


def spot():
    return trisplat.read_mesh(DATA / "spot_triangulated.obj")


def test_bound_centres_are_trimesh_triangle_centres():
    ref = json.loads((REFERENCE / "python" / "python.json").read_text())["spot"]
    mesh = spot()
    bound = trisplat.bind(mesh)
    assert bound.local and bound.binding.dtype == np.uint32
    np.testing.assert_array_equal(bound.binding, np.arange(mesh.triangle_count))
    world = trisplat.deform(mesh, bound, mesh.vertices)
    # float32 means of float64 centroids.
    np.testing.assert_allclose(world.means[:64], ref["triangles_center_first_64"], atol=1e-6)
    np.testing.assert_allclose(world.means.mean(0), ref["triangles_center_mean"], atol=1e-6)


@pytest.mark.parametrize("mode", ["binding", "jacobian"])
def test_gaussians_follow_the_mesh(mode):
    mesh = spot()
    bound = trisplat.bind(mesh, per_triangle=3, opacity=0.5)
    deformer = trisplat.Deformer(mesh, mode=mode)
    rest = deformer.deform(bound, mesh.vertices)
    moved = deformer.deform(bound, mesh.vertices + [0.25, -1.0, 2.0])
    np.testing.assert_allclose(moved.means, rest.means + [0.25, -1.0, 2.0], atol=1e-5)
    np.testing.assert_allclose(moved.rotations, rest.rotations, atol=1e-6)
    np.testing.assert_array_equal(moved.opacity_logits, bound.opacity_logits)
    with pytest.raises(trisplat.TrisplatError, match="vert"):
        deformer.deform(bound, mesh.vertices[:10])


def test_attach_binds_world_gaussians_to_their_triangles():
    mesh = spot()
    world = trisplat.deform(mesh, trisplat.bind(mesh), mesh.vertices)
    bound = trisplat.attach(world, mesh)
    np.testing.assert_array_equal(bound.binding, np.arange(mesh.triangle_count))
    again = trisplat.deform(mesh, bound, mesh.vertices)
    np.testing.assert_allclose(again.means, world.means, atol=1e-6)


@pytest.mark.parametrize("camera", range(3))
def test_render_matches_gsplat(camera):
    """Within the Rust parity test's limits (tests/tests/render_gsplat_parity.rs)."""
    scene = trisplat.read_gaussians(DATA / "render" / "random_deg3.ply")
    cam = trisplat.read_cameras(DATA / "render" / "random_cameras.json")[camera]
    out = trisplat.render(scene, cam, outputs=["rgb", "alpha", "depth", "normal"])
    ref = {k: np.load(REFERENCE / "render" / f"random_{cam.name}_{k}.npy") for k in ["rgb", "alpha", "depth"]}
    assert out["rgb"].shape == (cam.height, cam.width, 3) == ref["rgb"].shape
    assert out["alpha"].shape == (cam.height, cam.width) and out["normal"].shape == out["rgb"].shape
    mse = np.mean((out["rgb"].astype(np.float64) - ref["rgb"]) ** 2)
    assert mse == 0 or 10 * np.log10(1 / mse) >= 50
    assert np.abs(out["alpha"] - ref["alpha"]).max() <= 1e-3
    covered = ref["alpha"] > 0.5
    rel = np.abs(out["depth"][covered] - ref["depth"][covered]) / ref["depth"][covered]
    assert rel.max() <= 1e-4
    # Ray depth keeps the coverage and tilts each splat's depth; an unknown rule is refused.
    ray = trisplat.render(scene, cam, outputs=["alpha", "depth"], splat_depth="ray")
    np.testing.assert_array_equal(ray["alpha"], out["alpha"])
    assert np.isfinite(ray["depth"]).all() and np.abs(ray["depth"] - out["depth"]).max() > 1e-4
    with pytest.raises(ValueError, match="splat_depth"):
        trisplat.render(scene, cam, splat_depth="centre")


def test_render_refuses_local_gaussians():
    mesh = spot()
    cam = trisplat.Camera.look_at([0, 0, 3], [0, 0, 0], 32, 32)
    with pytest.raises(trisplat.TrisplatError, match="local triangle frames"):
        trisplat.render(trisplat.bind(mesh), cam)
    with pytest.raises(ValueError, match="output 'colour'|output \"colour\""):
        trisplat.render(trisplat.deform(mesh, trisplat.bind(mesh), mesh.vertices), cam, outputs=["colour"])


def test_camera_round_trip():
    cam = trisplat.Camera.look_at([0, 0, 3], [0, 0, 0], 64, 48, fov_y=50)
    again = trisplat.Camera(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, cam.rotation, cam.position)
    np.testing.assert_allclose(again.rotation, cam.rotation, atol=1e-12)
    np.testing.assert_allclose(cam.position, [0, 0, 3])
    # The camera looks down -z: its z axis (third column) is world -z.
    np.testing.assert_allclose(cam.rotation[:, 2], [0, 0, -1], atol=1e-12)


def test_session_frame_by_frame():
    session = trisplat.Session(
        DATA / "anim" / "RiggedFigure.glb", methods=["delaunay", "alpha"], frames="0..2", gt="template",
        topology="per-frame",  # every frame meshed (the incremental Delaunay's record per frame)
    )
    assert session.frames == [0, 1]
    assert len(session.gaussians) > 0 and session.gaussians.local
    for f in session.frames:
        result = session.frame(f)
        assert result["frame"] == f and set(result["methods"]) == {"delaunay", "alpha"}
        for name, m in result["methods"].items():
            assert m["mesh"].triangle_count > 0, name
            assert 0 < m["metrics"]["fscore"] <= 1
            # The method's frame record, as the run's events and report.json carry it.
            assert m["frame"] == f and m["time"] == result["time"], name
            assert m["faces"] == m["mesh"].triangle_count, name
            assert m["vertices"] == m["mesh"].vertex_count, name
            assert m["ms"] > 0 and isinstance(m["watertight"], bool), name
        assert result["methods"]["delaunay"]["delaunay"]["frame"] == f
        np.testing.assert_array_equal(session.positions(f).shape, (session.template.vertex_count, 3))
    with pytest.raises(trisplat.TrisplatError):
        trisplat.Session(DATA / "missing.glb")


def test_session_of_a_lam_avatar_folder():
    """The folder stands for its template and per-vertex Gaussians (extract --avatar), with
    extract's other options by name."""
    lam = DATA / "lam_mini"
    session = trisplat.Session(
        lam, animation=str(lam / "expression.json"), methods=["tsdf", "alpha"], frames="0..2",
        gt="gaussians", tsdf_depth="expected", views=6, resolution=64, alpha_keep_clusters=1,
        tau=0.002,
    )
    assert session.frames == [0, 1]
    assert len(session.gaussians) == session.template.vertex_count  # one per vertex (LAM)
    result = session.frame(1)
    for name, m in result["methods"].items():
        assert m["mesh"].triangle_count > 0, name
        assert m["metrics"]["tau"] == 0.002 and m["metrics"]["tau_fraction"] is None, name
    assert result["methods"]["alpha"]["metrics"]["structure"]["components"] == 1
    assert isinstance(session.unused_channels, list)
    used = session.gaussians_used  # the mouth's and eyes' inner Gaussians render nothing
    assert used["hidden"] > 0 and used["floaters"] == 0 and used["floater_std_ratio"] is None
    assert used["kept"] + used["hidden"] == used["total"] == len(session.gaussians)
    assert used["poses"] == 5  # the rest pose and 4 frames spread over the 10-frame track
    every = trisplat.Session(lam, animation=str(lam / "expression.json"), methods=["alpha"],
                             min_contribution=0.0, floater_std_ratio=1.0, tsdf_alpha_cut=0.25)
    assert every.gaussians_used["hidden"] == 0 and every.gaussians_used["floaters"] > 0
    with pytest.raises(ValueError, match="brings its own"):
        trisplat.Session(lam, gaussians=lam / "offset.ply")
    with pytest.raises(ValueError, match="layout"):
        trisplat.Session(DATA / "anim" / "RiggedFigure.glb", layout="flat")
    with pytest.raises(ValueError, match="tsdf_depth"):
        trisplat.Session(DATA / "anim" / "RiggedFigure.glb", tsdf_depth="mean")
    with pytest.raises(ValueError, match="tsdf_splat_depth"):
        trisplat.Session(DATA / "anim" / "RiggedFigure.glb", tsdf_splat_depth="centre")
    with pytest.raises(ValueError, match="not both"):
        trisplat.Session(DATA / "anim" / "RiggedFigure.glb", gt="template", gt_sequence="x/*.ply")
