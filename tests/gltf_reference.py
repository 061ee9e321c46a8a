"""Independent glTF forward kinematics for tests: pygltflib + numpy, none of kinema's code.

`world_positions(path, clip, times)` returns ``{node name: (len(times), 3)}`` world positions of every
skin joint, computed straight from the node TRS and LINEAR/STEP/CUBICSPLINE animation channels of the file.
"""

from __future__ import annotations

import numpy as np
import pygltflib

_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _read(g: pygltflib.GLTF2, index: int) -> np.ndarray:
    acc = g.accessors[index]
    view = g.bufferViews[acc.bufferView]
    width = _WIDTH[acc.type]
    blob = g.binary_blob()
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    return (
        np.frombuffer(blob, dtype=_DTYPES[acc.componentType], count=acc.count * width, offset=start)
        .reshape(acc.count, width)
        .astype(np.float64)
    )


def _rot(q) -> np.ndarray:
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _nlerp_slerp(a, b, u):
    a, b = np.asarray(a), np.asarray(b)
    if np.dot(a, b) < 0:
        b = -b
    d = min(abs(float(np.dot(a, b))), 1.0)
    th = np.arccos(d)
    if th < 1e-9:
        return (1 - u) * a + u * b
    return (np.sin((1 - u) * th) * a + np.sin(u * th) * b) / np.sin(th)


def _value(times, values, t, interp, rotation):
    i = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
    if interp == "CUBICSPLINE":  # rows: in-tangent, value, out-tangent per key (glTF spec, Appendix C)
        a, v, b = values[0::3], values[1::3], values[2::3]
        if i == len(times) - 1:
            out = v[i]
        else:
            d = times[i + 1] - times[i]
            s = (t - times[i]) / d
            h = [2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2]
            out = h[0] * v[i] + d * h[1] * b[i] + h[2] * v[i + 1] + d * h[3] * a[i + 1]
        return out / np.linalg.norm(out) if rotation else out
    if i == len(times) - 1 or interp == "STEP":
        return values[i]
    u = (t - times[i]) / (times[i + 1] - times[i])
    return _nlerp_slerp(values[i], values[i + 1], u) if rotation else (1 - u) * values[i] + u * values[i + 1]


def world_positions(path, clip: str | None, times) -> dict[str, np.ndarray]:
    """World positions of every skin joint of ``path`` (a file, or an already loaded pygltflib.GLTF2)."""
    g = path if isinstance(path, pygltflib.GLTF2) else pygltflib.GLTF2().load(str(path))
    anim = None
    if clip is not None:
        anim = next(a for a in g.animations if a.name == clip)
    tracks = {}
    if anim is not None:
        for c in anim.channels:
            s = anim.samplers[c.sampler]
            tracks[(c.target.node, c.target.path)] = (_read(g, s.input)[:, 0], _read(g, s.output), s.interpolation)
    parent = {c: i for i, n in enumerate(g.nodes) for c in (n.children or [])}
    joints = sorted({j for s in g.skins for j in s.joints})
    out = {g.nodes[j].name: np.zeros((len(times), 3)) for j in joints}
    for k, t in enumerate(times):
        local = {}
        for i, n in enumerate(g.nodes):
            trs = {
                "translation": n.translation or [0, 0, 0],
                "rotation": n.rotation or [0, 0, 0, 1],
                "scale": n.scale or [1, 1, 1],
            }
            for path_ in trs:
                if (i, path_) in tracks:
                    tt, vv, interp = tracks[(i, path_)]
                    trs[path_] = _value(tt, vv, t, interp, path_ == "rotation")
            m = np.eye(4)
            if n.matrix:
                m = np.asarray(n.matrix, dtype=np.float64).reshape(4, 4).T
            else:
                m[:3, :3] = _rot(trs["rotation"]) * np.asarray(trs["scale"], dtype=np.float64)
                m[:3, 3] = trs["translation"]
            local[i] = m
        for j in joints:
            m, n = np.eye(4), j
            while n is not None:
                m = local[n] @ m
                n = parent.get(n)
            out[g.nodes[j].name][k] = m[:3, 3]
    return out
