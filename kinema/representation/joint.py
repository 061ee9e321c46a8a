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

import math
from dataclasses import dataclass, field
from functools import cached_property

import torch

from kinema.constraints.character import JointTarget, Keyframe, RootMotion, RootPath
from kinema.errors import KinemaError
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
#: the root row's heading rate (rad/s), after the heading's cosine and sine
ROOT_HEADING_RATE = ROOT_HEADING_SIN + 1
#: the root row's channels that place the body: ground velocity, height, rotation, heading
ROOT_PLACEMENT = list(range(ROOT_HEADING_SIN + 1))


@dataclass(frozen=True)
class FeatureTargets:
    """Un-normalised targets and their {0, 1} mask, both ``(T, J, C)`` (`JointRepresentation.encode`)."""

    x_tgt: torch.Tensor
    mask: torch.Tensor

    def any(self) -> bool:
        return bool(self.mask.any())


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
        heading = torch.stack([torch.cos(psi), torch.sin(psi), rate], dim=-1)
        out[:, root, ROOT_HEADING_COS : ROOT_HEADING_RATE + 1] = heading
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

    def encode(self, constraints, scale: float, frames: int) -> FeatureTargets:
        """Feature targets ``(T, J, C)`` (rig units: ``scale`` per metre) and their mask for character-frame
        ``constraints`` (kinema.constraints.character) on a motion of ``frames`` frames."""
        J = self.num_joints
        x = torch.zeros(frames, J, NUM_CHANNELS)
        m = torch.zeros(frames, J, NUM_CHANNELS)
        root = self.rig.root
        for c in constraints:
            if isinstance(c, JointTarget):
                j, f = self.joint_index(c.joint), _frame(c.frame, frames, "joint target")
                if j == root and c.position is not None:
                    raise KinemaError("a joint position target on the root joint: use RootPath for where the root goes")
                if c.position is not None:
                    x[f, j, POS] = torch.as_tensor(c.position, dtype=torch.float32) * scale
                    m[f, j, POS] = 1.0
                if c.rotation is not None:
                    x[f, j, ROT] = quat_to_sixd(c.unit_rotation()).to(x.dtype)
                    m[f, j, ROT] = 1.0
            elif isinstance(c, Keyframe):
                f = _frame(c.frame, frames, "keyframe")
                if c.pose.num_joints != J:
                    raise KinemaError(f"keyframe pose has {c.pose.num_joints} joints, the rig has {J}")
                feats = self.from_motion(self._scaled(c.pose, scale).crop(c.pose_frame, c.pose_frame + 1))[0]
                x[f], m[f, :, POSE] = feats, 1.0
                m[f, root] = 0.0
                m[f, root, ROOT_HEIGHT] = 1.0  # the root row: height only (its rotation is the root joint's)
                m[f, root, ROT] = 1.0
            elif isinstance(c, RootPath):
                _root_path(c, x, m, root, scale, frames, self.fps)
            elif isinstance(c, RootMotion):
                n = min(c.until, frames, c.motion.num_frames)
                lt = None if c.motion.local_translations is None else c.motion.local_translations * scale
                moved = Motion(
                    self.rig.skeleton, self.fps, c.motion.root_translation * scale, c.motion.local_rotations, None, lt
                )
                rows = ROOT_PLACEMENT
                x[:n, root, rows] = self.from_motion(moved.crop(0, n)).to(x.dtype)[:, root, rows]
                m[:n, root, rows] = 1.0
            else:
                raise KinemaError(
                    f"unknown constraint {type(c).__name__}; expected JointTarget, Keyframe, RootPath or RootMotion"
                )
        return FeatureTargets(x, m)

    def joint_index(self, joint: str | int) -> int:
        """A constraint's joint (a name of the rig, or an index) as an index; one-line errors otherwise."""
        skel = self.rig.skeleton
        if isinstance(joint, str):
            if joint not in skel.names:
                raise KinemaError(f"constraint joint {joint!r} is not in rig {skel.name or ''} "
                                  f"({skel.num_joints} joints)")
            return skel.index(joint)
        if not 0 <= int(joint) < skel.num_joints:
            raise KinemaError(f"constraint joint {joint} outside 0..{skel.num_joints - 1}")
        return int(joint)

    def _scaled(self, m: Motion, scale: float) -> Motion:
        """``m`` (metres) on this representation's skeleton in its units, bone translations included (the
        Quaternius rigs move the body and IK feet by translation)."""
        lt = None if m.local_translations is None else m.local_translations * scale
        return Motion(self.rig.skeleton, self.fps, m.root_translation * scale, m.local_rotations, None, lt)

    def __repr__(self) -> str:
        return f"JointRepresentation({self.rig.skeleton!r}, {self.num_joints} x {NUM_CHANNELS}, {self.fps:g} fps)"


def _frame(f: int, T: int, what: str) -> int:
    if isinstance(f, bool) or not isinstance(f, int) or not 0 <= f < T:
        raise KinemaError(f"{what}: frame {f!r} outside 0..{T - 1}")
    return f


def _root_path(c: RootPath, x, m, root: int, scale: float, T: int, fps: float) -> None:
    frames = [0, *(_frame(f, T, "root waypoint") for f in c.frames)]
    pts = [(0.0, 0.0), *((float(a), float(b)) for a, b in c.xz)]
    if len(frames) != len(pts) or any(b <= a for a, b in zip(frames, frames[1:], strict=False)):
        raise KinemaError("root path: one (x, z) per frame, frames increasing after 0")
    for (fa, pa), (fb, pb) in zip(zip(frames, pts, strict=True), zip(frames[1:], pts[1:], strict=True), strict=False):
        dx, dz = pb[0] - pa[0], pb[1] - pa[1]
        speed = math.hypot(dx, dz) * fps / (fb - fa) * scale
        psi = math.atan2(dx, dz)
        span = slice(fa, fb)
        x[span, root, ROOT_LATERAL], x[span, root, ROOT_FORWARD] = 0.0, speed
        x[span, root, ROOT_HEADING_COS], x[span, root, ROOT_HEADING_SIN] = math.cos(psi), math.sin(psi)
        for channel in (ROOT_LATERAL, ROOT_FORWARD, ROOT_HEADING_COS, ROOT_HEADING_SIN):
            m[span, root, channel] = 1.0
