"""Kimodo's own example files: ``meta.json`` and constraints carrying whole poses (docs/constraints.md).

Kimodo (NVIDIA) saves an example as a folder with ``meta.json`` (text or texts, duration(s), seed,
diffusion steps, guidance) and ``constraints.json`` whose ``frame_indices`` are at Kimodo's 30 fps.
`read_kimodo_meta` reads the meta file for use as generation defaults; `find_kimodo_meta` tells a
Kimodo folder apart (kinema then reads the frames at 30 fps, see kinema.constraints.fps).

Kimodo stores an end-effector constraint (``left-hand``, ..., ``end-effector`` + ``joint_names``) as a
whole pose, ``local_joints_rot`` (K, J, 3) + ``root_positions`` (K, 3) + ``smooth_root_2d`` (K, 2),
and derives the joint's target by forward kinematics. `adapt_pose_form` does the same on the model
skeleton when the pose has its joint count. A pose with the joint count of one of Kimodo's skeletons
(`KIMODO_SKELETONS`: SOMA 30 or 77, G1 34, SMPL-X 22; kinema's human has 21) cannot be mapped joint by
joint: with ``foreign_poses="root"``
(default) the skeleton-independent part, the root's ground position (x, z) at those frames, is kept
as a ``root2d`` constraint and a `ConstraintWarning` names what was dropped; with ``"error"`` it is a
`ConstraintError`. Fullbody poses are treated the same way. Other joint counts are an error (a mistake,
most likely).
"""

from __future__ import annotations

import json
import math
import numbers
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

from kinema.constraints.types import EFFECTOR_SHORTHANDS, ConstraintError, ConstraintWarning, json_array, resolve_joint
from kinema.diffusion.guidance import Guidance
from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat, quat_to_axis_angle
from kinema.kinematics import forward_kinematics
from kinema.skeleton import Skeleton

KIMODO_FPS = 30.0
#: Joint counts of the skeletons Kimodo's models use (for messages only).
KIMODO_SKELETONS = {30: "Kimodo SOMA, somaskel30", 77: "Kimodo SOMA, somaskel77", 34: "Kimodo Unitree G1, g1skel34",
                    22: "Kimodo SMPL-X, smplx22"}
FOREIGN_POSES = ("root", "error")
ROT_KEYS = ("local_joints_rot", "local_rotations")
FRAME_KEYS = ("frame_indices", "times")


# ---------------------------------------------------------------------------- meta.json
@dataclass(frozen=True)
class KimodoMeta:
    """What a Kimodo ``meta.json`` asks for. ``segments``: ``(prompt, seconds)``, one per text;
    ``guidance``: None when the file has no ``cfg`` (use the model's setting)."""

    path: Path
    segments: tuple[tuple[str, float], ...]
    seed: int | None = None
    steps: int | None = None
    samples: int | None = None
    guidance: Guidance | None = None
    fps: float = KIMODO_FPS

    @property
    def seconds(self) -> float:
        return sum(s for _, s in self.segments)

    def prompt_or_timeline(self) -> str | list[dict]:
        """A single prompt, or a timeline ``[{"prompt", "seconds"}, ...]`` (what `generate` takes)."""
        if len(self.segments) == 1:
            return self.segments[0][0]
        return [{"prompt": p, "seconds": s} for p, s in self.segments]


def _meta_error(path, field: str | None, reason: str) -> KinemaError:
    return KinemaError(f"{path}: " + (f"field '{field}': " if field else "") + reason)


def _looks_like_kimodo(data) -> bool:
    if not isinstance(data, dict):
        return False
    return ("text" in data or "texts" in data) and ("duration" in data or "durations" in data)


def find_kimodo_meta(constraints_path: str | os.PathLike) -> Path | None:
    """The Kimodo ``meta.json`` next to a constraints file, or None (absent, unreadable or not Kimodo's:
    it must hold ``text``/``texts`` and ``duration``/``durations``)."""
    meta = Path(constraints_path).parent / "meta.json"
    try:
        data = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        return None
    return meta if _looks_like_kimodo(data) else None


def _positive(path, key: str, value, kind=float):
    ok = not isinstance(value, bool) and isinstance(value, numbers.Integral if kind is int else numbers.Real)
    if not ok or not (math.isfinite(value) and value > 0):
        raise _meta_error(path, key, f"expected a positive {'integer' if kind is int else 'number'}, "
                                     f"got {json.dumps(value)}")
    return kind(value)


def read_kimodo_meta(path: str | os.PathLike) -> KimodoMeta:
    """Read a Kimodo ``meta.json`` (or the folder holding it) into `KimodoMeta` (validated).

    Keys read: ``text`` + ``duration`` (seconds) or ``texts`` + ``durations`` (a timeline), ``seed``,
    ``diffusion_steps``, ``num_samples``, ``cfg`` (``enabled``, ``text_weight``, ``constraint_weight``;
    disabled = guidance mode ``none``). Other keys are ignored. Errors are one-line `KinemaError`s.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "meta.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise _meta_error(path, None, "file not found") from None
    except (OSError, UnicodeDecodeError) as err:
        raise _meta_error(path, None, f"cannot read the file ({err})") from None
    except json.JSONDecodeError as err:
        raise _meta_error(path, None, f"not valid JSON: line {err.lineno}, column {err.colno}: {err.msg}") from None
    except RecursionError:
        raise _meta_error(path, None, "JSON nested too deeply to read") from None
    if not isinstance(data, dict):
        raise _meta_error(path, None, f"expected a JSON object, got {type(data).__name__}")
    seed = data.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise _meta_error(path, "seed", f"expected an integer, got {json.dumps(seed)}")
    steps = data.get("diffusion_steps")
    samples = data.get("num_samples")
    return KimodoMeta(
        path=path, segments=_segments(path, data), seed=seed,
        steps=None if steps is None else _positive(path, "diffusion_steps", steps, int),
        samples=None if samples is None else _positive(path, "num_samples", samples, int),
        guidance=_guidance(path, data.get("cfg")))


def _segments(path, data: dict) -> tuple[tuple[str, float], ...]:
    single, multi = ("text" in data or "duration" in data), ("texts" in data or "durations" in data)
    if single == multi:
        raise _meta_error(path, "text", "give 'text' + 'duration' or 'texts' + 'durations'")
    tkey, dkey = ("text", "duration") if single else ("texts", "durations")
    for key in (tkey, dkey):
        if key not in data:
            raise _meta_error(path, key, "missing required field")
    texts, durations = (data[tkey], data[dkey]) if multi else ([data[tkey]], [data[dkey]])
    if not isinstance(texts, list) or not all(isinstance(t, str) for t in texts) or not texts:
        raise _meta_error(path, tkey, f"expected {'a list of strings' if multi else 'a string'}, "
                                      f"got {json.dumps(data[tkey])}")
    if not isinstance(durations, list) or len(durations) != len(texts):
        raise _meta_error(path, dkey, f"expected one duration in seconds per text ({len(texts)}), "
                                      f"got {json.dumps(data[dkey])}")
    return tuple((t, _positive(path, dkey, d)) for t, d in zip(texts, durations, strict=True))


def _guidance(path, cfg) -> Guidance | None:
    if cfg is None:
        return None
    if not isinstance(cfg, dict):
        raise _meta_error(path, "cfg", f"expected an object, got {json.dumps(cfg)}")
    enabled = cfg.get("enabled", True)
    if not isinstance(enabled, bool):
        raise _meta_error(path, "cfg.enabled", f"expected true or false, got {json.dumps(enabled)}")
    weights = []
    for key in ("text_weight", "constraint_weight"):
        w = cfg.get(key, 2.0)
        if isinstance(w, bool) or not isinstance(w, numbers.Real) or not math.isfinite(w):
            raise _meta_error(path, f"cfg.{key}", f"expected a number, got {json.dumps(w)}")
        weights.append(float(w))
    return Guidance(mode="separated" if enabled else "none", w_text=weights[0], w_constr=weights[1])


# ---------------------------------------------------------------------------- whole-pose constraints
def adapt_pose_form(obj, skeleton: Skeleton, foreign_poses: str = "root") -> tuple[object, int | None]:
    """Kimodo's whole-pose form of a constraint object -> kinema's form (a JSON-style dict).

    Returns ``(object, foreign joint count or None)``: an end-effector pose on the model skeleton
    becomes the joint's world ``positions`` + ``rotations`` (forward kinematics); a pose with another
    joint count becomes a ``root2d`` object (``foreign_poses="root"``; the count is returned so the
    caller can warn) or raises. Anything else is returned unchanged.
    """
    if foreign_poses not in FOREIGN_POSES:
        raise KinemaError(f"foreign_poses must be one of {FOREIGN_POSES}, got {foreign_poses!r}")
    if not isinstance(obj, dict) or not isinstance(obj.get("type"), str):
        return obj, None
    kind = obj["type"]
    effector = kind == "end-effector" or kind in EFFECTOR_SHORTHANDS
    rot_key = next((k for k in ROT_KEYS if k in obj), None)
    if kind == "fullbody" and rot_key is not None:
        try:
            rots = _arr(obj[rot_key], rot_key)
        except ConstraintError:
            return obj, None  # reported by the usual checks
        J = rots.shape[1] if rots.ndim == 3 and rots.shape[-1] == 3 else skeleton.num_joints
        if J == skeleton.num_joints or J not in KIMODO_SKELETONS:
            return obj, None  # the usual checks apply
        return _foreign(obj, rot_key, rots.shape, skeleton, foreign_poses), rots.shape[1]
    if not effector or not ({*ROT_KEYS, "root_positions", "joint_names"} & obj.keys()):
        return obj, None
    for key in ("positions", "rotations"):
        if key in obj:
            raise ConstraintError(f"give either a whole pose ('local_joints_rot' + 'root_positions') or "
                                  f"'positions'/'rotations', not both ('{key}' given)", field=rot_key or key)
    if rot_key is None:
        raise ConstraintError("missing required field (a whole-pose end-effector constraint needs it)",
                              field="local_joints_rot")
    rots = _arr(obj[rot_key], rot_key)
    if rots.ndim != 3 or rots.shape[-1] != 3:
        raise ConstraintError(f"expected shape (K, J, 3), got {tuple(rots.shape)}", field=rot_key)
    if rots.shape[1] != skeleton.num_joints:
        return _foreign(obj, rot_key, rots.shape, skeleton, foreign_poses), rots.shape[1]
    return _effector_from_pose(obj, rot_key, rots, skeleton), None


def _arr(value, key: str):

    return json_array(value, key)


def _allowed_pose_keys(obj: dict) -> None:
    allowed = {"type", *FRAME_KEYS, *ROT_KEYS, "root_positions", "smooth_root_2d", "joint", "joint_names"}
    for key in obj:
        if key not in allowed and key != "comment" and not key.startswith("_"):
            raise ConstraintError(f"unknown field for a whole-pose constraint of type {obj['type']!r}; expected one "
                                  f"of {sorted(allowed)}", field=key)


def _foreign(obj: dict, rot_key: str, shape, skeleton: Skeleton, foreign_poses: str) -> dict:
    """The root's ground positions of a pose written for another skeleton, as a ``root2d`` object."""
    _allowed_pose_keys(obj)
    K, J = shape[0], shape[1]
    root_key = "smooth_root_2d" if "smooth_root_2d" in obj else "root_positions" if "root_positions" in obj else None
    if J not in KIMODO_SKELETONS:  # not a skeleton Kimodo writes: most likely a mistake
        hint = f"; for the root path alone, give '{root_key}' in a root2d constraint" if root_key else ""
        raise ConstraintError(f"expected shape {(K, skeleton.num_joints, 3)} (the model's skeleton{_name(skeleton)} "
                              f"has {skeleton.num_joints} joints), got {tuple(shape)}{hint}", field=rot_key)
    usable = (f"its skeleton-independent part, the root's ground position (x, z) from '{root_key}', can still "
              "be used (kept as a root2d waypoint with foreign_poses='root')") if root_key else \
        "it has no 'smooth_root_2d' or 'root_positions', so nothing in it can be used"
    if foreign_poses == "error" or root_key is None:
        raise ConstraintError(
            f"has {J} joints but the model's skeleton{_name(skeleton)} has {skeleton.num_joints}: this pose was "
            f"written for another skeleton ({KIMODO_SKELETONS[J]}?) and cannot be mapped joint by joint; {usable}",
            field=rot_key)
    width = 2 if root_key == "smooth_root_2d" else 3
    root = _arr(obj[root_key], root_key)
    if tuple(root.shape) != (K, width):
        raise ConstraintError(f"expected shape {(K, width)} (one row per keyframe, K = {K}), got "
                              f"{tuple(root.shape)}", field=root_key)
    xz = root if width == 2 else root[:, [0, 2]]
    out = {k: obj[k] for k in (*FRAME_KEYS, "comment") if k in obj}
    return {"type": "root2d", **out, "smooth_root_2d": xz.tolist()}


def _name(skeleton: Skeleton) -> str:
    return f" ({skeleton.name})" if skeleton.name else ""


def _effector_from_pose(obj: dict, rot_key: str, rots, skeleton: Skeleton) -> dict:
    """World position and rotation of the constrained joint, by forward kinematics of the pose."""

    _allowed_pose_keys(obj)
    joint = obj.get("joint", EFFECTOR_SHORTHANDS.get(obj["type"]))
    if "joint_names" in obj:
        names = obj["joint_names"]
        if not isinstance(names, list) or len(names) != 1 or not isinstance(names[0], str):
            raise ConstraintError(f"expected a list with one joint name (kinema constrains one joint per "
                                  f"constraint), got {json.dumps(names)}", field="joint_names")
        if "joint" in obj or obj["type"] != "end-effector":
            raise ConstraintError("the joint is already given ('joint' or the type)", field="joint_names")
        joint = names[0]
    if joint is None:
        raise ConstraintError("missing required field", field="joint")
    j = resolve_joint(skeleton, joint)
    if "root_positions" not in obj:
        raise ConstraintError("missing required field (the pose's root position)", field="root_positions")
    root = _arr(obj["root_positions"], "root_positions")
    if tuple(root.shape) != (rots.shape[0], 3):
        raise ConstraintError(f"expected shape {(rots.shape[0], 3)} (one row per keyframe), got "
                              f"{tuple(root.shape)}", field="root_positions")
    G, P = forward_kinematics(axis_angle_to_quat(rots), root, skeleton.offsets, skeleton.parents)
    out = {k: v for k, v in obj.items() if k not in (*ROT_KEYS, "root_positions", "joint_names")}
    if obj["type"] == "end-effector":
        out["joint"] = joint
    out["positions"] = P[:, j].tolist()
    out["rotations"] = quat_to_axis_angle(G[:, j]).tolist()
    return out


def warn_foreign(found: list[tuple[int, str, int]], source: str | None, skeleton: Skeleton) -> None:
    """One `ConstraintWarning` for the constraints (index, type, joint count) whose foreign poses were
    reduced to root waypoints."""
    if not found:
        return
    where = f"{source}: " if source else ""
    which = ", ".join(f"{i} ({kind})" for i, kind, _ in found)
    counts = sorted({J for _, _, J in found})
    names = "; ".join(f"{J} joints: {KIMODO_SKELETONS[J]}?" for J in counts)
    warnings.warn(
        f"{where}constraints {which}: poses with {'/'.join(map(str, counts))} joints but the model's "
        f"skeleton{_name(skeleton)} has {skeleton.num_joints} ({names}); kept only their root ground "
        "positions (x, z) as root2d waypoints at those frames; the poses (and hand/foot targets Kimodo derives "
        "from them) are dropped "
        "(pass foreign_poses='error' to refuse such files)", ConstraintWarning, stacklevel=3)
