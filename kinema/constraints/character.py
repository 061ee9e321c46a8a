"""Character-frame constraints: joint targets, keyframes and root paths for a model that works on any rig.

The constraint vocabulary of kinema is one: docs/constraints.md's types (kinema.constraints.types) in the
world frame, for every model, named by the rig's own joint names. The any-rig pipeline reads them in the
*character frame* its per-joint features use (kinema.anyrig.world does that translation), as these types,
which also carry a JSON form of their own (``{"type": "joint" | "root_path" | "keyframe", ...}``, for
targets read off a rig's own clips):

- `JointTarget(joint=, frame=, position=, rotation=)`: any joint's position and/or global rotation at a
  frame, in the character frame (relative to the rig's root joint, turned so the character faces +Z at
  that frame). The rotation is a unit quaternion (w, x, y, z) as forward kinematics gives it (rest
  orientation included), e.g. read off a frame of one of the rig's clips; on the root joint only a rotation;
- `Keyframe(frame=, pose=, pose_frame=0)`: a full-body pose (a `Motion` on the same skeleton, e.g. a frame
  of one of the rig's clips): every joint's position and rotation and the root height;
- `RootPath(frames=, xz=)`: world ground waypoints of the root, starting from the origin at frame 0;
  between waypoints the root moves straight at constant speed, facing where it goes;
- `RootMotion(motion=, until=)`: the root's path, height, rotation and heading copied from a motion on the
  same rig for frames ``[0, until)`` (kinema.anyrig.world uses it to meet world-frame targets; no JSON form).

Frames are at the model's fps; lengths in metres; Y up, +Z forward. `JointRepresentation.encode`
(kinema.representation.joint) turns them into per-joint feature targets.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.input_files import read_json_bounded
from kinema.io.gltf import read_gltf
from kinema.io.registry import load_motion
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton


@dataclass(frozen=True, kw_only=True)
class JointTarget:
    joint: str | int
    frame: int
    position: tuple[float, float, float] | None = None
    rotation: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.position is None and self.rotation is None:
            raise KinemaError(
                f"joint target on {self.joint!r} at frame {self.frame}: give a position, a rotation or both"
            )
        if self.rotation is not None:
            q = torch.as_tensor(self.rotation, dtype=torch.float64)
            if q.shape != (4,) or not bool(torch.isfinite(q).all()) or float(q.norm()) < 1e-6:
                raise KinemaError(
                    f"joint target on {self.joint!r}: rotation must be a quaternion [w, x, y, z], got {self.rotation!r}"
                )

    def unit_rotation(self) -> torch.Tensor:
        """The rotation target as a unit quaternion ``(4,)`` float64 (only when one is given)."""
        q = torch.as_tensor(self.rotation, dtype=torch.float64)
        return q / q.norm()

    def to_json(self) -> dict:
        """The target's JSON form (what `parse_constraints` reads)."""
        out: dict = {"type": "joint", "joint": self.joint, "frame": self.frame}
        if self.position is not None:
            out["position"] = [float(v) for v in self.position]
        if self.rotation is not None:
            out["rotation"] = [float(v) for v in self.rotation]
        return out


@dataclass(frozen=True, kw_only=True)
class Keyframe:
    frame: int
    pose: Motion
    pose_frame: int = 0


@dataclass(frozen=True, kw_only=True)
class RootPath:
    frames: Sequence[int]
    xz: Sequence[tuple[float, float]]

    def to_json(self) -> dict:
        """The path's JSON form (what `parse_constraints` reads)."""
        return {"type": "root_path", "frames": [int(f) for f in self.frames],
                "xz": [[float(a), float(b)] for a, b in self.xz]}


@dataclass(frozen=True, kw_only=True)
class RootMotion:
    """The root's path, height, rotation and heading on frames ``[0, until)`` taken from ``motion`` (metres,
    on the same skeleton; e.g. a first pass): world joint targets stay where they were read in its
    character frame (whose heading comes from the root's rotation)."""

    motion: Motion
    until: int


Constraint = JointTarget | Keyframe | RootPath | RootMotion


def _number_list(value, n: int | None, where: str) -> list[float]:
    if (
        not isinstance(value, list)
        or (n is not None and len(value) != n)
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    ):
        raise KinemaError(f"{where}: expected a list of {n or 'some'} numbers, got {value!r}")
    return [float(v) for v in value]


#: ``type`` values of the character-frame constraint list (`read_constraints`)
CHARACTER_TYPES = ("joint", "root_path", "keyframe")
KEYFRAME_KEYS = {"type", "frame", "clip", "animation", "clip_frame"}


def check_constraints(constraints: Sequence[Constraint], skeleton: Skeleton, frames: int, source: str) -> None:
    """Joint names / indices and frames of ``constraints`` checked against ``skeleton`` and a motion of
    ``frames`` frames, before generating; the one-line error names ``source`` and the constraint."""
    for i, c in enumerate(constraints):
        at = f"{source}: constraint {i}"
        if isinstance(c, JointTarget):
            if isinstance(c.joint, str) and c.joint not in skeleton.names:
                raise KinemaError(
                    f"{at}: joint {c.joint!r} is not in rig {skeleton.name or '?'} "
                    f"({skeleton.num_joints} joints: {', '.join(skeleton.names)})"
                )
            if not isinstance(c.joint, str) and not 0 <= c.joint < skeleton.num_joints:
                raise KinemaError(f"{at}: joint {c.joint} outside 0..{skeleton.num_joints - 1}")
            seen = [c.frame]
        elif isinstance(c, RootPath):
            seen = list(c.frames)
        elif isinstance(c, Keyframe):
            if list(c.pose.skeleton.names) != list(skeleton.names):
                raise KinemaError(
                    f"{at}: the keyframe's clip is on another skeleton than rig {skeleton.name or '?'} "
                    f"({c.pose.num_joints} joints, not the rig's {skeleton.num_joints} in its order)"
                )
            seen = [c.frame]
        else:
            continue
        bad = [f for f in seen if not 0 <= f < frames]
        if bad:
            raise KinemaError(f"{at}: frame {bad[0]} outside 0..{frames - 1} (the motion has {frames} frames)")


def _keyframe_from_json(obj: dict, at: str, base: Path, fps: float | None) -> Keyframe:
    """``{"type": "keyframe", "frame", "clip", "animation", "clip_frame"}``: the pose of frame ``clip_frame``
    (at ``fps``; the clip's own rate when None) of a BVH/npz clip or of a GLB's animation (by name, with
    or without its armature prefix), relative paths from the constraints file's folder."""
    frame, clip_frame, clip, anim = obj.get("frame"), obj.get("clip_frame", 0), obj.get("clip"), obj.get("animation")
    if (
        set(obj) - KEYFRAME_KEYS
        or not all(isinstance(f, int) and not isinstance(f, bool) and f >= 0 for f in (frame, clip_frame))
        or not isinstance(clip, str)
        or not isinstance(anim, (str, type(None)))
    ):
        raise KinemaError(
            f"{at}: a keyframe is {{type, frame (int), clip (GLB/BVH file), animation (GLB clip "
            "name), clip_frame (int, default 0)}}"
        )
    path = Path(clip) if Path(clip).is_absolute() or not (base / clip).is_file() else base / clip
    if not path.is_file():
        raise KinemaError(f"{at}: clip {clip!r}: no such file")
    if path.suffix.lower() in (".glb", ".gltf"):
        motions = read_gltf(path, fps=fps).motions
        names = {k: k for k in motions} | {k.split("|")[-1]: k for k in motions}
        if anim not in names:
            raise KinemaError(f"{at}: {path} has no animation {anim!r} (it has {', '.join(sorted(motions))})")
        pose = motions[names[anim]]
    else:
        pose = load_motion(path)
    if fps is not None and pose.fps != fps:
        pose = pose.resample(fps)
    if clip_frame >= pose.num_frames:
        raise KinemaError(f"{at}: clip_frame {clip_frame} outside 0..{pose.num_frames - 1} ({path})")
    return Keyframe(frame=frame, pose=pose, pose_frame=clip_frame)


def _from_json(i: int, obj, where: str, base: Path = Path("."), fps: float | None = None) -> Constraint:
    at = f"{where}[{i}]"
    if not isinstance(obj, dict) or obj.get("type") not in CHARACTER_TYPES:
        raise KinemaError(f"{at}: expected an object with type 'joint', 'root_path' or 'keyframe'")
    if obj["type"] == "keyframe":
        return _keyframe_from_json(obj, at, base, fps)
    if obj["type"] == "joint":
        unknown = set(obj) - {"type", "joint", "frame", "position", "rotation"}
        if (
            unknown
            or not isinstance(obj.get("joint"), (str, int))
            or not isinstance(obj.get("frame"), int)
            or not {"position", "rotation"} & set(obj)
        ):
            raise KinemaError(
                f"{at}: a joint target is {{type, joint (name or index), frame (int), position [x, y, z] and/or "
                "rotation [w, x, y, z]}"
            )
        pos = tuple(_number_list(obj["position"], 3, at)) if "position" in obj else None
        rot = tuple(_number_list(obj["rotation"], 4, f"{at}.rotation")) if "rotation" in obj else None
        try:
            return JointTarget(joint=obj["joint"], frame=obj["frame"], position=pos, rotation=rot)
        except KinemaError as err:
            raise KinemaError(f"{at}: {err}") from None
    unknown = set(obj) - {"type", "frames", "xz"}
    frames, xz = obj.get("frames"), obj.get("xz")
    if (
        unknown
        or not isinstance(frames, list)
        or not all(isinstance(f, int) for f in frames)
        or not isinstance(xz, list)
    ):
        raise KinemaError(f"{at}: a root path is {{type, frames [int, ...], xz [[x, z], ...]}}")
    return RootPath(frames=frames, xz=[tuple(_number_list(p, 2, f"{at}.xz")) for p in xz])


def read_constraints(path: str | Path, fps: float | None = None) -> list[Constraint]:
    """Constraints from a JSON list: ``{"type": "joint", "joint": "Head", "frame": 10, "position": [x, y, z]}``
    (character frame, metres; and/or ``"rotation": [w, x, y, z]``, the joint's global rotation there),
    ``{"type": "root_path", "frames": [40], "xz": [[0, 2]]}`` (world, metres) and ``{"type": "keyframe",
    "frame": 40, "clip": "Fox.glb", "animation": "Gallop", "clip_frame": 5}`` (a pose of a clip on the
    same skeleton; clip frames at ``fps``, the model's)."""
    path = Path(path)
    data = read_json_bounded(path, "constraints file")
    return parse_constraints(data, str(path), path.parent, fps)


def parse_constraints(data, where: str, base: Path = Path("."), fps: float | None = None) -> list[Constraint]:
    """Constraints from parsed JSON (see `read_constraints`); clip files are looked up in ``base``."""
    if not isinstance(data, list):
        raise KinemaError(f"{where}: any-rig constraints are a JSON list of objects")
    return [_from_json(i, obj, where, base, fps) for i, obj in enumerate(data)]
