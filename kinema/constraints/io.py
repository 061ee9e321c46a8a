"""Constraint files: JSON <-> typed constraints (format in docs/constraints.md).

A constraints file is a JSON list of objects (or ``{"fps": 30, "constraints": [...]}`` when its
``frame_indices`` are at another fps than the model's, see kinema.constraints.fps), each with a
``type`` (``fullbody``, ``end-effector``, ``left-hand``/``right-hand``/``left-foot``/``right-foot``,
``root2d``, ``foot-contact``), keyframes as
``frame_indices`` or ``times`` and per-type arrays with one row per keyframe. Kimodo's field names are
accepted (``smooth_root_2d``, ``global_root_heading``, ``local_joints_rot``, ``root_positions``), and
so are Kimodo's whole-pose end-effector constraints (kinema.constraints.kimodo_examples).
`load_constraints` validates everything against the model skeleton, fps and duration and raises
`ConstraintError` naming the file, the constraint (counted from 0), the field and the reason.
Keys starting with ``_`` (and ``comment``) are ignored, any other unknown key is an error (typos).
Poses from BVH (``"bvh": ...``) are read by kinema.constraints.bvh_poses (`poses_from_bvh`,
`fullbody_from_bvh`, re-exported here).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import torch

from kinema.atomic_files import atomic_write_bytes
from kinema.constraints.bvh_poses import SCALE_RATIO_LIMIT as SCALE_RATIO_LIMIT
from kinema.constraints.bvh_poses import fullbody_from_bvh as fullbody_from_bvh
from kinema.constraints.bvh_poses import poses_from_bvh
from kinema.constraints.fps import convert_frames, frames_to_source_times, read_constraints_json, source_fps_for
from kinema.constraints.json_values import int_list, time_list
from kinema.constraints.kimodo_examples import adapt_pose_form, warn_foreign
from kinema.constraints.plausibility import check_coordinates, check_root_speeds, check_rotations
from kinema.constraints.types import (
    CONSTRAINT_TYPES,
    EFFECTOR_SHORTHANDS,
    Constraint,
    ConstraintError,
    EndEffectorConstraint,
    FullBodyConstraint,
    json_array,
)
from kinema.skeleton import Skeleton

#: Per type: JSON key -> dataclass attribute (first key of each attribute is the one `save` writes).
KEYS: dict[str, dict[str, str]] = {
    "fullbody": {
        "local_joints_rot": "local_rotations",
        "local_rotations": "local_rotations",
        "root_positions": "root_positions",
        "smooth_root_2d": "smooth_root_2d",
    },
    "end-effector": {
        "joint": "joint",
        "positions": "positions",
        "rotations": "rotations",
        "smooth_root_2d": "smooth_root_2d",
    },
    "root2d": {
        "smooth_root_2d": "positions",
        "positions": "positions",
        "global_root_heading": "heading",
        "heading": "heading",
        "dense": "dense",
    },
    "foot-contact": {"contacts": "contacts", "foot_contacts": "contacts"},
}
COMMON_KEYS = ("type", "frame_indices", "times")
BVH_KEYS = ("bvh", "source_frames", "source_times", "scale", "recenter")


# ---------------------------------------------------------------------------- JSON values
def _resolve_file(path: str, base_dirs: Sequence[Path]) -> Path:
    """A relative path is looked up in each of ``base_dirs`` in turn (the constraints file's folder,
    then the current directory); an absolute one is used as is."""
    p = Path(path).expanduser()
    candidates = [p] if p.is_absolute() else [Path(b) / p for b in base_dirs]
    for c in candidates:
        if c.is_file():
            return c
    tried = ", ".join(str(c) for c in candidates)
    raise ConstraintError(f"BVH file not found: {path} (looked for {tried})", field="bvh")


# ---------------------------------------------------------------------------- parsing
def parse_constraint(
    obj, *, base_dirs: Sequence[Path] = (), skeleton: Skeleton | None = None, fps: float | None = None
) -> Constraint:
    """One JSON object -> constraint (not yet checked against skeleton/duration, except that a
    ``bvh`` source needs ``skeleton`` and ``fps``). Errors carry field names as written in JSON."""
    if not isinstance(obj, dict):
        raise ConstraintError(f"expected a JSON object, got {type(obj).__name__}")
    if "type" not in obj:
        raise ConstraintError("missing required field", field="type")
    kind = obj["type"]
    joint = EFFECTOR_SHORTHANDS.get(kind) if isinstance(kind, str) else None
    canonical = "end-effector" if joint else kind
    if canonical not in CONSTRAINT_TYPES:
        known = sorted([*CONSTRAINT_TYPES, *EFFECTOR_SHORTHANDS])
        raise ConstraintError(f"unknown constraint type {json.dumps(kind)}; choose from {known}", field="type")
    keys = KEYS[canonical]
    allowed = {*COMMON_KEYS, *keys, *(BVH_KEYS if canonical == "fullbody" else ())}
    kwargs: dict = {}
    written: dict[str, str] = {}
    for key, value in obj.items():
        if key.startswith("_") or key == "comment":
            continue
        if key not in allowed:
            raise ConstraintError(f"unknown field for type {kind!r}; expected one of {sorted(allowed)}", field=key)
        attr = keys.get(key)
        if attr is None:
            continue
        if attr in written:
            raise ConstraintError(f"given twice (also as {written[attr]!r})", field=key)
        written[attr] = key
        if attr == "joint":
            if not isinstance(value, str):
                raise ConstraintError(f"expected a joint name, got {json.dumps(value)}", field=key)
            if joint and value != joint:
                raise ConstraintError(f"type {kind!r} already fixes the joint to {joint!r}", field=key)
            kwargs[attr] = value
        elif attr == "dense":
            if not isinstance(value, bool):
                raise ConstraintError(f"expected true or false, got {json.dumps(value)}", field=key)
            kwargs[attr] = value
        else:
            kwargs[attr] = json_array(value, key, allow_bool=canonical == "foot-contact")
    if joint:
        kwargs["joint"] = joint
    elif canonical == "end-effector" and "joint" not in kwargs:
        raise ConstraintError("missing required field", field="joint")
    for key in ("frame_indices", "times"):
        if key in obj:
            kwargs[key] = int_list(obj[key], key) if key == "frame_indices" else time_list(obj[key])
    if canonical == "fullbody" and "bvh" in obj:
        return _fullbody_from_json(obj, kwargs, base_dirs, skeleton, fps)
    for key in BVH_KEYS[1:]:
        if key in obj:
            raise ConstraintError("only used together with 'bvh'", field=key)
    return CONSTRAINT_TYPES[canonical](**kwargs)


def _fullbody_from_json(obj: dict, kwargs: dict, base_dirs, skeleton, fps) -> FullBodyConstraint:
    for key in ("local_joints_rot", "local_rotations", "root_positions"):
        if key in obj:
            raise ConstraintError(
                f"give either 'bvh' or 'local_joints_rot' + 'root_positions', not both ('{key}' given)", field="bvh"
            )
    if skeleton is None or fps is None:
        raise ConstraintError("reading poses from a BVH file needs the model skeleton and fps", field="bvh")
    if not isinstance(obj["bvh"], str):
        raise ConstraintError(f"expected a file path, got {json.dumps(obj['bvh'])}", field="bvh")
    if ("source_frames" in obj) == ("source_times" in obj):
        raise ConstraintError(
            "give exactly one of 'source_frames' and 'source_times' (the poses of the BVH clip to take)",
            field="source_frames",
        )
    source = int_list(obj["source_frames"], "source_frames") if "source_frames" in obj else None
    source_times = time_list(obj["source_times"], "source_times") if "source_times" in obj else None
    recenter = obj.get("recenter", False)
    if not isinstance(recenter, bool):
        raise ConstraintError(f"expected true or false, got {json.dumps(recenter)}", field="recenter")
    path = _resolve_file(obj["bvh"], base_dirs)
    rots, root = poses_from_bvh(
        path,
        source,
        skeleton=skeleton,
        fps=fps,
        scale=obj.get("scale", 1.0),
        recenter=recenter,
        source_times=source_times,
    )
    if "frame_indices" not in kwargs and "times" not in kwargs:
        if source is not None:
            kwargs["frame_indices"] = source
        else:
            kwargs["times"] = source_times
    return FullBodyConstraint(local_rotations=rots, root_positions=root, **kwargs)


def load_constraints(
    path_or_obj,
    skeleton: Skeleton,
    fps: float,
    num_frames: int | None = None,
    *,
    base_dir: str | os.PathLike | None = None,
    source_fps: float | None = None,
    foreign_poses: str = "root",
) -> list[Constraint]:
    """Read and validate constraints from a JSON file (path) or already parsed JSON (list or object).

    ``num_frames`` is the motion length at ``fps`` (None: no upper bound is checked). Relative
    ``bvh`` paths are looked up in ``base_dir`` if given, else in the file's folder then the current
    directory. ``frame_indices`` are at ``source_fps`` (``kinema generate --constraints-fps``) or the
    file's ``"fps"`` (they must agree when both are given), or Kimodo's 30 fps for a file next to a
    Kimodo ``meta.json``, else at ``fps``; they are converted to ``fps`` by time (kinema.constraints.fps).
    Poses written for another skeleton keep their root (x, z) as waypoints with a `ConstraintWarning`
    (``foreign_poses="root"``) or raise (``"error"``), see kinema.constraints.kimodo_examples.
    Raises `ConstraintError` (``file: constraint i (type): field 'f': reason``).
    """
    data, source, base_dirs, file_fps = read_constraints_json(path_or_obj, base_dir)
    src_fps = source_fps_for(data, file_fps=file_fps, source_fps=source_fps, source=source, model_fps=fps)
    out, foreign, frames, renames = [], [], [], []
    for i, obj in enumerate(data):
        kind = obj.get("type") if isinstance(obj, dict) else None
        kind = kind if isinstance(kind, str) else None
        written, foreign_j = obj, None
        try:
            written, foreign_j = adapt_pose_form(obj, skeleton, foreign_poses)
            if foreign_j is not None:
                foreign.append((i, kind, foreign_j))
            c = parse_constraint(
                frames_to_source_times(written, src_fps, fps), base_dirs=base_dirs, skeleton=skeleton, fps=fps
            )
            c = convert_frames(c, src_fps, fps, num_frames)
            keyframes = c.check(skeleton, fps, num_frames)
        except ConstraintError as err:
            raise err.at(index=i, kind=kind, source=source, rename=_renames(written)) from None
        if foreign_j is None or not any(c.same_as(o) for o in out):  # Kimodo repeats a pose per hand/foot
            out.append(c)
            frames.append(keyframes)
            renames.append((i, _renames(written)))
    try:
        check_coordinates(out)
        check_rotations(out)
        check_root_speeds(out, frames, fps, skeleton)
    except ConstraintError as err:  # located by its index in ``out``: report the file's own index and key
        where, rename = renames[err.index] if err.index is not None else (None, None)
        raise ConstraintError(err.reason, field=(rename or {}).get(err.field, err.field), index=where,
                              kind=err.kind, source=source) from None
    warn_foreign(foreign, source, skeleton)
    return out


def _renames(obj) -> dict[str, str]:
    """Attribute -> the JSON key the user wrote (else the canonical key), for error messages."""
    kind = obj.get("type") if isinstance(obj, dict) else None
    if not isinstance(kind, str):
        return {}
    keys = KEYS.get("end-effector" if kind in EFFECTOR_SHORTHANDS else kind, {})
    rename = {a: k for k, a in reversed(keys.items())}  # canonical key by default
    rename.update({a: k for k, a in keys.items() if k in obj})  # the key the user wrote
    return rename


# ---------------------------------------------------------------------------- writing
def constraint_to_json(c: Constraint) -> dict:
    """A constraint as a JSON-ready dict with the canonical keys (arrays as nested lists)."""
    kind = c.kind
    out: dict = {"type": kind}
    if c.frame_indices is not None:
        out["frame_indices"] = [int(f) for f in c.frame_indices]
    if c.times is not None:
        out["times"] = [float(t) for t in c.times]
    written = set()
    for key, attr in KEYS[kind].items():
        if attr in written:
            continue
        written.add(attr)
        value = getattr(c, attr)
        if attr == "dense":
            if value:
                out[key] = True
        elif isinstance(value, torch.Tensor):
            out[key] = value.tolist()
        elif value is not None:
            out[key] = value
    if isinstance(c, EndEffectorConstraint) and c.joint == "":
        raise ConstraintError("missing required field", field="joint", kind=kind)
    return out


def dumps_constraints(constraints: Sequence[Constraint]) -> str:
    """JSON text: one key per line, arrays on one line each (readable and diff-friendly)."""
    blocks = []
    for i, c in enumerate(constraints):
        try:
            d = constraint_to_json(c)
            lines = [f"    {json.dumps(k)}: {json.dumps(v, allow_nan=False)}" for k, v in d.items()]
        except ValueError:
            raise ConstraintError("contains NaN or inf; nothing written", index=i, kind=c.kind) from None
        except ConstraintError as err:
            raise err.at(index=i) from None
        blocks.append("  {\n" + ",\n".join(lines) + "\n  }")
    return "[\n" + ",\n".join(blocks) + "\n]\n"


def save_constraints(constraints: Sequence[Constraint], path: str | os.PathLike) -> Path:
    """Write constraints as JSON atomically (temp file + rename); `load_constraints` reads it back."""
    text = dumps_constraints(constraints)
    atomic_write_bytes(Path(path), text.encode("utf-8"))
    return Path(path)
