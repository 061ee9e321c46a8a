"""What a stream hands out and how its windows are stitched: `StreamFrames`, the cross-fade of a new
window into the old one's provisional frames, and the facing/ground helpers the windows are placed with.

Units: metres, radians, Y up; a heading ``psi`` is measured from +Z towards +X (0 faces +Z), the
convention of the requests and of docs/constraints.md (``global_root_heading = (cos psi, sin psi)``).
Rotations are unit quaternions (w, x, y, z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch

from kinema.geometry.rotations import quat_make_continuous, quat_mul, quat_normalize, quat_slerp
from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time


@dataclass(frozen=True)
class StreamFrames:
    """Frames ``[start, start + n)`` of a stream: root translation ``(n, 3)``, local rotations
    ``(n, J, 4)`` and global joint positions ``(n, J, 3)`` on ``joint_names``, at ``fps``; on rigs that
    animate bone translations (the Quaternius rigs move the body and the IK feet so) also
    ``local_translations (n, J, 3)``, else None."""

    start: int
    fps: float
    joint_names: tuple[str, ...]
    root_translation: torch.Tensor
    local_rotations: torch.Tensor
    positions: torch.Tensor
    local_translations: torch.Tensor | None = None

    @classmethod
    def of(cls, motion: Motion, start: int) -> StreamFrames:
        lt = None if motion.local_translations is None else motion.local_translations.clone()
        return cls(start, motion.fps, tuple(motion.skeleton.names), motion.root_translation.clone(),
                   motion.local_rotations.clone(), motion.positions, lt)

    @property
    def num_frames(self) -> int:
        return int(self.root_translation.shape[0])

    @property
    def seconds(self) -> float:
        """Stream time of the first frame."""
        return self.start / self.fps

    def to_json(self, decimals: int = 4) -> dict:
        """The frames as plain JSON lists (rounded), for the WebSocket and logs."""
        def rounded(t: torch.Tensor) -> list:
            return torch.round(t.float(), decimals=decimals).tolist()

        out = {"start": self.start, "fps": self.fps, "root_translation": rounded(self.root_translation),
               "local_rotations": rounded(self.local_rotations), "positions": rounded(self.positions)}
        if self.local_translations is not None:
            out["local_translations"] = rounded(self.local_translations)
        return out


def stitch(old: Motion, new: Motion, skip: int, blend: int) -> Motion:
    """The motion from stream frame ``s`` on, where ``old`` (the previous window's frames) and ``new``
    (the new window's) both start at frame ``s - 1``: ``skip`` frames of ``old``, then ``blend``
    frames cross-faded from ``old`` to ``new`` (weight of ``new`` rising as a raised cosine), then the
    rest of ``new``. Rotations are slerped, root heights and bone translations lerped; the root's
    ground position follows the blended *velocity* from ``old``'s, and the rest of ``new`` is moved to
    continue from there, so a window that lags or leads the previous one does not make the root jump."""
    n = skip + blend
    if old.num_frames < n + 1 or new.num_frames < n + 1:
        raise ValueError(f"stitch: needs {n + 1} frames of each motion, got {old.num_frames} and {new.num_frames}")
    w = torch.zeros(n, dtype=old.dtype)
    w[skip:] = 0.5 - 0.5 * torch.cos(math.pi * (torch.arange(blend, dtype=old.dtype) + 1) / (blend + 1))
    qa = quat_make_continuous(old.local_rotations[1 : n + 1], dim=0)
    qb = new.local_rotations[1 : n + 1].to(old.dtype)
    qb = qb * torch.where((qa * qb).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(qb.dtype)
    rots = quat_normalize(quat_slerp(qa, qb, w[:, None]))
    ra, rb = old.root_translation[: n + 1], new.root_translation[: n + 1].to(old.dtype)
    velocity = (1 - w[:, None]) * (ra[1:] - ra[:-1]) + w[:, None] * (rb[1:] - rb[:-1])
    root = ra[0] + torch.cumsum(velocity, 0)
    root[:, 1] = (1 - w) * ra[1:, 1] + w * rb[1:, 1]
    contacts = None
    if old.foot_contacts is not None and new.foot_contacts is not None:
        later = new.foot_contacts[1 : n + 1].to(old.dtype)
        contacts = torch.where(w[:, None] < 0.5, old.foot_contacts[1 : n + 1], later)
    trans = None
    if old.local_translations is not None or new.local_translations is not None:
        ta = old.translations_or_offsets()[1 : n + 1]
        tb = new.translations_or_offsets()[1 : n + 1].to(old.dtype)
        trans = (1 - w[:, None, None]) * ta + w[:, None, None] * tb
    out = Motion(new.skeleton, new.fps, root, rots, contacts, trans)
    if new.num_frames == n + 1:
        return out
    rest = new.crop(n + 1).to(old.dtype)
    move = root[-1] - rb[-1]
    return out.concatenate(shifted(rest, float(move[0]), float(move[2])))


def ease_root_velocity(before: torch.Tensor, motion: Motion, frames: int, sigma_frames: float) -> Motion:
    """``motion``, which continues the ground path ``before`` (root x/z ``(H, 2)``, its last point the
    frame just before ``motion``'s first), with its root's ground velocity low-passed over its first
    ``frames`` frames: a Gaussian of ``sigma_frames`` over the velocity of ``before`` and ``motion``
    together, faded (raised cosine) from fully smoothed at the first frame to ``motion``'s own velocity
    at frame ``frames``; positions are integrated from ``before[-1]``, so the rest of ``motion`` keeps
    its path, moved by what the eased frames gained or lost. The denoiser's first free frames after
    context keyframes jolt the pelvis (speed 2.9, 1.4, 0.2, 4.0 m/s on consecutive frames of a jog),
    which a cross-fade of poses does not hide; a step's own speed swing (a period of 10+ frames) passes
    a 1.5-frame Gaussian almost unchanged."""
    T = motion.num_frames
    frames = min(frames, T)
    if frames < 1 or sigma_frames <= 0:
        return motion
    before = before.to(motion.dtype)
    xz = torch.cat([before, motion.root_translation[:, [0, 2]]])
    velocity = xz[1:] - xz[:-1]
    own = velocity[before.shape[0] - 1 :]
    smooth = smooth_time(velocity, sigma_frames)[before.shape[0] - 1 :]
    w = torch.zeros(T, 1, dtype=motion.dtype)
    w[:frames, 0] = 0.5 + 0.5 * torch.cos(math.pi * torch.arange(frames, dtype=motion.dtype) / frames)
    root = motion.root_translation.clone()
    root[:, [0, 2]] = before[-1] + torch.cumsum(w * smooth + (1 - w) * own, 0)
    return replace(motion, root_translation=root)


def face_along(motion: Motion, headings: torch.Tensor, start: int, left_hip: int, right_hip: int,
               sigma_frames: float) -> Motion:
    """``motion`` turned about its pelvis, frame by frame from ``start`` on, so that its facing (the
    hips' heading smoothed over ``sigma_frames``, keeping the gait's sway) follows ``headings``
    (radians, one per frame from ``start``): the denoiser moves the root along a steered path but keeps
    the body facing the way the prompt walks, which would slide the feet sideways."""
    psi = facing(motion.positions, left_hip, right_hip)[start:]
    n = min(len(psi), len(headings))
    miss = torch.atan2(torch.sin(headings[:n] - psi[:n]), torch.cos(headings[:n] - psi[:n]))
    miss = smooth_time(miss[:, None].to(motion.dtype), sigma_frames)[:, 0]
    half = miss / 2
    yaw = torch.stack([half.cos(), torch.zeros_like(half), half.sin(), torch.zeros_like(half)], -1)
    rots = motion.local_rotations.clone()
    rots[start : start + n, 0] = quat_normalize(quat_mul(yaw, rots[start : start + n, 0]))
    return replace(motion, local_rotations=rots)


def ground_level(motion: Motion) -> float:
    """Where ``motion`` stands: the 10th percentile over frames of the lowest joint's height, metres
    (a stance frame's planted toe; airborne frames of a jog or a jump do not count)."""
    return float(torch.quantile(motion.positions[..., 1].amin(-1).float(), 0.1))


def turn_xz(xz: torch.Tensor, angle: float) -> torch.Tensor:
    """Ground points ``(..., 2)`` (x, z) turned about the origin by ``angle`` radians about +Y (positive
    turns +Z towards +X, as headings do)."""
    c, s = math.cos(angle), math.sin(angle)
    x, z = xz[..., 0], xz[..., 1]
    return torch.stack([x * c + z * s, -x * s + z * c], -1)


def turned(motion: Motion, angle: float) -> Motion:
    """``motion`` turned about the world's vertical axis through the origin by ``angle`` radians."""
    root = motion.root_translation.clone()
    root[:, [0, 2]] = turn_xz(root[:, [0, 2]], angle)
    half = torch.tensor(angle / 2, dtype=motion.dtype)
    yaw = torch.stack([half.cos(), half * 0, half.sin(), half * 0]).expand(motion.num_frames, 4)
    rots = motion.local_rotations.clone()
    rots[:, 0] = quat_normalize(quat_mul(yaw, rots[:, 0]))
    return replace(motion, root_translation=root, local_rotations=rots)


def shifted(motion: Motion, dx: float, dz: float) -> Motion:
    """``motion`` moved by ``(dx, 0, dz)`` metres on the ground."""
    move = torch.tensor([dx, 0.0, dz], dtype=motion.dtype)
    return replace(motion, root_translation=motion.root_translation + move)


def facing(positions: torch.Tensor, left_hip: int, right_hip: int) -> torch.Tensor:
    """Heading ``psi`` (radians, 0 = +Z) of each frame of ``positions (T, J, 3)``, from the hips: the
    ground direction perpendicular to left->right hip, pointing forward."""
    across = positions[:, right_hip] - positions[:, left_hip]
    return torch.atan2(across[:, 2], -across[:, 0])


def wrap_angle(a: float) -> float:
    """``a`` radians wrapped into ``(-pi, pi]``."""
    return math.atan2(math.sin(a), math.cos(a))
