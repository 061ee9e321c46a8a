"""Root motion recovered from planted feet: the travel of a clip animated in place (the shared root-motion
recovery; skeleton-agnostic).

Game clips of walks, runs and gallops are usually animated *on the spot*: the body stays over the origin
and the feet slide backwards under it while planted (a treadmill). In the real motion a planted foot does
not slide: the body moves instead. So the body's ground velocity is minus the ground velocity of the feet
that are planted, and integrating it gives the travel the clip leaves out:

- **planted**: a foot joint is planted on frames where its height above the floor (along ``up``) is
  within a band of the lowest it comes in the clip (per foot: feet of game rigs stand at different
  heights): ``PLANT_BAND`` x the body size, or ``PLANT_SHARE`` of the foot's own lift where that is less
  (the apatosaurus lifts its front feet only 0.015 body sizes), and, among those frames, not in the
  fastest ``1 - PLANT_SLOWEST`` share of its own ground speeds (a swinging foot skimming the floor);
- **velocity**: per frame, minus the mean ground velocity (forward differences) of the planted feet;
  then a second pass drops planted frames whose foot moves along the clip's mean body velocity (a
  swinging foot goes forward, a planted one backwards under an in-place body) and averages again; frames with no
  planted foot (a gallop's flight) take the velocity interpolated linearly between the nearest frames
  that have one (held at the ends);
- **feet**: a given joint whose lowest point in the clip is more than ``FLOOR_BAND`` x the body size above
  the lowest joint never touches the floor and is never planted (a mech's knees taken for feet);
- **idle**: a clip whose planted feet barely slide (mean recovered ground speed below ``IDLE_SPEED`` x
  the body size per second) gets no travel at all: an idle's foot shuffles are not steps;
- the result is the travel ``(T, 3)`` along the ground plane (zero on frame 0); add it to the root (or
  the whole motion) to make the clip travel. Lengths are in the units of ``positions``.

`forward_agreement` then checks a rig's forward axis against a walk: the cosine between the recovered
net travel and the axis the rig says is forward (on the ground plane); a negative value means the rig
walks the other way than its axis says (its "forward" is its tail).

API: ``recover_travel(positions (T, J, 3), feet, fps, up=(0, 1, 0), size=None) -> RecoveredTravel``
(``travel (T, 3)``, ``planted (T, F)``, ``speed`` mean ground speed, ``net`` net distance);
``forward_agreement(travel (T, 3), forward, up) -> float``. Feet are joint indices of ``positions``
(every contact joint of the rig: heels and toes may both be given). Nothing here knows a skeleton or a
file format: the caller gives world joint positions (Quaternius creatures, Bandai Namco humans, ...).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

#: x body size: a foot this close to its lowest height in the clip may be planted ...
PLANT_BAND = 0.03
#: ... or this share of the foot's own lift in the clip, where that is less ...
PLANT_SHARE = 0.3
#: a foot whose lowest point in the clip is more than this (x body size) above the lowest joint is no foot
FLOOR_BAND = 0.05
#: ... unless it is among the fastest (1 - this) of its own ground speeds on those frames
PLANT_SLOWEST = 0.85
#: x body size per second: a clip whose recovered mean ground speed is below this does not travel
IDLE_SPEED = 0.02


@dataclass(frozen=True)
class RecoveredTravel:
    """Travel recovered from planted feet (see the module)."""

    travel: torch.Tensor  # (T, 3) ground-plane offset of the body from frame 0
    planted: torch.Tensor  # (T, F) bool, per given foot
    speed: float  # mean ground speed (units/s)
    net: float  # distance from the first frame's position to the last (units)


def _ground(v: torch.Tensor, up: torch.Tensor) -> torch.Tensor:
    """The part of vectors ``v (..., 3)`` along the ground plane (normal ``up``)."""
    return v - (v * up).sum(-1, keepdim=True) * up


def _fill(v: torch.Tensor, known: torch.Tensor) -> torch.Tensor:
    """``v (T, 3)`` with rows where ``known (T,)`` is False linearly interpolated between the nearest
    known rows (held at the ends); all zero when none is known."""
    idx = torch.nonzero(known).flatten()
    if len(idx) == 0:
        return torch.zeros_like(v)
    out = v.clone()
    T = v.shape[0]
    for t in range(T):
        if known[t]:
            continue
        after = idx[idx > t]
        before = idx[idx < t]
        if len(before) == 0:
            out[t] = v[after[0]]
        elif len(after) == 0:
            out[t] = v[before[-1]]
        else:
            a, b = int(before[-1]), int(after[0])
            w = (t - a) / (b - a)
            out[t] = (1 - w) * v[a] + w * v[b]
    return out


def recover_travel(
    positions: torch.Tensor,
    feet: Sequence[int],
    fps: float,
    *,
    up: Sequence[float] = (0.0, 1.0, 0.0),
    size: float | None = None,
) -> RecoveredTravel:
    """The travel of an in-place clip from its planted ``feet`` (see the module). ``positions (T, J, 3)``
    world joint positions; ``size`` the body size (default: the largest side of the joints' bounding box
    on frame 0)."""
    P = positions.double()
    T = P.shape[0]
    u = torch.tensor(up, dtype=P.dtype)
    u = u / u.norm()
    zero = RecoveredTravel(torch.zeros(T, 3, dtype=P.dtype), torch.zeros(T, len(feet), dtype=torch.bool), 0.0, 0.0)
    if T < 3 or not feet:
        return zero
    if size is None:
        size = float((P[0].max(0).values - P[0].min(0).values).max())
    floor = float((P * u).sum(-1).min())
    F = P[:, list(feet)]  # (T, F, 3)
    h = (F * u).sum(-1)  # (T, F)
    on_floor = h.amin(0) <= floor + FLOOR_BAND * size  # (F,): the others never touch the floor
    vel = torch.zeros_like(F)
    vel[:-1] = (F[1:] - F[:-1]) * fps
    vel[-1] = vel[-2]
    gvel = _ground(vel, u)  # (T, F, 3)
    speed = gvel.norm(dim=-1)
    lift = h.amax(0, keepdim=True) - h.amin(0, keepdim=True)
    band = torch.minimum(torch.full_like(lift, PLANT_BAND * size), PLANT_SHARE * lift)
    low = h <= h.amin(0, keepdim=True) + band
    planted = low & on_floor
    for k in range(len(feet)):
        s = speed[low[:, k], k]
        if len(s) > 2:
            planted[:, k] &= speed[:, k] <= torch.quantile(s, PLANT_SLOWEST)
    body = -(gvel * planted[..., None]).sum(1) / planted.sum(1).clamp_min(1)[:, None]
    planted &= (gvel * body.mean(0)).sum(-1) <= 0.0  # not moving the way the body goes over the clip
    n = planted.sum(1)
    body = -(gvel * planted[..., None]).sum(1) / n.clamp_min(1)[:, None]
    body = _fill(body, n > 0)
    mean_speed = float(body.norm(dim=-1).mean())
    if mean_speed < IDLE_SPEED * size:
        return RecoveredTravel(zero.travel, planted, 0.0, 0.0)
    travel = torch.zeros_like(body)
    travel[1:] = torch.cumsum(body[:-1] / fps, dim=0)
    return RecoveredTravel(travel, planted, mean_speed, float(travel[-1].norm()))


def forward_agreement(travel: torch.Tensor, forward: Sequence[float], up: Sequence[float] = (0.0, 1.0, 0.0)) -> float:
    """Cosine between the net recovered travel ``(T, 3)`` and ``forward`` on the ground plane (0 when the
    clip does not travel): 1 = the clip goes where the axis points, -1 = the opposite way."""
    u = torch.tensor(up, dtype=torch.float64)
    u = u / u.norm()
    d = _ground(travel[-1].double() - travel[0].double(), u)
    f = _ground(torch.tensor(forward, dtype=torch.float64), u)
    if float(d.norm()) < 1e-9 or float(f.norm()) < 1e-9:
        return 0.0
    return float((d / d.norm() * f / f.norm()).sum())
