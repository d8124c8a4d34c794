#!/usr/bin/env python3
"""Opens trisplat's USD mesh cache with Pixar's own USD library (PyPI `usd-core`) and checks it
against the per-frame PLY files it was made from.

    check_usd_cache.py CACHE.usda FRAME_DIR [--frames N]

- the stage opens, its default prim holds one `Mesh`, and every validator USD registers
  (`UsdValidation`, what `usdchecker` runs) reports no error;
- `points` has one time sample per frame file (N, when given), at increasing time codes
  inside [startTimeCode, endTimeCode];
- at frame k's time code, `points` equals frame k's vertices rounded to float32, exactly, and
  `faceVertexIndices` / `faceVertexCounts` are frame k's triangles (the topology samples hold
  between keys), and `extent` is the points' bounding box.

Exit 0 when every check holds; 1 with the first difference otherwise. The frame files are read
with a small reader of their binary little-endian PLY (the format trisplat writes), so the only
third-party code is USD's.
"""

import argparse
import pathlib
import sys

import numpy as np
from pxr import Usd, UsdGeom, UsdValidation


def read_ply(path):
    """Vertices (n, 3) float64 and triangles (m, 3) of a binary little-endian PLY."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise SystemExit(f"{path}: not a binary little-endian PLY")
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4", "uint": "<u4"}
    elements = []
    for line in header:
        words = line.split()
        if words[:1] == ["element"]:
            elements.append((words[1], int(words[2]), []))
        elif words[:1] == ["property"]:
            elements[-1][2].append(words[1:])
    offset = end
    vertices = np.zeros((0, 3))
    faces = np.zeros((0, 3), dtype=np.int64)
    for name, count, props in elements:
        if name == "vertex":
            dtype = np.dtype([(p[-1], types[p[0]]) for p in props])
            rows = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            vertices = np.stack([rows["x"], rows["y"], rows["z"]], axis=1).astype(np.float64)
            offset += dtype.itemsize * count
        elif name == "face":
            if props != [["list", "uchar", "int", "vertex_indices"]]:
                raise SystemExit(f"{path}: faces are not 'list uchar int vertex_indices'")
            dtype = np.dtype([("n", "u1"), ("v", "<i4", (3,))])
            rows = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            if count and not np.all(rows["n"] == 3):
                raise SystemExit(f"{path}: a face is not a triangle")
            faces = rows["v"].astype(np.int64)
            offset += dtype.itemsize * count
        else:
            raise SystemExit(f"{path}: unexpected element {name}")
    return vertices, faces


def fail(message):
    print(f"FAIL: {message}")
    sys.exit(1)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("cache", type=pathlib.Path)
    parser.add_argument("frame_dir", type=pathlib.Path)
    parser.add_argument("--frames", type=int)
    args = parser.parse_args()

    files = sorted(args.frame_dir.glob("frame_*.ply"))
    if args.frames is not None and len(files) != args.frames:
        fail(f"{args.frame_dir} holds {len(files)} frame files, expected {args.frames}")
    stage = Usd.Stage.Open(str(args.cache))
    if stage is None:
        fail(f"{args.cache}: USD could not open it")
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    errors = context.Validate(stage)
    if errors:
        fail(f"{args.cache}: USD's validators report " +
             "; ".join(f"{e.GetName()}: {e.GetMessage()}" for e in errors))
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    if len(meshes) != 1 or not meshes[0].GetPath().HasPrefix(stage.GetDefaultPrim().GetPath()):
        fail(f"{args.cache}: expected one Mesh under the default prim, found {meshes}")
    mesh = UsdGeom.Mesh(meshes[0])
    codes = mesh.GetPointsAttr().GetTimeSamples()
    if len(codes) != len(files):
        fail(f"points has {len(codes)} time samples for {len(files)} frame files")
    if list(codes) != sorted(codes):
        fail("time codes do not increase")
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    if codes and (codes[0] != start or codes[-1] != end):
        fail(f"time samples {codes[0]}..{codes[-1]} but stage range {start}..{end}")
    keys = 0
    for k, (code, file) in enumerate(zip(codes, files)):
        vertices, faces = read_ply(file)
        time = Usd.TimeCode(code)
        points = np.array(mesh.GetPointsAttr().Get(time), dtype=np.float32).reshape(-1, 3)
        expected = vertices.astype(np.float32)
        if points.shape != expected.shape or not np.array_equal(points, expected):
            fail(f"frame {k} ({file.name}): points differ from the PLY's vertices as float32")
        indices = np.array(mesh.GetFaceVertexIndicesAttr().Get(time), dtype=np.int64)
        counts = np.array(mesh.GetFaceVertexCountsAttr().Get(time), dtype=np.int64)
        if not np.array_equal(indices, faces.reshape(-1)) or not np.all(counts == 3) \
                or len(counts) != len(faces):
            fail(f"frame {k} ({file.name}): topology differs from the PLY's triangles")
        if code in mesh.GetFaceVertexIndicesAttr().GetTimeSamples():
            keys += 1
        extent = np.array(mesh.GetExtentAttr().Get(time), dtype=np.float32)
        if len(expected) and not np.array_equal(
                extent, np.stack([expected.min(axis=0), expected.max(axis=0)])):
            fail(f"frame {k} ({file.name}): extent is not the points' bounding box")
    rate = stage.GetTimeCodesPerSecond()
    print(f"ok: {args.cache}: {len(codes)} time samples equal to the frames "
          f"({rate:g} time codes per second), {keys} topology key(s)")


if __name__ == "__main__":
    main()
