"""Frame rates of constraint files: the ``{"fps": ..., "constraints": [...]}`` form and frame conversion.

A constraints file is either a JSON list of constraint objects (its ``frame_indices`` are at the
model's fps) or an object ``{"fps": 30, "constraints": [...]}`` whose ``frame_indices`` (and BVH
``source_frames``) are at that fps. `source_fps_for` picks the fps a file's frames are read at (the
file's ``fps``, the caller's ``source_fps`` such as ``kinema generate --constraints-fps``, Kimodo's 30
fps for a Kimodo example folder, else the model fps) and `convert_frames` moves a constraint's frames
to the model fps by time: frame ``floor(f * fps / source_fps + 0.5)``, the rule ``times`` follow.
A per-frame root path (consecutive frames) that would put two points on one model frame is resampled
onto the model's frames by linear interpolation; other frames that collide are an error.
"""

from __future__ import annotations

import json
import math
import numbers
import os
import warnings
from pathlib import Path

import numpy as np
import torch

from kinema.constraints.kimodo_examples import KIMODO_FPS, find_kimodo_meta
from kinema.constraints.types import (
    Constraint,
    ConstraintError,
    ConstraintWarning,
    Root2DConstraint,
    frames_from_times,
)
from kinema.errors import KinemaError
from kinema.input_files import read_text_bounded

FILE_KEYS = ("fps", "constraints", "objectives")  # objectives: read by kinema.objectives.io


def read_constraints_json(path_or_obj, base_dir=None) -> tuple[list, str | None, list[Path], float | None]:
    """A constraints file (path) or parsed JSON -> ``(constraint objects, source, base dirs, file fps)``.

    ``source`` is the path as given (for messages; None for parsed JSON), the base dirs are where
    relative ``bvh`` paths are looked up, the file fps is None for the plain list form.
    """
    source = None
    if isinstance(path_or_obj, str | os.PathLike):
        path = Path(path_or_obj)
        source = str(path_or_obj)
        if not path.exists():
            raise ConstraintError("file not found", source=source)
        text = read_text_bounded(path, "constraints file")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as err:
            raise ConstraintError(f"not valid JSON: line {err.lineno}, column {err.colno}: {err.msg}",
                                  source=source) from None
        except RecursionError:
            raise ConstraintError("JSON nested too deeply to read (not a constraints file)", source=source) from None
        base_dirs = [Path(base_dir)] if base_dir is not None else [path.parent, Path.cwd()]
    else:
        data = path_or_obj
        base_dirs = [Path(base_dir) if base_dir is not None else Path.cwd()]
    file_fps = None
    if isinstance(data, dict):
        data, file_fps = _object_form(data, source)
    if not isinstance(data, list):
        raise ConstraintError(f"expected a JSON list of constraint objects (or an object "
                              f'{{"fps": ..., "constraints": [...]}}), got {type(data).__name__}', source=source)
    return data, source, base_dirs, file_fps


def _object_form(data: dict, source: str | None) -> tuple[object, float | None]:
    for key in data:
        if key not in FILE_KEYS and key != "comment" and not key.startswith("_"):
            raise ConstraintError(f"unknown top-level field; expected {list(FILE_KEYS)} (and 'comment', '_...')",
                                  field=key, source=source)
    if "constraints" not in data and "objectives" in data:
        data = dict(data, constraints=[])  # objectives only (kinema.objectives)
    if "constraints" not in data:
        raise ConstraintError("missing required field (the list of constraint objects)", field="constraints",
                              source=source)
    if not isinstance(data["constraints"], list):
        raise ConstraintError(f"expected a list of constraint objects, got {type(data['constraints']).__name__}",
                              field="constraints", source=source)
    fps = data.get("fps")
    if fps is not None:
        fps = check_fps(fps, what="the frame rate of the file's frame_indices", field="fps", source=source)
    return data["constraints"], fps


def check_fps(value, *, what: str = "a frame rate", field: str | None = None, source: str | None = None) -> float:
    """A positive, finite number of frames per second (else `ConstraintError`)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (math.isfinite(value) and value > 0):
        raise ConstraintError(f"expected a positive number of frames per second ({what}), got {json.dumps(value)}",
                              field=field, source=source)
    return float(value)


def _uses_frames(data: list) -> bool:
    return any(isinstance(o, dict) and ("frame_indices" in o or "source_frames" in o) for o in data)


def source_fps_for(data: list, *, file_fps: float | None, source_fps: float | None, source: str | None,
                   model_fps: float) -> float:
    """The fps a file's frame numbers are at: the file's ``fps`` and the caller's ``source_fps`` must
    agree when both are given; a list file next to a Kimodo ``meta.json`` is at Kimodo's 30 fps (a
    `ConstraintWarning` says so); otherwise the model fps."""
    if source_fps is not None:
        try:
            source_fps = check_fps(source_fps, what="constraints fps")
        except ConstraintError as err:
            raise KinemaError(str(err)) from None
    if file_fps is not None:
        if source_fps is not None and not math.isclose(file_fps, source_fps, rel_tol=1e-9):
            raise ConstraintError(f"the file says its frames are at {file_fps:g} fps but {source_fps:g} fps was "
                                  "asked for (constraints fps option); drop one of them", field="fps", source=source)
        return file_fps
    if source_fps is not None:
        return source_fps
    meta = find_kimodo_meta(source) if source is not None else None
    if meta is not None and _uses_frames(data):
        warnings.warn(f"{source}: no 'fps' key, and a Kimodo meta.json lies next to it ({meta}): reading its "
                      f"frame_indices at Kimodo's {KIMODO_FPS:g} fps (converted to the model's {model_fps:g} fps); "
                      'write {"fps": ..., "constraints": [...]} or pass the constraints fps to choose',
                      ConstraintWarning, stacklevel=3)
        return KIMODO_FPS
    return float(model_fps)


def frames_to_source_times(obj, source_fps: float, fps: float):
    """A BVH-pose object whose ``source_frames`` are at ``source_fps``: the same poses as ``source_times``
    (seconds), so that the clip resampled to the model fps is indexed by time. Other objects unchanged."""
    if math.isclose(source_fps, fps, rel_tol=1e-9) or not isinstance(obj, dict) or "source_frames" not in obj:
        return obj
    raw = obj["source_frames"]
    if "source_times" in obj or not isinstance(raw, list) or not all(_is_frame(f) for f in raw):
        return obj  # the usual checks report it
    out = {k: v for k, v in obj.items() if k != "source_frames"}
    out["source_times"] = [int(f) / source_fps for f in raw]
    return out


def _is_frame(f) -> bool:
    return (not isinstance(f, bool) and isinstance(f, numbers.Real) and math.isfinite(f) and float(f) == int(f)
            and f >= 0)


def convert_frames(c: Constraint, source_fps: float, fps: float, num_frames: int | None = None) -> Constraint:
    """``c`` with its ``frame_indices`` moved from ``source_fps`` to ``fps`` by time (``times`` need no
    conversion). Invalid frames are left for `Constraint.check` to report."""
    if c.frame_indices is None or math.isclose(source_fps, fps, rel_tol=1e-9):
        return c
    raw = list(c.frame_indices)
    if not raw or not all(_is_frame(f) for f in raw):
        return c
    raw = [int(f) for f in raw]
    frames = frames_from_times([f / source_fps for f in raw], fps)
    if num_frames is not None:
        frames = [_inside(f, g, source_fps, fps, num_frames) for f, g in zip(raw, frames, strict=True)]
    if len(set(frames)) == len(frames) or len(set(raw)) != len(raw):
        return c.copy(frame_indices=frames)  # repeated source frames: reported by check
    if isinstance(c, Root2DConstraint) and _is_path(raw, c.dense):
        return _resample_path(c, raw, source_fps, fps, num_frames)
    clash = next((a, b, g) for (a, g), (b, h) in _pairs(raw, frames) if g == h)
    raise ConstraintError(
        f"frames {clash[0]} and {clash[1]} at {source_fps:g} fps both fall on frame {clash[2]} at the model's "
        f"{fps:g} fps; keep keyframes at least {source_fps / fps:.3g} frames apart, or use 'times'",
        field="frame_indices")


def _inside(f: int, g: int, source_fps: float, fps: float, num_frames: int) -> int:
    """Model frame ``g`` of source frame ``f``; a time inside the motion (``< num_frames / fps``) whose
    nearest frame is one past the end goes to the last frame, a later one is an error."""
    if g < num_frames:
        return g
    if f / source_fps < num_frames / fps - 1e-9:
        return num_frames - 1
    raise ConstraintError(
        f"frame {f} at {source_fps:g} fps ({f / source_fps:.3f} s, frame {g} at {fps:g} fps) is beyond the "
        f"motion's duration: the motion lasts {num_frames} frames = {num_frames / fps:.3f} s at {fps:g} fps "
        f"(last frame {num_frames - 1})", field="frame_indices")


def _pairs(raw: list[int], frames: list[int]):
    items = sorted(zip(raw, frames, strict=True))
    return zip(items, items[1:], strict=False)


def _is_path(raw: list[int], dense: bool) -> bool:
    """Increasing keyframes that describe a path: a dense one, or one point per frame."""
    increasing = all(b > a for a, b in zip(raw, raw[1:], strict=False))
    return increasing and (dense or all(b == a + 1 for a, b in zip(raw, raw[1:], strict=False)))


def _resample_path(c: Root2DConstraint, raw: list[int], source_fps: float, fps: float,
                   num_frames: int | None) -> Root2DConstraint:
    """A root path sampled at ``source_fps`` -> every model frame inside its time span (linear)."""
    first = math.ceil(raw[0] * fps / source_fps - 1e-9)
    last = math.floor(raw[-1] * fps / source_fps + 1e-9)
    if num_frames is not None:
        last = min(last, num_frames - 1)
    frames = list(range(first, last + 1))
    at = np.array(frames, dtype=np.float64) * source_fps / fps
    src = np.array(raw, dtype=np.float64)

    def interp(v: torch.Tensor | None) -> torch.Tensor | None:
        if v is None or v.shape[0] != len(raw):
            return v  # wrong shapes are reported by check
        cols = [np.interp(at, src, v[:, i].numpy()) for i in range(v.shape[1])]
        return torch.from_numpy(np.stack(cols, axis=-1))

    heading = interp(c.heading)
    if heading is not None and heading.shape[0] == len(frames):
        norm = heading.norm(dim=-1, keepdim=True)
        heading = torch.where(norm > 1e-9, heading / norm.clamp_min(1e-12), heading)
    return c.copy(frame_indices=frames, positions=interp(c.positions), heading=heading)
