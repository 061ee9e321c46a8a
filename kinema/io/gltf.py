"""glTF 2.0 / GLB reading: a skinned rig (`Skeleton` with its `SkinnedMesh`) and one `Motion` per animation.

What is read, and how it maps to kinema (metres, Y up, quaternions ``(w, x, y, z)``):
- Joints are the union of every skin's joints (several skins over the same joints are one rig), plus
  any plain nodes lying between two joints. Joints that carry no skin weight and have no weighted joint
  below them (IK targets, pole targets) are *helper joints*: dropped unless ``keep_helpers``.
- The rig needs one root: when the kept joints form several trees, their common parent node (the
  armature) becomes joint 0, or else a synthetic ``root`` at the origin.
- Everything above the top joints (the armature node with its rotation and scale, e.g. Quaternius'
  ``scale 100``) is applied, so joint positions are the file's world positions; uniform joint scales are
  folded into bone lengths (non-uniform or animated scale cannot be represented: a warning says so).
- The rest pose is the node (default) pose: ``offsets`` are bone translations, ``rest_rotations`` the
  node rotations. Skins are posed there with their inverse bind matrices (kinema.io.gltf_mesh).
- Each animation's translation/rotation channels (LINEAR, STEP, CUBICSPLINE) are sampled at ``fps``
  from the clip's first to its last key; joints a clip does not animate keep their rest values. Bone
  translations that move become ``Motion.local_translations``.
"""

from __future__ import annotations

import math
import reprlib
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from kinema.finite import is_finite_real
from kinema.geometry.rotations import quat_mul, quat_rotate
from kinema.input_files import read_bytes_bounded
from kinema.io.gltf_data import GltfBuffers, GltfDocument, GltfError, decompose, node_matrix, parse_document, sample
from kinema.io.gltf_mesh import RawPart, read_parts
from kinema.limits import MAX_ASSET_BYTES, MAX_RIG_REACH
from kinema.mesh import SkinnedMesh, vertex_normals
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

__all__ = ["GltfAsset", "GltfError", "load_document", "load_gltf_motion", "read_gltf"]

_SCALE_TOL = 1e-5  # relative: float32 noise (1e-7) is quiet, a 1e-5 skew already moves a tail tip ~0.01 mm


@dataclass(frozen=True)
class GltfAsset:
    """A rig and its clips read from one glTF/GLB file (see the module docstring)."""

    path: Path
    skeleton: Skeleton
    motions: dict[str, Motion]
    source_fps: float | None
    scale: float
    helper_joints: tuple[str, ...]
    warnings: tuple[str, ...]


def load_document(path: str | Path) -> GltfDocument:
    """The parsed glTF document of ``path``; unreadable files raise a one-line `GltfError`."""
    path = Path(path)
    raw = read_bytes_bounded(path, "glTF/GLB file", MAX_ASSET_BYTES, error=GltfError)
    gltf = parse_document(raw, path)
    if not gltf.nodes:
        raise GltfError(f"{path}: has no nodes")
    return gltf


def _parents(gltf, path: Path) -> dict[int, int]:
    parent: dict[int, int] = {}
    for i, node in enumerate(gltf.nodes):
        for c in node.children or []:
            if not 0 <= c < len(gltf.nodes) or c in parent or c == i:
                raise GltfError(f"{path}: node {i} lists child {c}, which is missing or has two parents")
            parent[c] = i
    return parent


def _world(gltf, parent: dict[int, int]) -> np.ndarray:
    """(N, 4, 4) rest (default pose) world matrices of every node."""
    local = np.stack([node_matrix(n) for n in gltf.nodes])
    world = np.full_like(local, np.nan)
    for i in range(len(gltf.nodes)):
        chain = [i]
        while chain[-1] in parent and np.isnan(world[parent[chain[-1]], 0, 0]):
            chain.append(parent[chain[-1]])
        for n in reversed(chain):
            world[n] = (world[parent[n]] if n in parent else np.eye(4)) @ local[n]
    return world


def _check_skins(gltf, path: Path) -> None:
    """Each skin lists its joints as a non-empty list of node indices, and each node's ``skin`` is a skin."""
    for i, skin in enumerate(gltf.skins):
        joints = skin.joints
        if not isinstance(joints, list) or not joints or not all(type(j) is int for j in joints):
            raise GltfError(f"{path}: skin {i} lists no joints ('joints' must be a non-empty list of node indices)")
    for n, node in enumerate(gltf.nodes):
        if node.skin is not None and not (type(node.skin) is int and 0 <= node.skin < len(gltf.skins)):
            raise GltfError(f"{path}: node {n} uses skin {node.skin!r}, which does not exist")


_TRANSFORM_SIZES = {"matrix": 16, "translation": 3, "rotation": 4, "scale": 3}


def _check_transforms(gltf, path: Path) -> None:
    """Every node's matrix / translation / rotation / scale is a list of finite numbers of its size, and a
    rotation is no zero quaternion (NaN transforms used to reach the rig as numpy warnings and an error
    naming no file)."""
    for n, node in enumerate(gltf.nodes):
        for key, size in _TRANSFORM_SIZES.items():
            value = getattr(node, key)
            if value is None:
                continue
            ok = isinstance(value, list) and len(value) == size and all(is_finite_real(v) for v in value)
            if not ok or (key == "rotation" and not any(value)):
                raise GltfError(f"{path}: node {n} ({_node_name(gltf, n)}) has a bad {key} {reprlib.repr(value)}; "
                                f"expected {size} finite numbers{' (not all zero)' if key == 'rotation' else ''}")


def _select_joints(gltf, parent, parts: list[RawPart], keep_helpers: bool):
    """(kept joint nodes, helper names): skin joints + nodes between them, less weightless leaves."""
    joints = {j for s in gltf.skins for j in s.joints}
    for j in list(joints):
        chain, p = [], parent.get(j)
        while p is not None and p not in joints:
            chain.append(p)
            p = parent.get(p)
        if p is not None:
            joints.update(chain)
    weighted = {int(n) for part in parts for n in part.nodes[part.weights > 0].ravel()}
    needed = set()
    for n in weighted & joints:
        while n is not None and n not in needed:
            needed.add(n)
            n = parent.get(n)
    needed &= joints
    helpers = joints - needed if needed else set()
    names = tuple(_node_name(gltf, n) for n in sorted(helpers))
    return (joints if keep_helpers or not needed else needed), names


def _node_name(gltf, n: int) -> str:
    return gltf.nodes[n].name or f"node{n}"


def _order(gltf, parent, kept: set[int]) -> tuple[list[int], list[int]]:
    """Depth-first joint order (glTF node ids, -1 = synthetic root) and kinema parents."""
    roots = sorted(j for j in kept if parent.get(j) not in kept)
    if len(roots) > 1:
        common = {parent.get(r) for r in roots}
        top = common.pop() if len(common) == 1 and None not in common else -1
    else:
        top = roots[0]
    order, parents, todo = [], [], [(top, -1)]
    while todo:
        n, p = todo.pop()
        order.append(n)
        parents.append(p)
        kids = roots if n == -1 or (n == top and len(roots) > 1) else (gltf.nodes[n].children or [])
        todo.extend((c, len(order) - 1) for c in reversed(kids) if c in kept)
    return order, parents


def _check_unique_names(names: list[str], path: Path) -> None:
    """Joint names decide which limb and side a joint is (kinema.retarget.detect), so two joints with one
    name are refused, as a BVH's are, not renamed: a left foot also named ``RightFoot`` drove the right leg."""
    twice = sorted(n for n, count in Counter(names).items() if count > 1)
    if twice:
        raise GltfError(f"{path}: duplicate joint names {twice[:6]}; give each joint its own name")


def _unique(names: list[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for n in names:
        k = seen.get(n, 0)
        seen[n] = k + 1
        out.append(n if k == 0 else f"{n}.{k}")
    return out


class _Rig:
    """How glTF node transforms become kinema bone translations and rotations (module docstring)."""

    def __init__(self, gltf, parent, world, order, kparents, warns: list[str]):
        self.order, self.kparents = order, kparents
        J = len(order)
        self.rest_t, self.rest_r = np.zeros((J, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
        self.rest_s = np.ones((J, 3))
        self.base = np.tile(np.eye(4), (J, 1, 1))  # static transform above top joints
        self.top = np.zeros(J, dtype=bool)
        for j, n in enumerate(order):
            if n < 0:
                self.top[j] = True
                continue
            self.rest_t[j], self.rest_r[j], self.rest_s[j] = decompose(node_matrix(gltf.nodes[n]))
            if kparents[j] < 0 or order[kparents[j]] < 0:
                self.top[j] = True
                if n in parent:
                    self.base[j] = world[parent[n]]
        self.base_t = self.base[:, :3, 3]
        base_r, base_s = [], []
        for b in self.base:
            _, r, s = decompose(b)
            base_r.append(r)
            base_s.append(s)
        self.base_r, base_s = np.stack(base_r), np.stack(base_s)
        for j, n in enumerate(order):
            for what, s in (("the node above", base_s[j]), ("", self.rest_s[j])):
                if n >= 0 and np.ptp(s) > _SCALE_TOL * abs(s).max():
                    warns.append(
                        f"{what or 'joint'} {_node_name(gltf, n)} has non-uniform scale "
                        f"[{', '.join(f'{x:.7g}' for x in s)}]; kinema uses its mean"
                    )
        self.base_scale = base_s.mean(axis=1)
        acc = np.ones(J)  # accumulated uniform scale of each joint's frame
        for j in range(J):
            p = kparents[j]
            acc[j] = (self.base_scale[j] if self.top[j] else acc[p]) * self.rest_s[j].mean()
        self.root_scale = float(f"{acc[0]:.6g}")  # the armature scale applied (Quaternius: 100, 300, 39.5...)
        self.parent_scale = np.array([self.base_scale[j] if self.top[j] else acc[kparents[j]] for j in range(J)])

    def convert(self, t: np.ndarray, r_xyzw: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """(T, J, 3) node translations and (T, J, 4) xyzw rotations -> kinema translations and wxyz rotations."""
        r = torch.from_numpy(np.ascontiguousarray(r_xyzw[..., [3, 0, 1, 2]]))
        base_r = torch.from_numpy(np.ascontiguousarray(self.base_r[:, [3, 0, 1, 2]]))
        trans = torch.from_numpy(t * self.parent_scale[:, None])
        top = torch.from_numpy(self.top)
        r = torch.where(top[:, None], quat_mul(base_r.expand_as(r), r), r)
        moved = quat_rotate(base_r.expand_as(r), trans) + torch.from_numpy(self.base_t)
        trans = torch.where(top[:, None], moved, trans)
        return trans, r


def _channels(gltf, buffers, anim, where: str) -> dict[tuple[int, str], tuple]:
    out = {}
    for c in anim.channels:
        if c.target is None or c.target.node is None or c.target.path not in ("translation", "rotation", "scale"):
            continue
        try:
            smp = anim.samplers[c.sampler]
        except (IndexError, TypeError):
            raise GltfError(f"{buffers.path}: {where} channel names missing sampler {c.sampler}") from None
        times = buffers.accessor(smp.input).astype(np.float64).reshape(-1)
        values = buffers.accessor(smp.output).astype(np.float64)
        interp = smp.interpolation or "LINEAR"
        per_key = 3 if interp == "CUBICSPLINE" else 1
        if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise GltfError(f"{buffers.path}: {where} uses unknown interpolation {interp!r}")
        if len(times) == 0 or len(values) != per_key * len(times) or np.any(np.diff(times) < 0):
            raise GltfError(
                f"{buffers.path}: {where} sampler {c.sampler} has {len(times)} key times (must increase) and "
                f"{len(values)} values ({per_key} per key expected for {interp})"
            )
        if not (np.isfinite(times).all() and np.isfinite(values).all()):
            raise GltfError(f"{buffers.path}: {where} sampler {c.sampler} holds NaN or infinite values")
        out[(c.target.node, c.target.path)] = (times, values, interp)
    return out


def _estimate_fps(channel_sets: list[dict]) -> float | None:
    """Key rate of the file: 1 / median key spacing, snapped to an integer within 1 %."""
    gaps = [np.diff(times) for chans in channel_sets for times, _, _ in chans.values() if len(times) > 1]
    gaps = np.concatenate(gaps) if gaps else np.zeros(0)
    gaps = gaps[gaps > 1e-6]
    if not gaps.size:
        return None
    fps = 1.0 / float(np.median(gaps))
    return float(round(fps)) if abs(fps - round(fps)) <= 0.01 * fps else round(fps, 3)


def _clip(rig: _Rig, skeleton: Skeleton, chans: dict, fps: float, index: dict[int, int], scale_warn) -> Motion:
    """Sample one animation's channels at ``fps`` into a Motion on ``skeleton``."""
    t0 = min(float(t[0]) for t, _, _ in chans.values()) if chans else 0.0
    t1 = max(float(t[-1]) for t, _, _ in chans.values()) if chans else 0.0
    at = t0 + np.arange(int(math.floor((t1 - t0) * fps + 1e-3)) + 1) / fps  # 1e-3: float32 key times
    T = len(at)
    t = np.repeat(rig.rest_t[None], T, axis=0)
    r = np.repeat(rig.rest_r[None], T, axis=0)
    for (node, path), (times, values, interp) in chans.items():
        j = index.get(node)
        if j is None:
            continue
        v = sample(times, values, interp, at, rotation=path == "rotation")
        if path == "translation":
            t[:, j] = v
        elif path == "rotation":
            r[:, j] = v
        elif np.abs(v - rig.rest_s[j]).max() > _SCALE_TOL * np.abs(rig.rest_s[j]).max():
            scale_warn(j, float(np.abs(v / rig.rest_s[j] - 1).max()))
    trans, rot = rig.convert(t, r)
    local_t = trans if (trans - skeleton.offsets).abs().max() > 1e-6 else None
    return Motion(skeleton, fps, trans[:, 0].clone(), rot, None, local_t)


def _mesh(parts: list[RawPart], index: dict[int, int]) -> SkinnedMesh | None:
    if not parts:
        return None
    lookup = np.zeros(max(max(index) + 1, max(int(p.nodes.max()) for p in parts) + 1), dtype=np.int64)
    for node, j in index.items():
        if node >= 0:
            lookup[node] = j
    starts = np.cumsum([0] + [len(p.vertices) for p in parts])
    verts = np.concatenate([p.vertices for p in parts])
    faces = np.concatenate([p.faces + s for p, s in zip(parts, starts, strict=False)])
    normals = [p.normals if p.normals is not None else vertex_normals(p.vertices, p.faces) for p in parts]
    weights = np.concatenate([p.weights for p in parts])
    joints = np.where(weights > 0, np.concatenate([lookup[p.nodes] for p in parts]), 0)
    colors = sorted({p.color for p in parts})
    face_parts = np.concatenate([np.full(len(p.faces), colors.index(p.color)) for p in parts])
    return SkinnedMesh(
        verts.astype(np.float32),
        np.concatenate(normals).astype(np.float32),
        faces.astype(np.int64),
        joints.astype(np.int64),
        weights.astype(np.float32),
        face_parts.astype(np.int64),
        np.asarray(colors, dtype=np.float32).reshape(-1, 4),
    )


def _pick(names: list[str], wanted: Sequence[str] | None, path: Path) -> list[int]:
    """Indices of the requested animations (full name, or the part after ``Armature|``)."""
    if wanted is None:
        return list(range(len(names)))
    out = []
    for w in wanted:
        hits = [i for i, n in enumerate(names) if w in (n, n.split("|")[-1])]
        if not hits:
            raise GltfError(f"{path}: no animation named {w!r}; the file has {names}")
        out += [i for i in hits if i not in out]
    return out


def read_gltf(
    path: str | Path,
    *,
    fps: float | None = None,
    animations: Sequence[str] | None = None,
    keep_helpers: bool = False,
) -> GltfAsset:
    """Read a skinned rig and its animations from a ``.glb``/``.gltf`` file (see the module docstring).

    ``fps`` resamples every clip (``None``: the file's key rate, 30 when it has none); ``animations``
    selects clips by name. Files kinema cannot use raise a one-line `GltfError` naming the file.
    """
    path = Path(path)
    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise GltfError(f"fps must be a positive number, got {fps}")
    gltf = load_document(path)
    if not gltf.skins:
        raise GltfError(f"{path}: has no skin (armature); kinema reads skinned, rigged models")
    _check_skins(gltf, path)
    _check_transforms(gltf, path)
    buffers = GltfBuffers(gltf, path)
    parent = _parents(gltf, path)
    world = _world(gltf, parent)
    skin_nodes = {j for s in gltf.skins for j in s.joints}
    if any(not 0 <= j < len(gltf.nodes) for j in skin_nodes):
        raise GltfError(f"{path}: a skin names a joint node that does not exist")
    warns: list[str] = []
    parts = read_parts(buffers, world, parent, skin_nodes, warns)
    kept, helpers = _select_joints(gltf, parent, parts, keep_helpers)
    order, kparents = _order(gltf, parent, kept)
    rig = _Rig(gltf, parent, world, order, kparents, warns)
    _check_unique_names([_node_name(gltf, n) for n in order if n >= 0], path)
    names = _unique(["root" if n < 0 else _node_name(gltf, n) for n in order])
    index = {n: j for j, n in enumerate(order)}
    rest_t, rest_r = rig.convert(rig.rest_t[None], rig.rest_r[None])
    mesh = _mesh(parts, index)
    skeleton = Skeleton(names, kparents, rest_t[0], rest_r[0], name=path.stem.removesuffix("-transformed"), mesh=mesh)
    if not skeleton.reach() <= MAX_RIG_REACH:
        raise GltfError(f"{path}: the rig reaches {skeleton.reach():.3g} m from its root (armature scale "
                        f"{rig.root_scale:g} applied); at most {MAX_RIG_REACH:g} m: is the export's unit or scale "
                        f"wrong?")
    anim_names = _unique([a.name or f"animation_{i}" for i, a in enumerate(gltf.animations)])
    chosen = _pick(anim_names, animations, path)
    chans = [_channels(gltf, buffers, gltf.animations[i], f"animation {anim_names[i]!r}") for i in chosen]
    source_fps = _estimate_fps(chans)
    rate = fps or source_fps or 30.0
    scaled: dict[str, float] = {}

    def scale_warn(j: int, amount: float) -> None:
        scaled[names[j]] = max(scaled.get(names[j], 0.0), amount)

    motions = {
        anim_names[i]: _clip(rig, skeleton, c, rate, index, scale_warn) for i, c in zip(chosen, chans, strict=True)
    }
    warns += [f"scale animation of joint {n} (up to {100 * a:.3g} %) is ignored" for n, a in scaled.items()]
    return GltfAsset(path, skeleton, motions, source_fps, rig.root_scale, helpers, tuple(warns))


def load_gltf_motion(path: str | Path, *, animation: str | None = None, fps: float | None = None) -> Motion:
    """One clip of a glTF file as a Motion (the format registry's reader): ``animation`` by name, else the first."""
    asset = read_gltf(path, fps=fps, animations=None if animation is None else [animation])
    if not asset.motions:
        raise GltfError(f"{path}: has no animations")
    return next(iter(asset.motions.values()))
