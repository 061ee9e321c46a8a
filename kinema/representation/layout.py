"""The Kimodo flat feature layout: where each channel group lives in the per-frame vector, and every
index computation on it (no other module does index arithmetic on flat features).

Per frame, for a skeleton of J joints, ``D = 5 + 12 J + 4`` channels:
``[root_pos (3), heading (2), joint_pos (3J), joint_vel (3J), joint_rot (6J), contacts (4)]``
(see kinema.representation.kimodo_features for what each means). Channel indices are plain ints / lists /
slices, valid on any ``(..., D)`` tensor.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

ROOT_DIM = 5
LOCAL_ROOT_DIM = 4
#: the local root (kimodo_features.global_to_local_root): heading rate, lateral and forward velocity, then height
LOCAL_ROOT_RATES = slice(0, 3)
LOCAL_ROOT_HEIGHT = slice(3, LOCAL_ROOT_DIM)
CONTACT_DIM = 4
#: channels per joint in each per-joint group
JOINT_WIDTHS = {"joint_pos": 3, "joint_vel": 3, "joint_rot": 6}


@dataclass(frozen=True)
class FeatureLayout:
    """Where each feature group lives in the per-frame vector, for a skeleton of ``num_joints``."""

    num_joints: int

    @property
    def dim(self) -> int:
        return ROOT_DIM + 12 * self.num_joints + CONTACT_DIM

    @property
    def body_dim(self) -> int:
        return self.dim - ROOT_DIM

    @property
    def slices(self) -> dict[str, slice]:
        J = self.num_joints
        edges = {
            "root_pos": 3,
            "heading": 2,
            "joint_pos": 3 * J,
            "joint_vel": 3 * J,
            "joint_rot": 6 * J,
            "contacts": CONTACT_DIM,
        }
        out, start = {}, 0
        for name, size in edges.items():
            out[name] = slice(start, start + size)
            start += size
        return out

    @property
    def root_xz(self) -> list[int]:
        """Channel indices of the smoothed root's ground-plane x and z (metres before normalisation)."""
        start = self.slices["root_pos"].start
        return [start, start + 2]

    def group(self, name: str) -> list[int]:
        """Every channel of one group (``root_pos``, ``heading``, ``joint_pos``, ...)."""
        return list(range(self.slices[name].start, self.slices[name].stop))

    def channels(self, *groups: str) -> list[int]:
        """The channels of several groups, in the order given."""
        return [c for name in groups for c in self.group(name)]

    def group_mask(self, *groups: str) -> torch.Tensor:
        """Boolean ``(D,)``: True on the channels of ``groups``."""
        out = torch.zeros(self.dim, dtype=torch.bool)
        out[self.channels(*groups)] = True
        return out

    def joint_channels(self, group: str, joints=None, coords=None) -> list[int]:
        """Channels of ``joints`` (default all) in a per-joint group, ``coords`` of each (default all:
        x, y, z for positions and velocities, the 6 numbers of a rotation), joint by joint."""
        width = JOINT_WIDTHS[group]
        start = self.slices[group].start
        joints = range(self.num_joints) if joints is None else joints
        coords = range(width) if coords is None else coords
        return [start + width * int(j) + c for j in joints for c in coords]

    def joint_axis(self, group: str, coord: int, device=None) -> torch.Tensor:
        """``(J,)`` long: the ``coord`` channel of every joint in a per-joint group (e.g. every joint's
        ``joint_pos`` x is ``joint_axis("joint_pos", 0)``)."""
        return torch.tensor(self.joint_channels(group, coords=[coord]), dtype=torch.long, device=device)

    @property
    def root_pos_xz_of_joint0(self) -> list[int]:
        """``joint_pos`` x and z of joint 0 (the pelvis: its offset from the smoothed root)."""
        return self.joint_channels("joint_pos", [0], [0, 2])

    def split(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        """Named views of ``x (..., D)``; per-joint groups reshaped to ``(..., J, C)``."""
        J = self.num_joints
        s = self.slices
        return {
            "root_pos": x[..., s["root_pos"]],
            "heading": x[..., s["heading"]],
            "joint_pos": x[..., s["joint_pos"]].unflatten(-1, (J, 3)),
            "joint_vel": x[..., s["joint_vel"]].unflatten(-1, (J, 3)),
            "joint_rot": x[..., s["joint_rot"]].unflatten(-1, (J, 6)),
            "contacts": x[..., s["contacts"]],
        }

    def xz_pairs(self) -> list[tuple[int, int]]:
        """(x, z) channel index pairs of every ground-plane vector: root position, heading (cos, sin),
        and per joint its position, velocity and both 6D rotation columns."""
        s = self.slices
        pairs = [(s["root_pos"].start, s["root_pos"].start + 2), (s["heading"].start, s["heading"].start + 1)]
        for group, width in (("joint_pos", 3), ("joint_vel", 3), ("joint_rot", 3)):
            start = s[group].start
            n = (s[group].stop - start) // width
            pairs += [(start + k * width, start + k * width + 2) for k in range(n)]
        return pairs

    def to_dict(self) -> dict:
        return {
            "num_joints": self.num_joints,
            "dim": self.dim,
            "slices": {k: [v.start, v.stop] for k, v in self.slices.items()},
        }
