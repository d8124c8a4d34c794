"""Reference vertex/face counts for mesh I/O, from trimesh 5.2.0 (and Open3D 0.20.0 in the check).

How trimesh is asked (the options every count here uses):

    trimesh.load(path, force="mesh", process=False)

- `process=False` keeps vertices as stored (no merging), so counts are the file's own.
- OBJ: trimesh splits vertices wherever texture coordinates (or normals) are indexed differently
  from positions, per `usemtl` group; our `ObjVertices::SplitSeams` mode matches that. OBJ files
  are opened as file objects without a resolver, so trimesh does not load the `.mtl` and its
  texture (it needs Pillow for the image, which the pinned environment does not have; the counts
  do not depend on materials, the `usemtl` grouping is read from the OBJ itself).
- glTF/GLB: every primitive of every node instance of scene `scene` (or 0), node transforms
  applied, skins and morph targets ignored.
- A PLY without faces (a point cloud) loads as an empty mesh with `force="mesh"`; for those the
  vertex count is taken from `trimesh.load(path)` (a PointCloud) and faces are 0.

Modes:
    python ref_io.py                       # writes fixtures/data/reference/io/trimesh_counts.json
    python ref_io.py --check-shared BINARY # converts every mesh of ../shared/data with
                                           # `BINARY convert` to .ply/.obj/.glb and checks that
                                           # trimesh and Open3D read the outputs with the counts
                                           # trimesh reports for the input; prints a table
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "fixtures" / "data"
OUT = FIXTURES / "reference" / "io" / "trimesh_counts.json"
# The shared data folder beside the repository checkout (../shared/data).
SHARED = ROOT.parent / "shared" / "data"

# Fixture meshes whose counts the Rust test compares exactly (paths relative to fixtures/data).
FIXTURE_MESHES = [
    "spot_triangulated.obj",
    "gltf/SimpleSkin.gltf",
    "gltf/RiggedSimple.glb",
    "gltf/SimpleMorph/SimpleMorph.gltf",
    "gltf/AnimatedMorphCube/AnimatedMorphCube.gltf",
    "gltf/MorphPrimitivesTest/MorphPrimitivesTest.gltf",
    "io/quad_uchar_int_ascii.ply",
    "io/quad_int_int_le.ply",
    "io/quad_uchar_uint_be.ply",
    "io/unknown_props.ply",
]

MESH_SUFFIXES = {".obj", ".ply", ".gltf", ".glb"}


class _Arrays:
    """Vertices and faces of trimesh's geometries, concatenated as `force="mesh"` does."""

    def __init__(self, vertices, faces):
        self.vertices = vertices
        self.faces = faces


def load_trimesh(path: Path):
    """trimesh's view of a mesh file, with the options stated in the module docstring."""
    if path.suffix.lower() == ".obj":
        # trimesh.load(..., force="mesh") builds texture visuals and deep-copies them, which
        # needs Pillow; call its OBJ parser (the same code `load` runs) and concatenate its
        # per-material geometries the way `Scene.to_mesh` does.
        from trimesh.exchange.obj import load_obj

        with open(path, "rb") as f:
            parsed = load_obj(f, process=False)
        parts = list(parsed["geometry"].values()) if "geometry" in parsed else [parsed]
        vertices, faces, offset = [], [], 0
        for part in parts:
            v = np.asarray(part.get("vertices", np.zeros((0, 3))))
            vertices.append(v)
            # Trimesh(faces=...) triangulates quads (and mixed polygons) this way.
            f = part.get("faces", np.zeros((0, 3), int))
            f = trimesh.geometry.triangulate_quads(f) if len(f) else np.zeros((0, 3), int)
            faces.append(np.asarray(f) + offset)
            offset += len(v)
        return _Arrays(np.concatenate(vertices), np.concatenate(faces))
    loaded = trimesh.load(path, process=False)
    if isinstance(loaded, trimesh.Scene):
        # What `force="mesh"` computes (Scene.to_mesh: every geometry instance, transformed,
        # concatenated), without its deep copy of texture visuals, which needs Pillow.
        vertices, faces, offset = [], [], 0
        for node in loaded.graph.nodes_geometry:
            transform, name = loaded.graph[node]
            geometry = loaded.geometry[name]
            if not isinstance(geometry, trimesh.Trimesh):
                continue
            v = trimesh.transform_points(np.asarray(geometry.vertices), transform)
            vertices.append(v)
            faces.append(np.asarray(geometry.faces) + offset)
            offset += len(v)
        if not vertices:
            return _Arrays(np.zeros((0, 3)), np.zeros((0, 3), int))
        return _Arrays(np.concatenate(vertices), np.concatenate(faces))
    if isinstance(loaded, trimesh.Trimesh):
        return loaded
    return _Arrays(np.zeros((0, 3)), np.zeros((0, 3), int))


def counts(path: Path) -> dict:
    mesh = load_trimesh(path)
    n_v, n_f = len(mesh.vertices), len(mesh.faces)
    if n_f == 0 and path.suffix.lower() == ".ply":
        cloud = trimesh.load(path, process=False)
        n_v = len(getattr(cloud, "vertices", []))
        vertices = np.asarray(cloud.vertices)
    else:
        vertices = np.asarray(mesh.vertices)
    out = {"vertices": int(n_v), "faces": int(n_f)}
    if n_v > 0:
        out["bounds"] = [vertices.min(axis=0).tolist(), vertices.max(axis=0).tolist()]
    return out


def counts_or_error(path: Path) -> dict:
    """Counts, or the error trimesh raised (the Rust test skips those entries)."""
    try:
        return counts(path)
    except Exception as e:  # noqa: BLE001 - the reference records what trimesh says
        return {"trimesh_error": f"{type(e).__name__}: {e}"}


def write_fixture_counts() -> None:
    result = {
        "tool": f"trimesh {trimesh.__version__}",
        "options": 'trimesh.load(path, force="mesh", process=False); OBJ opened as a file '
        "object without a resolver (materials not loaded)",
        "files": {name: counts_or_error(FIXTURES / name) for name in FIXTURE_MESHES},
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {OUT.relative_to(ROOT)}")


def open3d_counts(path: Path) -> tuple[int, int]:
    import open3d as o3d

    if path.suffix == ".ply":
        mesh = o3d.io.read_triangle_mesh(str(path))
        if len(mesh.triangles) == 0:
            cloud = o3d.io.read_point_cloud(str(path))
            return len(cloud.points), 0
        return len(mesh.vertices), len(mesh.triangles)
    mesh = o3d.io.read_triangle_mesh(str(path))
    return len(mesh.vertices), len(mesh.triangles)


def point_count(path: Path) -> int:
    """Number of vertices trimesh loads from `path`, whatever geometry it holds."""
    loaded = trimesh.load(path, process=False)
    if isinstance(loaded, trimesh.Scene):
        return sum(
            len(loaded.geometry[name].vertices)
            for name in (loaded.graph[node][1] for node in loaded.graph.nodes_geometry)
        )
    return len(loaded.vertices)


def merged_count(ply_path: Path) -> int:
    """Vertices left after merging identical (position, uv, normal) rows: what Open3D reports
    for OBJ and glTF, which it reads through Assimp with JoinIdenticalVertices always on."""
    mesh = trimesh.load(ply_path, process=False)
    rows = [np.asarray(mesh.vertices)]
    uv = getattr(getattr(mesh, "visual", None), "uv", None)
    if uv is not None:
        rows.append(np.asarray(uv))
    if "vertex_normals" in mesh._cache:
        rows.append(np.asarray(mesh.vertex_normals))
    return len(np.unique(np.hstack(rows), axis=0))


def check_shared(binary: str) -> int:
    files = sorted(p for p in SHARED.rglob("*") if p.suffix.lower() in MESH_SUFFIXES)
    failures = 0
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for src in files:
            want = counts(src)
            expected = (want["vertices"], want["faces"])
            merged = None
            try:
                o3d_input = open3d_counts(src)
            except Exception:  # noqa: BLE001 - Open3D may not read every input format
                o3d_input = None
            row = [str(src.relative_to(SHARED)), f"{expected[0]}/{expected[1]}"]
            for ext in (".ply", ".obj", ".glb"):
                dst = Path(tmp) / (src.stem + ext)
                run = subprocess.run(
                    [binary, "--quiet", "convert", str(src), str(dst)],
                    capture_output=True,
                    text=True,
                )
                if run.returncode != 0:
                    row.append(f"FAIL({run.stderr.strip()[:60]})")
                    failures += 1
                    continue
                if want["faces"] == 0 and ext != ".ply":
                    # A point cloud: only PLY keeps it as points for both tools.
                    got_t = (point_count(dst), 0)
                    got_o = got_t
                else:
                    t = counts(dst)
                    got_t = (t["vertices"], t["faces"])
                    got_o = open3d_counts(dst)
                # Open3D reads OBJ and glTF through Assimp with JoinIdenticalVertices always on,
                # so it merges vertices whose position, uv and normal are all equal: accept its
                # count when it equals that merge of our own PLY output, or what Open3D
                # itself reports for the input (Assimp also merges within a tolerance).
                if ext == ".ply" and want["faces"] > 0:
                    merged = merged_count(dst)
                o3d_ok = (
                    got_o == expected
                    or got_o == (merged, expected[1])
                    or got_o == o3d_input
                )
                ok = got_t == expected and o3d_ok
                failures += not ok
                if ok and got_o == expected:
                    mark = "ok"
                elif ok:
                    why = "identical vertices merged" if got_o[0] == merged else "as for the input"
                    mark = f"ok (open3d {got_o[0]}/{got_o[1]}: {why})"
                else:
                    mark = (
                        f"trimesh {got_t[0]}/{got_t[1]} open3d {got_o[0]}/{got_o[1]}"
                        f" (merged: {merged}, open3d on the input: {o3d_input})"
                    )
                row.append(mark)
                dst.unlink(missing_ok=True)
            rows.append(row)
    header = ["file", "trimesh v/f", ".ply", ".obj", ".glb"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(f"{failures} failures")
    return 1 if failures else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check-shared", metavar="BINARY")
    args = parser.parse_args()
    if args.check_shared:
        return check_shared(args.check_shared)
    write_fixture_counts()
    return 0


if __name__ == "__main__":
    sys.exit(main())
