"""Typed kinematic constraints: what a user asks of a generated motion (Kimodo paper Sec. 2.2, 4.3).

One dataclass per constraint type the model is trained on:

- `FullBodyConstraint`: whole poses (local rotations + root position) at keyframes (in-betweening);
- `EndEffectorConstraint`: global position and/or rotation of one joint (hand, foot, head, ...);
- `Root2DConstraint`: ground-plane waypoints of the smoothed root, optionally with heading, or a dense
  path over an interval;
- `FootContactConstraint`: which heels/toes are planted.

Each holds its keyframes as ``frame_indices`` (ints at the model fps) or ``times`` (seconds, frame
``floor(t * fps + 0.5)``), exactly one of the two, and arrays with one row per keyframe (``K``).
Units: metres, radians (axis-angle vectors), world frame Y up (docs/conventions.md). The objects are
plain data: `check` validates them against a skeleton, fps and duration and returns the frames;
kinema.representation.encode turns them into model features; kinema.constraints.io reads/writes JSON.
Errors are `ConstraintError` (a `KinemaError`) naming the constraint, the field and the reason.
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import ClassVar

import torch

from kinema.errors import KinemaError, SkeletonError
from kinema.skeleton import Skeleton

#: Order of the four foot-contact flags (as the features' contact channels).
CONTACT_NAMES = ("left_heel", "left_toe", "right_heel", "right_toe")


class ConstraintError(KinemaError):
    """A constraint is malformed. The message is ``[source: ][constraint i (type): ][field 'f': ]reason``."""

    def __init__(self, reason: str, *, field: str | None = None, index: int | None = None,
                 kind: str | None = None, source: str | None = None):
        self.reason, self.field, self.index, self.kind, self.source = reason, field, index, kind, source
        parts = [] if source is None else [str(source)]
        if index is not None:
            parts.append(f"constraint {index}" + (f" ({kind})" if kind else ""))
        if field is not None:
            parts.append(f"field '{field}'")
        super().__init__(": ".join([*parts, reason]))

    def at(self, *, index: int | None = None, kind: str | None = None, source: str | None = None,
           rename: dict[str, str] | None = None) -> ConstraintError:
        """The same error located in a list/file (fields already set are kept); ``rename`` maps
        attribute names to the JSON keys the user wrote."""
        name = (rename or {}).get(self.field, self.field) if self.field else self.field
        return ConstraintError(
            self.reason, field=name, index=self.index if self.index is not None else index,
            kind=self.kind or kind, source=self.source if self.source is not None else source,
        )


class ConstraintWarning(UserWarning):
    """Something in a constraints file was interpreted or dropped (the CLI prints it on stderr)."""


def json_array(value, key: str, allow_bool: bool = False) -> torch.Tensor:
    """Nested JSON lists of numbers -> float64 tensor (ragged rows and non-numbers are errors)."""

    def shape_of(v) -> tuple:
        if isinstance(v, list):
            shapes = {shape_of(x) for x in v}
            if len(shapes) > 1:
                raise ConstraintError("rows have different lengths (ragged array)", field=key)
            return (len(v), *(shapes.pop() if shapes else ()))
        if (isinstance(v, bool) and not allow_bool) or not isinstance(v, int | float):
            raise ConstraintError(f"expected numbers, found {json.dumps(v)}", field=key)
        return ()

    shape_of(value)
    return torch.tensor(value, dtype=torch.float64)


def as_array(value, name: str) -> torch.Tensor | None:
    """``value`` (nested lists, numpy, tensor or None) as a float64 tensor; errors name ``name``."""
    if value is None:
        return None
    try:
        return torch.as_tensor(value, dtype=torch.float64).clone()
    except (TypeError, ValueError, RuntimeError) as err:
        raise ConstraintError(f"not an array of numbers ({err})", field=name) from None


def frames_from_times(times: Sequence[float], fps: float) -> list[int]:
    """Frame of each time (seconds): ``floor(t * fps + 0.5)`` (round half up); tiny float noise is
    absorbed so that e.g. ``0.35 s`` at 20 fps is frame 7."""
    return [int(math.floor(t * fps + 0.5 + 1e-9)) for t in times]


@dataclass(eq=False, kw_only=True)
class Constraint:
    """Base class: keyframes as ``frame_indices`` or ``times`` (exactly one)."""

    kind: ClassVar[str] = ""
    #: (attribute, trailing shape after K, required); ``"J"`` stands for the number of joints.
    ARRAYS: ClassVar[tuple[tuple[str, tuple, bool], ...]] = ()

    frame_indices: Sequence[int] | None = None
    times: Sequence[float] | None = None

    def __post_init__(self) -> None:
        if self.frame_indices is not None and not isinstance(self.frame_indices, torch.Tensor):
            self.frame_indices = tuple(self.frame_indices)
        elif isinstance(self.frame_indices, torch.Tensor):
            self.frame_indices = tuple(int(f) for f in self.frame_indices.reshape(-1).tolist())
        if self.times is not None:
            self.times = tuple(float(t) for t in self.times)
        for name, _, _ in self.ARRAYS:
            setattr(self, name, as_array(getattr(self, name), name))

    # ------------------------------------------------------------------ frames
    def frames(self, fps: float, num_frames: int | None = None) -> list[int]:
        """Keyframes at ``fps`` (validated: exactly one of frame_indices/times, integers, not negative,
        no repeats, inside ``num_frames`` when given)."""
        if (self.frame_indices is None) == (self.times is None):
            both = "both" if self.frame_indices is not None else "neither"
            raise ConstraintError(f"give exactly one of 'frame_indices' and 'times' ({both} given)",
                                  field="frame_indices")
        duration = "" if num_frames is None else (
            f"the motion lasts {num_frames} frames = {num_frames / fps:.3f} s at {fps:g} fps "
            f"(last frame {num_frames - 1})")
        if self.times is not None:
            name, raw = "times", list(self.times)
            for t in raw:
                if not math.isfinite(t):
                    raise ConstraintError(f"time {t} is not a finite number", field=name)
                if t < 0:
                    raise ConstraintError(f"negative time {t:g} s", field=name)
            frames = frames_from_times(raw, fps)
            label = [f"time {t:g} s (frame {f})" for t, f in zip(raw, frames, strict=True)]
        else:
            name, raw = "frame_indices", list(self.frame_indices)
            for f in raw:
                if isinstance(f, bool) or not isinstance(f, numbers.Real) or not math.isfinite(f) or float(f) != int(f):
                    raise ConstraintError(f"frame {f!r} is not an integer", field=name)
            frames = [int(f) for f in raw]
            label = [f"frame {f}" for f in frames]
            for f in frames:
                if f < 0:
                    raise ConstraintError(f"negative frame {f}", field=name)
        if not frames:
            raise ConstraintError("needs at least one frame", field=name)
        for f, lab in zip(frames, label, strict=True):
            if num_frames is not None and f >= num_frames:
                raise ConstraintError(f"{lab} is beyond the motion's duration: {duration}", field=name)
        if len(set(frames)) != len(frames):
            dup = sorted({f for f in frames if frames.count(f) > 1})
            raise ConstraintError(f"frames {dup} are given more than once", field=name)
        return frames

    # ------------------------------------------------------------------ validation
    def check(self, skeleton: Skeleton, fps: float, num_frames: int | None = None) -> list[int]:
        """Validate against the model skeleton, fps and duration (frames); returns the keyframes."""
        frames = self.frames(fps, num_frames)
        K = len(frames)
        for name, trailing, required in self.ARRAYS:
            value = getattr(self, name)
            if value is None:
                if required:
                    raise ConstraintError("missing required field", field=name)
                continue
            shape = (K, *(skeleton.num_joints if d == "J" else d for d in trailing))
            if tuple(value.shape) != shape:
                raise ConstraintError(
                    f"expected shape {shape} (one row per keyframe, K = {K}), got {tuple(value.shape)}",
                    field=name)
            if not torch.isfinite(value).all():
                row = int((~torch.isfinite(value)).reshape(K, -1).any(-1).nonzero()[0, 0])
                raise ConstraintError(f"contains NaN or inf (row {row}, keyframe {frames[row]})", field=name)
        self._check_more(skeleton, frames)
        return frames

    def _check_more(self, skeleton: Skeleton, frames: list[int]) -> None:
        """Type-specific checks (overridden)."""

    def copy(self, **changes) -> Constraint:
        """A copy with some fields replaced (dataclasses.replace)."""
        return replace(self, **changes)

    def same_as(self, other: Constraint, atol: float = 0.0) -> bool:
        """Equal type, frames and arrays (within ``atol``); used by round-trip tests and tools."""
        if type(self) is not type(other):
            return False
        for f in fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, torch.Tensor) or isinstance(b, torch.Tensor):
                if a is None or b is None or a.shape != b.shape or not torch.allclose(a, b, atol=atol, rtol=0):
                    return False
            elif a != b:
                return False
        return True


def resolve_joint(skeleton: Skeleton, joint: str) -> int:
    """Joint index of an exact joint name or a role (``left_hand``, ``left_foot`` = the ankle, ...)."""
    if not isinstance(joint, str) or not joint:
        raise ConstraintError(f"expected a joint name or role, got {joint!r}", field="joint")
    try:
        return skeleton.index(joint)
    except SkeletonError:
        roles = set(skeleton.roles)
        roles |= {f"{side}_foot" for side in ("left", "right") if f"{side}_ankle" in roles}
        roles = sorted(roles)
        raise ConstraintError(
            f"unknown joint or role {joint!r} (roles: {roles}; joints: {list(skeleton.names)})", field="joint"
        ) from None


@dataclass(eq=False, kw_only=True)
class FullBodyConstraint(Constraint):
    """Whole poses at keyframes.

    ``local_rotations (K, J, 3)``: axis-angle (radians) local rotation of every joint, in the model
    skeleton's joint order (parent frame -> joint frame, all zeros = rest pose).
    ``root_positions (K, 3)``: world position of the root joint (metres).
    ``smooth_root_2d (K, 2)``: optional smoothed-root (x, z); without it the pelvis ground projection
    stands in (see kinema.representation.encode).
    """

    kind: ClassVar[str] = "fullbody"
    ARRAYS: ClassVar = (("local_rotations", ("J", 3), True), ("root_positions", (3,), True),
                        ("smooth_root_2d", (2,), False))

    local_rotations: torch.Tensor | None = None
    root_positions: torch.Tensor | None = None
    smooth_root_2d: torch.Tensor | None = None


@dataclass(eq=False, kw_only=True)
class EndEffectorConstraint(Constraint):
    """One joint's global position and/or rotation at keyframes.

    ``joint``: exact joint name or role (``left_hand``, ``right_hand``, ``left_foot``/``right_foot``
    = the ankle joint, ``head``, ``pelvis``...). ``positions (K, 3)``: world position, metres.
    ``rotations (K, 3)``: global (world) rotation as axis-angle, radians (zero = rest orientation).
    ``smooth_root_2d (K, 2)``: optional smoothed-root (x, z) at those frames (as Kimodo's files carry);
    it lets the world x/z be written straight into the root-relative joint features.
    """

    kind: ClassVar[str] = "end-effector"
    ARRAYS: ClassVar = (("positions", (3,), False), ("rotations", (3,), False), ("smooth_root_2d", (2,), False))

    joint: str = ""
    positions: torch.Tensor | None = None
    rotations: torch.Tensor | None = None
    smooth_root_2d: torch.Tensor | None = None

    def _check_more(self, skeleton: Skeleton, frames: list[int]) -> None:
        resolve_joint(skeleton, self.joint)
        if self.positions is None and self.rotations is None:
            raise ConstraintError("missing required field: give 'positions' and/or 'rotations'", field="positions")


@dataclass(eq=False, kw_only=True)
class Root2DConstraint(Constraint):
    """Smoothed-root ground positions (waypoints, or a dense path).

    ``positions (K, 2)``: root (x, z) in metres (JSON ``smooth_root_2d``). ``heading (K, 2)``: optional
    ``(cos psi, sin psi)`` (JSON ``global_root_heading``; normalised, must not be zero). ``dense``: the
    keyframes describe a path over the interval [first, last] frame: positions (and headings) are
    linearly interpolated onto every frame in between (keyframes must then be increasing).
    """

    kind: ClassVar[str] = "root2d"
    ARRAYS: ClassVar = (("positions", (2,), True), ("heading", (2,), False))

    positions: torch.Tensor | None = None
    heading: torch.Tensor | None = None
    dense: bool = False

    def _check_more(self, skeleton: Skeleton, frames: list[int]) -> None:
        if not isinstance(self.dense, bool):
            raise ConstraintError(f"expected true or false, got {self.dense!r}", field="dense")
        if self.heading is not None and bool((self.heading.norm(dim=-1) < 1e-6).any()):
            raise ConstraintError("heading vectors (cos, sin) must not be zero", field="heading")
        if self.dense and any(b <= a for a, b in zip(frames, frames[1:], strict=False)):
            name = "times" if self.times is not None else "frame_indices"
            raise ConstraintError("a dense path needs increasing keyframes", field=name)


@dataclass(eq=False, kw_only=True)
class FootContactConstraint(Constraint):
    """Planted feet at keyframes: ``contacts (K, 4)`` in {0, 1} for [L heel, L toe, R heel, R toe]."""

    kind: ClassVar[str] = "foot-contact"
    ARRAYS: ClassVar = (("contacts", (4,), True),)

    contacts: torch.Tensor | None = None

    def _check_more(self, skeleton: Skeleton, frames: list[int]) -> None:
        if not bool(((self.contacts == 0) | (self.contacts == 1)).all()):
            raise ConstraintError("values must be 0 or 1 (or false/true)", field="contacts")


#: JSON ``type`` -> class (the shorthands fix the joint of an end-effector constraint).
CONSTRAINT_TYPES: dict[str, type[Constraint]] = {
    "fullbody": FullBodyConstraint,
    "end-effector": EndEffectorConstraint,
    "root2d": Root2DConstraint,
    "foot-contact": FootContactConstraint,
}
EFFECTOR_SHORTHANDS = {"left-hand": "left_hand", "right-hand": "right_hand",
                       "left-foot": "left_foot", "right-foot": "right_foot"}

__all__ = [
    "CONSTRAINT_TYPES", "CONTACT_NAMES", "EFFECTOR_SHORTHANDS", "Constraint", "ConstraintError", "ConstraintWarning",
    "EndEffectorConstraint", "FootContactConstraint", "FullBodyConstraint", "Root2DConstraint",
    "as_array", "frames_from_times", "json_array", "resolve_joint",
]
