"""Bring out-of-reach end-effector targets within reach by moving the whole body.

Two-bone IK can only place a hand or foot within ``|upper| + |lower|`` of the shoulder or hip. When a
target lies farther away, the root translation is shifted (smoothly blended into neighbouring frames)
by the missing distance, so the subsequent IK step can hit it exactly.
"""

from __future__ import annotations

import torch

from kinema.motion.core import Motion
from kinema.postprocess.ik import chain_for_joint, limb_chain, spread_corrections

#: fraction of the straight-limb length treated as reachable (a fully straight limb is degenerate)
REACH = 0.995


def _chain(skel, j: int, toes: dict) -> tuple[tuple[int, int, int], bool]:
    if j in toes:
        return limb_chain(skel, f"{toes[j]}_leg"), True
    return chain_for_joint(skel, j), False


def reach_shift(motion: Motion, joint_positions: dict, pinned: torch.Tensor, radius: float) -> torch.Tensor:
    """(T, 3) root translation offsets that put every positional target within its limb's reach.

    ``joint_positions``: joint index -> (frames (K,), world targets (K, 3)); ``pinned`` (T,) frames that
    must not move (full-body keyframes)."""
    skel, T = motion.skeleton, motion.num_frames
    _, P = motion.global_transforms()
    roles = skel.roles
    toes = {roles.get(f"{s}_toe"): s for s in ("left", "right")}
    frames_all, shifts_all = [], []
    for j, (frames, targets) in joint_positions.items():
        if j == 0 or skel.depths[j] < 2:
            continue
        keep = ~pinned[frames]
        frames, targets = frames[keep], targets[keep].to(P.dtype)
        if not frames.numel():
            continue
        (a, b, c), is_toe = _chain(skel, j, toes)
        goal = targets - (P[frames, j] - P[frames, c]) if is_toe else targets  # toe target -> ankle goal
        reach = REACH * (skel.offsets[b].norm() + skel.offsets[c].norm()).to(P.dtype)
        d = goal - P[frames, a]
        dist = d.norm(dim=-1, keepdim=True).clamp_min(1e-9)
        excess = (dist - reach).clamp_min(0.0)
        frames_all.append(frames)
        shifts_all.append(d / dist * excess)
    if not frames_all:
        return torch.zeros(T, 3, dtype=P.dtype)
    frames, shifts = torch.cat(frames_all), torch.cat(shifts_all)
    if not bool((shifts.abs() > 0).any()):
        return torch.zeros(T, 3, dtype=P.dtype)
    field, _ = spread_corrections(frames, shifts, T, radius)
    return field * (~pinned)[:, None].to(field.dtype)
