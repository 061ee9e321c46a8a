"""Time-agnostic path following (SFControl Sec. 3.1.2, Eq. 1).

A joint must trace a given 3D path (or a ground path: x/z only) between ``t0`` and ``t1`` with no
per-frame timing. Both the generated segment ``C_seg`` (L = f1 - f0 + 1 frames) and the target
polyline are resampled to L points evenly spaced in arc length; the loss is their mean point distance
(geometric term) plus ``scale_weight * |s_L - L(target)|`` (the length term that keeps the motion's
scale). The paper fits a differentiable cubic spline before resampling; here the resampling is
piecewise linear in arc length (exact for a polyline target, and the generated segment is a dense
sequence of frames, so the two differ by far less than the errors measured). Differentiable in the
positions: the interpolation weights depend on them through the cumulative lengths.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from kinema.constraints.types import ConstraintError
from kinema.objectives.terms import Bound, Objective


def arc_resample(x: torch.Tensor, n: int) -> torch.Tensor:
    """``n`` points evenly spaced in arc length along the polyline ``x (B, L, d)`` -> ``(B, n, d)``.

    The segment of each sample point is found on detached lengths; the position inside it is
    interpolated with weights that stay differentiable. A polyline of zero length returns its first
    point ``n`` times."""
    seg = (x[:, 1:] - x[:, :-1]).norm(dim=-1)  # (B, L-1)
    s = torch.cat([seg.new_zeros(seg.shape[0], 1), seg.cumsum(dim=1)], dim=1)  # (B, L)
    total = s[:, -1:]
    u = torch.linspace(0.0, 1.0, n, dtype=x.dtype)[None] * total  # (B, n)
    i = torch.searchsorted(s.detach().contiguous(), u.detach().contiguous(), right=True) - 1
    i = i.clamp(0, x.shape[1] - 2)
    s0, s1 = s.gather(1, i), s.gather(1, i + 1)
    w = ((u - s0) / (s1 - s0).clamp_min(1e-9)).clamp(0.0, 1.0)[..., None]
    idx = i[..., None].expand(-1, -1, x.shape[-1])
    return (1 - w) * x.gather(1, idx) + w * x.gather(1, idx + 1)


@dataclass(frozen=True, kw_only=True)
class PathTimeAgnostic(Objective):
    """``joint`` follows ``path`` (K >= 2 points, (x, y, z) or ground (x, z)) during ``window`` (required),
    at its own pace. Error: mean distance between the arc-length resampled trajectories (metres)."""

    joint: str
    path: tuple[tuple[float, ...], ...]
    scale_weight: float = 0.5
    kind: str = field(default="path-time-agnostic", init=False)

    def joint_names(self):
        return (self.joint,)

    @property
    def ground(self) -> bool:
        return len(self.path[0]) == 2

    def bind(self, skeleton, fps, num_frames):
        if self.window is None:
            raise ConstraintError("a time-agnostic path needs its window [t0, t1] (seconds)", field="window")
        b = super().bind(skeleton, fps, num_frames)
        if b.f1 - b.f0 < 2:
            raise ConstraintError("the window must span at least 3 frames", field="window")
        return b

    def _parts(self, b: Bound, P):
        c = P[:, b.f0 : b.f1 + 1, b.joints[0]]
        if self.ground:
            c = c[..., [0, 2]]
        target = c.new_tensor(self.path)[None].expand(c.shape[0], -1, -1)
        n = c.shape[1]
        geo = (arc_resample(c, n) - arc_resample(target, n)).norm(dim=-1).mean(dim=1)
        length = (c[:, 1:] - c[:, :-1]).norm(dim=-1).sum(dim=1)
        target_length = (target[:, 1:] - target[:, :-1]).norm(dim=-1).sum(dim=1)
        return geo, (length - target_length).abs()

    def loss_fn(self, b, P):
        geo, scale = self._parts(b, P)
        return (geo + self.scale_weight * scale) ** 2

    def error_fn(self, b, P):
        return self._parts(b, P)[0]
