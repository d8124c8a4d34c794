#!/usr/bin/env python3
"""Reference evaluation of glTF animations (skins, morph targets, clips) with pygltflib + numpy.

An independent float64 implementation of glTF 2.0 animation evaluation, written from the spec
(not from trisplat's code), used to check `trisplat_geometry::animation::GltfTemplate`:

- node TRS hierarchy (T * R * S, column vectors), matrix nodes as stored;
- samplers: LINEAR (slerp on the shortest path for rotations, via arccos), STEP, CUBICSPLINE
  (Hermite, tangents scaled by the key interval, rotations normalised after); times clamp to the
  first/last key; LINEAR/STEP rotation keys are normalised on read;
- morph targets: p = base + sum_t w_t * delta_t, weights from the clip, else node.weights, else
  mesh.weights, else 0; sparse accessors and normalised integers decoded per the spec;
- skins: every JOINTS_n/WEIGHTS_n set, weights divided by their sum (zero sum: the node's world
  transform), vertex = sum_i w_i * world(joint_i) @ inverseBind_i @ p; the mesh node's own
  transform is ignored for skinned meshes;
- vertex order: triangle primitives (TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN) of mesh nodes in
  depth-first pre-order from the default scene's roots, primitives in file order
  (strips (a,b,c)/(b,a,c) alternating, fans (v_i, v_i+1, v_0); mirroring nodes reverse the winding).

It also writes `fixtures/data/anim/SyntheticFeatures.gltf`: a small hand-made file with the
features the Khronos samples here lack (STEP and CUBICSPLINE on every path, sparse morph
targets, normalised-integer weights and rotation outputs, 8 joint influences per vertex, a
zero-weight vertex, a matrix node, a triangle strip and fan, node.weights).

Outputs (float64 JSON) go to `fixtures/data/reference/animation/<model>.json`: for each case
(model, clip, times) a subset of vertex positions plus the sum and absolute sum of all positions.
"""

import base64
import json
import pathlib
import struct
import urllib.parse

import numpy as np
import pygltflib

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent
DATA = ROOT / "fixtures" / "data"
OUT = DATA / "reference" / "animation"

# Vertices listed per case (evenly spaced over the vertex array); sums cover all of them.
SUBSET = 96

COMPONENT = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


# ---------------------------------------------------------------------------------------------
# Reading


def load_buffers(g, path):
    out = []
    for b in g.buffers:
        if b.uri is None:
            out.append(bytes(g.binary_blob()))
        elif b.uri.startswith("data:"):
            out.append(base64.b64decode(b.uri.split(";base64,", 1)[1]))
        else:
            out.append((path.parent / urllib.parse.unquote(b.uri)).read_bytes())
    return out


def normalise(values, ctype):
    v = values.astype(np.float64)
    if ctype == 5120:
        return np.maximum(v / 127.0, -1.0)
    if ctype == 5121:
        return v / 255.0
    if ctype == 5122:
        return np.maximum(v / 32767.0, -1.0)
    if ctype == 5123:
        return v / 65535.0
    if ctype == 5125:
        return v / 4294967295.0
    return v


def read_view(g, bufs, view_index, offset, count, ncomp, ctype, stride=None):
    view = g.bufferViews[view_index]
    data = bufs[view.buffer]
    start = (view.byteOffset or 0) + offset
    dtype = np.dtype(COMPONENT[ctype])
    elem = dtype.itemsize * ncomp
    stride = stride or view.byteStride or elem
    rows = [np.frombuffer(data, dtype=dtype, count=ncomp, offset=start + i * stride) for i in range(count)]
    return np.array(rows, dtype=dtype).reshape(count, ncomp)


def read_accessor(g, bufs, index):
    a = g.accessors[index]
    ncomp = NCOMP[a.type]
    if a.bufferView is not None:
        raw = read_view(g, bufs, a.bufferView, a.byteOffset or 0, a.count, ncomp, a.componentType)
    else:
        raw = np.zeros((a.count, ncomp), dtype=COMPONENT[a.componentType])
    raw = raw.copy()
    if a.sparse is not None:
        s = a.sparse
        idx = read_view(g, bufs, s.indices.bufferView, s.indices.byteOffset or 0, s.count, 1,
                        s.indices.componentType, stride=np.dtype(COMPONENT[s.indices.componentType]).itemsize)
        vals = read_view(g, bufs, s.values.bufferView, s.values.byteOffset or 0, s.count, ncomp,
                         a.componentType, stride=np.dtype(COMPONENT[a.componentType]).itemsize * ncomp)
        raw[idx[:, 0].astype(np.int64)] = vals
    if a.normalized:
        return normalise(raw, a.componentType)
    return raw.astype(np.float64)


# ---------------------------------------------------------------------------------------------
# Math (column vectors, quaternions x y z w)


def quat_to_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def trs_matrix(t, r, s):
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(r) @ np.diag(s)
    m[:3, 3] = t
    return m


def slerp(a, b, s):
    d = float(np.dot(a, b))
    if d < 0.0:
        b, d = -b, -d
    if d > 1.0 - 1e-12:
        q = a + s * (b - a)
        return q / np.linalg.norm(q)
    theta = np.arccos(min(d, 1.0))
    q = (np.sin((1 - s) * theta) * a + np.sin(s * theta) * b) / np.sin(theta)
    return q / np.linalg.norm(q)


def sample(times, values, interpolation, width, t, is_rotation):
    """values: (keys * per_key, width) float64."""
    n = len(times)
    cubic = interpolation == "CUBICSPLINE"
    per = 3 if cubic else 1
    vals = values.reshape(n, per, width)
    key_values = vals[:, 1] if cubic else vals[:, 0]
    if is_rotation and not cubic:
        key_values = key_values / np.linalg.norm(key_values, axis=1, keepdims=True)
    if t <= times[0] or n == 1:
        return key_values[0].copy()
    if t >= times[-1]:
        return key_values[-1].copy()
    k = int(np.searchsorted(times, t, side="right")) - 1
    t0, t1 = times[k], times[k + 1]
    dt = t1 - t0
    s = (t - t0) / dt
    if interpolation == "STEP":
        return key_values[k].copy()
    if interpolation == "LINEAR":
        if is_rotation:
            return slerp(key_values[k], key_values[k + 1], s)
        return key_values[k] + s * (key_values[k + 1] - key_values[k])
    v0, b0 = vals[k, 1], vals[k, 2]
    a1, v1 = vals[k + 1, 0], vals[k + 1, 1]
    p = ((2 * s**3 - 3 * s**2 + 1) * v0 + (s**3 - 2 * s**2 + s) * dt * b0
         + (-2 * s**3 + 3 * s**2) * v1 + (s**3 - s**2) * dt * a1)
    if is_rotation:
        p = p / np.linalg.norm(p)
    return p


# ---------------------------------------------------------------------------------------------
# Evaluation


def triangles_of(mode, idx):
    mode = 4 if mode is None else mode
    if mode == 4:
        return idx.reshape(-1, 3)
    if mode == 5:
        return np.array([[idx[i], idx[i + 1], idx[i + 2]] if i % 2 == 0 else [idx[i + 1], idx[i], idx[i + 2]]
                         for i in range(len(idx) - 2)]).reshape(-1, 3)
    if mode == 6:
        return np.array([[idx[i], idx[i + 1], idx[0]] for i in range(1, len(idx) - 1)]).reshape(-1, 3)
    return None


def raw_json(path):
    """The JSON document itself (pygltflib drops node.weights): plain file or GLB chunk 0."""
    data = path.read_bytes()
    if data[:4] == b"glTF":
        length, _kind = struct.unpack_from("<II", data, 12)
        return json.loads(data[20:20 + length])
    return json.loads(data)


class Scene:
    def __init__(self, path):
        self.path = path
        self.g = g = pygltflib.GLTF2().load(str(path))
        self.node_weights = [n.get("weights") for n in raw_json(path).get("nodes", [])]
        self.bufs = load_buffers(g, path)
        self.parent = {}
        for i, n in enumerate(g.nodes):
            for c in n.children or []:
                self.parent[c] = i
        scene = g.scenes[g.scene if g.scene is not None else 0]
        self.instances = []

        def visit(i):
            if g.nodes[i].mesh is not None:
                self.instances.append(i)
            for c in g.nodes[i].children or []:
                visit(c)

        for r in scene.nodes:
            visit(r)
        self.prims = {}
        for m, mesh in enumerate(g.meshes):
            out = []
            for p in mesh.primitives:
                pos = read_accessor(g, self.bufs, p.attributes.POSITION)
                idx = (read_accessor(g, self.bufs, p.indices)[:, 0].astype(np.int64)
                       if p.indices is not None else np.arange(len(pos)))
                tris = triangles_of(p.mode, idx)
                if tris is None:
                    continue
                targets = [read_accessor(g, self.bufs, t["POSITION"]) if t.get("POSITION") is not None
                           else np.zeros_like(pos) for t in (p.targets or [])]
                attrs = p.attributes.__dict__ if hasattr(p.attributes, "__dict__") else {}
                extra = {k: v for k, v in attrs.items()}
                joints, weights = [], []
                s = 0
                while True:
                    j = extra.get(f"JOINTS_{s}")
                    w = extra.get(f"WEIGHTS_{s}")
                    if j is None or w is None:
                        break
                    joints.append(read_accessor(g, self.bufs, j).astype(np.int64))
                    weights.append(read_accessor(g, self.bufs, w))
                    s += 1
                skin = None
                if joints:
                    J = np.concatenate(joints, axis=1)
                    W = np.concatenate(weights, axis=1)
                    sums = W.sum(axis=1, keepdims=True)
                    W = np.where(sums > 0, W / np.where(sums > 0, sums, 1.0), 0.0)
                    skin = (J, W, sums[:, 0] > 0)
                out.append(dict(pos=pos, tris=tris, targets=targets, skin=skin))
            self.prims[m] = out

    def local(self, i, overrides):
        n = self.g.nodes[i]
        if i in overrides:
            t, r, s = overrides[i]
            return trs_matrix(t, r, s)
        if n.matrix is not None and len(n.matrix) == 16:
            return np.array(n.matrix, dtype=np.float64).reshape(4, 4).T
        return trs_matrix(*self.rest_trs(i))

    def rest_trs(self, i):
        n = self.g.nodes[i]
        t = np.array(n.translation if n.translation is not None else [0, 0, 0], dtype=np.float64)
        r = np.array(n.rotation if n.rotation is not None else [0, 0, 0, 1], dtype=np.float64)
        s = np.array(n.scale if n.scale is not None else [1, 1, 1], dtype=np.float64)
        return t, r / np.linalg.norm(r), s

    def world(self, i, overrides, cache):
        if i not in cache:
            m = self.local(i, overrides)
            p = self.parent.get(i)
            cache[i] = m if p is None else self.world(p, overrides, cache) @ m
        return cache[i]

    def evaluate(self, clip, t):
        g = self.g
        overrides, weights = {}, {}
        if clip is not None:
            anim = g.animations[clip]
            for ch in anim.channels:
                smp = anim.samplers[ch.sampler]
                times = read_accessor(g, self.bufs, smp.input)[:, 0]
                vals = read_accessor(g, self.bufs, smp.output)
                node, path = ch.target.node, ch.target.path
                interp = smp.interpolation or "LINEAR"
                if path == "weights":
                    width = len(self.prims[g.nodes[node].mesh][0]["targets"])
                    weights[node] = sample(times, vals.reshape(-1, width), interp, width, t, False)
                    continue
                if node not in overrides:
                    n = g.nodes[node]
                    if n.matrix is not None and len(n.matrix) == 16:
                        raise SystemExit("animated matrix node: not in the reference")
                    overrides[node] = list(self.rest_trs(node))
                width = 4 if path == "rotation" else 3
                v = sample(times, vals.reshape(-1, width), interp, width, t, path == "rotation")
                overrides[node][{"translation": 0, "rotation": 1, "scale": 2}[path]] = v
        cache = {}
        out = []
        for i in self.instances:
            n = g.nodes[i]
            mesh = g.meshes[n.mesh]
            prims = self.prims[n.mesh]
            ntargets = len(prims[0]["targets"]) if prims else 0
            if i in weights:
                w = weights[i]
            elif self.node_weights[i] is not None:
                w = np.array(self.node_weights[i], dtype=np.float64)
            elif mesh.weights is not None:
                w = np.array(mesh.weights, dtype=np.float64)
            else:
                w = np.zeros(ntargets)
            node_world = self.world(i, overrides, cache)
            mats = None
            if n.skin is not None:
                skin = g.skins[n.skin]
                ibm = (read_accessor(g, self.bufs, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
                       if skin.inverseBindMatrices is not None else np.tile(np.eye(4), (len(skin.joints), 1, 1)))
                mats = np.array([self.world(j, overrides, cache) @ ibm[k] for k, j in enumerate(skin.joints)])
            for p in prims:
                pos = p["pos"].copy()
                for wt, d in zip(w, p["targets"]):
                    pos = pos + wt * d
                h = np.concatenate([pos, np.ones((len(pos), 1))], axis=1)
                if mats is not None and p["skin"] is not None:
                    J, W, ok = p["skin"]
                    res = np.zeros((len(pos), 3))
                    for c in range(J.shape[1]):
                        m = mats[J[:, c]]  # (n, 4, 4)
                        res += W[:, c:c + 1] * np.einsum("nij,nj->ni", m, h)[:, :3]
                    res[~ok] = (h[~ok] @ node_world.T)[:, :3]
                else:
                    res = (h @ node_world.T)[:, :3]
                out.append(res)
        return np.concatenate(out, axis=0)

    def triangle_count(self):
        return sum(len(p["tris"]) for i in self.instances for p in self.prims[self.g.nodes[i].mesh])

    def triangles(self):
        out, base, cache = [], 0, {}
        for i in self.instances:
            mirrored = np.linalg.det(self.world(i, {}, cache)) < 0
            for p in self.prims[self.g.nodes[i].mesh]:
                t = p["tris"] + base
                out.append(t[:, [0, 2, 1]] if mirrored else t)
                base += len(p["pos"])
        return np.concatenate(out, axis=0)

    def clip_end(self, clip):
        anim = self.g.animations[clip]
        return max(float(read_accessor(self.g, self.bufs, anim.samplers[c.sampler].input)[-1, 0])
                   for c in anim.channels)


# ---------------------------------------------------------------------------------------------
# The synthetic feature file


def write_synthetic(path):
    """Writes SyntheticFeatures.gltf (data-URI buffer) exercising the features listed above."""
    blob = bytearray()
    views, accessors = [], []

    def add(array, ctype, atype, normalized=False, target=None, minmax=False):
        dtype = np.dtype(COMPONENT[ctype])
        data = np.ascontiguousarray(array, dtype=dtype).tobytes()
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        if target:
            views[-1]["target"] = target
        blob.extend(data)
        a = {"bufferView": len(views) - 1, "componentType": ctype, "count": int(len(array)), "type": atype}
        if normalized:
            a["normalized"] = True
        if minmax:
            arr = np.asarray(array, dtype=np.float64).reshape(len(array), -1)
            a["min"] = [float(x) for x in arr.min(axis=0)]
            a["max"] = [float(x) for x in arr.max(axis=0)]
        accessors.append(a)
        return len(accessors) - 1

    F, U8, U16, I16 = 5126, 5121, 5123, 5122
    # Skinned strip: 2 x 6 grid along +y, 3 joints at y = 0, 1, 2.
    ys = np.arange(6) * 0.5
    pos = np.array([[x, y, 0.0] for y in ys for x in (-0.25, 0.25)], dtype=np.float32)
    nv = len(pos)
    tris = np.array([[2 * i, 2 * i + 1, 2 * i + 3, 2 * i, 2 * i + 3, 2 * i + 2] for i in range(5)]).reshape(-1)
    j0 = np.zeros((nv, 4), dtype=np.uint8)
    w0 = np.zeros((nv, 4), dtype=np.uint8)
    j1 = np.zeros((nv, 4), dtype=np.uint16)
    w1 = np.zeros((nv, 4), dtype=np.uint16)
    rng = np.random.default_rng(7)
    for v in range(nv):
        j0[v] = [0, 1, 2, 1]
        j1[v] = [2, 0, 1, 0]
        w0[v] = rng.integers(0, 200, 4)
        w1[v] = rng.integers(0, 30000, 4)
    w0[5] = 0  # vertex 5: all eight weights zero -> placed by the node's transform
    w1[5] = 0
    w1[6] = 0  # vertex 6: only the first set
    ibm = np.array([np.linalg.inv(trs_matrix([0, y, 0], [0, 0, 0, 1], [1, 1, 1])).T.reshape(-1)
                    for y in (0.0, 1.0, 2.0)], dtype=np.float32)
    d0 = np.zeros((nv, 3), dtype=np.float32)
    d0[:, 0] = np.sign(pos[:, 0]) * 0.1 * (1 + pos[:, 1])
    a_pos = add(pos, F, "VEC3", minmax=True, target=34962)
    a_idx = add(tris, U16, "SCALAR", target=34963)
    a_j0 = add(j0, U8, "VEC4")
    a_w0 = add(w0, U8, "VEC4", normalized=True)
    a_j1 = add(j1, U16, "VEC4")
    a_w1 = add(w1, U16, "VEC4", normalized=True)
    a_ibm = add(ibm, F, "MAT4")
    a_d0 = add(d0, F, "VEC3", minmax=True)
    # Sparse target: only vertices 3, 8, 11 move (no base buffer view: zeros elsewhere).
    sp_idx = np.array([3, 8, 11], dtype=np.uint16)
    sp_val = np.array([[0, 0, 0.3], [0.1, -0.2, 0.0], [0.0, 0.0, -0.4]], dtype=np.float32)
    a_spi = add(sp_idx, U16, "SCALAR")
    a_spv = add(sp_val, F, "VEC3")
    sparse_acc = {"componentType": F, "count": nv, "type": "VEC3",
                  "min": [-0.1, -0.2, -0.4], "max": [0.1, 0.0, 0.3],
                  "sparse": {"count": 3, "indices": {"bufferView": accessors[a_spi]["bufferView"], "componentType": U16},
                             "values": {"bufferView": accessors[a_spv]["bufferView"]}}}
    accessors.append(sparse_acc)
    a_sparse = len(accessors) - 1
    # Morph-only mesh: a triangle strip and a triangle fan, 2 targets.
    strip = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 2, 0], [1, 2.5, 0]], dtype=np.float32)
    fan = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.5], [-1, 0.5, 1]], dtype=np.float32)
    a_strip = add(strip, F, "VEC3", minmax=True)
    a_fan = add(fan, F, "VEC3", minmax=True)
    a_fan_idx = add(np.array([0, 1, 2, 3, 4], dtype=np.uint8), U8, "SCALAR")
    ts0 = add((rng.standard_normal((6, 3)) * 0.2).astype(np.float32), F, "VEC3", minmax=True)
    ts1 = add((rng.standard_normal((6, 3)) * 0.2).astype(np.float32), F, "VEC3", minmax=True)
    tf0 = add((rng.standard_normal((5, 3)) * 0.2).astype(np.float32), F, "VEC3", minmax=True)
    tf1 = add((rng.standard_normal((5, 3)) * 0.2).astype(np.float32), F, "VEC3", minmax=True)
    # Animation 0 ("features"): every path with STEP and CUBICSPLINE.
    def quat(axis, angle):
        axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
        return np.concatenate([axis * np.sin(angle / 2), [np.cos(angle / 2)]])

    times3 = np.array([0.0, 0.6, 1.5], dtype=np.float32)
    t_in = add(times3, F, "SCALAR", minmax=True)
    rot_keys = [quat([0, 0, 1], 0.0), quat([0, 0, 1], 0.8), quat([1, 0, 1], 1.9)]
    rot_cubic = []
    for k, q in enumerate(rot_keys):
        rot_cubic += [np.array([0.1, -0.2, 0.05, 0.0]) * (k + 1), q, np.array([-0.05, 0.3, 0.1, 0.02]) * (k + 1)]
    a_rot_cubic = add(np.array(rot_cubic, dtype=np.float32), F, "VEC4")
    times4 = np.array([0.2, 0.5, 0.9, 1.2], dtype=np.float32)
    t_in4 = add(times4, F, "SCALAR", minmax=True)
    a_tr_step = add(np.array([[0, 1, 0], [0.2, 1, 0], [0.2, 1.3, 0.1], [0, 0.9, 0]], dtype=np.float32), F, "VEC3")
    rot_i16 = np.array([np.round(quat([0, 1, 0], a) * 32767) for a in (0.0, 0.5, -0.7, 1.2)], dtype=np.int16)
    a_rot_step = add(rot_i16, I16, "VEC4", normalized=True)
    a_scale_lin = add(np.array([[1, 1, 1], [1.5, 0.8, 1], [0.7, 1.2, 1.3], [1, 1, 1]], dtype=np.float32), F, "VEC3")
    a_scale_cubic = add(np.array([[0, 0, 0], [1, 1, 1], [0.5, 0, 0], [0.2, 0.1, 0], [1.4, 0.9, 1.1], [0, 0, 0],
                                  [0, 0, 0.3], [0.8, 1.1, 1.0], [0, 0, 0]], dtype=np.float32), F, "VEC3")
    a_w_cubic_in = add(np.array([0.0, 1.0, 1.5], dtype=np.float32), F, "SCALAR", minmax=True)
    a_node_tr = add(np.array([[5, 0, 0], [9, 9, 9], [5, 0, 0], [0, 0, 0]], dtype=np.float32), F, "VEC3")
    a_w_lin = add(np.array([0.0, 1.0, 1.0, 0.0, 0.5, 0.5], dtype=np.float32).reshape(-1, 1), F, "SCALAR")
    a_w_lin_in = add(np.array([0.0, 1.0, 2.0], dtype=np.float32), F, "SCALAR", minmax=True)
    a_w_u8 = add(np.array([0, 255, 128, 64, 255, 0], dtype=np.uint8).reshape(-1, 1), U8, "SCALAR", normalized=True)
    # (Cubic weights: 3 keys x 3 (in, value, out) x 2 targets = 18 values.)
    wc = np.array([[0.0, 0.0], [0.1, 0.9], [0.5, -0.5],
                   [1.0, 0.0], [0.6, 0.2], [-0.3, 0.4],
                   [0.2, 0.1], [0.0, 1.0], [0.0, 0.0]], dtype=np.float32).reshape(-1, 1)
    a_w_cubic = add(wc, F, "SCALAR")

    nodes = [
        {"name": "armature", "matrix": [1.2, 0, 0, 0, 0, 1.2, 0, 0, 0, 0, 1.2, 0, 0.1, -0.2, 0.3, 1], "children": [1, 4]},
        {"name": "joint0", "translation": [0, 0, 0], "children": [2]},
        {"name": "joint1", "translation": [0, 1, 0], "children": [3]},
        {"name": "joint2", "translation": [0, 1, 0], "rotation": [0, 0, 0.1736482, 0.9848078]},
        {"name": "skinned", "mesh": 0, "skin": 0, "translation": [3, 3, 3]},
        {"name": "morphed", "mesh": 1, "translation": [2, 0, 0], "rotation": [0, 0.3826834, 0, 0.9238795],
         "weights": [0.25, 0.75]},
    ]
    meshes = [
        {"name": "strip", "weights": [0.5, 0.0], "primitives": [{
            "attributes": {"POSITION": a_pos, "JOINTS_0": a_j0, "WEIGHTS_0": a_w0, "JOINTS_1": a_j1, "WEIGHTS_1": a_w1},
            "indices": a_idx, "mode": 4, "targets": [{"POSITION": a_d0}, {"POSITION": a_sparse}]}],
         "extras": {"targetNames": ["widen", "dents"]}},
        {"name": "shapes", "primitives": [
            {"attributes": {"POSITION": a_strip}, "mode": 5, "targets": [{"POSITION": ts0}, {"POSITION": ts1}]},
            {"attributes": {"POSITION": a_fan}, "indices": a_fan_idx, "mode": 6,
             "targets": [{"POSITION": tf0}, {"POSITION": tf1}]}],
         "extras": {"targetNames": ["a", "b"]}},
    ]
    animations = [
        {"name": "features", "samplers": [
            {"input": t_in, "output": a_rot_cubic, "interpolation": "CUBICSPLINE"},
            {"input": t_in4, "output": a_tr_step, "interpolation": "STEP"},
            {"input": t_in4, "output": a_rot_step, "interpolation": "STEP"},
            {"input": t_in4, "output": a_scale_lin, "interpolation": "LINEAR"},
            {"input": t_in, "output": a_scale_cubic, "interpolation": "CUBICSPLINE"},
            {"input": a_w_cubic_in, "output": a_w_cubic, "interpolation": "CUBICSPLINE"},
            {"input": t_in4, "output": a_node_tr, "interpolation": "LINEAR"},
        ], "channels": [
            {"sampler": 0, "target": {"node": 1, "path": "rotation"}},
            {"sampler": 1, "target": {"node": 2, "path": "translation"}},
            {"sampler": 2, "target": {"node": 2, "path": "rotation"}},
            {"sampler": 3, "target": {"node": 3, "path": "scale"}},
            {"sampler": 4, "target": {"node": 1, "path": "scale"}},
            {"sampler": 5, "target": {"node": 5, "path": "weights"}},
            {"sampler": 6, "target": {"node": 4, "path": "translation"}},
        ]},
        {"name": "weights", "samplers": [
            {"input": a_w_lin_in, "output": a_w_lin, "interpolation": "LINEAR"},
            {"input": a_w_lin_in, "output": a_w_u8, "interpolation": "STEP"},
        ], "channels": [
            {"sampler": 0, "target": {"node": 4, "path": "weights"}},
            {"sampler": 1, "target": {"node": 5, "path": "weights"}},
        ]},
    ]
    doc = {
        "asset": {"version": "2.0", "generator": "trisplat tests/reference/ref_animation.py"},
        "scene": 0,
        "scenes": [{"nodes": [0, 5]}],
        "nodes": nodes,
        "meshes": meshes,
        "skins": [{"joints": [1, 2, 3], "inverseBindMatrices": a_ibm, "skeleton": 1}],
        "animations": animations,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()}],
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1) + "\n")


# ---------------------------------------------------------------------------------------------


def fixture(name):
    """Prefer the shared glTF fixture folder, else this area's own copy."""
    for folder in ("gltf", "anim"):
        p = DATA / folder / name
        if p.exists():
            return p
    raise SystemExit(f"missing fixture {name}")


CASES = [
    # (output name, fixture, clips, extra times)
    ("SimpleSkin", "SimpleSkin.gltf", [0], [0.25, 1.7, 2.25]),
    ("RiggedSimple", "RiggedSimple.glb", [0], [0.3, 1.05, 2.5]),
    ("RiggedFigure", "RiggedFigure.glb", [0], [0.17, 0.52, 1.11]),
    ("CesiumMan", "CesiumMan.glb", [0], [0.1, 0.77, 1.43]),
    ("MorphStressTest", "MorphStressTest.gltf", ["Individuals", "Pulse", "TheWave"], [0.4, 1.3]),
    ("AnimatedMorphSphere", "AnimatedMorphSphere/AnimatedMorphSphere.gltf", ["Globe"], [0.35, 1.1, 2.6]),
    ("SimpleMorph", "SimpleMorph/SimpleMorph.gltf", [0], [0.5, 1.9, 3.3]),
    ("AnimatedMorphCube", "AnimatedMorphCube/AnimatedMorphCube.gltf", ["Square"], [0.45, 1.7]),
    ("SyntheticFeatures", "SyntheticFeatures.gltf", ["features", "weights"], [0.1, 0.3, 0.55, 0.6, 0.75, 1.0, 1.3]),
]


def main():
    write_synthetic(DATA / "anim" / "SyntheticFeatures.gltf")
    OUT.mkdir(parents=True, exist_ok=True)
    for name, file, clips, extra in CASES:
        path = fixture(file)
        scene = Scene(path)
        names = [a.name for a in scene.g.animations]
        rest = scene.evaluate(None, 0.0)
        n = len(rest)
        subset = sorted(set(np.linspace(0, n - 1, min(SUBSET, n)).round().astype(int).tolist()))
        result = {
            "file": str(path.relative_to(DATA)),
            "vertex_count": n,
            "triangle_count": scene.triangle_count(),
            "vertex_indices": subset,
            "cases": [],
        }
        if name == "SyntheticFeatures":
            result["triangles"] = scene.triangles().tolist()
        result["cases"].append({"clip": None, "time": None, "positions": rest[subset].tolist(),
                                "sum": rest.sum(axis=0).tolist(), "abs_sum": np.abs(rest).sum(axis=0).tolist()})
        for clip in clips:
            index = clip if isinstance(clip, int) else names.index(clip)
            end = scene.clip_end(index)
            times = sorted(set([-0.5, 0.0] + [t for t in extra] + [end * 0.5, end, end + 0.75]))
            for t in times:
                p = scene.evaluate(index, t)
                result["cases"].append({
                    "clip": clip, "time": t, "positions": p[subset].tolist(),
                    "sum": p.sum(axis=0).tolist(), "abs_sum": np.abs(p).sum(axis=0).tolist(),
                })
        out = OUT / f"{name}.json"
        out.write_text(json.dumps(result) + "\n")
        print(f"{name}: {n} vertices, {len(result['cases'])} cases -> {out.relative_to(ROOT)} "
              f"({out.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
