"""Checks of JSON list values shared by the constraint reader (kinema.constraints.io) and the BVH
pose source (kinema.constraints.bvh_poses); errors are `ConstraintError` naming the JSON field."""

from __future__ import annotations

import json
import numbers

from kinema.constraints.types import ConstraintError


def int_list(value, key: str) -> list[int]:
    """``value`` itself when it is a JSON list (its elements are checked later, by Constraint.frames)."""
    if not isinstance(value, list):
        raise ConstraintError(f"expected a list of integers, got {json.dumps(value)}", field=key)
    return value  # element checks (integers, range) happen in Constraint.frames


def time_list(value, key: str = "times") -> list[float]:
    """A JSON list of real numbers (seconds) as floats; booleans and other values are refused."""
    if not isinstance(value, list) or any(isinstance(t, bool) or not isinstance(t, numbers.Real) for t in value):
        raise ConstraintError(f"expected a list of times in seconds, got {value!r}", field=key)
    return [float(t) for t in value]
