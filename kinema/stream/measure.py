"""Measurements of a streamed motion: joins against the windows' own motion, the floor, trunk lean,
walking speed and heading, and the process's resident memory. Used by ``kinema bench stream``, the
tests and docs/stream.md. Units: metres, seconds, degrees; frames at the motion's fps.
"""

from __future__ import annotations

import math
import resource
import sys
from dataclasses import dataclass
from pathlib import Path

import torch

from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time
from kinema.stream.frames import StreamFrames, facing

#: frames either side of a join inspected for pops
JOIN_RADIUS = 3


def frames_to_motion(parts: list[StreamFrames], skeleton) -> Motion:
    """Consecutive `StreamFrames` as one `Motion` on ``skeleton``."""
    root = torch.cat([p.root_translation for p in parts])
    rots = torch.cat([p.local_rotations for p in parts])
    lt = None
    if parts[0].local_translations is not None:
        lt = torch.cat([p.local_translations for p in parts])
    return Motion(skeleton, parts[0].fps, root, rots, None, lt)


def pelvis_speed(motion: Motion) -> torch.Tensor:
    """Ground speed of the pelvis between consecutive frames ``(T - 1,)``, m/s."""
    return _ground_speed(motion.root_translation[:, [0, 2]], motion.fps)


def joint_acceleration(motion: Motion) -> torch.Tensor:
    """Largest joint acceleration of each inner frame ``(T - 2,)``, m/s^2 (frame i is motion frame i + 1)."""
    return _largest_acceleration(motion.positions, motion.fps)


def _ground_speed(xz: torch.Tensor, fps: float) -> torch.Tensor:
    """Speed between consecutive ground points ``(T, 2)`` -> ``(T - 1,)``, m/s."""
    return (xz[1:] - xz[:-1]).norm(dim=-1) * fps


def _speed_change(speed: torch.Tensor, fps: float) -> torch.Tensor:
    """|change| of consecutive speeds ``(T - 1,)`` -> ``(T - 2,)``, m/s^2 (index i: around frame i + 1)."""
    return (speed[1:] - speed[:-1]).abs() * fps


def _largest_acceleration(positions: torch.Tensor, fps: float) -> torch.Tensor:
    """Largest joint acceleration of each inner frame of positions ``(T, J, 3)`` -> ``(T - 2,)``, m/s^2."""
    p = positions
    return ((p[2:] - 2 * p[1:-1] + p[:-2]).norm(dim=-1) * fps**2).amax(-1)


@dataclass(frozen=True)
class JoinReport:
    """Pops at window joins against the windows' own motion: the largest pelvis speed change (m/s per
    second) and joint acceleration (m/s^2) within `JOIN_RADIUS` frames of any seam, and the largest and
    the 99th percentile of the same quantities over the frames away from joins. ``ok``: no join goes
    beyond what the windows themselves contain."""

    joins: int
    join_speed_change: float
    inside_speed_change_max: float
    inside_speed_change_p99: float
    join_acceleration: float
    inside_acceleration_max: float
    inside_acceleration_p99: float

    @property
    def ok(self) -> bool:
        return (self.join_speed_change <= self.inside_speed_change_max
                and self.join_acceleration <= self.inside_acceleration_max)

    def to_json(self) -> dict:
        return {k: round(v, 3) if isinstance(v, float) else v for k, v in self.__dict__.items()} | {"ok": self.ok}


def join_report(motion: Motion, seams: list[tuple[int, int]]) -> JoinReport:
    """Compare the motion around ``seams`` (frame ranges ``[lo, hi)`` where one window is stitched to
    the next: `MotionStream.seams`) with the rest of it."""
    return _report(_speed_change(pelvis_speed(motion), motion.fps), joint_acceleration(motion), motion.num_frames,
                   seams)


def _report(dspeed: torch.Tensor, acc: torch.Tensor, num_frames: int, seams: list[tuple[int, int]]) -> JoinReport:
    """`JoinReport` from the pelvis speed change and the largest joint acceleration of each inner frame
    (index i: frame i + 1) of a ``num_frames``-frame motion."""
    near = torch.zeros(num_frames, dtype=torch.bool)
    for lo, hi in seams:
        near[max(0, lo - JOIN_RADIUS) : hi + JOIN_RADIUS] = True
    inner = near[1:-1]
    away = ~inner
    if not bool(inner.any()) or not bool(away.any()):
        return JoinReport(len(seams), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    ds, da = dspeed[away], acc[away]
    return JoinReport(len(seams), float(dspeed[inner].max()), float(ds.max()),
                      float(torch.quantile(ds, 0.99)), float(acc[inner].max()), float(da.max()),
                      float(torch.quantile(da, 0.99)))


class JoinMeter:
    """`join_report` over a stream of any length without keeping its frames: fed each `StreamFrames`
    in order, it keeps the last two frames and two float32 numbers per frame (96 kB for 10 minutes at
    20 fps), so a 10-minute benchmark measures every join and its memory stays the stream's."""

    def __init__(self) -> None:
        self._root: torch.Tensor | None = None  # the last (up to) 2 frames' root x/z
        self._pos: torch.Tensor | None = None  # and joint positions
        self._dspeed: list[torch.Tensor] = []
        self._acc: list[torch.Tensor] = []
        self.num_frames = 0
        self.fps = 0.0

    def feed(self, frames: StreamFrames) -> None:
        if frames.start != self.num_frames:
            raise ValueError(f"JoinMeter: frames start at {frames.start}, expected {self.num_frames}")
        self.fps = frames.fps
        root = frames.root_translation[:, [0, 2]].float()
        pos = frames.positions.float()
        if self._root is not None:
            root, pos = torch.cat([self._root, root]), torch.cat([self._pos, pos])
        if root.shape[0] >= 3:
            self._dspeed.append(_speed_change(_ground_speed(root, self.fps), self.fps))
            self._acc.append(_largest_acceleration(pos, self.fps))
        self._root, self._pos = root[-2:], pos[-2:]
        self.num_frames += frames.num_frames

    def report(self, seams: list[tuple[int, int]]) -> JoinReport:
        """The joins ``seams`` (frame ranges, `MotionStream.seams`) that end `JOIN_RADIUS` frames before
        the last frame fed, against the rest."""
        if not self._dspeed:
            return JoinReport(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        seams = [(lo, hi) for lo, hi in seams if hi + JOIN_RADIUS < self.num_frames]
        return _report(torch.cat(self._dspeed), torch.cat(self._acc), self.num_frames, seams)


def trunk_lean_deg(motion: Motion) -> torch.Tensor:
    """Forward lean of the trunk per frame (degrees from vertical of the pelvis -> neck line)."""
    roles = motion.skeleton.roles
    p = motion.positions
    v = p[:, roles["neck"]] - p[:, roles["pelvis"]]
    return torch.rad2deg(torch.atan2(v[:, [0, 2]].norm(dim=-1), v[:, 1]))


def headings_deg(motion: Motion) -> torch.Tensor:
    """Facing per frame, degrees (0 = +Z, 90 = +X)."""
    roles = motion.skeleton.roles
    return torch.rad2deg(facing(motion.positions, roles["left_hip"], roles["right_hip"]))


def travel_speed(motion: Motion, start: int, end: int) -> float:
    """Mean ground speed (m/s) of the smoothed pelvis over frames ``[start, end)``."""
    xz = smooth_time(motion.root_translation[:, [0, 2]], DEFAULT_ROOT_SIGMA_SECONDS * motion.fps)
    end = min(end, motion.num_frames)
    return float((xz[start + 1 : end] - xz[start : end - 1]).norm(dim=-1).sum()) * motion.fps / max(1, end - 1 - start)


def floor_heights(motion: Motion) -> torch.Tensor:
    """The lowest joint's height per frame ``(T,)``, metres (0 = the floor)."""
    return motion.positions[..., 1].amin(-1)


def rss_mb() -> float:
    """This process's resident memory now, MiB (from /proc; the peak where /proc is missing)."""
    status = Path("/proc/self/status")
    if status.exists():
        for line in status.read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024 * 1024 if sys.platform == "darwin" else 1024)


def circular_mean_deg(values: torch.Tensor) -> float:
    r = torch.deg2rad(values)
    return math.degrees(math.atan2(float(r.sin().mean()), float(r.cos().mean())))
