"""`FlatRepresentation`: the Kimodo flat feature layout as one object (paper Sec. 4.1-4.2).

It answers every question about a flat feature tensor ``(..., T, D)``, ``D = 5 + 12 J + 4``, so that no
sampler, planner or post-processing step does index arithmetic of its own:

- ``layout`` (kinema.representation.layout) and the named channel accessors samplers need (root x/z,
  heading, joint positions per axis, the pelvis offset, the motion channels a segment join copies);
- ``normalize`` / ``denormalize`` with the statistics saved next to the weights;
- ``from_motion`` / ``to_motion`` (kinema.representation.kimodo_features);
- ``encode(constraints)`` -> targets and masks (kinema.representation.encode, masks from
  kinema.representation.masks, shared with training's curriculum);
- ``pose(features)``: world joint positions exactly as ``to_motion`` would pose them (for keyjoints).

Units: metres, seconds, radians; Y up, +Z forward. The human rig's root is the pelvis, joint 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import torch

from kinema.kinematics import positions_from_sixd
from kinema.motion.core import Motion
from kinema.representation.encode import ConstraintTargets, encode_constraints
from kinema.representation.kimodo_features import features_to_motion, motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.rig import Rig
from kinema.skeleton import Skeleton

#: the feature groups that describe the motion itself (everything but the contact labels)
MOTION_GROUPS = ("root_pos", "heading", "joint_pos", "joint_vel", "joint_rot")


@dataclass(frozen=True, eq=False)
class FlatRepresentation:
    """The Kimodo flat layout for one rig at one frame rate, with its normalisation statistics."""

    rig: Rig
    fps: float
    stats: NormStats | None = field(default=None)

    @classmethod
    def for_skeleton(cls, skeleton: Skeleton, fps: float, stats: NormStats | None = None) -> FlatRepresentation:
        return cls(Rig.from_skeleton(skeleton), float(fps), stats)

    # ------------------------------------------------------------------ layout
    @property
    def skeleton(self) -> Skeleton:
        return self.rig.skeleton

    @cached_property
    def layout(self) -> FeatureLayout:
        return FeatureLayout(self.skeleton.num_joints)

    @property
    def dim(self) -> int:
        return self.layout.dim

    @property
    def num_joints(self) -> int:
        return self.layout.num_joints

    @property
    def root_xz(self) -> list[int]:
        """Smoothed root x and z channels."""
        return self.layout.root_xz

    @property
    def heading(self) -> slice:
        """Heading (cos, sin) channels."""
        return self.layout.slices["heading"]

    @property
    def joint_pos(self) -> slice:
        """Every joint's position channels (``J x 3``, x/z relative to the smoothed root)."""
        return self.layout.slices["joint_pos"]

    @property
    def pelvis_xz(self) -> list[int]:
        """``joint_pos`` x/z of the root joint: its offset from the smoothed root."""
        return self.layout.joint_channels("joint_pos", [self.rig.root], [0, 2])

    def joint_pos_axis(self, coord: int) -> torch.Tensor:
        """``(J,)`` channel of coordinate ``coord`` (0 x, 1 y, 2 z) of every joint's position."""
        return self.layout.joint_axis("joint_pos", coord)

    @cached_property
    def motion_channels(self) -> torch.Tensor:
        """Boolean ``(D,)``: root, heading, joint positions, velocities and rotations (not contacts)."""
        return self.layout.group_mask(*MOTION_GROUPS)

    def split(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        return self.layout.split(x)

    def shift_root_xz(self, x: torch.Tensor, shift: torch.Tensor) -> torch.Tensor:
        """``x (..., D)`` with ``shift (..., 2)`` metres added to the smoothed root x/z (in place; returned)."""
        rx, rz = self.root_xz
        x[..., rx] += shift[..., 0]
        x[..., rz] += shift[..., 1]
        return x

    # ------------------------------------------------------------------ normalisation
    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        return x if self.stats is None else self.stats.normalize(x)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        return x if self.stats is None else self.stats.denormalize(x)

    @property
    def std(self) -> torch.Tensor:
        return torch.ones(self.dim) if self.stats is None else self.stats.std

    @property
    def mean(self) -> torch.Tensor:
        return torch.zeros(self.dim) if self.stats is None else self.stats.mean

    # ------------------------------------------------------------------ motion <-> features
    def from_motion(self, motion: Motion) -> torch.Tensor:
        """Unnormalised features ``(T, D)`` of a motion on this rig."""
        return motion_to_features(motion)

    def to_motion(self, features: torch.Tensor) -> Motion:
        """The motion of unnormalised features ``(T, D)``."""
        return features_to_motion(features, self.skeleton, self.fps)

    def pose(self, features: torch.Tensor) -> torch.Tensor:
        """World joint positions ``(..., T, J, 3)`` of unnormalised ``features (..., T, D)``, posed as
        :meth:`to_motion` does: root joint = its ``joint_pos`` plus the smoothed root x/z, the rest by FK
        from the global rotations (vectorised, no loop over joints)."""
        parts = self.split(features)
        rx, rz = self.root_xz
        p = parts["joint_pos"][..., self.rig.root, :]
        root = torch.stack([p[..., 0] + features[..., rx], p[..., 1], p[..., 2] + features[..., rz]], dim=-1)
        return positions_from_sixd(parts["joint_rot"], root, self.skeleton)

    # ------------------------------------------------------------------ constraints
    def encode(self, constraints, num_frames: int, dtype: torch.dtype = torch.float32) -> ConstraintTargets:
        """Targets and masks ``(T, D)`` (plus world joint x/z) of validated-on-the-way constraints."""
        return encode_constraints(constraints, self.skeleton, self.layout, self.fps, num_frames, dtype=dtype)

    def __repr__(self) -> str:
        return f"FlatRepresentation({self.skeleton!r}, D={self.dim}, {self.fps:g} fps)"
