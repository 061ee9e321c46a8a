"""Rig overrides: a small JSON object (file or mapping) that replaces what kinema.rig.find guessed.

Keys (all optional; joints by exact name or role, kinema.skeleton.Skeleton.index)::

    {"root": "Hips",
     "up": [0, 1, 0], "forward": [0, 0, 1],
     "contacts": ["Foot_L", "Toes_L", "Foot_R", "Toes_R"],
     "end_effectors": {"tail": "Tail_05"},
     "limbs": {"tail": ["Tail_01", "Tail_02", "Tail_03"]}}

``end_effectors`` and ``limbs`` replace the found ones entirely when given. Any other key is an error
naming the closest valid key, and ``comment`` / ``_anything`` keys are ignored (notes for humans).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from pathlib import Path

from kinema.errors import SkeletonError
from kinema.input_files import read_json_bounded
from kinema.skeleton import Skeleton

OVERRIDE_KEYS = ("root", "up", "forward", "contacts", "end_effectors", "limbs")


def read_overrides(overrides: str | Path | Mapping | None) -> tuple[dict, str]:
    """(the override mapping, where it came from) from a JSON file path or a mapping; unknown keys raise."""
    if overrides is None:
        return {}, "overrides"
    source = "overrides"
    if isinstance(overrides, (str, Path)):
        source = str(overrides)
        overrides = read_json_bounded(overrides, "rig override file", error=SkeletonError)
    if not isinstance(overrides, Mapping):
        raise SkeletonError(f"{source}: rig overrides must be a JSON object with keys {list(OVERRIDE_KEYS)}")
    out = {}
    for key, value in overrides.items():
        if key == "comment" or (isinstance(key, str) and key.startswith("_")):
            continue
        if key not in OVERRIDE_KEYS:
            close = difflib.get_close_matches(str(key), OVERRIDE_KEYS, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise SkeletonError(
                f"{source}: unknown rig override key {key!r}{hint}; expected some of {list(OVERRIDE_KEYS)}"
            )
        out[key] = value
    return out, source


def joint(skeleton: Skeleton, value, source: str, field: str) -> int:
    """A joint index from a name / role (or an index), with an error naming the field."""
    if isinstance(value, int) and not isinstance(value, bool):
        if 0 <= value < skeleton.num_joints:
            return value
        raise SkeletonError(f"{source}: '{field}': joint index {value} outside 0..{skeleton.num_joints - 1}")
    if not isinstance(value, str):
        raise SkeletonError(f"{source}: '{field}' must name a joint, got {value!r}")
    try:
        return skeleton.index(value)
    except SkeletonError:
        raise SkeletonError(
            f"{source}: '{field}' names unknown joint {value!r}; joints are {list(skeleton.names)}"
        ) from None


def joints(skeleton: Skeleton, values, source: str, field: str) -> tuple[int, ...]:
    if not isinstance(values, (list, tuple)):
        raise SkeletonError(f"{source}: '{field}' must be a list of joint names, got {values!r}")
    return tuple(joint(skeleton, v, source, f"{field}[{i}]") for i, v in enumerate(values))


def named_joints(skeleton: Skeleton, mapping, source: str, field: str) -> dict[str, int]:
    if not isinstance(mapping, Mapping):
        raise SkeletonError(f"{source}: '{field}' must be an object {{name: joint}}, got {mapping!r}")
    return {str(k): joint(skeleton, v, source, f"{field}.{k}") for k, v in mapping.items()}


def named_chains(skeleton: Skeleton, mapping, source: str, field: str) -> dict[str, tuple[int, ...]]:
    if not isinstance(mapping, Mapping):
        raise SkeletonError(f"{source}: '{field}' must be an object {{name: [joints]}}, got {mapping!r}")
    return {str(k): joints(skeleton, v, source, f"{field}.{k}") for k, v in mapping.items()}


def axis(value, source: str, field: str) -> tuple[float, float, float]:
    """A unit axis from three numbers (normalised; zero or non-finite is an error)."""
    try:
        x, y, z = (float(v) for v in value)
    except (TypeError, ValueError):
        raise SkeletonError(f"{source}: '{field}' must be three numbers, got {value!r}") from None
    n = (x * x + y * y + z * z) ** 0.5
    if not n > 0 or n != n or n == float("inf"):
        raise SkeletonError(f"{source}: '{field}' must be a non-zero finite vector, got {value!r}")
    return (x / n, y / n, z / n)
