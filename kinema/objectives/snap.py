"""Snap: objectives turned into explicit keyjoint targets at the timing the optimised motion chose.

Noise optimisation with a few iterations brings a joint *near* its goal and, more importantly, picks
*when* (the frame of closest approach, the pace along a path). That timing is then imposed the way
explicit controls are: as end-effector constraints at those frames, sampled again from the optimised
noise with imputation, and met exactly by post-processing (IK). This mirrors SFControl's split: the
objective shapes the keyjoint trajectory, dense keyjoint targets complete the body. Not every
objective has an explicit form: ``reach`` (its target at the closest frame, plus a root waypoint moved
by the ground miss when the joint was more than 15 cm short, so the body walks there instead of
stretching), ``joint-distance`` with
``when="any"`` (the first joint put ``distance`` from the second at the closest frame, where it is
further) and ``path-time-agnostic`` (every frame of the window on the path at the arc-length fraction
the motion reached; ground paths keep the motion's own height, and a ground path of the root joint
becomes a dense ``root2d`` path, which the sampler's root displacement follows closely) do;
``stay-within`` on the root joint becomes a dense ``root2d`` path moved back inside the box's x/z
bounds where the pelvis left them; ``avoid``, other ``stay-within`` and ``realism`` keep what
optimisation gave. Positions ``P (T, J, 3)`` metres.
"""

from __future__ import annotations

import torch

from kinema.constraints.types import EndEffectorConstraint, Root2DConstraint
from kinema.objectives.path import PathTimeAgnostic
from kinema.objectives.terms import Bound, JointDistance, Reach, StayWithin

#: how far inside a stay-within box (metres) a root that left it is put back
BOX_MARGIN = 0.03
#: a reach target further than this (metres, on the ground) from where the joint got also moves the root
REACH_SLACK = 0.15


def point_at_fraction(path: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """Points of the polyline ``path (K, d)`` at arc-length fractions ``u (n,)`` in [0, 1] -> ``(n, d)``."""
    seg = (path[1:] - path[:-1]).norm(dim=-1)
    s = torch.cat([seg.new_zeros(1), seg.cumsum(0)])
    target = u.clamp(0, 1) * s[-1]
    i = (torch.searchsorted(s.contiguous(), target.contiguous(), right=True) - 1).clamp(0, len(path) - 2)
    w = ((target - s[i]) / (s[i + 1] - s[i]).clamp_min(1e-9)).clamp(0, 1)[:, None]
    return (1 - w) * path[i] + w * path[i + 1]


def _corridor(spec: StayWithin, b: Bound, pelvis: torch.Tensor, root_xz: torch.Tensor) -> list:
    """A dense root path over the window: the smoothed root moved by what puts the pelvis ``(W, 3)`` back
    inside the box's x/z bounds (with a margin); nothing when it never left them."""
    lo = torch.tensor([-torch.inf if v is None else v + BOX_MARGIN for v in (spec.min[0], spec.min[2])])
    hi = torch.tensor([torch.inf if v is None else v - BOX_MARGIN for v in (spec.max[0], spec.max[2])])
    p = pelvis[:, [0, 2]]
    shift = torch.minimum(torch.maximum(p, lo), hi) - p
    if float(shift.abs().max()) < 1e-4:
        return []
    frames = list(range(b.f0, b.f1 + 1))
    return [Root2DConstraint(frame_indices=frames, positions=(root_xz[b.f0 : b.f1 + 1] + shift).float(), dense=True)]


def _name(b: Bound, skeleton, k: int = 0) -> str:
    return skeleton.names[b.joints[k]]


def snap_constraints(
    bound: list[Bound], P: torch.Tensor, skeleton, root_xz: torch.Tensor, *, paths: bool = True
) -> list:
    """Constraints that impose the timing ``P``'s objectives reached (module docstring); ``root_xz (T, 2)``
    is the motion's smoothed root. ``paths=False`` leaves time-agnostic paths out (post-processing's
    per-frame pass would drag a path followed at its own pace back onto one timing)."""
    out: list = []
    for b in bound:
        spec, w = b.spec, P[b.f0 : b.f1 + 1]
        if isinstance(spec, Reach):
            d = (w[:, b.joints[0]] - w.new_tensor(spec.target)).norm(dim=-1)
            f = b.f0 + int(d.argmin())
            out.append(
                EndEffectorConstraint(
                    joint=_name(b, skeleton),
                    frame_indices=[f],
                    positions=torch.tensor([spec.target], dtype=torch.float32),
                )
            )
            miss = torch.tensor([spec.target[0], spec.target[2]]) - P[f, b.joints[0], [0, 2]]
            if float(miss.norm()) > REACH_SLACK and b.joints[0] != 0:  # walk there: move the root by the miss
                out.append(Root2DConstraint(frame_indices=[f], positions=(root_xz[f] + miss)[None].float()))
        elif isinstance(spec, JointDistance) and spec.when == "any":
            a, c = w[:, b.joints[0]], w[:, b.joints[1]]
            d = (a - c).norm(dim=-1)
            k = int(d.argmin())
            if float(d[k]) > spec.distance:
                goal = c[k] + (a[k] - c[k]) / d[k].clamp_min(1e-6) * spec.distance
                out.append(
                    EndEffectorConstraint(
                        joint=_name(b, skeleton), frame_indices=[b.f0 + k], positions=goal[None].float()
                    )
                )
        elif isinstance(spec, StayWithin) and b.joints == (0,):
            out += _corridor(spec, b, w[:, 0], root_xz)
        elif isinstance(spec, PathTimeAgnostic) and paths:
            c = w[:, b.joints[0]]
            xy = c[:, [0, 2]] if spec.ground else c
            seg = (xy[1:] - xy[:-1]).norm(dim=-1)
            s = torch.cat([seg.new_zeros(1), seg.cumsum(0)])
            u = s / s[-1].clamp_min(1e-9) if float(s[-1]) > 1e-6 else torch.linspace(0, 1, len(s))
            pts = point_at_fraction(torch.tensor(spec.path, dtype=torch.float32), u)
            frames = list(range(b.f0, b.f1 + 1))
            if spec.ground and b.joints[0] == 0:  # the root on the ground: a dense root2d path
                out.append(Root2DConstraint(frame_indices=frames, positions=pts.float(), dense=True))
                continue
            pos = torch.stack([pts[:, 0], c[:, 1], pts[:, 1]], -1) if spec.ground else pts
            out.append(EndEffectorConstraint(joint=_name(b, skeleton), frame_indices=frames, positions=pos.float()))
    return out
