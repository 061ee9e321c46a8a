"""Objectives: differentiable functions of world joint positions that noise optimisation minimises.

SFControl (Sec. 3.1.2) and DNO define implicit controls as objectives on joint positions rather than
per-frame targets. Each objective here is a frozen dataclass written with joint *names* and times in
*seconds* (as in a constraints file), bound to a skeleton, fps and length with :meth:`bind` (which
validates names and windows). A bound objective gives

- ``loss(P) -> (B,)``: what the optimiser minimises (smooth, squared-metre scale);
- ``error(P) -> (B,)``: the value reported before/after (metres, except ``realism``: m/s^2).

Shapes: ``P (B, T, J, 3)`` world joint positions in metres, Y up; windows are inclusive frame ranges.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from kinema.constraints.types import ConstraintError, resolve_joint
from kinema.skeleton import Skeleton

#: softmin temperature (metres) for "at some time in the window" objectives
SOFTMIN_METRES = 0.05
#: acceleration scale (m/s^2) of the realism term
REALISM_ACCEL = 10.0


def _frames(window: tuple[float, float] | None, fps: float, T: int) -> tuple[int, int]:
    """Inclusive frame range of a ``(t0, t1)`` seconds window (None = the whole motion)."""
    if window is None:
        return 0, T - 1
    t0, t1 = window
    f0, f1 = int(math.floor(t0 * fps + 0.5)), int(math.floor(t1 * fps + 0.5))
    if not (0 <= f0 <= f1 <= T - 1):
        raise ConstraintError(
            f"window [{t0:g}, {t1:g}] s must satisfy 0 <= t0 <= t1 <= {(T - 1) / fps:g} s (the motion's last frame)",
            field="window",
        )
    return f0, f1


def softmin(x: torch.Tensor, tau: float, dim: int = -1) -> torch.Tensor:
    """A smooth minimum of ``x`` along ``dim``: ``-tau log mean exp(-x / tau)`` (>= min, -> min as tau -> 0)."""
    n = x.shape[dim]
    return -tau * (torch.logsumexp(-x / tau, dim=dim) - math.log(n))


@dataclass(frozen=True)
class Bound:
    """An objective bound to a rig: joint indices, frame range and the arrays it needs."""

    spec: Objective
    joints: tuple[int, ...]
    f0: int
    f1: int
    fps: float

    def loss(self, P: torch.Tensor) -> torch.Tensor:
        return self.spec.weight * self.spec.loss_fn(self, P)

    def error(self, P: torch.Tensor) -> torch.Tensor:
        return self.spec.error_fn(self, P)


@dataclass(frozen=True, kw_only=True)
class Objective:
    """Base: ``weight`` scales the loss; ``window`` (seconds) limits the frames (None = all)."""

    weight: float = 1.0
    window: tuple[float, float] | None = None
    kind: str = field(default="", init=False)

    def joint_names(self) -> Sequence[str]:
        return ()

    def bind(self, skeleton: Skeleton, fps: float, num_frames: int) -> Bound:
        joints = tuple(resolve_joint(skeleton, j) for j in self.joint_names())
        f0, f1 = _frames(self.window, fps, num_frames)
        return Bound(self, joints, f0, f1, fps)

    def loss_fn(self, b: Bound, P: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError  # every concrete objective overrides it

    def error_fn(self, b: Bound, P: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class Reach(Objective):
    """``joint`` touches ``target`` (x, y, z metres) at some frame inside ``window``; timing is free."""

    joint: str
    target: tuple[float, float, float]
    kind: str = field(default="reach", init=False)

    def joint_names(self):
        return (self.joint,)

    def _dist(self, b: Bound, P):
        p = P[:, b.f0 : b.f1 + 1, b.joints[0]]
        return (p - p.new_tensor(self.target)).norm(dim=-1)  # (B, W)

    def loss_fn(self, b, P):
        return softmin(self._dist(b, P), SOFTMIN_METRES) ** 2

    def error_fn(self, b, P):
        return self._dist(b, P).amin(dim=1)


@dataclass(frozen=True, kw_only=True)
class JointDistance(Objective):
    """The distance between ``joints[0]`` and ``joints[1]`` is at most ``distance`` metres, at some frame
    of the window (``when="any"``, e.g. hand-to-head) or on every frame (``"all"``)."""

    joints: tuple[str, str]
    distance: float = 0.0
    when: str = "any"
    kind: str = field(default="joint-distance", init=False)

    def joint_names(self):
        return tuple(self.joints)

    def _excess(self, b: Bound, P):
        a, c = P[:, b.f0 : b.f1 + 1, b.joints[0]], P[:, b.f0 : b.f1 + 1, b.joints[1]]
        return torch.relu((a - c).norm(dim=-1) - self.distance)  # (B, W)

    def loss_fn(self, b, P):
        e = self._excess(b, P)
        return softmin(e, SOFTMIN_METRES) ** 2 if self.when == "any" else (e**2).mean(dim=1)

    def error_fn(self, b, P):
        e = self._excess(b, P)
        return e.amin(dim=1) if self.when == "any" else e.amax(dim=1)


def _sphere_depth(p: torch.Tensor, spheres) -> torch.Tensor:
    out = torch.zeros(p.shape[:-1], dtype=p.dtype)
    for center, radius in spheres:
        out = torch.maximum(out, torch.relu(radius - (p - p.new_tensor(center)).norm(dim=-1)))
    return out


def _box_depth(p: torch.Tensor, boxes) -> torch.Tensor:
    out = torch.zeros(p.shape[:-1], dtype=p.dtype)
    for lo, hi in boxes:
        inside = torch.minimum(p - p.new_tensor(lo), p.new_tensor(hi) - p).amin(dim=-1)
        out = torch.maximum(out, torch.relu(inside))
    return out


@dataclass(frozen=True, kw_only=True)
class Avoid(Objective):
    """``joints`` (default: every joint) stay out of ``spheres`` ((center, radius) pairs) and axis-aligned
    ``boxes`` ((min, max) corner pairs). Error: the deepest penetration (metres)."""

    joints: tuple[str, ...] = ()
    spheres: tuple[tuple[tuple[float, float, float], float], ...] = ()
    boxes: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = ()
    kind: str = field(default="avoid", init=False)

    def joint_names(self):
        return tuple(self.joints)

    def bind(self, skeleton, fps, num_frames):
        b = super().bind(skeleton, fps, num_frames)
        if not self.joints:
            b = Bound(self, tuple(range(skeleton.num_joints)), b.f0, b.f1, fps)
        return b

    def _depth(self, b: Bound, P):
        p = P[:, b.f0 : b.f1 + 1][:, :, list(b.joints)]
        return torch.maximum(_sphere_depth(p, self.spheres), _box_depth(p, self.boxes))  # (B, W, J)

    def loss_fn(self, b, P):
        return (self._depth(b, P) ** 2).flatten(1).sum(dim=1) / max(1, b.f1 - b.f0 + 1)

    def error_fn(self, b, P):
        return self._depth(b, P).flatten(1).amax(dim=1)


@dataclass(frozen=True, kw_only=True)
class StayWithin(Objective):
    """``joints`` (default: the root joint) stay inside the box ``min``/``max`` (None = unbounded axis),
    e.g. a corridor ``min=(-0.3, None, None), max=(0.3, None, None)``. Error: the furthest excursion."""

    joints: tuple[str, ...] = ()
    min: tuple[float | None, float | None, float | None] = (None, None, None)
    max: tuple[float | None, float | None, float | None] = (None, None, None)
    kind: str = field(default="stay-within", init=False)

    def joint_names(self):
        return tuple(self.joints)

    def bind(self, skeleton, fps, num_frames):
        b = super().bind(skeleton, fps, num_frames)
        if not self.joints:
            b = Bound(self, (0,), b.f0, b.f1, fps)
        return b

    def _outside(self, b: Bound, P):
        p = P[:, b.f0 : b.f1 + 1][:, :, list(b.joints)]  # (B, W, J, 3)
        lo = p.new_tensor([-math.inf if v is None else v for v in self.min])
        hi = p.new_tensor([math.inf if v is None else v for v in self.max])
        return (torch.relu(lo - p) + torch.relu(p - hi)).norm(dim=-1)  # (B, W, J)

    def loss_fn(self, b, P):
        return (self._outside(b, P) ** 2).flatten(1).sum(dim=1) / max(1, b.f1 - b.f0 + 1)

    def error_fn(self, b, P):
        return self._outside(b, P).flatten(1).amax(dim=1)


@dataclass(frozen=True, kw_only=True)
class Realism(Objective):
    """A prior on the output: mean squared joint acceleration over (10 m/s^2)^2. Error: RMS m/s^2."""

    kind: str = field(default="realism", init=False)

    def _acc(self, b: Bound, P):
        p = P[:, b.f0 : b.f1 + 1]
        return (p[:, 2:] - 2 * p[:, 1:-1] + p[:, :-2]) * b.fps**2  # (B, W-2, J, 3)

    def loss_fn(self, b, P):
        return (self._acc(b, P) ** 2).sum(-1).flatten(1).mean(dim=1) / REALISM_ACCEL**2

    def error_fn(self, b, P):
        return (self._acc(b, P) ** 2).sum(-1).flatten(1).mean(dim=1).sqrt()
