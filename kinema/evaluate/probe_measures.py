"""What the phrasing probes measure on a motion (kinema.evaluate.phrasings; docs/evaluation.md).

Positions in metres, Y up; the joints come from the skeleton's roles (``pelvis``, ``head``,
``left_hand``, ``right_hand``); speeds in m/s at the motion's fps.
"""

from __future__ import annotations

import math

import torch

from kinema.geometry.rotations import quat_rotate
from kinema.motion.core import Motion

# Speed probes are generated again at this length: every captured run covers the ~8 m capture room
# (5.7-9.8 m), so slow runs are the long clips (5.7 s on average) and fast runs and dashes the short
# ones (2.4 / 2.7 s). A 4-s motion's mean speed is then capped near 2.4 m/s for anything that runs, by
# the data; at 2 s the captures hold slow, medium and fast runs alike (docs/evaluation.md).
SHORT_SPEED_SECONDS = 2.0
# A sample follows a hand probe's side when the named hand gets this much higher than the other hand:
# half the smallest gap of any captured raise-up-*-hand style (feminine, 0.41 m; docs/evaluation.md).
SIDE_MARGIN = 0.2


def ground_speed(motion: Motion) -> float:
    """Mean ground speed of the pelvis (m/s): horizontal start-to-end distance over the duration."""
    pelvis = motion.skeleton.require_roles(("pelvis",))["pelvis"]
    p = motion.positions[:, pelvis].double()
    travel = (p[-1, [0, 2]] - p[0, [0, 2]]).norm()
    return float(travel) * motion.fps / max(motion.num_frames - 1, 1)


def hand_heights(motion: Motion, side: str) -> tuple[float, float]:
    """(named hand, other hand): the most each gets above the head joint over the motion (m; < 0 = below).

    ``side`` is 'left' or 'right' (the character's own side, as the skeleton's roles name it)."""
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    other = "right" if side == "left" else "left"
    roles = motion.skeleton.require_roles(("head", f"{side}_hand", f"{other}_hand"))
    y = motion.positions[..., 1].double()  # (T, J), Y up
    head = y[:, roles["head"]]
    return float((y[:, roles[f"{side}_hand"]] - head).max()), float((y[:, roles[f"{other}_hand"]] - head).max())


def raises_hand(named: float, other: float) -> bool:
    """Whether a motion with these :func:`hand_heights` raises the named hand (above head and other hand)."""
    return named > 0.0 and named > other


def follows_side(named: float, other: float) -> bool:
    """Whether a motion with these :func:`hand_heights` raises the named hand and not the other: the named
    hand gets :data:`SIDE_MARGIN` higher than the other one does (above the head or not)."""
    return named - other >= SIDE_MARGIN


def window_speed(motion: Motion, seconds: float = SHORT_SPEED_SECONDS) -> float | None:
    """Mean :func:`ground_speed` of the motion's ``seconds``-long windows (every 0.5 s), or None when it is
    shorter: what a generated motion of that length could do, by the captures."""
    n = int(round(seconds * motion.fps))
    if motion.num_frames < n + 1:
        return None
    stride = max(1, int(round(0.5 * motion.fps)))
    pelvis = motion.skeleton.require_roles(("pelvis",))["pelvis"]
    p = motion.positions[:, pelvis][:, [0, 2]].double()
    starts = torch.arange(0, motion.num_frames - n, stride)
    return float((p[starts + n] - p[starts]).norm(dim=-1).mean()) * motion.fps / n


def group_step(a: dict, b: dict, separation: float) -> tuple[float, float, bool]:
    """(gap, its standard error, separated) from speed group ``a`` to ``b`` (each ``mean``, ``std`` over
    ``n`` samples): b is faster when its mean is more than ``separation`` standard errors above a's."""
    se = math.sqrt(a["std"] ** 2 / max(a["n"] - 1, 1) + b["std"] ** 2 / max(b["n"] - 1, 1))
    gap = b["mean"] - a["mean"]
    return gap, se, gap > separation * se


def body_forward(P: torch.Tensor, left_shoulder: int, right_shoulder: int) -> torch.Tensor:
    """Per frame, the body's horizontal forward unit vector ``(T, 3)`` of positions ``P (T, J, 3)``: square to
    the line from the right shoulder to the left, Y up. The shoulders, not the pelvis' travel, say where the
    body faces: a backward walk or a sidestep faces away from where it goes."""
    across = P[:, left_shoulder] - P[:, right_shoulder]
    fwd = torch.cross(across, torch.tensor([0.0, 1.0, 0.0], dtype=P.dtype).expand_as(across), dim=-1)
    fwd[:, 1] = 0
    return fwd / fwd.norm(dim=-1, keepdim=True).clamp_min(1e-9)


def head_ranges(P: torch.Tensor, Q: torch.Tensor, head: int, left_shoulder: int,
                right_shoulder: int) -> tuple[float, float]:
    """Ranges (degrees) of the head's pitch and yaw over a motion: positions ``P (T, J, 3)``, global
    rotations ``Q (T, J, 4)``, joint indices. The head's forward axis is the one of its local axes that points
    most along the body's forward (from the shoulders) at the first frame, so any rig's head axes work."""
    fwd = body_forward(P, left_shoulder, right_shoulder)
    up = torch.tensor([0.0, 1.0, 0.0], dtype=P.dtype).expand_as(fwd)
    q = Q[:, head].to(P.dtype)
    axes = torch.cat([torch.eye(3, dtype=P.dtype), -torch.eye(3, dtype=P.dtype)])
    first = quat_rotate(q[:1].expand(6, 4), axes)
    h = quat_rotate(q, axes[int((first * fwd[0]).sum(-1).argmax())].expand(len(q), 3))
    pitch = torch.rad2deg(torch.asin(h[:, 1].clamp(-1, 1)))
    flat = torch.nn.functional.normalize(h * torch.tensor([1.0, 0.0, 1.0], dtype=P.dtype), dim=-1)
    side = torch.cross(fwd, up, dim=-1)
    yaw = torch.rad2deg(torch.atan2((flat * side).sum(-1), (flat * fwd).sum(-1)))
    return float(pitch.max() - pitch.min()), float(yaw.max() - yaw.min())
