"""Contact-aware legs: where each target foot goes, planted where the source's is, and two-bone IK.

Per leg (kinema.retarget.mapping.Leg) and frame, the target ankle's goal is the source ankle's
position relative to its hip, scaled by the body scale ``s`` and added to the target's hip; its height
is the source ankle's height scaled, corrected by how much higher the target's ankle sits above its
lowest joint at rest than the scaled source's (big shoes, chibi feet). While the source's heel
(ankle) contact is planted the goal's x/z is held at its mean over that contact; while only the toe
is planted the toe is held instead and the ankle goal follows from the foot's rotation. The holds
are blended in and out with raised-cosine ramps (kinema.postprocess.ik.spread_corrections) over
``BLEND_SECONDS``, so nothing pops.

Where a planted goal lies beyond the leg's reach (a character whose IK foot bone sits on the floor
while the source's ankle is 8 cm up, or a stiff-legged rest pose), the hips are lowered just enough,
eased in and out like the holds, so the foot stays put instead of being dragged.

The IK treats ``upper -> lower`` and ``lower -> ankle`` as two rigid segments in the upper and lower
joints' frames (an unmapped joint between them, such as a mech's ``MidLeg``, rides along), keeps the
knee in the plane the source's knee bend gives (the hips' forward where the leg is straight) and
turns the two segments by shortest arcs. A foot that hangs off the leg (Quaternius ``Foot.L`` under
the root) is a *virtual* end: the rest-pose offset from the lower leg to it, which is where the foot
is placed afterwards.

Shapes: rotations ``(T, J, 4)`` wxyz, positions ``(T, J, 3)``, float64; lengths in the target's units.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import quat_between, quat_inverse, quat_mul, quat_rotate
from kinema.postprocess.footlock import contact_segments
from kinema.postprocess.ik import spread_corrections
from kinema.retarget.mapping import Leg

BLEND_SECONDS = 0.1
#: a planted leg is lowered to reach its goal at this fraction of its full length (never locked straight)
REACH = 0.995
_EPS = 1e-9


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(_EPS)


def segment(G0: torch.Tensor, P0: torch.Tensor, a: int, b: int) -> torch.Tensor:
    """(3,) rest vector from joint ``a`` to joint ``b`` in ``a``'s frame (rigid while ``a`` turns)."""
    return quat_rotate(quat_inverse(G0[a]), P0[b] - P0[a])


def _hold(goal: torch.Tensor, segs: list[tuple[int, int]]) -> tuple[list[int], list[torch.Tensor]]:
    frames, values = [], []
    for start, end in segs:
        mean = goal[start:end, [0, 2]].mean(dim=0)
        for t in range(start, end):
            frames.append(t)
            values.append(mean - goal[t, [0, 2]])
    return frames, values


def planted_goals(
    goal: torch.Tensor, heel: torch.Tensor, toe: torch.Tensor | None, toe_offset: torch.Tensor | None, fps: float
) -> torch.Tensor:
    """(T, 3) ankle goals with planted contacts held (module docstring).

    ``heel``/``toe`` (T,) bool planted flags of the source's ankle and toe; ``toe_offset (T, 3)`` the
    world vector from the target's ankle to its toe (None without toes)."""
    frames, values = _hold(goal, contact_segments(heel))
    if toe is not None and toe_offset is not None:
        f2, v2 = _hold(goal + toe_offset, contact_segments(toe & ~heel))
        frames, values = frames + f2, values + v2
    if not frames:
        return goal
    field, _ = spread_corrections(torch.tensor(frames), torch.stack(values), goal.shape[0], BLEND_SECONDS * fps)
    out = goal.clone()
    out[:, [0, 2]] += field
    return out


def reach_drop(
    P: torch.Tensor, legs: tuple[Leg, ...], segs, goals: list[torch.Tensor], planted: list[torch.Tensor], fps: float
) -> torch.Tensor | None:
    """(T,) how far to lower the hips so that every planted leg reaches its goal (eased in and out),
    or None when every planted goal is within reach. ``segs``: (seg1, seg2) per leg."""
    need = torch.zeros(P.shape[0], dtype=P.dtype)
    for leg, (seg1, seg2), goal, on in zip(legs, segs, goals, planted, strict=True):
        reach = REACH * float(seg1.norm() + seg2.norm())
        v = goal - P[:, leg.upper]
        flat = v[:, [0, 2]].norm(dim=-1).clamp(max=reach)
        short = (-v[:, 1] - (reach * reach - flat * flat).sqrt()).clamp(min=0)
        need = torch.maximum(need, torch.where(on, short, torch.zeros_like(short)))
    frames = torch.nonzero(need > 1e-6).flatten()
    if frames.numel() == 0:
        return None
    field, _ = spread_corrections(frames, need[frames, None], P.shape[0], 2 * BLEND_SECONDS * fps)
    return torch.maximum(field[:, 0], need)


def two_bone_ik(
    G: torch.Tensor,
    P: torch.Tensor,
    chain: tuple[int, int],
    seg1: torch.Tensor,
    seg2: torch.Tensor,
    goal: torch.Tensor,
    forward: torch.Tensor,
) -> torch.Tensor:
    """Turn the world rotations of ``chain = (upper, lower)`` in ``G`` (in place) so the chain's end
    reaches ``goal (T, 3)`` (as near as the limb's length allows); returns the reached end (T, 3).

    ``seg1``/``seg2``: rigid segments (kinema.retarget.legs.segment); ``forward (T, 3)``: the bend
    direction used where the limb is straight (forward for knees, backward for elbows)."""
    u, lo = chain
    H = P[:, u]
    K = H + quat_rotate(G[:, u], seg1.expand_as(H))
    l1, l2 = float(seg1.norm()), float(seg2.norm())
    to_goal = goal - H
    d = to_goal.norm(dim=-1, keepdim=True).clamp(min=abs(l1 - l2) + 1e-6, max=l1 + l2 - 1e-6)
    axis = _unit(to_goal)
    bend = (K - H) - ((K - H) * axis).sum(-1, keepdim=True) * axis
    fallback = forward - (forward * axis).sum(-1, keepdim=True) * axis
    straight = bend.norm(dim=-1, keepdim=True) < 1e-4 * (l1 + l2)
    bend = _unit(torch.where(straight, fallback, bend))
    cos_a = ((l1 * l1 + d * d - l2 * l2) / (2 * l1 * d)).clamp(-1, 1)
    knee = H + l1 * (cos_a * axis + (1 - cos_a * cos_a).clamp_min(0).sqrt() * bend)
    end = H + d * axis
    d1 = quat_between(_unit(K - H), _unit(knee - H))
    lower = quat_mul(d1, G[:, lo])
    e1 = knee + quat_rotate(lower, seg2.expand_as(H))
    d2 = quat_between(_unit(e1 - knee), _unit(end - knee))
    G[:, u] = quat_mul(d1, G[:, u])
    G[:, lo] = quat_mul(d2, lower)
    return end
