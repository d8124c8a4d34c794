"""Cut-down LAM avatar for the tests (fixtures/data/lam_mini), from LAM's p2-1 export.

Keeps the face around the mouth: the vertices of skin.glb within RADIUS of CENTRE, the
triangles among them, three ARKit morph targets, the skin (every node and joint of skin.glb,
their weights on the kept vertices), their rows of offset.ply (values unchanged,
same header), vertex_order.json restricted to them (same relative order), and the first
FRAMES frames of test_expression_1s.json for the kept targets plus `tongueOut`, which drives
nothing, and their `head_pose` (which turns the joint named `head`).

Usage: python make_lam_fixture.py ../shared/data/avatars/lam_p2-1 fixtures/data/lam_mini
Pinned: numpy 2.4.6, pygltflib 1.16.5, plyfile 1.1.5 (requirements.txt). Source licence MIT
(LAM_WebRender), kept beside the output as LICENSE.
"""

import json
import shutil
import struct
import sys
from pathlib import Path

import numpy as np
import plyfile
import pygltflib

CENTRE = np.array([0.0, 1.60, 0.09])
RADIUS = 0.035
TARGETS = ["jawOpen", "mouthSmileLeft", "eyeBlinkLeft"]
FRAMES = 10


DTYPES = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}


def read_view(g, blob, view_index, offset, dtype, count):
    view = g.bufferViews[view_index]
    start = (view.byteOffset or 0) + (offset or 0)
    return np.frombuffer(blob, dtype, count=count, offset=start)


def accessor(g, blob, index):
    """An accessor's values as [count, width], sparse accessors included."""
    a = g.accessors[index]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[a.type]
    dtype = DTYPES[a.componentType]
    if a.bufferView is None:
        values = np.zeros((a.count, width), dtype)
    else:
        values = read_view(g, blob, a.bufferView, a.byteOffset, dtype, a.count * width).reshape(a.count, width).copy()
    if a.sparse is not None:
        s = a.sparse
        rows = read_view(g, blob, s.indices.bufferView, s.indices.byteOffset, DTYPES[s.indices.componentType], s.count)
        values[rows] = read_view(g, blob, s.values.bufferView, s.values.byteOffset, dtype, s.count * width).reshape(s.count, width)
    return values


def main(src, dst):
    src, dst = Path(src), Path(dst)
    dst.mkdir(parents=True, exist_ok=True)
    g = pygltflib.GLTF2().load(str(src / "skin.glb"))
    blob = g.binary_blob()
    prim = g.meshes[0].primitives[0]
    names = g.meshes[0].extras["targetNames"]
    pos = accessor(g, blob, prim.attributes.POSITION).astype(np.float32)
    tris = accessor(g, blob, prim.indices).reshape(-1, 3)
    keep = np.linalg.norm(pos - CENTRE, axis=1) < RADIUS
    tris = tris[keep[tris].all(axis=1)]
    used = np.unique(tris)
    new_of = np.full(len(pos), -1, np.int64)
    new_of[used] = np.arange(len(used))
    tris = new_of[tris].astype(np.uint32)
    positions = pos[used]
    deltas = [accessor(g, blob, prim.targets[names.index(n)]["POSITION"])[used].astype(np.float32) for n in TARGETS]

    # glTF: positions, indices, one POSITION delta per target; mesh.extras.targetNames.
    chunks, views, accessors = [], [], []

    def add(array, target, kind, component, bounds):
        data = array.tobytes()
        views.append(pygltflib.BufferView(buffer=0, byteOffset=sum(len(c) for c in chunks), byteLength=len(data), target=target))
        chunks.append(data + b"\0" * (-len(data) % 4))
        acc = pygltflib.Accessor(bufferView=len(views) - 1, componentType=component, count=len(array), type=kind)
        if bounds:
            acc.min = array.min(axis=0).tolist()
            acc.max = array.max(axis=0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    joints = accessor(g, blob, prim.attributes.JOINTS_0)[used]
    weights = accessor(g, blob, prim.attributes.WEIGHTS_0)[used].astype(np.float32)
    inverse_bind = accessor(g, blob, g.skins[0].inverseBindMatrices).astype(np.float32)
    p = add(positions, pygltflib.ARRAY_BUFFER, "VEC3", pygltflib.FLOAT, True)
    j = add(joints.astype(np.uint16 if joints.dtype == np.uint16 else np.uint8), pygltflib.ARRAY_BUFFER, "VEC4", pygltflib.UNSIGNED_SHORT if joints.dtype == np.uint16 else pygltflib.UNSIGNED_BYTE, False)
    w = add(weights, pygltflib.ARRAY_BUFFER, "VEC4", pygltflib.FLOAT, False)
    ibm = add(inverse_bind, None, "MAT4", pygltflib.FLOAT, False)
    i = add(tris.reshape(-1), pygltflib.ELEMENT_ARRAY_BUFFER, "SCALAR", pygltflib.UNSIGNED_INT, False)
    targets = [{"POSITION": add(d, pygltflib.ARRAY_BUFFER, "VEC3", pygltflib.FLOAT, True)} for d in deltas]
    buffer = b"".join(chunks)
    out = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0", generator="trisplat tests/reference/make_lam_fixture.py"),
        scene=0,
        scenes=[pygltflib.Scene(nodes=list(g.scenes[g.scene or 0].nodes))],
        nodes=g.nodes,
        skins=[pygltflib.Skin(joints=list(g.skins[0].joints), inverseBindMatrices=ibm, skeleton=g.skins[0].skeleton)],
        meshes=[pygltflib.Mesh(name="head", primitives=[pygltflib.Primitive(attributes=pygltflib.Attributes(POSITION=p, JOINTS_0=j, WEIGHTS_0=w), indices=i, targets=targets)], weights=[0.0] * len(TARGETS), extras={"targetNames": TARGETS})],
        accessors=accessors,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=len(buffer))],
    )
    out.set_binary_blob(buffer)
    out.save_binary(str(dst / "skin.glb"))

    ply = plyfile.PlyData.read(str(src / "offset.ply"))
    rows = ply["vertex"].data[used]
    plyfile.PlyData([plyfile.PlyElement.describe(rows, "vertex")], byte_order="<").write(str(dst / "offset.ply"))

    order = np.array(json.load(open(src / "vertex_order.json")))
    kept = new_of[order]
    json.dump(kept[kept >= 0].tolist(), open(dst / "vertex_order.json", "w"))

    track = json.load(open(src / "test_expression_1s.json"))
    columns = [track["names"].index(n) for n in TARGETS + ["tongueOut"]]
    frames = [{"weights": [f["weights"][c] for c in columns], "time": f["time"], "rotation": []} for f in track["frames"][:FRAMES]]
    json.dump({"names": TARGETS + ["tongueOut"], "frames": frames, "head_pose": track["head_pose"][:FRAMES]}, open(dst / "expression.json", "w"), indent=1)
    shutil.copy(src / "LICENSE", dst / "LICENSE")
    print(f"{len(used)} vertices, {len(tris)} triangles, {len(TARGETS)} targets, {FRAMES} frames")


if __name__ == "__main__":
    main(*sys.argv[1:3])
