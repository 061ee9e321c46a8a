"""`JointRepresentation`: per-joint features ``(T, J, C)`` for any rig (AnyTop / "How to Move Your
Dragon", adapted), with joint and channel masks so rigs of different sizes share one batch.

Every joint row has ``C = 13`` channels, in the *heading frame* (the world turned about +Y so that the
rig's forward axis points along +Z; so a motion and its turned copy share their body features):

- ``pos`` (0:3) metres: joint position relative to the rig's root joint;
- ``rot`` (3:9): global rotation, 6D (first two matrix columns), relative to the heading;
- ``vel`` (9:12) m/s: joint velocity (forward differences, the last frame repeats the previous);
- ``contact`` (12): planted flag in {0, 1}, only for the rig's contact joints (masked elsewhere).

The root row's ``pos`` slots carry instead ``[lateral ground velocity (m/s), height (m), forward ground
velocity (m/s)]`` and its ``vel`` slots ``[cos psi, sin psi, heading rate (rad/s)]``; its contact slot
is masked. The heading psi is measured from +Z towards +X: the rig's ``forward`` axis carried by the
root's rotation relative to its rest rotation, projected on the ground. ``to_motion`` integrates the
ground velocity from a start point (default: the origin) and poses the joints from the rotations, so
a round trip reproduces joint positions up to float precision. Shapes: ``(..., T, J, 13)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import torch

from kinema.geometry.rotations import quat_inverse, quat_mul, quat_rotate, quat_to_sixd, sixd_to_quat
from kinema.kinematics import forward_kinematics
from kinema.motion.contacts import foot_contacts
from kinema.motion.core import Motion
from kinema.rig import Rig

CHANNELS = {"pos": slice(0, 3), "rot": slice(3, 9), "vel": slice(9, 12), "contact": slice(12, 13)}
NUM_CHANNELS = 13
#: every joint row: position relative to the root (m), global rotation in 6D, the planted flag
POS, ROT, CONTACT = CHANNELS["pos"], CHANNELS["rot"], 12
#: position and rotation together (what a full-body keyframe pins)
POSE = slice(POS.start, ROT.stop)
#: the root row: lateral and forward ground velocity, height, and the heading's cosine and sine
ROOT_LATERAL, ROOT_HEIGHT, ROOT_FORWARD = 0, 1, 2
ROOT_HEADING_COS, ROOT_HEADING_SIN = 9, 10
ROOT_HEADING = slice(ROOT_HEADING_COS, ROOT_HEADING_SIN + 1)


def yaw_quat(psi: torch.Tensor) -> torch.Tensor:
    """Rotations ``(..., 4)`` about +Y by ``psi`` (+Z turns towards +X)."""
    half = 0.5 * psi
    zero = torch.zeros_like(psi)
    return torch.stack([torch.cos(half), zero, torch.sin(half), zero], dim=-1)


def _forward_diff(x: torch.Tensor, fps: float) -> torch.Tensor:
    """Forward differences along frames (dim 0) times ``fps``; the last frame repeats the previous."""
    v = torch.zeros_like(x)
    if x.shape[0] > 1:
        v[:-1] = (x[1:] - x[:-1]) * fps
        v[-1] = v[-2]
    return v


@dataclass(frozen=True, eq=False)
class JointStats:
    """Mean and standard deviation per joint and channel ``(J, C)``; masked channels get 0 and 1."""

    mean: torch.Tensor
    std: torch.Tensor

    @classmethod
    def compute(cls, chunks: list[torch.Tensor], channel_mask: torch.Tensor, min_std: float = 1e-2) -> JointStats:
        """Exact statistics over all frames of ``chunks`` (each ``(T_i, J, C)``), in float64."""
        x = torch.cat([c.double() for c in chunks])
        mean, std = x.mean(0), x.std(0, unbiased=False).clamp_min(min_std)
        keep = channel_mask.bool()
        return cls(torch.where(keep, mean, 0.0).float(), torch.where(keep, std, 1.0).float())

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean.to(x)) / self.std.to(x)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.std.to(x) + self.mean.to(x)


@dataclass(frozen=True, eq=False)
class JointRepresentation:
    """Per-joint features of one rig at one frame rate (see the module docstring)."""

    rig: Rig
    fps: float
    stats: JointStats | None = field(default=None)

    @property
    def num_joints(self) -> int:
        return self.rig.num_joints

    @property
    def num_channels(self) -> int:
        return NUM_CHANNELS

    @cached_property
    def channel_mask(self) -> torch.Tensor:
        """Boolean ``(J, C)``: False on the contact slot of every non-contact joint and of the root."""
        mask = torch.ones(self.num_joints, NUM_CHANNELS, dtype=torch.bool)
        mask[:, CONTACT] = False
        mask[list(self.rig.contacts), CONTACT] = True
        mask[self.rig.root, CONTACT] = False
        return mask

    @cached_property
    def _rest_root(self) -> torch.Tensor:
        """Global rest rotation ``(4,)`` of the root joint (its rig faces ``forward`` in this pose)."""
        skel = self.rig.skeleton
        rest = skel.rest_rotations
        if rest is None:
            return torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=torch.float64)
        G, _ = forward_kinematics(rest[None], torch.zeros(1, 3, dtype=torch.float64), skel.offsets, skel.parents)
        return G[0, self.rig.root]

    def heading(self, global_rotations: torch.Tensor) -> torch.Tensor:
        """Heading angle ``(T,)`` radians of global rotations ``(T, J, 4)``."""
        rel = quat_mul(global_rotations[:, self.rig.root], quat_inverse(self._rest_root.to(global_rotations)))
        f = quat_rotate(rel, torch.tensor(self.rig.forward, dtype=rel.dtype).expand(rel.shape[0], 3))
        return torch.atan2(f[:, 0], f[:, 2])

    # ------------------------------------------------------------------ motion -> features
    def from_motion(self, motion: Motion) -> torch.Tensor:
        """Features ``(T, J, 13)`` (float64 for a float64 motion, else float32)."""
        m = motion.to(torch.float64)
        G, P = m.global_transforms()
        root = self.rig.root
        psi = self.heading(G)
        inv = quat_inverse(yaw_quat(psi))[:, None]  # (T, 1, 4)
        T, J = P.shape[:2]
        out = torch.zeros(T, J, NUM_CHANNELS, dtype=torch.float64)
        out[..., 0:3] = quat_rotate(inv.expand(T, J, 4), P - P[:, root : root + 1])
        out[..., 3:9] = quat_to_sixd(quat_mul(inv.expand(T, J, 4), G))
        out[..., 9:12] = quat_rotate(inv.expand(T, J, 4), _forward_diff(P, m.fps))
        out[:, list(self.rig.contacts), CONTACT] = self._contacts(m, P)
        ground = out[:, root, 9:12].clone()
        out[:, root, 0:3] = torch.stack([ground[:, 0], P[:, root, 1], ground[:, 2]], dim=-1)
        rate = torch.zeros_like(psi)
        if T > 1:  # wrapped heading change per frame, the last frame repeating the previous
            rate[:-1] = (torch.remainder(psi[1:] - psi[:-1] + torch.pi, 2 * torch.pi) - torch.pi) * m.fps
            rate[-1] = rate[-2]
        out[:, root, 9:12] = torch.stack([torch.cos(psi), torch.sin(psi), rate], dim=-1)
        out[:, root, CONTACT] = 0.0
        return out.to(motion.dtype if motion.dtype == torch.float64 else torch.float32)

    def _contacts(self, m: Motion, P: torch.Tensor) -> torch.Tensor:
        """``(T, C)`` planted flags of the rig's contact joints: the motion's own (thresholded) or estimated."""
        if not self.rig.contacts:
            return P.new_zeros(P.shape[0], 0)
        if m.foot_contacts is not None and m.foot_contacts.shape[1] == len(self.rig.contacts):
            return (m.foot_contacts > 0.5).to(P.dtype)
        return foot_contacts(P, m.fps, m.skeleton, joints=self.rig.contacts).to(P.dtype)

    # ------------------------------------------------------------------ features -> motion
    def to_motion(self, features: torch.Tensor, start_xz=(0.0, 0.0)) -> Motion:
        """The motion of features ``(T, J, 13)``: root ground path integrated from ``start_xz`` (metres),
        root height from its row, every joint's rotation from its 6D channels (then FK)."""
        f = features.to(torch.float64)
        root, skel = self.rig.root, self.rig.skeleton
        T = f.shape[0]
        psi = torch.atan2(f[:, root, 10], f[:, root, 9])
        qh = yaw_quat(psi)
        G = quat_mul(qh[:, None].expand(T, skel.num_joints, 4), sixd_to_quat(f[..., 3:9]))
        local_v = torch.stack([f[:, root, 0], torch.zeros_like(psi), f[:, root, 2]], dim=-1)
        v = quat_rotate(qh, local_v) / self.fps
        start = torch.as_tensor(start_xz, dtype=torch.float64)
        x = start[0] + torch.cumsum(v[:, 0], 0) - v[:, 0]
        z = start[1] + torch.cumsum(v[:, 2], 0) - v[:, 2]
        root_pos = torch.stack([x, f[:, root, 1], z], dim=-1)
        probe = Motion.from_global(skel, self.fps, torch.zeros(T, 3, dtype=torch.float64), G)
        translation = root_pos - probe.positions[:, root]  # joint 0 sits where the rig's root lands
        contacts = f[:, list(self.rig.contacts), CONTACT].clamp(0, 1)
        return Motion(skel, self.fps, translation, probe.local_rotations, contacts)

    # ------------------------------------------------------------------ normalisation
    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        return x if self.stats is None else self.stats.normalize(x)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        return x if self.stats is None else self.stats.denormalize(x)

    def __repr__(self) -> str:
        return f"JointRepresentation({self.rig.skeleton!r}, {self.num_joints} x {NUM_CHANNELS}, {self.fps:g} fps)"
