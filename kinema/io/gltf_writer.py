"""GLB writing: motions on one rig as a skinned, animated glTF 2.0 binary that Blender, three.js and viser play.

The file holds one node per joint (rest pose as node TRS: ``offsets``/``rest_rotations``, metres, Y up),
one skin over all joints whose inverse bind matrices are the rest pose's inverses, the rig's mesh
(``Skeleton.mesh``, from the GLB it came from; a rig without one, like the BVH human, gets a generated
bone mesh: kinema.mesh.bone_mesh) with one flat-colour material per part, and one animation per clip:
root translation, every joint's rotation, and translations of joints the clip moves
(``Motion.local_translations``), all LINEAR at the clip's frame times.
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_make_continuous
from kinema.kinematics import forward_kinematics
from kinema.mesh import SkinnedMesh, bone_mesh
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

_FLOAT, _USHORT, _UINT = 5126, 5123, 5125
_ARRAY, _ELEMENTS = 34962, 34963


class _Builder:
    """Collects the JSON arrays and the binary chunk (4-byte aligned views, one accessor each)."""

    def __init__(self):
        self.doc: dict = {"asset": {"version": "2.0", "generator": "kinema"}, "bufferViews": [], "accessors": []}
        self.blob = bytearray()

    def add(self, array: np.ndarray, kind: str, component: int, target: int | None = None, minmax=False) -> int:
        dtype = {_FLOAT: np.float32, _USHORT: np.uint16, _UINT: np.uint32}[component]
        data = np.ascontiguousarray(array, dtype=dtype)
        self.blob += b"\0" * (-len(self.blob) % 4)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": data.nbytes}
        if target is not None:
            view["target"] = target
        self.doc["bufferViews"].append(view)
        self.blob += data.tobytes()
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[kind]
        acc = {
            "bufferView": len(self.doc["bufferViews"]) - 1,
            "componentType": component,
            "count": len(data),
            "type": kind,
        }
        if minmax:
            flat = data.reshape(len(data), width)
            acc["min"], acc["max"] = flat.min(axis=0).tolist(), flat.max(axis=0).tolist()
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def glb(self) -> bytes:
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.doc["buffers"] = [{"byteLength": len(self.blob)}]
        text = json.dumps(self.doc, separators=(",", ":")).encode("utf-8")
        text += b" " * (-len(text) % 4)
        total = 12 + 8 + len(text) + 8 + len(self.blob)
        return b"".join(
            [
                struct.pack("<4sII", b"glTF", 2, total),
                struct.pack("<II", len(text), 0x4E4F534A),
                text,
                struct.pack("<II", len(self.blob), 0x004E4942),
                bytes(self.blob),
            ]
        )


def rest_world(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """(J, 4) global rotations (wxyz) and (J, 3) positions of the rest pose, root at ``offsets[0]``."""
    rest = skeleton.rest_rotations
    if rest is None:
        rest = torch.zeros(skeleton.num_joints, 4, dtype=torch.float64)
        rest[:, 0] = 1.0
    G, P = forward_kinematics(rest.double(), skeleton.offsets[0].double(), skeleton.offsets, skeleton.parents)
    return G.numpy(), P.numpy()


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _nodes(b: _Builder, skeleton: Skeleton) -> None:
    rest = skeleton.rest_rotations
    nodes = []
    for j, name in enumerate(skeleton.names):
        node: dict = {"name": name, "translation": [float(x) for x in skeleton.offsets[j]]}
        if rest is not None:
            w, x, y, z = (float(v) for v in rest[j])
            node["rotation"] = [x, y, z, w]
        kids = list(skeleton.children[j])
        if kids:
            node["children"] = kids
        nodes.append(node)
    b.doc["nodes"] = nodes


def _skin_and_mesh(b: _Builder, skeleton: Skeleton, mesh: SkinnedMesh) -> None:
    G, P = rest_world(skeleton)
    ibm = np.zeros((skeleton.num_joints, 4, 4))
    for j in range(skeleton.num_joints):
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = _quat_matrix(G[j]), P[j]
        ibm[j] = np.linalg.inv(m)
    J = skeleton.num_joints
    b.doc["skins"] = [
        {
            "joints": list(range(J)),
            "skeleton": 0,
            "name": "rig",
            "inverseBindMatrices": b.add(ibm.transpose(0, 2, 1).reshape(J, 16), "MAT4", _FLOAT),
        }
    ]
    attrs = {
        "POSITION": b.add(mesh.vertices, "VEC3", _FLOAT, _ARRAY, minmax=True),
        "JOINTS_0": b.add(mesh.joints, "VEC4", _USHORT, _ARRAY),
        "WEIGHTS_0": b.add(
            mesh.weights / mesh.weights.sum(axis=1, keepdims=True).clip(min=1e-12), "VEC4", _FLOAT, _ARRAY
        ),
    }
    if mesh.normals is not None:
        attrs["NORMAL"] = b.add(mesh.normals, "VEC3", _FLOAT, _ARRAY)
    prims, materials = [], []
    for k, color in enumerate(mesh.colors):
        faces = mesh.faces[mesh.face_parts == k]
        if not len(faces):
            continue
        materials.append(
            {
                "name": f"part{k}",
                "pbrMetallicRoughness": {
                    "baseColorFactor": [float(c) for c in color],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.8,
                },
            }
        )
        index = b.add(faces.reshape(-1), "SCALAR", _UINT, _ELEMENTS)
        prims.append({"attributes": attrs, "indices": index, "material": len(materials) - 1})
    b.doc["materials"] = materials
    b.doc["meshes"] = [{"name": f"{skeleton.name or 'rig'}_mesh", "primitives": prims}]
    b.doc["nodes"].append({"name": f"{skeleton.name or 'rig'}_mesh", "mesh": 0, "skin": 0})


def _animation(b: _Builder, name: str, motion: Motion, nodes: Skeleton) -> dict:
    """One clip's channels; bone translations are written wherever they differ from the nodes' rest
    translations (``nodes``: the file's skeleton, whose offsets may differ from this clip's own)."""
    T = motion.num_frames
    times = b.add(np.arange(T) / motion.fps, "SCALAR", _FLOAT, minmax=True)
    rots = quat_make_continuous(motion.local_rotations.detach().double().cpu(), dim=0).numpy()[..., [1, 2, 3, 0]]
    tracks = [(0, "translation", motion.root_translation.detach().double().cpu().numpy())]
    tracks += [(j, "rotation", rots[:, j]) for j in range(motion.num_joints)]
    trans = motion.translations_or_offsets().detach().double().cpu().numpy()
    offsets = nodes.offsets.numpy()
    tracks += [
        (j, "translation", trans[:, j])
        for j in range(1, motion.num_joints)
        if np.abs(trans[:, j] - offsets[j]).max() > 1e-9
    ]
    samplers, channels = [], []
    for node, path, values in tracks:
        out = b.add(values, "VEC4" if path == "rotation" else "VEC3", _FLOAT)
        samplers.append({"input": times, "output": out, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})
    return {"name": name, "samplers": samplers, "channels": channels}


def glb_bytes(clips: Mapping[str, Motion], *, mesh: SkinnedMesh | None = None) -> bytes:
    """The GLB bytes for ``clips`` (name -> Motion, all on one skeleton topology); see the module docstring."""
    if not clips:
        raise KinemaError("nothing to write: no motions")
    skeleton = next(iter(clips.values())).skeleton
    for name, m in clips.items():
        if not m.skeleton.same_topology(skeleton):
            raise KinemaError(f"clip {name!r} is on another skeleton; one GLB holds one rig")
        if not m.is_finite() or (m.local_translations is not None and not torch.isfinite(m.local_translations).all()):
            raise KinemaError(f"clip {name!r} holds NaN or infinite values; nothing written")
    b = _Builder()
    _nodes(b, skeleton)
    mesh = mesh or skeleton.mesh or bone_mesh(skeleton, rest_world(skeleton))
    if not (np.isfinite(mesh.vertices).all() and np.isfinite(mesh.weights).all()):
        raise KinemaError("the rig's mesh holds NaN or infinite vertices or weights; nothing written")
    _skin_and_mesh(b, skeleton, mesh)
    b.doc["animations"] = [_animation(b, name, m, skeleton) for name, m in clips.items()]
    b.doc["scenes"] = [{"name": skeleton.name or "kinema", "nodes": [0, len(b.doc["nodes"]) - 1]}]
    b.doc["scene"] = 0
    return b.glb()


def write_glb(motion: Motion | Mapping[str, Motion], path: str | os.PathLike, *, name: str = "motion") -> Path:
    """Write one motion (clip ``name``) or several (name -> Motion) as a GLB, atomically; returns the path."""
    clips = {name: motion} if isinstance(motion, Motion) else dict(motion)
    path = Path(path)
    atomic_write_bytes(path, glb_bytes(clips))
    return path
