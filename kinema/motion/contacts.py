"""Foot contact labels from joint heights and speeds (Kimodo Sec. 4.1: [L heel, L toe, R heel, R toe]).

A contact joint is planted on a frame when it is both near the floor and nearly still:
``height < floor + height_threshold`` and ``speed < speed_threshold``. Where a rig has no heel joint
the ankle stands in for it (Bandai Namco: ``Foot_*`` and ``Toes_*``). The floor is taken as y = 0
(datasets are expected to stand on the ground plane; kinema's Bandai loader checks this).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from kinema.skeleton import Skeleton, side_contacts


@dataclass(frozen=True)
class ContactThresholds:
    """Heights in metres above the floor and speeds in metres per second."""

    heel_height: float = 0.15  # ankle joints sit 8-10 cm above the floor when planted
    toe_height: float = 0.08  # toe joints sit 2-5.5 cm up inside the shoe when planted (Bandai)
    speed: float = 0.30


def contact_joints(skeleton: Skeleton) -> list[int]:
    """Indices of [left heel, left toe, right heel, right toe] (ankles when the rig has no heels)."""
    out: list[int] = []
    for side in ("left", "right"):
        pair = side_contacts(skeleton.roles, side)
        if pair is None:
            skeleton.require_roles([f"{side}_ankle", f"{side}_toe"])
        out += pair
    return out


def foot_contacts(
    positions: torch.Tensor,
    fps: float,
    skeleton: Skeleton,
    thresholds: ContactThresholds = ContactThresholds(),
    floor: float = 0.0,
    joints: Sequence[int] | None = None,
) -> torch.Tensor:
    """(T, C) float {0, 1} contact flags from global positions (T, J, 3) in metres.

    ``joints`` are the C contact joints (a rig's ``contacts``; default: the human four of
    :func:`contact_joints`). A joint with children (an ankle) is planted below ``heel_height``, a leaf
    (a toe, an insect's foot) below ``toe_height``."""
    if joints is None:
        idx = contact_joints(skeleton)
        heights = [thresholds.heel_height, thresholds.toe_height] * 2
    else:
        idx = list(joints)
        heights = [thresholds.heel_height if skeleton.children[j] else thresholds.toe_height for j in idx]
    p = positions[:, idx]  # (T, C, 3)
    speed = torch.zeros(p.shape[:2], dtype=p.dtype)
    if p.shape[0] > 1:
        v = (p[1:] - p[:-1]).norm(dim=-1) * fps
        # speed of frame t: mean of the two adjacent finite differences
        speed[1:-1] = 0.5 * (v[1:] + v[:-1])
        speed[0], speed[-1] = v[0], v[-1]
    h_thr = torch.tensor(heights, dtype=p.dtype)
    planted = (p[..., 1] < floor + h_thr) & (speed < thresholds.speed)
    return planted.to(positions.dtype)
