"""Forward kinematics: local rotations + root translation -> global rotations and joint positions.

Batched over any leading axes and differentiable. Shapes: local rotations ``(..., J, 4)`` wxyz,
root translation ``(..., 3)`` metres, offsets ``(J, 3)`` metres (or per frame ``(..., J, 3)``), parents
length J (root -1).
"""

from __future__ import annotations

from collections.abc import Sequence
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
    ``root_translation`` with rotation ``L_root``.
    """
    offsets = offsets.to(dtype=local_rotations.dtype, device=local_rotations.device)
    rots: list[torch.Tensor] = []
    pos: list[torch.Tensor] = []
    for j, p in enumerate(parents):
        if p < 0:
            rots.append(local_rotations[..., j, :])
            pos.append(root_translation.to(local_rotations.dtype))
        else:
            rots.append(quat_mul(rots[p], local_rotations[..., j, :]))
            pos.append(pos[p] + quat_rotate(rots[p], offsets[..., j, :].expand_as(pos[p])))
    return torch.stack(rots, dim=-2), torch.stack(pos, dim=-2)


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
