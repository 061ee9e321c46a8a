"""Kinematic constraints for the any-rig model, and their encoding as per-joint feature targets.

Three kinds (frames at the model's fps; lengths in metres; Y up, +Z forward):

- `JointTarget(joint=, frame=, position=, rotation=)`: any joint's position and/or global rotation at a
  frame, in the *character frame* (relative to the rig's root joint, turned so the character faces +Z
  at that frame) -- the frame the per-joint features use, so the model is told it exactly. The
  rotation is a unit quaternion (w, x, y, z) as forward kinematics gives it (rest orientation
  included), e.g. read off a frame of one of the rig's clips; on the root joint only a rotation;
- `Keyframe(frame=, pose=, pose_frame=0)`: a full-body pose (a `Motion` on the same skeleton, e.g. a
  frame of one of the rig's clips): every joint's position and rotation and the root height;
- `RootPath(frames=, xz=)`: world ground waypoints of the root, starting from the origin at frame 0;
  between waypoints the root moves straight at constant speed, facing where it goes;
- `RootMotion(motion=, until=)`: the root's path, height, rotation and heading copied from a motion on
  the same rig for frames ``[0, until)`` (kinema.anyrig.world uses it to meet world-frame targets).

`encode_constraints` turns them into `FeatureTargets` on a rig in its normalised units (``scale`` =
units per metre). `post_targets` turns them into world-frame `PostTargets` for the exact pass, once
the motion (and so the root position and heading at each frame) is known.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch

from kinema.anyrig.sampling import FeatureTargets
from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_mul, quat_rotate, quat_to_sixd
from kinema.io.gltf import read_gltf
from kinema.io.registry import load_motion
from kinema.motion.core import Motion
from kinema.postprocess.targets import PostTargets
from kinema.representation.joint import (
    NUM_CHANNELS,
    POS,
    POSE,
    ROOT_FORWARD,
    ROOT_HEADING_COS,
    ROOT_HEADING_SIN,
    ROOT_HEIGHT,
    ROOT_LATERAL,
    ROT,
    JointRepresentation,
    yaw_quat,
)
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


@dataclass(frozen=True, kw_only=True)
class Keyframe:
    frame: int
    pose: Motion
    pose_frame: int = 0


@dataclass(frozen=True, kw_only=True)
class RootPath:
    frames: Sequence[int]
    xz: Sequence[tuple[float, float]]


@dataclass(frozen=True, kw_only=True)
class RootMotion:
    """The root's path, height, rotation and heading on frames ``[0, until)`` taken from ``motion`` (metres,
    on the same skeleton; e.g. a first pass): world joint targets stay where they were read in its
    character frame (whose heading comes from the root's rotation)."""

    motion: Motion
    until: int


Constraint = JointTarget | Keyframe | RootPath | RootMotion


def _joint(rep: JointRepresentation, joint: str | int) -> int:
    skel = rep.rig.skeleton
    if isinstance(joint, str):
        if joint not in skel.names:
            raise KinemaError(f"constraint joint {joint!r} is not in rig {skel.name or ''} ({skel.num_joints} joints)")
        return skel.index(joint)
    if not 0 <= int(joint) < skel.num_joints:
        raise KinemaError(f"constraint joint {joint} outside 0..{skel.num_joints - 1}")
    return int(joint)


def _frame(f: int, T: int, what: str) -> int:
    if isinstance(f, bool) or not isinstance(f, int) or not 0 <= f < T:
        raise KinemaError(f"{what}: frame {f!r} outside 0..{T - 1}")
    return f


def encode_constraints(
    constraints: Sequence[Constraint], rep: JointRepresentation, scale: float, frames: int
) -> FeatureTargets:
    """Feature targets ``(T, J, 13)`` (rig units) and their mask for ``constraints`` (see module)."""
    J = rep.num_joints
    x = torch.zeros(frames, J, NUM_CHANNELS)
    m = torch.zeros(frames, J, NUM_CHANNELS)
    root = rep.rig.root
    for c in constraints:
        if isinstance(c, JointTarget):
            j, f = _joint(rep, c.joint), _frame(c.frame, frames, "joint target")
            if j == root and c.position is not None:
                raise KinemaError("a joint position target on the root joint: use RootPath for where the root goes")
            if c.position is not None:
                x[f, j, POS] = torch.as_tensor(c.position, dtype=torch.float32) * scale
                m[f, j, POS] = 1.0
            if c.rotation is not None:
                x[f, j, ROT] = quat_to_sixd(c.unit_rotation()).to(x.dtype)
                m[f, j, ROT] = 1.0
        elif isinstance(c, Keyframe):
            f = _frame(c.frame, frames, "keyframe")
            if c.pose.num_joints != J:
                raise KinemaError(f"keyframe pose has {c.pose.num_joints} joints, the rig has {J}")
            feats = rep.from_motion(_scaled(c.pose, rep, scale).crop(c.pose_frame, c.pose_frame + 1))[0]
            x[f], m[f, :, POSE] = feats, 1.0
            m[f, root] = 0.0
            m[f, root, ROOT_HEIGHT] = 1.0  # the root row: height only (its rotation is the root joint's)
            m[f, root, ROT] = 1.0
        elif isinstance(c, RootPath):
            _root_path(c, x, m, root, scale, frames, rep.fps)
        elif isinstance(c, RootMotion):
            n = min(c.until, frames, c.motion.num_frames)
            lt = None if c.motion.local_translations is None else c.motion.local_translations * scale
            moved = Motion(
                rep.rig.skeleton, rep.fps, c.motion.root_translation * scale, c.motion.local_rotations, None, lt
            )
            rows = list(range(11))  # ground velocity (heading frame), height, rotation, heading
            x[:n, root, rows] = rep.from_motion(moved.crop(0, n)).to(x.dtype)[:, root, rows]
            m[:n, root, rows] = 1.0
        else:
            raise KinemaError(
                f"unknown constraint {type(c).__name__}; expected JointTarget, Keyframe, RootPath or RootMotion"
            )
    return FeatureTargets(x, m)


def _scaled(m: Motion, rep: JointRepresentation, scale: float) -> Motion:
    """``m`` (metres) on the representation's skeleton in its units, bone translations included (the
    Quaternius rigs move the body and IK feet by translation)."""
    lt = None if m.local_translations is None else m.local_translations * scale
    return Motion(rep.rig.skeleton, rep.fps, m.root_translation * scale, m.local_rotations, None, lt)


def _root_path(c: RootPath, x, m, root: int, scale: float, T: int, fps: float) -> None:
    frames = [0, *(_frame(f, T, "root waypoint") for f in c.frames)]
    pts = [(0.0, 0.0), *((float(a), float(b)) for a, b in c.xz)]
    if len(frames) != len(pts) or any(b <= a for a, b in zip(frames, frames[1:], strict=False)):
        raise KinemaError("root path: one (x, z) per frame, frames increasing after 0")
    for (fa, pa), (fb, pb) in zip(zip(frames, pts, strict=True), zip(frames[1:], pts[1:], strict=True), strict=False):
        dx, dz = pb[0] - pa[0], pb[1] - pa[1]
        speed = math.hypot(dx, dz) * fps / (fb - fa) * scale
        psi = math.atan2(dx, dz)
        span = slice(fa, fb)
        x[span, root, ROOT_LATERAL], x[span, root, ROOT_FORWARD] = 0.0, speed
        x[span, root, ROOT_HEADING_COS], x[span, root, ROOT_HEADING_SIN] = math.cos(psi), math.sin(psi)
        for channel in (ROOT_LATERAL, ROOT_FORWARD, ROOT_HEADING_COS, ROOT_HEADING_SIN):
            m[span, root, channel] = 1.0


def post_targets(
    constraints: Sequence[Constraint],
    motion: Motion,
    rep: JointRepresentation,
    scale: float = 1.0,
    translated: Sequence[int] = (),
) -> PostTargets:
    """World-frame targets of the joint and keyframe constraints (given in metres) on a generated
    ``motion`` in units of ``scale`` per metre on the same skeleton: the character frame is placed at
    the motion's own root and heading. A keyframe's pose keeps its bone translations only on the
    ``translated`` joints (those generation moves by translation); elsewhere its bones have their rest
    lengths, as the generated motion has: the pose the rig can take, not one it cannot."""
    G, P = motion.global_transforms()
    psi = rep.heading(G)
    root = rep.rig.root
    positions: dict[int, tuple[list[int], list[torch.Tensor]]] = {}
    rotations: dict[int, tuple[list[int], list[torch.Tensor]]] = {}

    def add(into: dict, j: int, f: int, value: torch.Tensor) -> None:
        into.setdefault(j, ([], []))[0].append(f)
        into[j][1].append(value)

    for c in constraints:
        if isinstance(c, JointTarget):
            j, turn = _joint(rep, c.joint), yaw_quat(psi[c.frame])
            if c.position is not None:
                local = torch.as_tensor(c.position, dtype=torch.float64) * scale
                add(positions, j, c.frame, P[c.frame, root] + quat_rotate(turn, local))
            if c.rotation is not None:
                add(rotations, j, c.frame, quat_mul(turn, c.unit_rotation()))
        elif isinstance(c, Keyframe):  # the pose, turned to the generated heading and put at the generated root
            pose = _rest_lengths(c.pose.to(torch.float64), translated)
            Gp, Pp = pose.global_transforms()
            turn = quat_mul(yaw_quat(psi[c.frame]), yaw_quat(-rep.heading(Gp)[c.pose_frame]))
            for j in range(motion.num_joints):
                add(rotations, j, c.frame, quat_mul(turn, Gp[c.pose_frame, j]))
                if j == 0 and translated:  # a floor-level armature: generation keeps it on the floor
                    continue
                local = quat_rotate(turn, Pp[c.pose_frame, j] - Pp[c.pose_frame, root]) * scale
                add(positions, j, c.frame, P[c.frame, root] + local)  # the root itself stays where it was

    def pack(d: dict) -> dict:
        return {j: (torch.tensor(fs), torch.stack(vs)) for j, (fs, vs) in d.items()}

    return PostTargets(joint_positions=pack(positions), joint_rotations=pack(rotations))


def _rest_lengths(pose: Motion, keep: Sequence[int]) -> Motion:
    """``pose`` with the rest offsets as bone translations, except on the joints ``keep``."""
    if pose.local_translations is None:
        return pose
    lt = pose.skeleton.offsets.to(pose.local_translations)[None].repeat(pose.num_frames, 1, 1)
    lt[:, list(keep)] = pose.local_translations[:, list(keep)]
    return Motion(pose.skeleton, pose.fps, pose.root_translation, pose.local_rotations, pose.foot_contacts, lt)


def _number_list(value, n: int | None, where: str) -> list[float]:
    if (
        not isinstance(value, list)
        or (n is not None and len(value) != n)
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    ):
        raise KinemaError(f"{where}: expected a list of {n or 'some'} numbers, got {value!r}")
    return [float(v) for v in value]


#: ``type`` values of the any-rig constraint list (`read_constraints`)
ANYRIG_TYPES = ("joint", "root_path", "keyframe")
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
    if not isinstance(obj, dict) or obj.get("type") not in ANYRIG_TYPES:
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
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as err:
        raise KinemaError(f"{path}: cannot read constraints ({err})") from None
    return parse_constraints(data, str(path), path.parent, fps)


def parse_constraints(data, where: str, base: Path = Path("."), fps: float | None = None) -> list[Constraint]:
    """Constraints from parsed JSON (see `read_constraints`); clip files are looked up in ``base``."""
    if not isinstance(data, list):
        raise KinemaError(f"{where}: any-rig constraints are a JSON list of objects")
    return [_from_json(i, obj, where, base, fps) for i, obj in enumerate(data)]
