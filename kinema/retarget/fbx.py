"""FBX characters read with ufbx (PyPI ``ufbx``): armature, rest pose, skin, and the first animation.

ufbx converts the file to Y up, metres and right-handed axes while loading, so every FBX (Blender's,
Maya's, Mixamo's, Autodesk's) arrives in kinema's frame. What is read:

- joints: every node that is a bone (or a skin cluster's bone), plus the nodes between two of them,
  less the helper joints (IK and pole targets) with ``keep_helpers=False`` (the any-rig model's reading);
  when that leaves several trees, their common parent (the armature node) becomes joint 0, else a
  synthetic ``root`` at the origin;
- the rest pose: each joint's world transform at bind time (its skin cluster's), else its node's
  world transform; scale is taken out (an armature at
  scale 100, as Blender writes centimetre FBX, gives bones in metres) and offsets and rest rotations
  are derived from the world transforms, as for glTF (kinema.io.gltf);
- the skin: every skinned mesh's triangles (polygons fanned), vertex positions in the world at rest,
  up to four strongest joint weights per vertex, one flat colour per material (its base colour);
- ``animation``: the first animation stack sampled at ``fps`` (default the file's frame rate, else
  30) into a `Motion` on that skeleton, from the joints' world transforms.

Everything is copied into numpy inside one function while the scene is open. The scene itself is
never freed: with ufbx 0.0.5, freeing a scene (``with scene:`` leaving) crashed the process now and
then (a segmentation fault in the free, once in about six full test runs), so each FBX read keeps
its scene and the wrappers it touched (`_KEPT`, with an extra reference so that not even the
interpreter's exit frees them) until the process ends: memory of the order of the
file's size per read. Unreadable files raise a one-line `KinemaError` naming the file.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import ufbx

from kinema.errors import KinemaError
from kinema.geometry.rotations import matrix_to_quat, quat_inverse, quat_mul, quat_rotate
from kinema.mesh import SkinnedMesh, vertex_normals
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

#: every scene read, with the wrappers it handed out, kept until the process ends (module docstring)
_KEPT: list = []


@dataclass(frozen=True)
class FbxAsset:
    """A rig (with its skin) and its first animation (None without one) read from an FBX file."""

    path: Path
    skeleton: Skeleton
    motion: Motion | None


class _Held:
    """Holds every ufbx object touched while a scene is open. ufbx 0.0.5 hands out cached wrappers:
    one freed early and asked for again is used after free (a crash), so none may die before the
    scene (which kinema keeps, with them, in `_KEPT`)."""

    def __init__(self):
        self.objects: list = []

    def __call__(self, obj):
        self.objects.append(obj)
        return obj

    def items(self, ufbx_list) -> list:
        """The elements of a ufbx list by index (iterating one directly runs past its end)."""
        self(ufbx_list)
        return [self(ufbx_list[i]) for i in range(len(ufbx_list))]

    def array(self, ufbx_list, dtype) -> np.ndarray:
        """A ufbx number or vector list copied into numpy (through its buffer when it has one)."""
        self(ufbx_list)
        try:
            return np.array(memoryview(ufbx_list), dtype=dtype)
        except TypeError:
            return np.array([ufbx_list[i] for i in range(len(ufbx_list))], dtype=dtype)

    def release(self) -> None:
        self.objects.clear()


def _matrix(m) -> np.ndarray:
    out = np.eye(4)
    for k, c in enumerate((m.c0, m.c1, m.c2, m.c3)):
        out[:3, k] = (c.x, c.y, c.z)
    return out


def _bind_matrices(scene, h: _Held) -> dict[int, np.ndarray]:
    """{bone node id: its world matrix at bind time} from the skin clusters (the skin's rest pose)."""
    out: dict[int, np.ndarray] = {}
    for cluster in h.items(scene.skin_clusters):
        bone = h(cluster.bone_node)
        if bone is not None and bone.element_id not in out:
            out[bone.element_id] = _matrix(cluster.bind_to_world)
    return out


def _joint_nodes(scene, h: _Held, keep_helpers: bool = True) -> tuple[list[int | None], list[int], dict]:
    """(joint node ids parent-first, kinema parents, id -> node); a None id is a synthetic root."""
    nodes = h.items(scene.nodes)
    by_id = {n.element_id: n for n in nodes}
    parent = {n.element_id: (None if h(n.parent) is None else n.parent.element_id) for n in nodes}
    ids = {n.element_id for n in nodes if h(n.bone) is not None}
    for cluster in h.items(scene.skin_clusters):
        if h(cluster.bone_node) is not None:
            ids.add(cluster.bone_node.element_id)
    for i in list(ids):  # nodes between two joints are joints too
        chain, p = [], parent[i]
        while p is not None and p not in ids:
            chain.append(p)
            p = parent[p]
        if p is not None:
            ids.update(chain)
    if not keep_helpers:
        ids = _without_helpers(ids, parent, scene, h)
    tops = sorted(i for i in ids if parent[i] not in ids)
    top = tops[0] if len(tops) == 1 else None
    common = {parent[i] for i in tops}
    if len(tops) > 1 and len(common) == 1 and None not in common and not by_id[next(iter(common))].is_root:
        top = next(iter(common))
        ids.add(top)
    kids: dict = {i: [] for i in [*ids, None]}
    for i in sorted(ids):
        if i != top and (parent[i] in ids or i in tops):
            kids[parent[i] if parent[i] in ids else top].append(i)
    order, parents, todo = [], [], [(top, -1)]
    while todo:
        i, p = todo.pop()
        order.append(i)
        parents.append(p)
        todo.extend((c, len(order) - 1) for c in reversed(kids[i]))
    return order, parents, by_id


def _without_helpers(ids: set, parent: dict, scene, h: _Held) -> set:
    """``ids`` less the helper joints (IK and pole targets), as kinema.io.gltf drops them: joints that
    carry no skin weight and have no weighted joint below them; all of ``ids`` when none is weighted."""
    needed: set = set()
    for cluster in h.items(scene.skin_clusters):
        node = h(cluster.bone_node)
        if node is None or not (h.array(cluster.weights, np.float64) > 0).any():
            continue
        i = node.element_id
        while i is not None and i not in needed:
            needed.add(i)
            i = parent[i]
    return (needed & ids) or ids


def _rest(world: np.ndarray, parents: list[int]) -> tuple[torch.Tensor, torch.Tensor]:
    """(offsets (J, 3), rest rotations (J, 4)) from world matrices (J, 4, 4), scale taken out."""
    R = torch.from_numpy(world[:, :3, :3].copy())
    R = R / R.norm(dim=1, keepdim=True).clamp_min(1e-12)
    G = matrix_to_quat(R)
    P = torch.from_numpy(world[:, :3, 3].copy())
    pi = [max(p, 0) for p in parents]
    offsets = quat_rotate(quat_inverse(G[pi]), P - P[pi])
    local = quat_mul(quat_inverse(G[pi]), G)
    offsets[0], local[0] = P[0], G[0]
    return offsets, local


def _weights(mesh, count: int, index: dict[int, int], h: _Held) -> tuple[np.ndarray, np.ndarray]:
    """(joints (V, 4), weights (V, 4)): each vertex's four strongest joint weights."""
    w = np.zeros((count, max(1, len(index))))
    for cluster in h.items(h(h(mesh.skin_deformers)[0]).clusters):
        bone = h(cluster.bone_node)
        j = None if bone is None else index.get(bone.element_id)
        if j is not None and len(h(cluster.vertices)):
            w[h.array(cluster.vertices, np.int64), j] += h.array(cluster.weights, np.float64)
    top = np.argsort(-w, axis=1)[:, :4]
    tw = np.take_along_axis(w, top, axis=1)
    return np.where(tw > 0, top, 0), tw


def _skin(scene, index: dict[int, int], h: _Held) -> SkinnedMesh | None:
    """Every skinned mesh of ``scene`` as one SkinnedMesh over the joints ``index`` (element id -> joint)."""
    verts, faces, joints, weights, parts, colors = [], [], [], [], [], []
    for mesh in h.items(scene.meshes):
        if not len(h(mesh.skin_deformers)) or not len(h(mesh.instances)):
            continue
        clusters = h.items(h(h(mesh.skin_deformers)[0]).clusters)
        to_world = _matrix((clusters[0] if clusters else h(mesh.instances[0])).geometry_to_world)
        pos = h.array(mesh.vertices, np.float64).reshape(-1, 3) @ to_world[:3, :3].T + to_world[:3, 3]
        j, w = _weights(mesh, len(pos), index, h)
        corner = h.array(mesh.vertex_indices, np.int64) + sum(len(v) for v in verts)
        mats = h.array(mesh.face_material, np.int64) if len(h(mesh.face_material)) else np.zeros(mesh.num_faces, int)
        materials = h.items(mesh.materials)
        for f, face in enumerate(h.items(mesh.faces)):
            c = corner[face.index_begin : face.index_begin + face.num_indices]
            color = _color(materials, int(mats[f]) if f < len(mats) else -1, h)
            if color not in colors:
                colors.append(color)
            faces += [(c[0], c[k], c[k + 1]) for k in range(1, len(c) - 1)]
            parts += [colors.index(color)] * max(0, len(c) - 2)
        verts.append(pos)
        joints.append(j)
        weights.append(w)
    if not verts:
        return None
    V, F = np.concatenate(verts).astype(np.float32), np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    W = np.concatenate(weights)
    W = W / W.sum(axis=1, keepdims=True).clip(min=1e-12)
    return SkinnedMesh(
        V,
        vertex_normals(V, F).astype(np.float32),
        F,
        np.concatenate(joints),
        W.astype(np.float32),
        np.asarray(parts, dtype=np.int64),
        np.asarray(colors, dtype=np.float32).reshape(-1, 4),
    )


def _color(materials: list, k: int, h: _Held) -> tuple[float, float, float, float]:
    if not 0 <= k < len(materials):
        return (0.75, 0.75, 0.78, 1.0)
    c = h(h(materials[k].pbr).base_color).value_vec4
    return (round(c.x, 6), round(c.y, 6), round(c.z, 6), 1.0)


def _world(order: list[int | None], scene, h: _Held, bind: dict[int, np.ndarray] | None = None) -> np.ndarray:
    """(J, 4, 4) world matrices of the joints: ``bind`` where given, else the nodes' current ones."""
    by_id = {n.element_id: n for n in h.items(scene.nodes)}
    bind = bind or {}
    return np.stack(
        [np.eye(4) if i is None else bind[i] if i in bind else _matrix(by_id[i].node_to_world) for i in order]
    )


def _animation(scene, order, skeleton: Skeleton, fps: float | None, h: _Held) -> Motion | None:
    stacks = h.items(scene.anim_stacks)
    if not stacks:
        return None
    stack = stacks[0]
    rate = fps or float(h(scene.settings).frames_per_second or 30.0)
    t0, t1 = float(stack.time_begin), float(stack.time_end)
    times = t0 + np.arange(int(math.floor((t1 - t0) * rate + 1e-3)) + 1) / rate
    Gs, Ps = [], []
    for t in times:
        frame = _Held()
        with ufbx.evaluate_scene(scene, h(stack.anim), float(t)) as ev:
            W = _world(order, ev, frame)
            frame.release()
        R = torch.from_numpy(W[:, :3, :3].copy())
        Gs.append(matrix_to_quat(R / R.norm(dim=1, keepdim=True).clamp_min(1e-12)))
        Ps.append(torch.from_numpy(W[:, :3, 3].copy()))
    G, P = torch.stack(Gs), torch.stack(Ps)
    return Motion.from_global(skeleton, rate, P[:, 0], G, positions=P)


def _read(scene, path: Path, fps: float | None, h: _Held, keep_helpers: bool = True) -> FbxAsset:
    order, parents, by_id = _joint_nodes(scene, h, keep_helpers)
    if len(order) < 2:
        raise KinemaError(f"{path}: has no armature (no bones); kinema reads rigged FBX characters")
    names, seen = [], set()
    for i in order:
        base = "root" if i is None else (by_id[i].name or "bone")
        name, k = base, 1
        while name in seen:
            name, k = f"{base}.{k}", k + 1
        seen.add(name)
        names.append(name)
    offsets, local = _rest(_world(order, scene, h, _bind_matrices(scene, h)), parents)
    index = {i: j for j, i in enumerate(order) if i is not None}
    skeleton = Skeleton(names, parents, offsets, local, name=path.stem, mesh=_skin(scene, index, h))
    return FbxAsset(path, skeleton, _animation(scene, order, skeleton, fps, h))


def read_fbx(path: str | Path, *, fps: float | None = None, keep_helpers: bool = True) -> FbxAsset:
    """The rig, skin and first animation of an FBX file (see the module docstring). ``keep_helpers``
    False drops the helper joints (IK and pole targets: no skin weight, no weighted joint below), as
    the any-rig model reads a GLB; a character to retarget onto keeps every bone."""
    path = Path(path)
    if not path.is_file():
        raise KinemaError(f"{path}: no such file")
    try:
        scene = ufbx.load_file(
            str(path),
            target_axes=ufbx.axes_right_handed_y_up,
            target_unit_meters=1.0,
            space_conversion=ufbx.SpaceConversion.MODIFY_GEOMETRY,
        )
    except ufbx.UfbxError as err:
        raise KinemaError(f"{path}: not a readable FBX file ({str(err).splitlines()[0]})") from None
    held = _Held()
    _KEPT.append((scene, held))  # never freed: see the module docstring
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(scene))  # not even when the interpreter clears modules at exit
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(held))
    return _read(scene, path, fps, held, keep_helpers)
