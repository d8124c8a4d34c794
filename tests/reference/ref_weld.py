#!/usr/bin/env python3
"""Reference for `trisplat_geometry::cleanup::weld_vertices` with trimesh 5.2.0.

glTF files split vertices at UV and normal seams. trimesh's
`merge_vertices(merge_tex=True, merge_norm=True)` merges them by position alone (rounded to 8
decimals), numbering the merged vertices in order of first occurrence. This script records, for
the skinned glTF fixtures, the vertex count as stored, the welded count, trimesh's old-to-new
vertex map (`inverse`) and whether the welded mesh is watertight and consistently wound.

Output: `fixtures/data/reference/weld/weld.json`. Run with the venv of requirements.txt:
    python tests/reference/ref_weld.py
"""

import json
import pathlib

import numpy as np
import trimesh

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent
DATA = ROOT / "fixtures" / "data"
OUT = DATA / "reference" / "weld" / "weld.json"
MODELS = ["anim/CesiumMan.glb", "anim/RiggedFigure.glb"]


def weld(path):
    scene = trimesh.load(str(DATA / path), process=False)
    (mesh,) = scene.geometry.values()
    stored = len(mesh.vertices)
    welded = mesh.copy()
    # No unreferenced vertices in these files: trimesh's map covers every vertex.
    referenced = np.zeros(stored, bool)
    referenced[mesh.faces.ravel()] = True
    assert referenced.all()
    welded.merge_vertices(merge_tex=True, merge_norm=True)
    # Recover trimesh's old-to-new map: each stored vertex goes to the welded vertex at its
    # (rounded) position, numbered by first occurrence.
    keys = np.round(np.asarray(mesh.vertices) * 1e8).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    inverse = rank[inverse.ravel()]
    assert np.allclose(welded.vertices, np.asarray(mesh.vertices)[np.sort(first)])
    assert len(welded.vertices) == len(order)
    return {
        "file": path,
        "vertices": stored,
        "triangles": len(mesh.faces),
        "welded_vertices": len(welded.vertices),
        "watertight": bool(welded.is_watertight),
        "winding_consistent": bool(welded.is_winding_consistent),
        "map": inverse.tolist(),
    }


def main():
    OUT.parent.mkdir(parents=True, exist_ok=True)
    cases = [weld(m) for m in MODELS]
    doc = {
        "generator": f"tests/reference/ref_weld.py, trimesh {trimesh.__version__}",
        "rule": "merge_vertices(merge_tex=True, merge_norm=True)",
        "cases": cases,
    }
    OUT.write_text(json.dumps(doc, separators=(",", ":")) + "\n")
    for c in cases:
        print(f"{c['file']}: {c['vertices']} -> {c['welded_vertices']} vertices, "
              f"watertight {c['watertight']}, winding consistent {c['winding_consistent']}")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
