"""A small synthetic skinned GLB built with pygltflib (not kinema), for the glTF reader and writer tests.

The rig: an ``Armature`` node (rotated -90 deg about X, scale 100, like Quaternius exports) above two
root bones: ``Body`` (with children ``Neck`` -> ``Head`` and ``Leg``) and ``Foot`` (a weighted IK-style
second root whose translation is animated), plus ``Pole``, a weightless helper root. Two skins (two
meshes, one quad each) share the joints. One animation, ``Rig|Move``, uses a LINEAR rotation on
``Body``, STEP translation on ``Foot``, a CUBICSPLINE rotation on ``Neck`` and a LINEAR translation on
``Pole``; ``Head`` and ``Leg`` are not animated.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pygltflib

JOINT_NAMES = ["Body", "Neck", "Head", "Leg", "Foot", "Pole"]


def _quat_x(deg: float) -> list[float]:
    h = math.radians(deg) / 2
    return [math.sin(h), 0.0, 0.0, math.cos(h)]


def _quat_z(deg: float) -> list[float]:
    h = math.radians(deg) / 2
    return [0.0, 0.0, math.sin(h), math.cos(h)]


class _Blob:
    def __init__(self, gltf: pygltflib.GLTF2):
        self.gltf, self.data = gltf, bytearray()

    def add(self, array: np.ndarray, kind: str, component: int, target: int | None = None) -> int:
        while len(self.data) % 4:
            self.data.append(0)
        raw = np.ascontiguousarray(array).tobytes()
        self.gltf.bufferViews.append(
            pygltflib.BufferView(buffer=0, byteOffset=len(self.data), byteLength=len(raw), target=target)
        )
        self.data += raw
        acc = pygltflib.Accessor(
            bufferView=len(self.gltf.bufferViews) - 1, componentType=component, count=len(array), type=kind
        )
        if kind == "VEC3" and component == pygltflib.FLOAT:
            acc.min, acc.max = array.min(axis=0).tolist(), array.max(axis=0).tolist()
        if kind == "SCALAR" and component == pygltflib.FLOAT:
            acc.min, acc.max = [float(array.min())], [float(array.max())]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1


def _world(nodes: list[pygltflib.Node], parent: dict[int, int], i: int) -> np.ndarray:
    m = np.eye(4)
    while i is not None:
        n = nodes[i]
        x, y, z, w = n.rotation or [0, 0, 0, 1]
        r = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        local = np.eye(4)
        local[:3, :3] = r * np.asarray(n.scale or [1, 1, 1])
        local[:3, 3] = n.translation or [0, 0, 0]
        m = local @ m
        i = parent.get(i)
    return m


def _mesh_quad(blob: _Blob, center: np.ndarray, joints: list[int], material: int) -> pygltflib.Mesh:
    """A quad around ``center`` (world units, bind pose) bound half to joints[0], half to joints[1]."""
    v = (center + np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]) * 0.002).astype(np.float32)
    j = np.array([[joints[0], 0, 0, 0]] * 2 + [[joints[1], joints[0], 0, 0]] * 2, dtype=np.uint8)
    w = np.array([[1, 0, 0, 0]] * 2 + [[0.75, 0.25, 0, 0]] * 2, dtype=np.float32)
    attrs = pygltflib.Attributes(
        POSITION=blob.add(v, "VEC3", pygltflib.FLOAT),
        JOINTS_0=blob.add(j, "VEC4", pygltflib.UNSIGNED_BYTE),
        WEIGHTS_0=blob.add(w, "VEC4", pygltflib.FLOAT),
    )
    idx = blob.add(np.array([0, 1, 2, 0, 2, 3], dtype=np.uint16), "SCALAR", pygltflib.UNSIGNED_SHORT)
    return pygltflib.Mesh(primitives=[pygltflib.Primitive(attributes=attrs, indices=idx, material=material)])


def write_synthetic_glb(path: Path) -> Path:
    """Write the synthetic rig described in the module docstring to ``path`` and return it."""
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"), scene=0)
    g.buffers.append(pygltflib.Buffer())
    blob = _Blob(g)
    # node 0 armature; 1 Body, 2 Neck, 3 Head, 4 Leg, 5 Foot, 6 Pole; 7, 8 mesh nodes
    g.nodes = [
        pygltflib.Node(name="Armature", rotation=_quat_x(-90), scale=[100, 100, 100], children=[1, 5, 6]),
        pygltflib.Node(name="Body", translation=[0, 0, 0.01], rotation=_quat_x(90), children=[2, 4]),
        pygltflib.Node(name="Neck", translation=[0, 0.004, 0], rotation=_quat_z(10), children=[3]),
        pygltflib.Node(name="Head", translation=[0, 0.003, 0]),
        pygltflib.Node(name="Leg", translation=[0.002, -0.004, 0], rotation=_quat_z(-20)),
        pygltflib.Node(name="Foot", translation=[0.003, 0, 0.001]),
        pygltflib.Node(name="Pole", translation=[0, -0.01, 0.002]),
        pygltflib.Node(name="MeshA", mesh=0, skin=0),
        pygltflib.Node(name="MeshB", mesh=1, skin=1),
    ]
    parent = {c: i for i, n in enumerate(g.nodes) for c in (n.children or [])}
    g.scenes = [pygltflib.Scene(nodes=[0, 7, 8])]
    g.materials = [
        pygltflib.Material(pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(baseColorFactor=[0.9, 0.4, 0.1, 1])),
        pygltflib.Material(pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(baseColorFactor=[0.2, 0.3, 0.8, 1])),
    ]
    skins = [[1, 2, 3, 4, 5, 6], [5, 1, 6, 3]]  # the second lists the shared joints in another order
    for joints in skins:
        ibm = np.stack([np.linalg.inv(_world(g.nodes, parent, j)).T for j in joints]).astype(np.float32)
        g.skins.append(pygltflib.Skin(joints=joints, inverseBindMatrices=blob.add(ibm.reshape(-1, 16), "MAT4", 5126)))
    g.meshes = [
        _mesh_quad(blob, np.array([0.0, 0.0, 0.012]), [0, 3], 0),  # skin 0 indices: Body, Leg
        _mesh_quad(blob, np.array([0.003, 0.0, 0.0]), [0, 3], 1),  # skin 1 indices: Foot, Head
    ]
    times = np.array([0.0, 0.25, 0.5, 1.0], dtype=np.float32)
    t_in = blob.add(times, "SCALAR", pygltflib.FLOAT)
    body = np.array([_quat_x(90), _quat_x(60), _quat_x(100), _quat_x(90)], dtype=np.float32)
    foot = np.array([[0.003, 0, 0.001], [0.004, 0.001, 0.001], [0.005, 0, 0.002], [0.003, 0, 0.001]], np.float32)
    neck_keys = [_quat_z(10), _quat_z(40), _quat_z(-10), _quat_z(10)]
    neck = np.array([v for q in neck_keys for v in ([0, 0, 0.2, 0], q, [0, 0, 0.2, 0])], dtype=np.float32)
    pole = np.array([[0, -0.01, 0.002], [0, -0.02, 0.002], [0, -0.01, 0.004], [0, -0.01, 0.002]], np.float32)
    samplers = [
        pygltflib.AnimationSampler(input=t_in, output=blob.add(body, "VEC4", 5126), interpolation="LINEAR"),
        pygltflib.AnimationSampler(input=t_in, output=blob.add(foot, "VEC3", 5126), interpolation="STEP"),
        pygltflib.AnimationSampler(input=t_in, output=blob.add(neck, "VEC4", 5126), interpolation="CUBICSPLINE"),
        pygltflib.AnimationSampler(input=t_in, output=blob.add(pole, "VEC3", 5126), interpolation="LINEAR"),
    ]
    targets = [(1, "rotation"), (5, "translation"), (2, "rotation"), (6, "translation")]
    channels = [
        pygltflib.AnimationChannel(sampler=i, target=pygltflib.AnimationChannelTarget(node=n, path=p))
        for i, (n, p) in enumerate(targets)
    ]
    g.animations = [pygltflib.Animation(name="Rig|Move", samplers=samplers, channels=channels)]
    g.buffers[0].byteLength = len(blob.data)
    g.set_binary_blob(bytes(blob.data))
    path.parent.mkdir(parents=True, exist_ok=True)
    g.save_binary(str(path))
    return path
