"""Keyjoint trajectories (SFControl Sec. 3.1): six global joint positions plus the root heading.

A keyjoint frame is ``(20,)``: world positions (metres, Y up) of the pelvis, head, left hand, right
hand, left ankle and right ankle (6 x 3, in that order), then the root heading ``(cos, sin)`` (0 faces
+Z). It is read straight from the flat features (``joint_pos`` holds positions with x/z relative to the
smoothed root, so the world position is ``joint_pos + root_xz``); kinema.human.keyjoint_planning turns a
planned trajectory back into body-model targets. Shapes: keyjoints ``(..., T, 20)``,
features ``(..., T, D)``.

Sparse training masks follow the paper's selection schemes (Sec. 4.4): *cross* (random keyjoints at
frames every ``r`` frames or with probability ``p``), *pelvis-only*, *hand-only* and *interval* (all
keyjoints over a contiguous span), plus an empty mask so the model also learns the unconstrained case.
"""

from __future__ import annotations

import math

import torch

from kinema.representation.flat import FlatRepresentation
from kinema.skeleton import Skeleton

KEYJOINT_ROLES = ("pelvis", "head", "left_hand", "right_hand", "left_ankle", "right_ankle")
NUM_KEYJOINTS = len(KEYJOINT_ROLES)
KEYJOINT_DIM = 3 * NUM_KEYJOINTS + 2
#: the keyjoint frame's channels: the six positions (flattened), then the heading
POSITIONS = slice(0, 3 * NUM_KEYJOINTS)
HEADING = slice(3 * NUM_KEYJOINTS, KEYJOINT_DIM)
#: the paper's frame intervals and probabilities for the cross scheme
CROSS_INTERVALS = (1, 2, 5, 10, 20, 30, 60)
CROSS_PROBABILITIES = (0.02, 0.05, 0.1, 0.2, 0.5, 1.0)


def keyjoint_indices(skeleton: Skeleton) -> list[int]:
    """Joint indices of :data:`KEYJOINT_ROLES` on ``skeleton`` (raises naming a missing role)."""
    roles = skeleton.require_roles(KEYJOINT_ROLES)
    return [roles[r] for r in KEYJOINT_ROLES]


def keyjoints_from_features(features: torch.Tensor, rep: FlatRepresentation, idx: list[int]) -> torch.Tensor:
    """Keyjoint frames ``(..., T, 20)`` of unnormalised flat ``features (..., T, D)``."""
    jp = rep.split(features)["joint_pos"][..., idx, :].clone()
    rx, rz = rep.root_xz
    jp[..., 0] += features[..., rx, None]
    jp[..., 2] += features[..., rz, None]
    return torch.cat([jp.flatten(-2), features[..., rep.heading]], dim=-1)


def keyjoint_positions(k: torch.Tensor) -> torch.Tensor:
    """The positions ``(..., T, 6, 3)`` of keyjoint frames or of their targets/masks ``(..., T, 20)`` (a view)."""
    return k[..., POSITIONS].unflatten(-1, (NUM_KEYJOINTS, 3))


def rotate_keyjoints(k: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Keyjoints turned by ``angle (...)`` radians about +Y through the origin (heading gains ``angle``)."""
    c, s = torch.cos(angle)[..., None, None], torch.sin(angle)[..., None, None]
    p = keyjoint_positions(k)
    x, y, z = p.unbind(-1)
    p = torch.stack([c * x + s * z, y, -s * x + c * z], dim=-1)
    hc, hs = k[..., HEADING].unbind(-1)
    c, s = c[..., 0], s[..., 0]
    return torch.cat([p.flatten(-2), torch.stack([hc * c - hs * s, hs * c + hc * s], dim=-1)], dim=-1)


def canonicalize_keyjoints(k: torch.Tensor, root_xz0: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Shift so the smoothed root of frame 0 (``root_xz0 (..., 2)``) is at the origin, then turn so that
    frame 0 faces ``angle`` radians (the body model's training convention)."""
    out = k.clone()
    p = keyjoint_positions(out)
    p[..., 0] -= root_xz0[..., 0, None, None]
    p[..., 2] -= root_xz0[..., 1, None, None]
    hc, hs = k[..., 0, HEADING].unbind(-1)
    return rotate_keyjoints(torch.cat([p.flatten(-2), out[..., HEADING]], dim=-1), angle - torch.atan2(hs, hc))


# ---------------------------------------------------------------------------- training masks
def _frames(T: int, g: torch.Generator) -> torch.Tensor:
    """(T,) bool: frames every r (random phase) or with probability p (cross scheme's frame choice)."""
    if torch.rand((), generator=g) < 0.5:
        r = CROSS_INTERVALS[int(torch.randint(len(CROSS_INTERVALS), (), generator=g))]
        return (torch.arange(T) - int(torch.randint(r, (), generator=g))) % r == 0
    p = CROSS_PROBABILITIES[int(torch.randint(len(CROSS_PROBABILITIES), (), generator=g))]
    return torch.rand(T, generator=g) < p


def sparse_mask(T: int, g: torch.Generator) -> torch.Tensor:
    """One random training mask ``(T, 20)`` in {0, 1}: cross 50 %, pelvis-only 15 %, hand-only 15 %,
    interval 10 %, nothing 10 %. Heading channels are never given (controls are positions; the first
    frame's heading comes as ``c_dir``)."""
    u = float(torch.rand((), generator=g))
    joints = torch.zeros(NUM_KEYJOINTS, dtype=torch.bool)
    frames = torch.zeros(T, dtype=torch.bool)
    if u < 0.5:  # cross
        joints = torch.rand(NUM_KEYJOINTS, generator=g) < 0.5
        joints[int(torch.randint(NUM_KEYJOINTS, (), generator=g))] = True
        frames = _frames(T, g)
    elif u < 0.65:  # pelvis-only
        joints[0] = True
        frames = _frames(T, g)
    elif u < 0.8:  # hand-only
        side = int(torch.randint(3, (), generator=g))
        joints[2], joints[3] = side != 1, side != 0
        frames = _frames(T, g)
    elif u < 0.9:  # interval
        joints[:] = True
        a = int(torch.randint(T, (), generator=g))
        b = a + 1 + int(torch.randint(max(1, T // 2), (), generator=g))
        frames[a : min(b, T)] = True
    m = (frames[:, None] & joints[None, :]).float()  # (T, 6)
    m = m[..., None].expand(T, NUM_KEYJOINTS, 3).reshape(T, 3 * NUM_KEYJOINTS)
    return torch.cat([m, torch.zeros(T, 2)], dim=-1)


def subsample_every(T: int, fps: float, seconds: float) -> list[int]:
    """Frames one every ``seconds`` (the sparse protocol's 1.5 s), starting at frame 0."""
    step = max(1, int(math.floor(seconds * fps + 0.5)))
    return list(range(0, T, step))
