"""Constraint masks over the Kimodo flat features: one builder per constraint type.

Used by constraint encoding at inference (kinema.representation.encode) and by training's phase-2
curriculum (kinema.train.constraints samples which builder to call), so inference never imports
training code. Every mask is ``(T, D)`` float in {0, 1} over the FeatureLayout channels
``[root_pos 3, heading 2, joint_pos 3J, joint_vel 3J, joint_rot 6J, contacts 4]``:

- ``fullbody``: root_pos (x, y, z), heading (2), joint_pos and joint_rot of every joint; not joint_vel,
  not contacts;
- ``end_effector``: joint_pos and/or joint_rot of the chosen effectors (a foot is its ankle and toe
  joints, a hand its hand joint, found via skeleton roles) plus root_pos x and z (joint_pos x/z are
  relative to the smoothed root, so a global position target needs the root x/z at those frames);
- ``root2d``: root_pos x and z (plus heading when asked); ``root_path``: the same on a dense interval;
- ``contacts``: the contact channels.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from kinema.errors import KinemaError
from kinema.representation.layout import FeatureLayout
from kinema.skeleton import Skeleton

EFFECTORS = ("left_hand", "right_hand", "left_foot", "right_foot")

Frames = Sequence[int] | torch.Tensor


def effector_joints(skeleton: Skeleton, effector: str) -> list[int]:
    """Joint indices of an effector: ``left_hand`` -> [hand]; ``left_foot`` -> [ankle, toe] (those that
    exist). Empty when the skeleton has none of them."""
    if effector not in EFFECTORS:
        raise KinemaError(f"unknown end effector {effector!r}; choose from {list(EFFECTORS)}")
    side, part = effector.split("_")
    roles = skeleton.roles
    wanted = [f"{side}_hand"] if part == "hand" else [f"{side}_ankle", f"{side}_toe"]
    return [roles[r] for r in wanted if r in roles]


def _frames(frames: Frames, T: int) -> torch.Tensor:
    f = torch.as_tensor(frames, dtype=torch.long).reshape(-1)
    if f.numel() and (f.min() < 0 or f.max() >= T):
        raise KinemaError(f"constraint frames {f.tolist()} fall outside a {T}-frame motion")
    return f


def _mask(T: int, layout: FeatureLayout, frames: Frames, channels: Sequence[int]) -> torch.Tensor:
    m = torch.zeros(T, layout.dim)
    f = _frames(frames, T)
    if f.numel() and len(channels):
        m[f[:, None], torch.as_tensor(channels, dtype=torch.long)[None, :]] = 1.0
    return m


# ---------------------------------------------------------------------------- public builders
def fullbody_mask(T: int, frames: Frames, layout: FeatureLayout) -> torch.Tensor:
    """(T, D): root_pos, heading, joint_pos and joint_rot of every joint at ``frames``."""
    return _mask(T, layout, frames, layout.channels("root_pos", "heading", "joint_pos", "joint_rot"))


def end_effector_mask(
    T: int,
    frames: Frames,
    layout: FeatureLayout,
    skeleton: Skeleton,
    positions: Sequence[str] = (),
    rotations: Sequence[str] = (),
) -> torch.Tensor:
    """(T, D): joint_pos of the ``positions`` effectors, joint_rot of the ``rotations`` effectors (names
    from :data:`EFFECTORS`) and root_pos x/z, at ``frames``."""
    pos_j = [j for e in positions for j in effector_joints(skeleton, e)]
    rot_j = [j for e in rotations for j in effector_joints(skeleton, e)]
    ch = layout.root_xz + layout.joint_channels("joint_pos", pos_j)
    return _mask(T, layout, frames, ch + layout.joint_channels("joint_rot", rot_j))


def root2d_mask(T: int, frames: Frames, layout: FeatureLayout, heading: bool = False) -> torch.Tensor:
    """(T, D): root_pos x/z (and heading when ``heading``) at ``frames`` (2D waypoints)."""
    return _mask(T, layout, frames, layout.root_xz + (layout.group("heading") if heading else []))


def root_path_mask(T: int, start: int, end: int, layout: FeatureLayout, heading: bool = False) -> torch.Tensor:
    """(T, D): root_pos x/z (and heading) on every frame of ``[start, end)`` (a dense 2D path)."""
    if not 0 <= start <= end <= T:
        raise KinemaError(f"root path [{start}, {end}) does not fit a {T}-frame motion")
    return root2d_mask(T, range(start, end), layout, heading)


def contacts_mask(T: int, frames: Frames, layout: FeatureLayout) -> torch.Tensor:
    """(T, D): the 4 foot contact channels at ``frames``."""
    return _mask(T, layout, frames, layout.group("contacts"))
