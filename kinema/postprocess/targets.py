"""Post-processing targets: what the exact pass must hit (kinema.postprocess) and where feet are planted.

Frames are LongTensors ``(K,)``; positions metres, world frame; rotations global wxyz quaternions;
``root_xz`` targets the *smoothed* root (the Gaussian-smoothed pelvis x/z, kinema.motion.smoothing).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from kinema.errors import KinemaError
from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time

Pair = tuple[torch.Tensor, torch.Tensor]


@dataclass
class PostTargets:
    """Kinematic targets for post-processing (all optional).

    - ``joint_positions``: joint index -> (frames (K,), positions (K, 3) metres, world)
    - ``joint_rotations``: joint index -> (frames (K,), global quaternions (K, 4) wxyz)
    - ``root_xz``: (frames (K,), smoothed-root x/z (K, 2))
    - ``contacts``: (frames (K,), planted flags (K, C), one per contact joint of the rig; human
      [L heel, L toe, R heel, R toe])
    - ``root_sigma``: seconds of the Gaussian that defines the smoothed root
    """

    joint_positions: dict[int, Pair] = field(default_factory=dict)
    joint_rotations: dict[int, Pair] = field(default_factory=dict)
    root_xz: Pair | None = None
    contacts: Pair | None = None
    root_sigma: float = DEFAULT_ROOT_SIGMA_SECONDS

    def is_empty(self) -> bool:
        return not (
            self.joint_positions or self.joint_rotations or self.root_xz is not None or self.contacts is not None
        )

    def validate(self, motion: Motion) -> PostTargets:
        """A copy with frames as LongTensors and values as float64, checked against ``motion``."""
        T, J = motion.num_frames, motion.num_joints

        def check(pair: Pair, width: int, what: str) -> Pair:
            frames = torch.as_tensor(pair[0]).long().reshape(-1)
            values = torch.as_tensor(pair[1]).to(torch.float64).reshape(-1, width)
            if frames.numel() != values.shape[0]:
                raise KinemaError(f"{what}: {frames.numel()} frames but {values.shape[0]} values")
            if frames.numel() and (frames.min() < 0 or frames.max() >= T):
                raise KinemaError(f"{what}: frames must lie in [0, {T}), got {frames.min()}..{frames.max()}")
            return frames, values

        def joints(d: dict[int, Pair], width: int, what: str) -> dict[int, Pair]:
            out = {}
            for j, pair in d.items():
                if not 0 <= int(j) < J:
                    raise KinemaError(f"{what}: joint {j} outside [0, {J})")
                out[int(j)] = check(pair, width, f"{what}[{motion.skeleton.names[int(j)]}]")
            return out

        return PostTargets(
            joints(self.joint_positions, 3, "joint_positions"),
            joints(self.joint_rotations, 4, "joint_rotations"),
            None if self.root_xz is None else check(self.root_xz, 2, "root_xz"),
            None
            if self.contacts is None
            else check(self.contacts, torch.as_tensor(self.contacts[1]).shape[-1], "contacts"),
            self.root_sigma,
        )

    def full_body_frames(self, num_joints: int) -> torch.Tensor:
        """Frames (sorted LongTensor) where every joint has a rotation target or every joint has a
        position target: full-body keyframes, set as a whole pose by the exact pass."""
        frames: set[int] = set()
        for table in (self.joint_rotations, self.joint_positions):
            if all(j in table for j in range(num_joints)):
                sets = [set(torch.as_tensor(table[j][0]).tolist()) for j in range(num_joints)]
                frames |= set.intersection(*sets)
        return torch.tensor(sorted(frames), dtype=torch.long)

    @classmethod
    def from_motion(
        cls,
        motion: Motion,
        full_body: list[int] | None = None,
        positions: dict[int, list[int]] | None = None,
        rotations: dict[int, list[int]] | None = None,
        root_xz: list[int] | None = None,
        root_sigma: float = DEFAULT_ROOT_SIGMA_SECONDS,
    ) -> PostTargets:
        """Targets read off a reference motion at the given frames (handy for tests and retiming)."""
        G, P = motion.global_transforms()
        pos = {j: list(f) for j, f in (positions or {}).items()}
        rot = {j: list(f) for j, f in (rotations or {}).items()}
        for k in full_body or []:
            for j in range(motion.num_joints):
                pos.setdefault(j, []).append(k)
                rot.setdefault(j, []).append(k)
        out = cls(root_sigma=root_sigma)
        for j, f in pos.items():
            f = torch.tensor(f, dtype=torch.long)
            out.joint_positions[j] = (f, P[f, j].to(torch.float64))
        for j, f in rot.items():
            f = torch.tensor(f, dtype=torch.long)
            out.joint_rotations[j] = (f, G[f, j].to(torch.float64))
        if root_xz:
            pelvis = motion.skeleton.require_roles(["pelvis"])["pelvis"]
            smooth = smooth_time(P[:, pelvis][:, [0, 2]].to(torch.float64), root_sigma * motion.fps)
            f = torch.tensor(root_xz, dtype=torch.long)
            out.root_xz = (f, smooth[f])
        return out
