"""Objectives in JSON: the ``"objectives"`` list of a constraints file (format in docs/objectives.md).

A constraints file in its object form may carry objectives next to (or instead of) constraints::

    {"constraints": [...], "objectives": [
        {"type": "reach", "joint": "Hand_R", "target": [0.3, 1.6, 0.4], "window": [2.0, 4.0]}]}

Every object has a ``type`` and the keys of that type; ``weight`` and ``window`` ([t0, t1] seconds) are
common; ``comment`` and keys starting with ``_`` are ignored; any other key is an error naming it.
Errors are `ObjectiveError`: ``file: objective i (type): field 'f': reason`` on one line.
"""

from __future__ import annotations

import json
import math
import numbers
import os

from kinema.constraints.types import ConstraintError
from kinema.errors import KinemaError
from kinema.input_files import read_text_bounded
from kinema.objectives.path import PathTimeAgnostic
from kinema.objectives.terms import Avoid, JointDistance, Objective, Reach, Realism, StayWithin

COMMON = ("type", "weight", "window")
KEYS = {
    "reach": ("joint", "target"),
    "joint-distance": ("joints", "distance", "when"),
    "hand-to-head": ("hand", "distance", "when"),
    "avoid": ("joints", "spheres", "boxes"),
    "stay-within": ("joints", "min", "max"),
    "path-time-agnostic": ("joint", "path", "scale_weight"),
    "realism": (),
}
REQUIRED = {
    "reach": ("joint", "target"),
    "joint-distance": ("joints",),
    "path-time-agnostic": ("joint", "path"),
    "avoid": (),
    "stay-within": (),
    "hand-to-head": (),
    "realism": (),
}


class ObjectiveError(KinemaError):
    """A malformed objective: ``[source: ][objective i (type): ][field 'f': ]reason``."""

    def __init__(
        self,
        reason: str,
        *,
        field: str | None = None,
        index: int | None = None,
        kind: str | None = None,
        source: str | None = None,
    ):
        self.reason, self.field, self.index, self.kind, self.source = reason, field, index, kind, source
        parts = [] if source is None else [str(source)]
        if index is not None:
            parts.append(f"objective {index}" + (f" ({kind})" if kind else ""))
        if field is not None:
            parts.append(f"field '{field}'")
        super().__init__(": ".join([*parts, reason]))


def _num(v, key: str) -> float:
    if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
        raise ObjectiveError(f"expected a finite number, got {json.dumps(v)}", field=key)
    return float(v)


def _vec(v, key: str, sizes=(3,), nullable: bool = False) -> tuple:
    if not isinstance(v, list) or len(v) not in sizes:
        want = " or ".join(str(s) for s in sizes)
        raise ObjectiveError(f"expected a list of {want} numbers, got {json.dumps(v)}", field=key)
    return tuple(None if (nullable and x is None) else _num(x, key) for x in v)


def _names(v, key: str, count: int | None = None) -> tuple[str, ...]:
    if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v) or (count and len(v) != count):
        n = f"{count} " if count else ""
        raise ObjectiveError(f"expected a list of {n}joint names, got {json.dumps(v)}", field=key)
    return tuple(v)


def _window(v):
    w = _vec(v, "window", sizes=(2,))
    if w[0] < 0 or w[1] < w[0]:
        raise ObjectiveError(f"expected [t0, t1] seconds with 0 <= t0 <= t1, got {json.dumps(v)}", field="window")
    return w


def _shapes(obj: dict):
    spheres = obj.get("spheres", [])
    boxes = obj.get("boxes", [])
    if not isinstance(spheres, list) or not isinstance(boxes, list):
        raise ObjectiveError("expected lists of {center, radius} / {min, max} objects", field="spheres/boxes")
    out_s, out_b = [], []
    for s in spheres:
        if not isinstance(s, dict) or set(s) != {"center", "radius"}:
            raise ObjectiveError(f'expected {{"center": [x, y, z], "radius": r}}, got {json.dumps(s)}', field="spheres")
        r = _num(s["radius"], "spheres")
        if r <= 0:
            raise ObjectiveError(f"radius must be positive, got {r:g}", field="spheres")
        out_s.append((_vec(s["center"], "spheres"), r))
    for b in boxes:
        if not isinstance(b, dict) or set(b) != {"min", "max"}:
            raise ObjectiveError(f'expected {{"min": [x, y, z], "max": [x, y, z]}}, got {json.dumps(b)}', field="boxes")
        out_b.append((_vec(b["min"], "boxes"), _vec(b["max"], "boxes")))
    if not out_s and not out_b:
        raise ObjectiveError("give at least one sphere or box", field="spheres")
    return tuple(out_s), tuple(out_b)


def _when(obj) -> str:
    when = obj.get("when", "any")
    if when not in ("any", "all"):
        raise ObjectiveError(f'expected "any" or "all", got {json.dumps(when)}', field="when")
    return when


def _build(kind: str, obj: dict, common: dict) -> Objective:
    if kind == "reach":
        return Reach(joint=_names([obj["joint"]], "joint")[0], target=_vec(obj["target"], "target"), **common)
    if kind in ("joint-distance", "hand-to-head"):
        if kind == "hand-to-head":
            hand = obj.get("hand", "right")
            if hand not in ("left", "right"):
                raise ObjectiveError(f'expected "left" or "right", got {json.dumps(hand)}', field="hand")
            joints = (f"{hand}_hand", "head")
        else:
            joints = _names(obj["joints"], "joints", count=2)
        distance = _num(obj.get("distance", 0.1 if kind == "hand-to-head" else 0.0), "distance")
        if distance < 0:
            raise ObjectiveError(f"expected a distance >= 0, got {distance:g}", field="distance")
        return JointDistance(joints=joints, distance=distance, when=_when(obj), **common)
    if kind == "avoid":
        spheres, boxes = _shapes(obj)
        return Avoid(joints=_names(obj.get("joints", []), "joints"), spheres=spheres, boxes=boxes, **common)
    if kind == "stay-within":
        lo, hi = (_vec(obj.get(k, [None] * 3), k, nullable=True) for k in ("min", "max"))
        if all(v is None for v in lo + hi):
            raise ObjectiveError("give at least one bound in min or max", field="min")
        return StayWithin(joints=_names(obj.get("joints", []), "joints"), min=lo, max=hi, **common)
    if kind == "path-time-agnostic":
        path = obj["path"]
        if not isinstance(path, list) or len(path) < 2:
            raise ObjectiveError("expected a list of at least 2 points", field="path")
        pts = tuple(_vec(p, "path", sizes=(2, 3)) for p in path)
        if len({len(p) for p in pts}) != 1:
            raise ObjectiveError("points must all be (x, y, z) or all ground (x, z)", field="path")
        sw = _num(obj.get("scale_weight", 0.5), "scale_weight")
        return PathTimeAgnostic(joint=_names([obj["joint"]], "joint")[0], path=pts, scale_weight=sw, **common)
    return Realism(**common)


def parse_objective(obj) -> Objective:
    """One objective from its JSON object (raises `ObjectiveError` without location)."""
    if isinstance(obj, Objective):
        return obj
    if not isinstance(obj, dict):
        raise ObjectiveError(f"expected an object, got {json.dumps(obj)[:80]}")
    kind = obj.get("type")
    if kind not in KEYS:
        raise ObjectiveError(f"unknown objective type {json.dumps(kind)}; expected one of {sorted(KEYS)}", field="type")
    allowed = set(COMMON) | set(KEYS[kind])
    for key in obj:
        if key not in allowed and key != "comment" and not key.startswith("_"):
            raise ObjectiveError(f"unknown key for a {kind} objective; expected {sorted(allowed)}", field=key)
    for key in REQUIRED[kind]:
        if key not in obj:
            raise ObjectiveError("missing required field", field=key)
    weight = _num(obj.get("weight", 1.0), "weight")
    if weight < 0:
        raise ObjectiveError(f"expected a weight >= 0, got {weight:g}", field="weight")
    window = _window(obj["window"]) if "window" in obj else None
    return _build(kind, obj, {"weight": weight, "window": window})


def load_objectives(path_or_obj) -> list[Objective]:
    """Objectives from a constraints file's ``"objectives"`` (path; a plain list file has none), a list
    of JSON objects / `Objective` objects, or None (no objectives)."""
    source = None
    if path_or_obj is None:
        return []
    if isinstance(path_or_obj, str | os.PathLike):
        source = str(path_or_obj)
        text = read_text_bounded(path_or_obj, "constraints file")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as err:  # before ValueError: a syntax error is no unreadable file
            raise ObjectiveError(f"not valid JSON: line {err.lineno}, column {err.colno}: {err.msg}",
                                 source=source) from None
        except RecursionError:
            raise ObjectiveError("JSON nested too deeply to read (not a constraints file)", source=source) from None
        items = data.get("objectives", []) if isinstance(data, dict) else []
    elif isinstance(path_or_obj, dict):
        items = path_or_obj.get("objectives", [])
    else:
        items = path_or_obj
    if not isinstance(items, list):
        raise ObjectiveError(
            f"expected a list of objective objects, got {type(items).__name__}", field="objectives", source=source
        )
    out = []
    for i, obj in enumerate(items):
        kind = obj.get("type") if isinstance(obj, dict) else getattr(obj, "kind", None)
        try:
            out.append(parse_objective(obj))
        except ObjectiveError as err:
            raise ObjectiveError(err.reason, field=err.field, index=i, kind=kind, source=source) from None
    return out


def bind_objectives(objectives: list[Objective], skeleton, fps: float, num_frames: int):
    """Bound objectives (joint names and windows checked against the rig and the motion's length)."""
    out = []
    for i, o in enumerate(objectives):
        try:
            out.append(o.bind(skeleton, fps, num_frames))
        except ConstraintError as err:
            raise ObjectiveError(err.reason, field=err.field, index=i, kind=o.kind) from None
    return out
