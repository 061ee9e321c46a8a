"""Forward kinematics: local rotations + root translation -> global rotations and joint positions.

Batched over any leading axes and differentiable. Shapes: local rotations ``(..., J, 4)`` wxyz,
root translation ``(..., 3)`` metres, offsets ``(J, 3)`` metres (or per frame ``(..., J, 3)``), parents
length J (root -1).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

import torch

from kinema.geometry.rotations import quat_mul, quat_rotate, sixd_to_matrix

if TYPE_CHECKING:
    from kinema.skeleton import Skeleton


def forward_kinematics(
    local_rotations: torch.Tensor,
    root_translation: torch.Tensor,
    offsets: torch.Tensor,
    parents: Sequence[int],
) -> tuple[torch.Tensor, torch.Tensor]:
    """Global rotations ``(..., J, 4)`` and positions ``(..., J, 3)`` of every joint.

    ``G_j = G_parent @ L_j`` and ``p_j = p_parent + G_parent @ offset_j``; the root sits at
    ``root_translation`` with rotation ``L_root``. All joints of one depth are done in one batched
    quaternion product (a 21-joint human: 7 levels instead of 21 joints), with the same arithmetic per
    element as joint by joint, so the results are bit for bit those of a per-joint loop.
    """
    return _by_depth(local_rotations, root_translation, offsets, parents, 1, quat_mul,
                     lambda G, offset: quat_rotate(G, offset))


def matmul3(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a @ b`` for stacks of 3x3 matrices ``(..., 3, 3)``."""
    return a @ b


def forward_kinematics_matrices(
    local_rotmats: torch.Tensor,
    root_translation: torch.Tensor,
    offsets: torch.Tensor,
    parents: Sequence[int],
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`forward_kinematics` on rotation matrices: local ``(..., J, 3, 3)`` -> global rotations
    ``(..., J, 3, 3)`` and positions ``(..., J, 3)``. One matrix product per depth level: the cheapest
    differentiable FK for an optimisation that runs it (and its backward pass) many times."""
    return _by_depth(local_rotmats, root_translation, offsets, parents, 2, matmul3,
                     lambda G, offset: (G * offset.unsqueeze(-2)).sum(-1))


def _by_depth(local, root_translation, offsets, parents, rot_dims: int, compose, rotate):
    """FK over depth levels for rotations with ``rot_dims`` trailing dimensions (quaternions 1, matrices
    2): ``compose(G_parent, L)`` and ``rotate(G_parent, offset)`` on all joints of a level at once."""
    offsets = offsets.to(dtype=local.dtype, device=local.device)
    order, levels = depth_levels(tuple(int(p) for p in parents))
    dim = local.dim() - 1 - rot_dims  # the joint axis (also of the positions)
    roots = levels[0][0]
    rots = [local.index_select(dim, roots)]
    root = root_translation.to(local.dtype).unsqueeze(-2)
    pos = [root.expand(*root.shape[:-2], len(roots), 3)]
    for joints, parent_slots in levels[1:]:  # each level's parents are all in the level before it
        Gp, Pp = rots[-1].index_select(dim, parent_slots), pos[-1].index_select(dim, parent_slots)
        rots.append(compose(Gp, local.index_select(dim, joints)))
        pos.append(Pp + rotate(Gp, offsets.index_select(offsets.dim() - 2, joints).expand_as(Pp)))
    G_done, P_done = torch.cat(rots, dim=dim), torch.cat(pos, dim=dim)
    if order is None:
        return G_done, P_done
    return G_done.index_select(dim, order), P_done.index_select(dim, order)


@lru_cache(maxsize=64)
def depth_levels(parents: tuple[int, ...]) -> tuple[torch.Tensor | None, list[tuple[torch.Tensor, torch.Tensor]]]:
    """The joints of ``parents`` grouped by depth: ``levels[d] = (joints, parent_slots)`` (LongTensors)
    where ``parent_slots`` index each joint's parent within level ``d - 1`` (level 0: the roots, no
    parents); and ``order``, the permutation from the depth order (all levels one after another) back to
    joint order (None when the joints are already in depth order). Linear in the joint count, so a
    5000-joint chain costs no more per joint than a human."""
    depth: list[int] = []
    by_depth: list[list[int]] = []
    for j, p in enumerate(parents):
        if p >= j:
            raise ValueError(f"joint {j}'s parent {p} does not come before it")
        depth.append(0 if p < 0 else depth[p] + 1)
        if depth[j] == len(by_depth):
            by_depth.append([])
        by_depth[depth[j]].append(j)
    levels: list[tuple[torch.Tensor, torch.Tensor]] = []
    within: dict[int, int] = {}  # joint -> its index inside its own level
    for d, joints in enumerate(by_depth):
        slots = [within[parents[j]] for j in joints] if d else []
        levels.append((torch.tensor(joints), torch.tensor(slots, dtype=torch.long)))
        within.update((j, i) for i, j in enumerate(joints))
    depth_order = [j for joints in by_depth for j in joints]
    order = [0] * len(parents)
    for slot, j in enumerate(depth_order):
        order[j] = slot
    return (None if depth_order == list(range(len(parents))) else torch.tensor(order)), levels


def positions_from_global_rotations(
    global_rotmats: torch.Tensor,
    root_position: torch.Tensor,
    offsets: torch.Tensor,
    ancestor_matrix: torch.Tensor,
    parents: Sequence[int],
) -> torch.Tensor:
    """Joint positions ``(..., J, 3)`` from *global* rotation matrices ``(..., J, 3, 3)``.

    With global rotations no chain product is needed: each bone vector is its parent's global rotation
    applied to its offset, and positions are the root plus the sum of bone vectors along the path
    (``ancestor_matrix`` from ``Skeleton.ancestor_matrix``). Used by the model's FK loss, so it avoids
    Python loops over frames and joints.
    """
    dtype = global_rotmats.dtype
    offsets = offsets.to(dtype=dtype, device=global_rotmats.device)
    parent_idx = torch.tensor([max(p, 0) for p in parents], device=global_rotmats.device)
    parent_rot = global_rotmats[..., parent_idx, :, :]  # (..., J, 3, 3)
    bones = torch.einsum("...jab,jb->...ja", parent_rot, offsets)  # (..., J, 3); row 0 unused
    A = ancestor_matrix.to(dtype=dtype, device=global_rotmats.device)
    return root_position.unsqueeze(-2) + torch.einsum("jk,...kc->...jc", A, bones)


def positions_from_sixd(rot6: torch.Tensor, root_position: torch.Tensor, skeleton: Skeleton) -> torch.Tensor:
    """Joint positions ``(..., J, 3)`` from *global* 6D rotations ``(..., J, 6)`` (unnormalised) with the
    root joint at ``root_position (..., 3)``: :func:`positions_from_global_rotations` on ``skeleton``."""
    return positions_from_global_rotations(
        sixd_to_matrix(rot6), root_position, skeleton.offsets, skeleton.ancestor_matrix, skeleton.parents
    )
