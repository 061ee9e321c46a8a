"""Rig augmentation ("How to Move Your Dragon" Sec. 4.2): new skeletons carrying the same motion.

Each function maps a `Motion` to a `Motion` on a changed skeleton (mesh dropped; names kept, new
joints named ``<child>_aug``):

- `scale_bones`: every bone length x U(0.8, 1.2), the same factor for left/right partners; the root
  path is shifted vertically so the lowest point of the clip stays where it was;
- `insert_joint`: one bone split in two at a random fraction by a new joint with an identity local
  rotation, so every existing joint keeps its world position exactly;
- `remove_leaf`: one leaf joint (never the root or one of ``keep``, e.g. the contacts) dropped; the
  others keep their world positions exactly;
- `reset_rest`: new local frames for some joints (a random rotation ``Q_j`` per joint; global
  rotations become ``G_j Q_j``, children's offsets ``Q_p^-1 o``), so joint positions are unchanged
  while rotation features and the rest pose change -- the model must read rotations through RestPE.

`augment` chains them at random. All work in float64; shapes ``(T, J, ...)``.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import quat_identity, quat_inverse, quat_mul, quat_normalize, quat_rotate
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton


def _skeleton(skel: Skeleton, names, parents, offsets, rest) -> Skeleton:
    return Skeleton(names, parents, offsets, rest, name=skel.name)


def _rest(skel: Skeleton) -> torch.Tensor:
    J = skel.num_joints
    return skel.rest_rotations if skel.rest_rotations is not None else quat_identity((J,), torch.float64)


def _offsets(m: Motion) -> torch.Tensor:
    """Per-frame bone offsets ``(T, J, 3)``: the animated translations or the rest offsets."""
    if m.local_translations is not None:
        return m.local_translations
    return m.skeleton.offsets[None].expand(m.num_frames, -1, -1)


def scale_bones(m: Motion, gen: torch.Generator, lo: float = 0.8, hi: float = 1.2) -> Motion:
    skel = m.skeleton
    s = lo + (hi - lo) * torch.rand(skel.num_joints, generator=gen, dtype=torch.float64)
    mirror = torch.tensor(skel.mirror_map)
    s = torch.where(mirror < torch.arange(skel.num_joints), s[mirror], s)
    s[0] = 1.0
    new = _skeleton(skel, skel.names, skel.parents, skel.offsets * s[:, None], skel.rest_rotations)
    lt = None if m.local_translations is None else m.local_translations * s[None, :, None]
    out = Motion(new, m.fps, m.root_translation.clone(), m.local_rotations, None, lt)
    dy = m.positions[..., 1].min() - out.positions[..., 1].min()
    out.root_translation[:, 1] += dy
    return out


def insert_joint(m: Motion, gen: torch.Generator) -> Motion:
    skel = m.skeleton
    c = int(torch.randint(1, skel.num_joints, (1,), generator=gen))
    a = float(0.3 + 0.4 * torch.rand(1, generator=gen, dtype=torch.float64))
    order = list(range(c)) + [-1] + list(range(c, skel.num_joints))  # -1 = the new joint, at index c
    new_index = {old: i for i, old in enumerate(order) if old >= 0}
    parents, names = [], []
    for old in order:
        if old < 0:
            parents.append(new_index[skel.parents[c]])
            names.append(_fresh(skel.names, skel.names[c] + "_aug"))
        else:
            p = skel.parents[old]
            parents.append(c if old == c else (new_index[p] if p >= 0 else -1))
            names.append(skel.names[old])
    off = _offsets(m)
    ins = lambda x, v: torch.cat([x[..., :c, :], v[..., None, :], x[..., c:, :]], dim=-2)  # noqa: E731
    offsets = ins(skel.offsets, a * skel.offsets[c])
    offsets[c + 1] = (1 - a) * skel.offsets[c]
    frames = ins(off, a * off[:, c])
    frames[:, c + 1] = (1 - a) * off[:, c]
    rest = ins(_rest(skel), quat_identity((), torch.float64))
    rots = ins(m.local_rotations.double(), quat_identity((m.num_frames,), torch.float64))
    new = _skeleton(skel, names, parents, offsets, rest)
    lt = frames if m.local_translations is not None else None
    return Motion(new, m.fps, m.root_translation, rots, None, lt)


def _fresh(names, name: str) -> str:
    while name in names:
        name += "_"
    return name


def remove_leaf(m: Motion, gen: torch.Generator, keep=()) -> Motion:
    skel = m.skeleton
    kids = skel.children
    leaves = [j for j in range(1, skel.num_joints) if not kids[j] and j not in keep]
    if not leaves or skel.num_joints <= 3:
        return m
    d = leaves[int(torch.randint(len(leaves), (1,), generator=gen))]
    keep_idx = [j for j in range(skel.num_joints) if j != d]
    remap = {old: i for i, old in enumerate(keep_idx)}
    parents = [remap[skel.parents[j]] if skel.parents[j] >= 0 else -1 for j in keep_idx]
    rest = None if skel.rest_rotations is None else skel.rest_rotations[keep_idx]
    new = _skeleton(skel, [skel.names[j] for j in keep_idx], parents, skel.offsets[keep_idx], rest)
    lt = None if m.local_translations is None else m.local_translations[:, keep_idx]
    return Motion(new, m.fps, m.root_translation, m.local_rotations[:, keep_idx], None, lt)


def reset_rest(m: Motion, gen: torch.Generator, fraction: float = 0.5, max_angle: float = 1.5) -> Motion:
    skel = m.skeleton
    J = skel.num_joints
    axis = torch.randn(J, 3, generator=gen, dtype=torch.float64)
    angle = max_angle * torch.rand(J, generator=gen, dtype=torch.float64)
    angle = torch.where(torch.rand(J, generator=gen, dtype=torch.float64) < fraction, angle, 0.0)
    axis = axis / axis.norm(dim=-1, keepdim=True).clamp_min(1e-9)
    Q = quat_normalize(torch.cat([torch.cos(angle / 2)[:, None], torch.sin(angle / 2)[:, None] * axis], dim=-1))
    parents = torch.tensor(skel.parents)
    Qp = torch.where((parents >= 0)[:, None], Q[parents.clamp_min(0)], quat_identity((J,), torch.float64))
    Qp_inv = quat_inverse(Qp)
    T = m.num_frames
    rots = quat_mul(quat_mul(Qp_inv.expand(T, J, 4), m.local_rotations.double()), Q.expand(T, J, 4))
    rest = quat_mul(quat_mul(Qp_inv, _rest(skel)), Q)
    offsets = quat_rotate(Qp_inv, skel.offsets)
    offsets[0] = skel.offsets[0]
    lt = None
    if m.local_translations is not None:
        lt = quat_rotate(Qp_inv.expand(T, J, 4), m.local_translations.double())
        lt[:, 0] = m.local_translations[:, 0]
    new = _skeleton(skel, skel.names, skel.parents, offsets, rest)
    return Motion(new, m.fps, m.root_translation, rots, None, lt)


def augment(m: Motion, gen: torch.Generator, keep=()) -> Motion:
    """Bone lengths always; then, each with probability 0.4, a joint inserted, a leaf removed (never one
    of ``keep``, e.g. the rig's contacts) and rest frames reset."""
    out = scale_bones(m.to(torch.float64), gen)
    if float(torch.rand(1, generator=gen)) < 0.4:
        out = remove_leaf(out, gen, keep)
    if float(torch.rand(1, generator=gen)) < 0.4:
        out = insert_joint(out, gen)
    if float(torch.rand(1, generator=gen)) < 0.4:
        out = reset_rest(out, gen)
    return out
