"""Bring out-of-reach end-effector targets within reach by moving the whole body.

Two-bone IK can only place a hand or foot within ``|upper| + |lower|`` of the shoulder or hip. When a
target lies farther away, the root translation is shifted (smoothly blended into neighbouring frames)
by the missing distance, so the subsequent IK step can hit it exactly.

The shift is bounded: a person leans or takes a step towards a target a little out of reach, but is not
dragged metres across the floor in a fraction of a second. Each target moves the body by at most
``MAX_SHIFT`` metres, and the shift is spread over enough frames that it adds at most ``MAX_SHIFT_SPEED``
to the root's speed. A target farther than that stays unmet, and the exact pass reports it (measured
before the bound: a hand target 50 m away moved the body 12 m per frame; a foot target behind a walk
dragged the root back 3.5 m in 0.25 s).
"""

from __future__ import annotations

import math

import torch

from kinema.motion.core import Motion
from kinema.postprocess.ik import chain_for_joint, limb_chain, spread_corrections

#: fraction of the straight-limb length treated as reachable (a fully straight limb is degenerate)
REACH = 0.995
#: metres: the most a single out-of-reach target may move the body
MAX_SHIFT = 0.5
#: m/s: the most the shift may add to the root's speed (it is spread over a wider window if needed)
MAX_SHIFT_SPEED = 1.0


def reach_radius_seconds() -> float:
    """The widest window (seconds either side of a target) over which a reach shift may spread."""
    return MAX_SHIFT * math.pi / 2 / MAX_SHIFT_SPEED


def _chain(skel, j: int, toes: dict) -> tuple[tuple[int, int, int], bool]:
    if j in toes:
        return limb_chain(skel, f"{toes[j]}_leg"), True
    return chain_for_joint(skel, j), False


def _limb_gap(skel, P: torch.Tensor, j: int, frames: torch.Tensor, targets: torch.Tensor, toes: dict):
    """``(base, tip, d, dist, reach)`` of position targets ``(K, 3)`` of joint ``j``: the limb's base
    position (shoulder or hip) ``(K, 3)``, the toe-to-ankle offset that turns a toe target into an ankle
    goal (0 for other joints), ``d = goal - base`` ``(K, 3)``, its length ``(K, 1)`` and the reachable
    length of the limb (metres)."""
    (a, b, c), is_toe = _chain(skel, j, toes)
    tip = (P[frames, j] - P[frames, c]).to(targets.dtype) if is_toe else 0.0
    base = P[frames, a].to(targets.dtype)
    d = targets - tip - base
    reach = REACH * float(skel.offsets[b].norm() + skel.offsets[c].norm())
    return base, tip, d, d.norm(dim=-1, keepdim=True).clamp_min(1e-9), reach


def _toes(skel) -> dict:
    return {skel.roles.get(f"{s}_toe"): s for s in ("left", "right")}


def reach_shift(motion: Motion, joint_positions: dict, pinned: torch.Tensor, radius: float) -> torch.Tensor:
    """(T, 3) root translation offsets that put every positional target within its limb's reach.

    ``joint_positions``: joint index -> (frames (K,), world targets (K, 3)); ``pinned`` (T,) frames that
    must not move (full-body keyframes)."""
    skel, T = motion.skeleton, motion.num_frames
    _, P = motion.global_transforms()
    toes = _toes(skel)
    frames_all, shifts_all = [], []
    for j, (frames, targets) in joint_positions.items():
        if j == 0 or skel.depths[j] < 2:
            continue
        keep = ~pinned[frames]
        frames, targets = frames[keep], targets[keep].to(P.dtype)
        if not frames.numel():
            continue
        _, _, d, dist, reach = _limb_gap(skel, P, j, frames, targets, toes)
        excess = (dist - reach).clamp(min=0.0, max=MAX_SHIFT)
        frames_all.append(frames)
        shifts_all.append(d / dist * excess)
    if not frames_all:
        return torch.zeros(T, 3, dtype=P.dtype)
    frames, shifts = torch.cat(frames_all), torch.cat(shifts_all)
    if not bool((shifts.abs() > 0).any()):
        return torch.zeros(T, 3, dtype=P.dtype)
    # a raised cosine of radius r frames rises by its height h with a peak slope of h * pi / (2 r) per frame
    fps = float(motion.fps)
    radius = max(radius, float(shifts.norm(dim=-1).max()) * math.pi / 2 * fps / MAX_SHIFT_SPEED)
    field, _ = spread_corrections(frames, shifts, T, radius)
    return field * (~pinned)[:, None].to(field.dtype)


def clip_to_reach(motion: Motion, joint_positions: dict) -> dict:
    """Position targets pulled in to what the body can meet: a target farther than its limb's reach plus
    ``MAX_SHIFT`` from the limb's base (shoulder or hip) at its frame is moved along the line towards the
    base to that distance; others are returned unchanged. Every stage aims at these, so no stage (the
    optimisation included) chases a target metres away; the unmet remainder is reported against the
    user's own targets."""
    skel = motion.skeleton
    _, P = motion.global_transforms()
    toes = _toes(skel)
    out = {}
    for j, (frames, targets) in joint_positions.items():
        if j == 0 or skel.depths[j] < 2:
            out[j] = (frames, targets)
            continue
        base, tip, d, dist, reach = _limb_gap(skel, P, j, frames, targets, toes)
        scale = ((reach + MAX_SHIFT) / dist).clamp(max=1.0)
        out[j] = (frames, base + tip + d * scale)
    return out
