"""Batching per-joint features of different rigs: pad frames and joints, with masks.

``pad_batch`` stacks clips ``(T_i, J_i, C)`` into ``x (B, T, J, C)`` with ``T = max T_i``, ``J = max
J_i``, and returns the masks a model and its loss need: ``frame_mask (B, T)`` (real frames),
``joint_mask (B, J)`` (real joints; padding joints are masked in attention and loss) and
``channel_mask (B, J, C)`` (real joint and a channel the rig defines, e.g. no contact flag on a joint
that never touches the ground). Padding values are zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from kinema.errors import KinemaError
from kinema.representation.joint import JointRepresentation


@dataclass(frozen=True)
class JointBatch:
    """Padded per-joint features and their masks (see the module docstring)."""

    x: torch.Tensor
    frame_mask: torch.Tensor
    joint_mask: torch.Tensor
    channel_mask: torch.Tensor

    @property
    def loss_mask(self) -> torch.Tensor:
        """``(B, T, J, C)``: the entries a loss should count (real frame, joint and channel)."""
        return self.frame_mask[:, :, None, None] & self.channel_mask[:, None]


def pad_batch(clips: list[torch.Tensor], reps: list[JointRepresentation]) -> JointBatch:
    """Pad ``clips[i] (T_i, J_i, C)`` (features of ``reps[i]``) into one `JointBatch`."""
    if not clips or len(clips) != len(reps):
        raise KinemaError(f"pad_batch needs one representation per clip, got {len(clips)} clips and {len(reps)}")
    C = clips[0].shape[-1]
    for i, (x, rep) in enumerate(zip(clips, reps, strict=True)):
        if x.ndim != 3 or x.shape[1:] != (rep.num_joints, rep.num_channels) or x.shape[-1] != C:
            raise KinemaError(f"clip {i}: features {tuple(x.shape)} do not fit {rep!r}")
    B, T, J = len(clips), max(x.shape[0] for x in clips), max(x.shape[1] for x in clips)
    out = torch.zeros(B, T, J, C, dtype=clips[0].dtype)
    frame_mask = torch.zeros(B, T, dtype=torch.bool)
    joint_mask = torch.zeros(B, J, dtype=torch.bool)
    channel_mask = torch.zeros(B, J, C, dtype=torch.bool)
    for i, (x, rep) in enumerate(zip(clips, reps, strict=True)):
        t, j = x.shape[:2]
        out[i, :t, :j] = x
        frame_mask[i, :t] = True
        joint_mask[i, :j] = True
        channel_mask[i, :j] = rep.channel_mask
    return JointBatch(out, frame_mask, joint_mask, channel_mask)
