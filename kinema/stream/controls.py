"""What a stream is told to do, and how that becomes one window's constraints (docs/constraints.md JSON).

A window is generated in a local frame whose first context root stands over the origin (as training
clips start), turned so that the context's last frame faces +Z; every position below is in that frame.
A window of ``W`` frames starts with ``C`` context frames (the last generated ones, imposed by the
stream's body: kinema.stream.bodies; for the human model `context_keyframes`), so it continues the
motion; the controls constrain the free frames ``[C, W)``:

- steering: a dense ``root2d`` path with headings that turns from the current facing towards
  ``direction_deg`` at most ``TURN_RATE_DEG`` per second and moves at ``speed`` m/s (reached over
  ``SPEED_RAMP_SECONDS``), starting where the context ends;
- a target: an ``end-effector`` position held every other frame from ``REACH_SECONDS`` after the
  context to the window's end.
"""

from __future__ import annotations

import math
import reprlib
from dataclasses import dataclass, field

import torch

from kinema.errors import KinemaError
from kinema.finite import is_finite_real
from kinema.geometry.rotations import quat_to_axis_angle
from kinema.motion.core import Motion
from kinema.stream.frames import wrap_angle

#: fastest turn of the steering path, degrees per second
TURN_RATE_DEG = 120.0
#: seconds over which the path's speed goes from the current one to the steered one
SPEED_RAMP_SECONDS = 0.5
#: seconds after the context before a target is imposed (the reach)
REACH_SECONDS = 0.5
#: fastest steered speed, m/s (a sprint)
MAX_SPEED = 6.0
#: the speed of a steer that gives none (m/s)
DEFAULT_SPEED = 1.2
#: the longest prompt a stream takes (characters)
MAX_PROMPT_CHARS = 2000
#: how far a target may be from the origin of the world, metres
MAX_TARGET_DISTANCE = 1000.0


@dataclass(frozen=True)
class Steer:
    """Move towards world heading ``direction_deg`` (0 = +Z, 90 = +X; None: the facing of the window
    the steer starts in) at ``speed`` m/s."""

    direction_deg: float | None
    speed: float

    @classmethod
    def checked(cls, direction_deg, speed) -> Steer:
        for name, v in (("direction_deg", direction_deg), ("speed", speed)):
            if v is None and name == "direction_deg":
                continue
            if not is_finite_real(v):
                raise KinemaError(f"steer: {name} must be a finite number, got {reprlib.repr(v)}")
        if not 0 <= speed <= MAX_SPEED:
            raise KinemaError(f"steer: speed must be in [0, {MAX_SPEED:g}] m/s, got {speed!r}")
        return cls(None if direction_deg is None else float(direction_deg), float(speed))


@dataclass(frozen=True)
class Target:
    """Put ``joint`` (a name or a role such as ``right_hand``) at world ``position`` (metres)."""

    joint: str
    position: tuple[float, float, float]

    @classmethod
    def checked(cls, joint, position, joint_names, roles) -> Target:
        if not isinstance(joint, str) or not (joint in joint_names or joint in roles):
            raise KinemaError(f"target: unknown joint {joint!r} (roles: {sorted(roles)})")
        try:
            xyz = tuple(float(v) for v in position)
        except (TypeError, ValueError, OverflowError):
            raise KinemaError(f"target: position must be three numbers [x, y, z], "
                              f"got {reprlib.repr(position)}") from None
        if len(xyz) != 3 or not all(math.isfinite(v) and abs(v) <= MAX_TARGET_DISTANCE for v in xyz):
            raise KinemaError(f"target: position must be three finite numbers within {MAX_TARGET_DISTANCE:g} m, "
                              f"got {reprlib.repr(position)}")
        return cls(joint, xyz)


@dataclass
class Controls:
    """The current prompt, steering and targets (what the coming windows are asked to do)."""

    prompt: str = ""
    steer: Steer | None = None
    targets: dict[str, Target] = field(default_factory=dict)

    def window_constraints(self, window: WindowFrame, first: int, num_frames: int) -> list[dict]:
        """The constraints JSON of the free frames ``[first, num_frames)`` of a window (the context, its
        first ``first`` frames, is imposed by the stream's body: kinema.stream.bodies)."""
        out = []
        if self.steer is not None:
            out.append(steer_path(self.steer, window, first, num_frames))
        reach = first + round(REACH_SECONDS * window.fps)
        frames = list(range(min(reach, num_frames - 1), num_frames, 2))
        for t in self.targets.values():
            x, z = window.local_xz(t.position[0], t.position[2])
            local = [x, t.position[1], z]
            out.append({"type": "end-effector", "joint": t.joint, "frame_indices": frames,
                        "positions": [local] * len(frames)})
        return out


@dataclass(frozen=True)
class WindowFrame:
    """Where a window starts: its local frame (``origin``: the world x, z of its first context root;
    ``yaw``: the world heading, radians, of the local +Z), the last context frame's root ground
    position ``root_xz`` and facing ``heading`` in that frame, its ground speed (m/s) and the model's
    frame rate."""

    origin: tuple[float, float]
    yaw: float
    root_xz: tuple[float, float]
    heading: float
    speed: float
    fps: float

    def local_xz(self, x: float, z: float) -> tuple[float, float]:
        """World ground point (x, z) in the window's frame."""
        dx, dz = x - self.origin[0], z - self.origin[1]
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return dx * c - dz * s, dx * s + dz * c


def context_keyframes(context: Motion, smooth_root: torch.Tensor) -> dict:
    """``context`` (local frame) as fullbody keyframes on the window's first frames."""
    return {"type": "fullbody", "frame_indices": list(range(context.num_frames)),
            "local_joints_rot": quat_to_axis_angle(context.local_rotations.float()).tolist(),
            "root_positions": context.root_translation.float().tolist(),
            "smooth_root_2d": smooth_root.float().tolist()}


def steer_path(steer: Steer, window: WindowFrame, first: int, num_frames: int) -> dict:
    """A dense root path with headings over frames ``[first - 1, num_frames)``: from the context's
    last root, turning towards the steered heading and ramping linearly to the steered speed."""
    dt = 1.0 / window.fps
    goal = window.heading if steer.direction_deg is None else math.radians(steer.direction_deg) - window.yaw
    psi, speed = window.heading, window.speed
    x, z = window.root_xz
    turn = math.radians(TURN_RATE_DEG) * dt
    ramp = abs(steer.speed - window.speed) * dt / SPEED_RAMP_SECONDS
    points, headings = [], []
    for _ in range(first - 1, num_frames):
        points.append([x, z])
        headings.append([math.cos(psi), math.sin(psi)])
        psi += max(-turn, min(turn, wrap_angle(goal - psi)))
        speed += max(-ramp, min(ramp, steer.speed - speed))
        x, z = x + speed * dt * math.sin(psi), z + speed * dt * math.cos(psi)
    return {"type": "root2d", "frame_indices": list(range(first - 1, num_frames)), "smooth_root_2d": points,
            "global_root_heading": headings}
