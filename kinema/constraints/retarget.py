"""Poses from a file whose bone frames differ from the model's: align the rest poses.

A BVH (or any skeleton) with the model's joint names can still orient its bones differently at rest:
kinema's synthetic clips stand facing +Z with identity rest rotations, while Bandai Namco's rest pose
lies along +X. Keeping a joint's global rotation then points the model's bone somewhere else (an
in-betweening keyframe from such a file threw the pelvis 21 m/s). The fix is the usual rest-pose
retarget: find, per joint, the constant rotation ``R_j`` that turns the model's child offsets onto the
file's (shortest arc for one child, a least-squares fit for several, the parent's for a leaf), and pose
the model with ``G_model = G_file * R_j``, so every bone points where the file's bone points.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import matrix_to_quat, quat_between, quat_mul, quat_normalize
from kinema.skeleton import Skeleton

#: rest poses whose bones all agree within this angle (degrees) are used as they are (no rotation)
ALIGNED_DEGREES = 1.0


def _fit(model: torch.Tensor, source: torch.Tensor) -> torch.Tensor:
    """Rotation ``(4,)`` taking the model's child offsets ``(C, 3)`` onto the source's directions."""
    if model.shape[0] == 1:
        return quat_between(model[0], source[0])
    a = model / model.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    b = source / source.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    U, _, Vh = torch.linalg.svd(b.T @ a)
    d = torch.sign(torch.linalg.det(U @ Vh))
    D = torch.diag(torch.stack([torch.ones_like(d), torch.ones_like(d), d]))
    return matrix_to_quat(U @ D @ Vh)


def rest_alignment(skeleton: Skeleton, source_offsets: torch.Tensor) -> torch.Tensor | None:
    """Per-joint rotations ``(J, 4)`` with ``G_model = G_source * R``, or None when the rest poses agree.

    ``source_offsets (J, 3)`` are the file's rest offsets in the model's joint order (any length unit)."""
    model = skeleton.offsets.to(torch.float64)
    source = source_offsets.to(torch.float64)
    kids = skeleton.children
    moving = [c for c in range(1, skeleton.num_joints) if model[c].norm() > 1e-9 and source[c].norm() > 1e-9]
    if moving:
        cos = torch.nn.functional.cosine_similarity(model[moving], source[moving], dim=-1)
        if float(torch.rad2deg(torch.arccos(cos.clamp(-1, 1))).max()) <= ALIGNED_DEGREES:
            return None
    R = torch.zeros(skeleton.num_joints, 4, dtype=torch.float64)
    R[:, 0] = 1.0
    for j in range(skeleton.num_joints):  # parents first
        used = [c for c in kids[j] if c in moving]
        if used:
            R[j] = _fit(model[used], source[used])
        elif skeleton.parents[j] >= 0:
            R[j] = R[skeleton.parents[j]]
    return quat_normalize(R)


def retarget_globals(G: torch.Tensor, R: torch.Tensor | None) -> torch.Tensor:
    """Global rotations ``(..., J, 4)`` of the file turned into the model's bone frames."""
    return G if R is None else quat_normalize(quat_mul(G, R.to(G.dtype)))


__all__ = ["rest_alignment", "retarget_globals"]
