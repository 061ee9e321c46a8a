"""Constraints no character can meet are refused before sampling (issue 36).

Three bounds, in metres, seconds and radians:

- ``MAX_COORDINATE`` (1000 m): every target position (root, waypoints, end effectors). float32 has
  6 cm steps at 1e6 m, so a waypoint there moved the whole motion 1e6 m with bones wobbling by
  centimetres; 1 km keeps steps below 0.1 mm. Move the scene's origin near the character instead.
- ``MAX_ROOT_SPEED`` (12 m/s, faster than any human has run) between consecutive root targets
  (``root2d`` waypoints and paths, full-body ``root_positions``, any ``smooth_root_2d``), scaled up
  for rigs larger than a person (by the rig's root-to-farthest-joint reach over ``HUMAN_REACH``).
  Targets 50 m apart half a second apart were met by a pelvis moving 100 m/s, a teleport, with a
  warning that claimed a 19 m miss.

- ``MAX_ROTATION`` (100 rad, 16 turns): each component of every axis-angle rotation (full-body
  ``local_joints_rot``, end-effector ``rotations``). Angles are periodic, but 1e300 rad turned into NaN
  in the exact pass (full-body: a LinAlgError traceback).

The check runs on the validated constraints (frames at the model fps) in
kinema.constraints.io.load_constraints, so every face (CLI, Python, server, batch, app) refuses the
same way, with a `ConstraintError` naming the constraint and field.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from kinema.constraints.types import (
    Constraint,
    ConstraintError,
    EndEffectorConstraint,
    FullBodyConstraint,
    Root2DConstraint,
)
from kinema.skeleton import Skeleton

MAX_COORDINATE = 1000.0
MAX_ROTATION = 100.0
MAX_ROOT_SPEED = 12.0
#: root-to-farthest-joint length of an adult human rig (metres): rigs this size or smaller get MAX_ROOT_SPEED
HUMAN_REACH = 1.0


def max_root_speed(skeleton: Skeleton) -> float:
    """`MAX_ROOT_SPEED`, scaled for rigs larger than a person."""
    return MAX_ROOT_SPEED * max(1.0, skeleton.reach() / HUMAN_REACH)


def _positions(c: Constraint) -> list[tuple[str, torch.Tensor]]:
    fields = {FullBodyConstraint: ("root_positions", "smooth_root_2d"),
              EndEffectorConstraint: ("positions", "smooth_root_2d"),
              Root2DConstraint: ("positions",)}
    names = next((f for cls, f in fields.items() if isinstance(c, cls)), ())
    return [(n, getattr(c, n)) for n in names if getattr(c, n, None) is not None]


def _root_xz(c: Constraint) -> tuple[str, torch.Tensor] | None:
    """The (x, z) root targets of a constraint, with the field they come from."""
    if isinstance(c, Root2DConstraint):
        return "positions", c.positions
    if getattr(c, "smooth_root_2d", None) is not None:
        return "smooth_root_2d", c.smooth_root_2d
    if isinstance(c, FullBodyConstraint) and c.root_positions is not None:
        return "root_positions", c.root_positions[:, [0, 2]]
    return None


def check_coordinates(constraints: Sequence[Constraint]) -> None:
    for i, c in enumerate(constraints):
        for name, values in _positions(c):
            big = values.abs().max().item() if values.numel() else 0.0
            if big > MAX_COORDINATE:
                raise ConstraintError(f"a target lies {big:.4g} m from the origin; at most {MAX_COORDINATE:g} m "
                                      "(float32 loses precision far out: move the scene's origin near the character)",
                                      field=name, index=i, kind=c.kind)


def check_rotations(constraints: Sequence[Constraint]) -> None:
    for i, c in enumerate(constraints):
        for name in ("local_rotations", "rotations"):
            values = getattr(c, name, None)
            if values is None or not values.numel():
                continue
            big = float(values.double().abs().max())  # a component: the norm of 1e300s overflows
            if big > MAX_ROTATION:
                raise ConstraintError(f"an axis-angle rotation of {big:.4g} rad; at most {MAX_ROTATION:g} (radians: "
                                      "the vector's length is the angle)", field=name, index=i, kind=c.kind)


def check_root_speeds(constraints: Sequence[Constraint], frames: Sequence[Sequence[int]], fps: float,
                      skeleton: Skeleton) -> None:
    """Refuse consecutive root targets (over all constraints, by frame) that only a speed above
    `max_root_speed` could join. ``frames[i]`` are constraint i's keyframes at ``fps``."""
    targets = []
    for i, (c, fr) in enumerate(zip(constraints, frames, strict=True)):
        found = _root_xz(c)
        if found is not None:
            name, xz = found
            targets += [(f, xz[k].double(), i, c.kind, name) for k, f in enumerate(fr)]
    targets.sort(key=lambda t: t[0])
    limit = max_root_speed(skeleton)
    for (f0, p0, *_), (f1, p1, i, kind, name) in zip(targets, targets[1:], strict=False):
        if f1 == f0:
            continue
        dist, dt = float((p1 - p0).norm()), (f1 - f0) / fps
        speed = dist / dt
        if speed > limit and math.isfinite(speed):
            raise ConstraintError(
                f"root targets at {f0 / fps:.3g} s ({p0[0]:.3g}, {p0[1]:.3g}) and {f1 / fps:.3g} s "
                f"({p1[0]:.3g}, {p1[1]:.3g}) are {dist:.3g} m apart in {dt:.3g} s: {speed:.3g} m/s, faster than "
                f"this character can move (at most {limit:.3g} m/s); give them more time or bring them closer",
                field=name, index=i, kind=kind)
